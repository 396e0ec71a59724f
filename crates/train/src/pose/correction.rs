//! Learned pose correction: per training frame, additive corrections of the SMPL parameters it was
//! given — a fitter's estimate, never exact on real video — learned with the reconstruction, as HUGS
//! and GauHuman optimise theirs.
//!
//! **Layout**: each knot (see below) holds [`CORRECTION_VALUES`] numbers: the mid-exposure
//! correction of the 72 axis-angle values (radians) and the translation (metres), then the change of that
//! correction over the exposure (end minus start; same units). A pose at exposure offset
//! `o = (s + ½)/S − ½ ∈ (−½, ½)` is corrected by `mid + o · change`; a frame rendered once (no
//! exposure model) has `o = 0`, so the change there only feels the regulariser and stays zero.
//! The correction is added to the axis-angle vector (not composed as rotations): exact for the
//! gradient, and for the few degrees a fitter errs by, indistinguishable from composition.
//!
//! **Regulariser**: `R = Σ_k λ₀ ‖δ_k‖² + λ_s Σ_k ‖δ_{k+1} − δ_k‖²` over the knots in time order;
//! a step on frame k applies `∂R/∂δ_j` for the knots j it is interpolated from (a block-coordinate
//! gradient of `R`).
//!
//! **Knots**: the corrections live on knots — every training slot by default, or every
//! `pose_correction_knot_every`-th one (and the last), so that each learned value hears the
//! gradients of several frames. A frame's correction is the linear interpolation, in frame number,
//! of the two knots around it ([`KnotSpan`]); its gradient reaches both, weighted.
//!
//! **Held-out frames** take the mid-exposure correction interpolated the same way between the
//! neighbouring knots (clamped to the nearest one outside their range): never fitted to held-out
//! images.
//!
//! The functions are generic over the float type so the f64 versions are finite-difference checked.

use num_traits::Float;
use smpl_deform::{SmplParams, NUM_JOINTS};

/// Corrected values per pose: 72 axis-angle values and 3 translation values.
pub const POSE_VALUES: usize = 3 * NUM_JOINTS + 3;

/// Correction values per knot: the mid-exposure correction and its change over the exposure.
pub const CORRECTION_VALUES: usize = 2 * POSE_VALUES;

/// The pose `pose` (72 axis-angle values, radians) and translation `transl` (m) corrected by a slot's
/// `correction` ([`CORRECTION_VALUES`] values) at exposure offset `offset` (−½ … ½; 0 at mid exposure).
pub fn correct_pose<T: Float>(
    pose: &[T],
    transl: [T; 3],
    correction: &[T],
    offset: T,
) -> (Vec<T>, [T; 3]) {
    let (mid, change) = correction.split_at(POSE_VALUES);
    let at = |k: usize| mid[k] + offset * change[k];
    let pose = pose.iter().enumerate().map(|(k, &p)| p + at(k)).collect();
    let n = 3 * NUM_JOINTS;
    let transl = [
        transl[0] + at(n),
        transl[1] + at(n + 1),
        transl[2] + at(n + 2),
    ];
    (pose, transl)
}

/// The indices, within a slot's [`CORRECTION_VALUES`], of the root's values: the global orientation
/// (axis-angle values 0..3) and the translation, in both the mid-exposure part and its change.
pub fn root_indices() -> impl Iterator<Item = usize> {
    let n = 3 * NUM_JOINTS;
    [0, 1, 2, n, n + 1, n + 2]
        .into_iter()
        .flat_map(|k| [k, k + POSE_VALUES])
}

/// Backward of [`correct_pose`]: adds `∂L/∂correction` to `grad` ([`CORRECTION_VALUES`] values) from
/// `∂L/∂pose` (72) and `∂L/∂transl` of a pose corrected at `offset`.
pub fn correct_pose_backward<T: Float>(d_pose: &[T], d_transl: [T; 3], offset: T, grad: &mut [T]) {
    let (mid, change) = grad.split_at_mut(POSE_VALUES);
    let values = d_pose.iter().copied().chain(d_transl);
    for ((m, c), d) in mid.iter_mut().zip(change.iter_mut()).zip(values) {
        *m = *m + d;
        *c = *c + offset * d;
    }
}

/// The SMPL parameters `params` corrected by `correction` at exposure offset `offset`
/// ([`correct_pose`] in the parameters' own f32).
pub fn corrected_params(params: &SmplParams, correction: &[f32], offset: f32) -> SmplParams {
    let (pose, transl) = correct_pose(&params.pose, params.transl, correction, offset);
    SmplParams {
        pose,
        transl,
        betas: params.betas.clone(),
    }
}

/// The exposure offset of sub-exposure render `s` of `count` (midpoint rule; 0 for one render).
pub fn exposure_offset(s: usize, count: usize) -> f32 {
    let count = count.max(1) as f32;
    (s as f32 + 0.5) / count - 0.5
}

