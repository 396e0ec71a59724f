//! The 3DGS adaptive density control as plain functions on a [`GaussianSet`] and its [`GaussianAdam`]
//! state: accumulate screen-space positional gradients, clone small and split large Gaussians above a
//! threshold, prune by opacity and size, and reset opacities.
//!
//! Every operation acts on the set, its optimiser moments and the statistics together, so the
//! per-Gaussian arrays stay aligned. Randomness (split sampling) comes from an explicit seed.
//! Scheduling (when to call what) belongs to the training loop, not here.

use crate::adam::GaussianAdam;
use crate::covariance::rotation_from_quat;
use crate::set::{inverse_sigmoid, sigmoid, GaussianSet};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Per-Gaussian statistics gathered between densification steps.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct DensityStats {
    /// Sum over views of ‖∂L/∂(mean in NDC)‖ (the 3DGS convention: pixel gradients × W/2, H/2).
    pub grad_accum: Vec<f32>,
    /// Number of views in which the Gaussian was visible.
    pub visible_count: Vec<u32>,
    /// Largest screen-space radius (pixels) seen.
    pub max_radius: Vec<f32>,
}

impl DensityStats {
    /// Zeroed statistics for `n` Gaussians.
    pub fn new(n: usize) -> Self {
        Self {
            grad_accum: vec![0.0; n],
            visible_count: vec![0; n],
            max_radius: vec![0.0; n],
        }
    }

    /// Adds one view: `grad_ndc[i]` is ∂L/∂(screen mean of i) in NDC units and `radius[i]` its
    /// screen radius in pixels (0 when not visible, which skips the Gaussian).
    pub fn accumulate(&mut self, grad_ndc: &[[f32; 2]], radius: &[f32]) {
        for i in 0..self.grad_accum.len() {
            if radius[i] > 0.0 {
                let [gx, gy] = grad_ndc[i];
                self.grad_accum[i] += (gx * gx + gy * gy).sqrt();
                self.visible_count[i] += 1;
                self.max_radius[i] = self.max_radius[i].max(radius[i]);
            }
        }
    }

    /// Adds one view whose gradient norms are already taken: `norm[i]` is ‖∂L/∂(screen mean of
    /// i)‖ in NDC units (e.g. summed over several renders of one view), `radius[i]` as in
    /// [`DensityStats::accumulate`].
    pub fn accumulate_norms(&mut self, norm: &[f32], radius: &[f32]) {
        for i in 0..self.grad_accum.len() {
            if radius[i] > 0.0 {
                self.grad_accum[i] += norm[i];
                self.visible_count[i] += 1;
                self.max_radius[i] = self.max_radius[i].max(radius[i]);
            }
        }
    }

    /// Mean accumulated gradient norm of Gaussian `i` (0 if never visible).
    pub fn mean_grad(&self, i: usize) -> f32 {
        if self.visible_count[i] == 0 {
            0.0
        } else {
            self.grad_accum[i] / self.visible_count[i] as f32
        }
    }
}

/// Settings of one densify-and-prune pass (defaults: the INRIA 3DGS values).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DensifyConfig {
    /// Mean NDC gradient norm above which a Gaussian is densified (3DGS: 2e-4).
    pub grad_threshold: f32,
    /// Gaussians with largest scale ≤ `percent_dense · scene_extent` are cloned, larger ones split
    /// (3DGS: 0.01).
    pub percent_dense: f32,
    /// Scene extent in metres (radius of the camera centres' bounding sphere × 1.1 in 3DGS).
    pub scene_extent: f32,
    /// Prune Gaussians with opacity below this (3DGS: 0.005; 3DGS-Avatar: 0.05).
    pub min_opacity: f32,
    /// Prune Gaussians whose screen radius exceeded this many pixels (None: no screen-size pruning).
    pub max_screen_radius: Option<f32>,
    /// Prune Gaussians with largest scale above this fraction of the extent (3DGS: 0.1), applied
    /// together with the screen-size rule as in 3DGS.
    pub max_world_size_fraction: f32,
    /// Upper bound on the number of Gaussians after densification (densification is skipped for the
    /// lowest-gradient candidates beyond it).
    pub max_gaussians: usize,
}

impl Default for DensifyConfig {
    fn default() -> Self {
        Self {
            grad_threshold: 2e-4,
            percent_dense: 0.01,
            scene_extent: 1.0,
            min_opacity: 0.005,
            max_screen_radius: None,
            max_world_size_fraction: 0.1,
            max_gaussians: usize::MAX,
        }
    }
}

/// What one densify-and-prune pass did.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct DensifyReport {
    /// Gaussians cloned.
    pub cloned: usize,
    /// Gaussians split (each replaced by two).
    pub split: usize,
    /// Gaussians pruned (after densification).
    pub pruned: usize,
}

