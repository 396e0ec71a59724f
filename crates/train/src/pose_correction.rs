//! Learned pose correction: per training frame, additive corrections of the SMPL parameters it was
//! given — a fitter's estimate, never exact on real video — learned with the reconstruction, as HUGS
//! and GauHuman optimise theirs.
//!
//! **Layout**: each training slot holds [`CORRECTION_VALUES`] numbers: the mid-exposure correction of
//! the 72 axis-angle values (radians) and the translation (metres), then the change of that
//! correction over the exposure (end minus start; same units). A pose at exposure offset
//! `o = (s + ½)/S − ½ ∈ (−½, ½)` is corrected by `mid + o · change`; a frame rendered once (no
//! exposure model) has `o = 0`, so the change there only feels the regulariser and stays zero.
//! The correction is added to the axis-angle vector (not composed as rotations): exact for the
//! gradient, and for the few degrees a fitter errs by, indistinguishable from composition.
//!
//! **Regulariser**: `R = Σ_k λ₀ ‖δ_k‖² + λ_s Σ_k ‖δ_{k+1} − δ_k‖²` over the training slots in time
//! order; a step on frame k applies `∂R/∂δ_k` (a block-coordinate gradient of `R`).
//!
//! **Held-out frames** take the mid-exposure correction interpolated linearly in frame number
//! between the neighbouring training frames (clamped to the nearest one outside their range): never
//! fitted to held-out images.
//!
//! The functions are generic over the float type so the f64 versions are finite-difference checked.

use num_traits::Float;
use smpl_deform::{SmplParams, NUM_JOINTS};

/// Corrected values per pose: 72 axis-angle values and 3 translation values.
pub const POSE_VALUES: usize = 3 * NUM_JOINTS + 3;

/// Correction values per training slot: the mid-exposure correction and its change over the exposure.
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
    /// λ_s, towards the neighbouring training frames' corrections.
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
    let slots = corrections.len() / CORRECTION_VALUES;
    let of = |k: usize| &corrections[k * CORRECTION_VALUES..(k + 1) * CORRECTION_VALUES];
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

/// The mid-exposure correction ([`POSE_VALUES`] values, then a zero change) of frame `index`: a
/// training frame's own, else interpolated linearly in frame number between the neighbouring
/// training frames (`frame_indices` ascending, one per slot of `corrections`), the nearest one's
/// outside their range. Empty when `corrections` is.
pub fn interpolated_correction(frame_indices: &[u32], corrections: &[f32], index: u32) -> Vec<f32> {
    if corrections.is_empty() || frame_indices.is_empty() {
        return Vec::new();
    }
    let mid = |k: usize| &corrections[k * CORRECTION_VALUES..k * CORRECTION_VALUES + POSE_VALUES];
    let after = frame_indices.partition_point(|&f| f < index);
    let mut out = vec![0.0f32; CORRECTION_VALUES];
    if after < frame_indices.len() && frame_indices[after] == index || after == 0 {
        out[..POSE_VALUES].copy_from_slice(mid(after.min(frame_indices.len() - 1)));
    } else if after == frame_indices.len() {
        out[..POSE_VALUES].copy_from_slice(mid(after - 1));
    } else {
        let (f0, f1) = (frame_indices[after - 1], frame_indices[after]);
        let u = (index - f0) as f32 / (f1 - f0) as f32;
        for (o, (&a, &b)) in out.iter_mut().zip(mid(after - 1).iter().zip(mid(after))) {
            *o = a + u * (b - a);
        }
    }
    out
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
