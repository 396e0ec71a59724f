//! A prior on the scale of the camera corrections' path (`TrainConfig::camera_scale_prior_weight`).
//!
//! A monocular reconstruction can shrink the camera's motion and push the room back: a camera
//! that rises and falls less, pitched so that the person stays put, sees the room's parallax
//! unchanged when the room sits deeper. Learned corrections drift along that direction
//! (`docs/notes/2026-12-07-camera-height-drift.md`: the corrected cameras rose and fell 25 % less
//! than the true ones). A tracker errs by drift and jitter, not by rescaling the motion it tracks,
//! so its error is nearly uncorrelated with the path it gives. The prior penalises the part of the
//! corrections' shifts that follows the given path:
//!
//! `P = λ / (K σ²) · Σ_a (Σ_k v_ka d_ka)² / Σ_k d_ka²`
//!
//! over the K training frames and the three camera axes a, with `v_k` frame k's stored
//! mid-exposure shift (metres, camera coordinates; `crate::pose::camera_correction`) and `d_k`
//! the given camera centre's deviation from the clip's mean centre, in that camera's coordinates
//! (metres). Each axis's term is the mean square of the shifts' projection on the given path's
//! deviation, in units of the tracker's centre error σ: a clip-wide shift (the gauge's) and any
//! error uncorrelated with the path cost nothing.

use super::camera_correction::{CAMERA_CORRECTION_VALUES, TWIST_VALUES};
use num_traits::Float;

/// Where a row's shift v starts: after the rotation ω, the first half of the mid-exposure twist.
const SHIFT: usize = TWIST_VALUES / 2;

/// The given camera centres' deviations from their mean, each in its own camera's coordinates
/// (metres): `R_k (c_k − c̄)` for the row-major `world_to_camera` transforms `cameras`
/// (`c_k = −R_kᵀ t_k`).
pub fn centre_deviations(cameras: &[[[f64; 4]; 4]]) -> Vec<[f64; 3]> {
    let centre = |m: &[[f64; 4]; 4]| -> [f64; 3] {
        std::array::from_fn(|j| -(0..3).map(|i| m[i][j] * m[i][3]).sum::<f64>())
    };
    let centres: Vec<[f64; 3]> = cameras.iter().map(centre).collect();
    let count = centres.len().max(1) as f64;
    let mean: [f64; 3] = std::array::from_fn(|j| centres.iter().map(|c| c[j]).sum::<f64>() / count);
    cameras
        .iter()
        .zip(&centres)
        .map(|(m, c)| std::array::from_fn(|i| (0..3).map(|j| m[i][j] * (c[j] - mean[j])).sum()))
        .collect()
}

/// The prior's value `P` (module docs) for the stored corrections `corrections`
/// ([`CAMERA_CORRECTION_VALUES`] per training frame) and the given path's `deviations` (one per
/// frame, [`centre_deviations`]), at weight `weight` and the tracker's centre error `sigma`
/// (metres). Adds ∂P/∂ every frame's shift to `grad` (the corrections' layout). An axis the given
/// path does not move along adds nothing.
pub fn scale_prior_terms<T: Float>(
    corrections: &[T],
    deviations: &[[T; 3]],
    (weight, sigma): (T, T),
    grad: &mut [T],
) -> T {
    let n = CAMERA_CORRECTION_VALUES;
    let frames = deviations.len().min(corrections.len() / n);
    if frames == 0 {
        return T::zero();
    }
    let scale = weight / (T::from(frames).unwrap_or_else(T::one) * sigma * sigma);
    let two = T::one() + T::one();
    let mut value = T::zero();
    for axis in 0..3 {
        let shift = |k: usize| corrections[k * n + SHIFT + axis];
        let spread = (0..frames).fold(T::zero(), |s, k| s + deviations[k][axis].powi(2));
        if spread <= T::zero() {
            continue;
        }
        let along = (0..frames).fold(T::zero(), |s, k| s + shift(k) * deviations[k][axis]);
        value = value + scale * along * along / spread;
        for (k, d) in deviations.iter().enumerate().take(frames) {
            grad[k * n + SHIFT + axis] =
                grad[k * n + SHIFT + axis] + scale * two * along / spread * d[axis];
        }
    }
    value
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rows(shifts: &[[f64; 3]]) -> Vec<f64> {
        let n = CAMERA_CORRECTION_VALUES;
        let mut out = vec![0.0; shifts.len() * n];
        for (k, s) in shifts.iter().enumerate() {
            out[k * n + 3..k * n + 6].copy_from_slice(s);
            out[k * n] = 0.5; // a rotation the prior ignores
        }
        out
    }

    #[test]
    fn shifts_that_follow_the_path_cost_and_others_do_not() {
        let deviations = [[0.0, -0.02, 0.0], [0.0, 0.0, 0.0], [0.0, 0.02, 0.0]];
        // A quarter of the path, against it: the projection's squared norm (−2e-4)² / 8e-4 = 5e-5 m²
        // over K σ² = 3e-4 m².
        let shrunk = rows(&[[0.0, 0.005, 0.0], [0.0, 0.0, 0.0], [0.0, -0.005, 0.0]]);
        let mut grad = vec![0.0; shrunk.len()];
        let value = scale_prior_terms(&shrunk, &deviations, (1.0, 0.01), &mut grad);
        assert!((value - 1.0 / 6.0).abs() < 1e-12, "{value}");
        assert!(grad[4] > 0.0 && grad[CAMERA_CORRECTION_VALUES * 2 + 4] < 0.0);
        assert_eq!(grad[0], 0.0);
        // A common shift and a shift along an axis the path does not move cost nothing.
        let common = rows(&[[0.01, 0.003, 0.0], [0.01, 0.003, 0.0], [0.01, 0.003, 0.0]]);
        let mut grad = vec![0.0; common.len()];
        assert_eq!(
            scale_prior_terms(&common, &deviations, (1.0, 0.01), &mut grad),
            0.0
        );
        assert!(grad.iter().all(|&g| g == 0.0));
    }

    #[test]
    fn deviations_are_in_each_cameras_coordinates() {
        // Two cameras turned by 90° about z, centres 2 m apart along the world's x axis.
        let turned = |x: f64| {
            [
                [0.0, 1.0, 0.0, 0.0],
                [-1.0, 0.0, 0.0, x],
                [0.0, 0.0, 1.0, 0.0],
                [0.0, 0.0, 0.0, 1.0],
            ]
        };
        // Centre c = −Rᵀt: t = (0, x, 0) gives c = (x, 0, 0).
        let d = centre_deviations(&[turned(1.0), turned(-1.0)]);
        // R (c − c̄) with c − c̄ = (±1, 0, 0): (0, ∓1, 0).
        assert_eq!(d, vec![[0.0, -1.0, 0.0], [0.0, 1.0, 0.0]]);
    }
}
