//! Initial Gaussian parameters from a point cloud, as in 3DGS: isotropic scales from the mean squared
//! distance to the three nearest neighbours (a k-d tree, O(N log N)), identity rotations, a constant
//! opacity and a colour for the SH DC term.

use crate::set::{inverse_sigmoid, GaussianSet};
use crate::sh::rgb_to_sh_dc;
use kiddo::immutable::float::kdtree::ImmutableKdTree;
use kiddo::SquaredEuclidean;
use std::num::NonZeroUsize;

/// Smallest mean squared neighbour distance used (m²), as the 3DGS `clamp_min(1e-7)`.
pub const MIN_NEIGHBOUR_DIST2: f32 = 1e-7;

/// Natural-log isotropic scale per point: ln √(mean of the squared distances to its 3 nearest other
/// points), with the squared distance clamped at [`MIN_NEIGHBOUR_DIST2`]. Fewer than 4 points: all
/// available neighbours are used; a single point gets the clamp value.
pub fn knn_log_scales(points: &[[f32; 3]]) -> Vec<[f32; 3]> {
    const NEIGHBOURS: usize = 3;
    if points.len() < 2 {
        let s = MIN_NEIGHBOUR_DIST2.sqrt().ln();
        return vec![[s; 3]; points.len()];
    }
    let tree: ImmutableKdTree<f32, u64, 3, 32> = ImmutableKdTree::new_from_slice(points);
    let want = (NEIGHBOURS + 1).min(points.len());
    let k = NonZeroUsize::new(want).unwrap_or(NonZeroUsize::MIN);
    points
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let found = tree.nearest_n::<SquaredEuclidean>(p, k);
            // Drop the query point itself (or, for exact duplicates, one zero-distance entry).
            let self_pos = found
                .iter()
                .position(|nn| nn.item == i as u64)
                .unwrap_or(found.len().saturating_sub(1));
            let (sum, count) = found
                .iter()
                .enumerate()
                .filter(|&(j, _)| j != self_pos)
                .fold((0.0f32, 0usize), |(s, c), (_, nn)| (s + nn.distance, c + 1));
            let mean = (sum / count.max(1) as f32).max(MIN_NEIGHBOUR_DIST2);
            [mean.sqrt().ln(); 3]
        })
        .collect()
}

/// Indices of the `k` nearest other points of every point (row-major, `k` per point, nearest first,
/// ties broken by index), through a k-d tree. Needs at least `k + 1` points; with fewer, every row lists
/// all other points and pads by repeating its last entry (or itself, for a single point).
pub fn knn_indices(points: &[[f32; 3]], k: usize) -> Vec<u32> {
    let n = points.len();
    if n == 0 || k == 0 {
        return Vec::new();
    }
    let tree: ImmutableKdTree<f32, u64, 3, 32> = ImmutableKdTree::new_from_slice(points);
    let want = NonZeroUsize::new((k + 1).min(n)).unwrap_or(NonZeroUsize::MIN);
    let mut out = Vec::with_capacity(n * k);
    for (i, p) in points.iter().enumerate() {
        let mut found = tree.nearest_n::<SquaredEuclidean>(p, want);
        found.sort_by(|a, b| a.distance.total_cmp(&b.distance).then(a.item.cmp(&b.item)));
        let start = out.len();
        let mut dropped_self = false;
        for nn in &found {
            if !dropped_self && nn.item == i as u64 {
                dropped_self = true;
                continue;
            }
            if out.len() - start < k {
                out.push(nn.item as u32);
            }
        }
        let last = out
            .get(start..)
            .and_then(|r| r.last().copied())
            .unwrap_or(i as u32);
        while out.len() - start < k {
            out.push(last);
        }
    }
    out
}

/// A set from a point cloud: means = points, kNN isotropic scales, identity rotations, opacity
/// `opacity` (in (0,1), stored as a logit), SH DC from linear RGB colours, zero higher SH, zero features
/// and zero semantic logits.
pub fn from_points(
    points: &[[f32; 3]],
    colors: &[[f32; 3]],
    opacity: f32,
    sh_degree: usize,
    feature_dim: usize,
    semantic_classes: usize,
) -> GaussianSet {
    let n = points.len();
    let mut set = GaussianSet::zeros(n, sh_degree, feature_dim, semantic_classes);
    set.means = points.to_vec();
    set.log_scales = knn_log_scales(points);
    set.quats = vec![[1.0, 0.0, 0.0, 0.0]; n];
    set.opacity_logits = vec![inverse_sigmoid(opacity); n];
    let stride = set.sh_coeffs_per_channel() * 3;
    for (i, rgb) in colors.iter().enumerate().take(n) {
        for c in 0..3 {
            set.sh[i * stride + c] = rgb_to_sh_dc(rgb[c]);
        }
    }
    set
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_spacing_gives_expected_scale() {
        // Points on a unit-spacing grid: interior points' 3 nearest neighbours are all at distance 1.
        let mut pts = Vec::new();
        for x in 0..6 {
            for y in 0..6 {
                for z in 0..6 {
                    pts.push([x as f32, y as f32, z as f32]);
                }
            }
        }
        let s = knn_log_scales(&pts);
        for (p, s) in pts.iter().zip(&s) {
            if p.iter().all(|&v| v > 0.0 && v < 5.0) {
                assert!(s[0].abs() < 1e-6, "{p:?} -> {s:?}");
            }
        }
    }

    #[test]
    fn matches_brute_force_on_random_points() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
        let pts: Vec<[f32; 3]> = (0..300)
            .map(|_| [rng.gen::<f32>(), rng.gen::<f32>(), rng.gen::<f32>()])
            .collect();
        let fast = knn_log_scales(&pts);
        for (i, p) in pts.iter().enumerate() {
            let mut d: Vec<f32> = pts
                .iter()
                .enumerate()
                .filter(|&(j, _)| j != i)
                .map(|(_, q)| (0..3).map(|a| (p[a] - q[a]).powi(2)).sum())
                .collect();
            d.sort_by(f32::total_cmp);
            let want = ((d[0] + d[1] + d[2]) / 3.0)
                .max(MIN_NEIGHBOUR_DIST2)
                .sqrt()
                .ln();
            assert!(
                (fast[i][0] - want).abs() < 1e-4,
                "{i}: {} vs {want}",
                fast[i][0]
            );
        }
    }

    #[test]
    fn knn_indices_exclude_self_and_sort_by_distance() {
        let pts: Vec<[f32; 3]> = (0..10).map(|i| [(i * i) as f32, 0.0, 0.0]).collect();
        let nn = knn_indices(&pts, 3);
        assert_eq!(&nn[0..3], &[1, 2, 3]);
        assert_eq!(&nn[5 * 3..6 * 3], &[4, 6, 3]);
        assert_eq!(knn_indices(&pts[..2], 3), vec![1, 1, 1, 0, 0, 0]);
    }

    #[test]
    fn duplicates_and_tiny_inputs_do_not_panic() {
        let s = knn_log_scales(&[[1.0, 2.0, 3.0]; 100]);
        assert!(s.iter().all(|v| v[0] == MIN_NEIGHBOUR_DIST2.sqrt().ln()));
        assert_eq!(knn_log_scales(&[]).len(), 0);
        assert_eq!(knn_log_scales(&[[0.0; 3]]).len(), 1);
        let two = knn_log_scales(&[[0.0; 3], [2.0, 0.0, 0.0]]);
        assert!((two[0][0] - 2.0f32.ln()).abs() < 1e-6);
    }
}