/// Weights of the regulariser (see the module documentation).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CorrectionPrior<T> {
    /// λ₀, towards zero.
    pub zero: T,
    /// λ_s, towards the neighbouring knots' corrections.
    pub smooth: T,
}

/// The regulariser's terms that involve slot `slot` — `λ₀ ‖δ_k‖² + λ_s Σ_{j = k±1} ‖δ_k − δ_j‖²` —
/// and `∂R/∂δ_k` added to `grad` ([`CORRECTION_VALUES`] values). `corrections` holds every slot.
pub fn prior_terms<T: Float>(
    corrections: &[T],
    slot: usize,
    prior: CorrectionPrior<T>,
    grad: &mut [T],
) -> T {
    knot_prior_terms(corrections, CORRECTION_VALUES, slot, prior, grad)
}

/// [`prior_terms`] for knots of `values_per_knot` values each (the camera corrections' too).
pub fn knot_prior_terms<T: Float>(
    corrections: &[T],
    values_per_knot: usize,
    slot: usize,
    prior: CorrectionPrior<T>,
    grad: &mut [T],
) -> T {
    let n = values_per_knot;
    let slots = corrections.len() / n;
    let of = |k: usize| &corrections[k * n..(k + 1) * n];
    let own = of(slot);
    let two = T::one() + T::one();
    let mut value = T::zero();
    for (g, &d) in grad.iter_mut().zip(own) {
        value = value + prior.zero * d * d;
        *g = *g + two * prior.zero * d;
    }
    let neighbours = [slot.checked_sub(1), Some(slot + 1).filter(|&k| k < slots)];
    for other in neighbours.into_iter().flatten() {
        for ((g, &d), &e) in grad.iter_mut().zip(own).zip(of(other)) {
            let diff = d - e;
            value = value + prior.smooth * diff * diff;
            *g = *g + two * prior.smooth * diff;
        }
    }
    value
}

/// The training slots that carry a knot when every `every`-th one does: 0, `every`, 2·`every`, …
/// and the last slot (every slot when `every` ≤ 1).
pub fn knot_slots(slots: usize, every: usize) -> Vec<usize> {
    let every = every.max(1);
    let mut knots: Vec<usize> = (0..slots).step_by(every).collect();
    if slots > 0 && knots.last() != Some(&(slots - 1)) {
        knots.push(slots - 1);
    }
    knots
}

/// Where a frame sits among the knots: at knot `first` (`next` = `None`: at a knot, or outside the
/// knots' range, clamped to the nearest), or a fraction `u` ∈ (0, 1) of the way from `first` to
/// `first + 1` in frame number.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct KnotSpan {
    /// The knot at or before the frame.
    pub first: usize,
    /// The knot after it and the fraction of the way to it.
    pub next: Option<(usize, f32)>,
}

impl KnotSpan {
    /// The span of frame `index` among knots at frame numbers `knot_frames` (ascending, at least
    /// one).
    pub fn of(knot_frames: &[u32], index: u32) -> Self {
        let after = knot_frames.partition_point(|&f| f < index);
        let at = |k: usize| Self {
            first: k,
            next: None,
        };
        if after < knot_frames.len() && knot_frames[after] == index || after == 0 {
            at(after.min(knot_frames.len().saturating_sub(1)))
        } else if after == knot_frames.len() {
            at(after - 1)
        } else {
            let (f0, f1) = (knot_frames[after - 1], knot_frames[after]);
            Self {
                first: after - 1,
                next: Some((after, (index - f0) as f32 / (f1 - f0) as f32)),
            }
        }
    }

    /// The knots and their weights in the interpolation (1, or 1 − u and u).
    pub fn weights(&self) -> Vec<(usize, f32)> {
        match self.next {
            None => vec![(self.first, 1.0)],
            Some((next, u)) => vec![(self.first, 1.0 - u), (next, u)],
        }
    }

    /// The interpolated values `a + u (b − a)` of `values_per_knot` values from `knots` (one row
    /// per knot), the first `count` of each row (the rest zero).
    pub fn blend<T: Float>(&self, knots: &[T], values_per_knot: usize, count: usize) -> Vec<T> {
        let row = |k: usize| &knots[k * values_per_knot..k * values_per_knot + count];
        let mut out = vec![T::zero(); values_per_knot];
        match self.next {
            None => out[..count].copy_from_slice(row(self.first)),
            Some((next, u)) => {
                let u = T::from(u).unwrap_or_else(T::zero);
                for (o, (&a, &b)) in out.iter_mut().zip(row(self.first).iter().zip(row(next))) {
                    *o = a + u * (b - a);
                }
            }
        }
        out
    }

    /// Backward of [`KnotSpan::blend`] (all values): adds `weight · d_values` to each knot's row
    /// of `grad`.
    pub fn blend_backward<T: Float>(&self, d_values: &[T], grad: &mut [T]) {
        let n = d_values.len();
        for (knot, w) in self.weights() {
            let w = T::from(w).unwrap_or_else(T::zero);
            for (g, &d) in grad[knot * n..(knot + 1) * n].iter_mut().zip(d_values) {
                *g = *g + w * d;
            }
        }
    }
}