/// Split children are placed at the parent's centre plus a normal sample in the parent's frame,
/// truncated to this Mahalanobis radius so each child's 3σ ellipsoid (parent scales / 1.6) lies inside
/// the parent's 3σ ellipsoid: 3·(1 − 1/1.6) = 1.125. (3DGS samples untruncated.)
pub const SPLIT_SAMPLE_MAX_RADIUS: f32 = 1.125;

/// Scale divisor of split children, 0.8 · N with N = 2 children (the 3DGS value).
pub const SPLIT_SCALE_DIVISOR: f32 = 1.6;

/// Removes the Gaussians whose `keep` flag is false from the set, its Adam state and its statistics.
pub fn prune(
    set: &mut GaussianSet,
    adam: &mut GaussianAdam,
    stats: &mut DensityStats,
    keep: &[bool],
) {
    adam.retain(set, keep);
    set.retain(keep);
    crate::set::retain_rows(&mut stats.grad_accum, 1, keep);
    crate::set::retain_rows(&mut stats.visible_count, 1, keep);
    crate::set::retain_rows(&mut stats.max_radius, 1, keep);
}

/// Appends copies of `rows` (already-built Gaussians) with zero Adam moments and zero statistics.
fn append_new(
    set: &mut GaussianSet,
    adam: &mut GaussianAdam,
    stats: &mut DensityStats,
    rows: &GaussianSet,
) {
    adam.append_zero_rows(set, rows.len());
    // Shapes were taken from `set` itself, so appending cannot fail.
    if set.append(rows).is_err() {
        unreachable!("density control appends rows shaped like the set");
    }
    let n = set.len();
    stats.grad_accum.resize(n, 0.0);
    stats.visible_count.resize(n, 0);
    stats.max_radius.resize(n, 0.0);
}

/// Two children for each parent index, sampled as described at [`SPLIT_SAMPLE_MAX_RADIUS`].
pub fn split_children(set: &GaussianSet, parents: &[usize], seed: u64) -> GaussianSet {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let doubled: Vec<usize> = parents.iter().flat_map(|&p| [p, p]).collect();
    let mut children = set.select(&doubled);
    for (c, &p) in doubled.iter().enumerate() {
        let scales = set.scales(p);
        let rot = rotation_from_quat(set.quats[p]);
        let z = loop {
            let z: [f32; 3] = [
                rng.sample(rand_distr::StandardNormal),
                rng.sample(rand_distr::StandardNormal),
                rng.sample(rand_distr::StandardNormal),
            ];
            if z.iter().map(|v| v * v).sum::<f32>()
                <= SPLIT_SAMPLE_MAX_RADIUS * SPLIT_SAMPLE_MAX_RADIUS
            {
                break z;
            }
        };
        let local = [z[0] * scales[0], z[1] * scales[1], z[2] * scales[2]];
        for a in 0..3 {
            children.means[c][a] = set.means[p][a]
                + rot[a][0] * local[0]
                + rot[a][1] * local[1]
                + rot[a][2] * local[2];
            children.log_scales[c][a] = set.log_scales[p][a] - SPLIT_SCALE_DIVISOR.ln();
        }
    }
    children
}

/// One 3DGS densify-and-prune pass: clone small high-gradient Gaussians, split large ones (the parents
/// are removed), then prune transparent and oversized ones. Statistics are reset afterwards.
pub fn densify_and_prune(
    set: &mut GaussianSet,
    adam: &mut GaussianAdam,
    stats: &mut DensityStats,
    config: &DensifyConfig,
    seed: u64,
) -> DensifyReport {
    let n = set.len();
    let size_limit = config.percent_dense * config.scene_extent;
    let max_scale = |set: &GaussianSet, i: usize| set.scales(i).into_iter().fold(0.0f32, f32::max);
    let mut candidates: Vec<usize> = (0..n)
        .filter(|&i| stats.mean_grad(i) >= config.grad_threshold)
        .collect();
    // Respect the budget: cloning adds one Gaussian, splitting one net; keep the largest gradients.
    let budget = config.max_gaussians.saturating_sub(n);
    if candidates.len() > budget {
        candidates.sort_by(|&a, &b| {
            stats
                .mean_grad(b)
                .total_cmp(&stats.mean_grad(a))
                .then(a.cmp(&b))
        });
        candidates.truncate(budget);
        candidates.sort_unstable();
    }
    let (clone_idx, split_idx): (Vec<usize>, Vec<usize>) = candidates
        .into_iter()
        .partition(|&i| max_scale(set, i) <= size_limit);
    let clones = set.select(&clone_idx);
    let children = split_children(set, &split_idx, seed);
    append_new(set, adam, stats, &clones);
    append_new(set, adam, stats, &children);
    let mut keep = vec![true; set.len()];
    for &p in &split_idx {
        keep[p] = false;
    }
    let before_prune = keep.iter().filter(|&&k| k).count();
    for i in 0..set.len() {
        if set.opacity(i) < config.min_opacity {
            keep[i] = false;
        }
        if let Some(max_r) = config.max_screen_radius {
            if stats.max_radius[i] > max_r
                || max_scale(set, i) > config.max_world_size_fraction * config.scene_extent
            {
                keep[i] = false;
            }
        }
    }
    let pruned = before_prune - keep.iter().filter(|&&k| k).count();
    prune(set, adam, stats, &keep);
    *stats = DensityStats::new(set.len());
    DensifyReport {
        cloned: clone_idx.len(),
        split: split_idx.len(),
        pruned,
    }
}

/// The 3DGS opacity reset: every opacity becomes min(opacity, `max_opacity`) (3DGS: 0.01) and the
/// opacity moments are zeroed; no other parameter or moment is touched.
pub fn reset_opacity(set: &mut GaussianSet, adam: &mut GaussianAdam, max_opacity: f32) {
    let cap = inverse_sigmoid(max_opacity);
    for l in &mut set.opacity_logits {
        if sigmoid(*l) > max_opacity {
            *l = cap;
        }
    }
    adam.opacity_logits.reset();
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::adam::AdamConfig;

    fn random_set(n: usize, seed: u64) -> GaussianSet {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut s = GaussianSet::new(1, 4, 2);
        for _ in 0..n {
            let mut r = |lo: f32, hi: f32| rng.gen_range(lo..hi);
            s.push(
                [r(-1.0, 1.0), r(-1.0, 1.0), r(-1.0, 1.0)],
                [r(-4.0, -1.0), r(-4.0, -1.0), r(-4.0, -1.0)],
                [r(-1.0, 1.0), r(-1.0, 1.0), r(-1.0, 1.0), r(0.5, 1.0)],
                r(-3.0, 3.0),
                &(0..12).map(|_| r(-1.0, 1.0)).collect::<Vec<_>>(),
                &[r(-1.0, 1.0), r(-1.0, 1.0), r(-1.0, 1.0), r(-1.0, 1.0)],
                &[r(-3.0, 3.0), r(-3.0, 3.0)],
            )
            .unwrap();
        }
        s
    }

    /// Mahalanobis norm of `p` in the 3σ ellipsoid frame of Gaussian `i` (≤ 1 inside the footprint).
    fn footprint_norm(set: &GaussianSet, i: usize, p: [f32; 3]) -> f32 {
        let r = rotation_from_quat(set.quats[i]);
        let s = set.scales(i);
        let d = [
            p[0] - set.means[i][0],
            p[1] - set.means[i][1],
            p[2] - set.means[i][2],
        ];
        (0..3)
            .map(|a| {
                let local = r[0][a] * d[0] + r[1][a] * d[1] + r[2][a] * d[2];
                (local / (3.0 * s[a])).powi(2)
            })
            .sum::<f32>()
            .sqrt()
    }

    #[test]
    fn norms_taken_per_render_add_up_where_summed_gradients_cancel() {
        // One Gaussian seen in two renders with opposite gradients: the summed statistic sees
        // nothing, the per-render norms see both.
        let (a, b) = ([[3.0f32, 4.0]], [[-3.0f32, -4.0]]);
        let mut summed = DensityStats::new(1);
        summed.accumulate(&[[a[0][0] + b[0][0], a[0][1] + b[0][1]]], &[2.0]);
        let mut per_render = DensityStats::new(1);
        per_render.accumulate_norms(&[5.0 + 5.0], &[2.0]);
        assert_eq!(summed.mean_grad(0), 0.0);
        assert_eq!(per_render.mean_grad(0), 10.0);
        assert_eq!(per_render.max_radius, summed.max_radius);
        // One render: the same statistic either way; invisible Gaussians are skipped.
        let mut one = DensityStats::new(2);
        one.accumulate(&[a[0], a[0]], &[2.0, 0.0]);
        let mut norms = DensityStats::new(2);
        norms.accumulate_norms(&[5.0, 5.0], &[2.0, 0.0]);
        assert_eq!(one, norms);
    }

    #[test]
    fn split_children_lie_inside_the_parent_footprint() {
        let set = random_set(50, 1);
        let parents: Vec<usize> = (0..50).collect();
        let children = split_children(&set, &parents, 7);
        assert_eq!(children.len(), 100);
        for (c, p) in parents.iter().flat_map(|&p| [p, p]).enumerate() {
            // Same orientation, scales / 1.6: sample the child's 3σ surface along its axes (the extreme
            // points of an ellipsoid sharing the parent's axes) and check they are inside the parent's.
            let r = rotation_from_quat(children.quats[c]);
            let s = children.scales(c);
            for a in 0..3 {
                for sign in [-1.0f32, 1.0] {
                    let p_world: [f32; 3] =
                        std::array::from_fn(|k| children.means[c][k] + sign * 3.0 * s[a] * r[k][a]);
                    let norm = footprint_norm(&set, p, p_world);
                    assert!(norm <= 1.0 + 1e-4, "child {c} of {p} pokes out: {norm}");
                }
            }
            assert!(children.scales(c)[0] < set.scales(p)[0]);
        }
    }

    #[test]
    fn densify_and_prune_keeps_everything_aligned() {
        let mut set = random_set(40, 2);
        let mut adam = GaussianAdam::new(&set, AdamConfig::default());
        // Give moments a recognisable per-Gaussian value: the Gaussian's opacity logit.
        for i in 0..set.len() {
            adam.opacity_logits.m[i] = set.opacity_logits[i];
            for a in 0..3 {
                adam.means.m[i * 3 + a] = set.means[i][a];
            }
        }
        let mut stats = DensityStats::new(set.len());
        let grads: Vec<[f32; 2]> = (0..40)
            .map(|i| [if i % 3 == 0 { 1e-3 } else { 0.0 }, 0.0])
            .collect();
        stats.accumulate(&grads, &[2.0; 40]);
        let config = DensifyConfig {
            percent_dense: 0.1,
            min_opacity: 0.2,
            ..DensifyConfig::default()
        };
        let report = densify_and_prune(&mut set, &mut adam, &mut stats, &config, 3);
        assert!(
            report.cloned + report.split > 0 && report.pruned > 0,
            "{report:?}"
        );
        set.validate().unwrap();
        let n = set.len();
        assert_eq!(adam.len(), n);
        assert_eq!(adam.means.m.len(), n * 3);
        assert_eq!(adam.sh.v.len(), set.sh.len());
        assert_eq!(adam.features.m.len(), set.features.len());
        assert_eq!(adam.semantic_logits.m.len(), set.semantic_logits.len());
        assert_eq!(stats.grad_accum.len(), n);
        for i in 0..n {
            assert!(set.opacity(i) >= 0.2);
            // Surviving originals carry their own moments; new Gaussians carry zeros.
            let m = adam.opacity_logits.m[i];
            assert!(
                m == 0.0 || m == set.opacity_logits[i],
                "misaligned moment at {i}"
            );
            if m != 0.0 {
                assert_eq!(&adam.means.m[i * 3..i * 3 + 3], &set.means[i]);
            }
        }
    }

    #[test]
    fn prune_keeps_rows_and_moments_together() {
        let mut set = random_set(10, 4);
        let mut adam = GaussianAdam::new(&set, AdamConfig::default());
        for i in 0..10 {
            adam.quats.v[i * 4 + 3] = i as f32;
            adam.sh.m[i * 12 + 11] = i as f32;
        }
        let mut stats = DensityStats::new(10);
        stats
            .visible_count
            .iter_mut()
            .enumerate()
            .for_each(|(i, c)| *c = i as u32);
        let original = set.clone();
        let keep: Vec<bool> = (0..10).map(|i| i % 4 != 1).collect();
        prune(&mut set, &mut adam, &mut stats, &keep);
        let kept: Vec<usize> = (0..10).filter(|i| i % 4 != 1).collect();
        assert_eq!(set, original.select(&kept));
        for (row, &orig) in kept.iter().enumerate() {
            assert_eq!(adam.quats.v[row * 4 + 3], orig as f32);
            assert_eq!(adam.sh.m[row * 12 + 11], orig as f32);
            assert_eq!(stats.visible_count[row], orig as u32);
        }
    }

    #[test]
    fn opacity_reset_touches_nothing_else() {
        let mut set = random_set(30, 5);
        let mut adam = GaussianAdam::new(&set, AdamConfig::default());
        adam.means.m.iter_mut().for_each(|m| *m = 0.5);
        adam.opacity_logits.v.iter_mut().for_each(|v| *v = 0.5);
        let before = set.clone();
        let adam_before = adam.clone();
        reset_opacity(&mut set, &mut adam, 0.01);
        for i in 0..set.len() {
            assert!(set.opacity(i) <= 0.01 + 1e-6);
            if before.opacity(i) <= 0.01 {
                assert_eq!(set.opacity_logits[i], before.opacity_logits[i]);
            }
        }
        let mut restored = set.clone();
        restored.opacity_logits = before.opacity_logits.clone();
        assert_eq!(restored, before);
        assert!(adam.opacity_logits.v.iter().all(|&v| v == 0.0));
        assert_eq!(adam.means, adam_before.means);
        assert_eq!(adam.sh, adam_before.sh);
    }
}