/// The mid-exposure correction ([`POSE_VALUES`] values, then a zero change) of frame `index`:
/// interpolated linearly in frame number between the knots around it (`knot_frames` ascending, one
/// per row of `knots`), the nearest one's outside their range. Empty when `knots` is.
pub fn interpolated_correction(knot_frames: &[u32], knots: &[f32], index: u32) -> Vec<f32> {
    if knots.is_empty() || knot_frames.is_empty() {
        return Vec::new();
    }
    KnotSpan::of(knot_frames, index).blend(knots, CORRECTION_VALUES, POSE_VALUES)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn slots(values: &[f32]) -> Vec<f32> {
        values
            .iter()
            .flat_map(|&v| {
                let mut c = vec![0.0; CORRECTION_VALUES];
                c[..POSE_VALUES].fill(v);
                c[POSE_VALUES..].fill(9.0);
                c
            })
            .collect()
    }

    #[test]
    fn held_out_frames_interpolate_their_neighbours_corrections() {
        let corrections = slots(&[1.0, 3.0, -1.0]);
        let frames = [2, 4, 8];
        let at = |i| interpolated_correction(&frames, &corrections, i);
        assert_eq!(at(2)[0], 1.0);
        assert_eq!(at(4)[5], 3.0);
        assert_eq!(at(3)[74], 2.0);
        assert_eq!(at(7)[0], 0.0);
        assert_eq!(at(0)[0], 1.0);
        assert_eq!(at(11)[0], -1.0);
        // Never the change over the exposure: a held-out frame is rendered once.
        assert!(at(3)[POSE_VALUES..].iter().all(|&v| v == 0.0));
        assert!(interpolated_correction(&frames, &[], 3).is_empty());
    }

    #[test]
    fn knots_sit_every_few_slots_and_at_the_last() {
        assert_eq!(knot_slots(4, 1), vec![0, 1, 2, 3]);
        assert_eq!(knot_slots(7, 3), vec![0, 3, 6]);
        assert_eq!(knot_slots(8, 3), vec![0, 3, 6, 7]);
        assert_eq!(knot_slots(1, 3), vec![0]);
        assert!(knot_slots(0, 3).is_empty());
    }

    #[test]
    fn a_frame_between_knots_blends_them_and_its_gradient_reaches_both() {
        let knots = [2u32, 6, 10];
        let span = KnotSpan::of(&knots, 7);
        assert_eq!(span.first, 1);
        assert_eq!(span.next, Some((2, 0.25)));
        assert_eq!(span.weights(), vec![(1, 0.75), (2, 0.25)]);
        assert_eq!(KnotSpan::of(&knots, 6).next, None);
        assert_eq!(KnotSpan::of(&knots, 0).first, 0);
        assert_eq!(KnotSpan::of(&knots, 12).first, 2);
        // f64 central differences of L = Σ c ⊙ blend(knots) against blend_backward.
        let values: Vec<f64> = (0..6).map(|k| (k as f64 * 0.7).sin()).collect();
        let c = [0.3, -1.1];
        let loss = |v: &[f64]| -> f64 {
            let b = span.blend(v, 2, 2);
            b.iter().zip(&c).map(|(x, y)| x * y).sum()
        };
        let mut grad = vec![0.0f64; 6];
        span.blend_backward(&c, &mut grad);
        let h = 1e-6;
        for k in 0..6 {
            let (mut up, mut down) = (values.clone(), values.clone());
            up[k] += h;
            down[k] -= h;
            let fd = (loss(&up) - loss(&down)) / (2.0 * h);
            // Linear in the knots: only rounding (≈ 1e-16 / 1e-6) separates the two.
            assert!(
                (fd - grad[k]).abs() < 1e-8,
                "knot value {k}: {fd} vs {}",
                grad[k]
            );
        }
        assert!(grad[..2].iter().all(|&g| g == 0.0) && grad[2] != 0.0 && grad[4] != 0.0);
    }

    #[test]
    fn a_zero_correction_changes_nothing_and_offsets_weigh_the_change() {
        let params = SmplParams {
            pose: (0..72).map(|k| k as f32 * 0.01).collect(),
            betas: vec![0.5],
            transl: [1.0, 2.0, 3.0],
        };
        let zero = vec![0.0f32; CORRECTION_VALUES];
        assert_eq!(corrected_params(&params, &zero, 0.3), params);
        let mut c = zero.clone();
        c[POSE_VALUES + 4] = 1.0; // change of pose value 4
        c[72] = 0.25; // mid translation x
        let p = corrected_params(&params, &c, -0.5);
        assert_eq!(p.pose[4], params.pose[4] - 0.5);
        assert_eq!(p.transl[0], 1.25);
        assert_eq!(exposure_offset(0, 1), 0.0);
        assert_eq!(exposure_offset(0, 2), -0.25);
        assert!((exposure_offset(4, 5) - 0.4).abs() < 1e-6);
    }
}
