//! Learned camera correction: per training frame, a rigid correction of the camera pose it was
//! given — a SLAM or SfM estimate, never exact — and of the camera's motion over the exposure,
//! learned with the reconstruction (as BAD-Gaussians learns each exposure's camera path).
//!
//! **Layout**: each training frame holds [`CAMERA_CORRECTION_VALUES`] numbers: the mid-exposure
//! twist `ξ = (ω, v)` (ω radians, v metres, both in the camera's coordinates), then its change over
//! the exposure (end minus start; same units). A render at exposure offset `o ∈ (−½, ½)`
//! (`crate::pose::correction::exposure_offset`; 0 at mid exposure) uses `ξ(o) = mid + o · change`
//! and the camera
//!
//! `world_to_camera' = [Exp(ω) | v] · world_to_camera`, i.e. `p_c' = Exp(ω) · p_c + v`:
//! the camera turned about its own centre by ω, then shifted by −v (seen in its coordinates).
//!
//! **Gradient**: the rasterizer gives `g = dL/dξ_left` for a further left twist of the corrected
//! camera (`rasterize_cpu::camera_pose_gradient`). A change δv of v is exactly such a twist, so
//! `dL/dv = g_v`; a change δω turns the camera by `φ = J_l(ω) δω` (the left Jacobian of SO(3)) about
//! the point that v then shifts, which is the left twist `(φ, v × φ)`, so
//! `dL/dω = J_l(ω)ᵀ (g_ω + g_v × v)` ([`twist_backward`]). Exact; checked by f64 central
//! differences through a render in `gradient-checks`.
//!
//! **Colours** keep the view directions of the given camera: the correction moves only the
//! camera the Gaussians are rasterized from (for the few millimetres and tenths of a degree a
//! tracker errs by, the view directions change by far less than a degree).
//!
//! **Held-out frames** take the mid-exposure correction of a least-squares line, in frame number,
//! through the training frames nearest to them ([`fitted_camera_correction`]), never fitted to
//! held-out images. The regulariser is the pose correction's
//! (`crate::pose::correction::knot_prior_terms`), one knot per training frame.
//!
//! **The gauge** (`TrainConfig::camera_gauge`): an offset common to every camera is nearly
//! invisible to the static room, which can turn with the cameras and fit the images as well; only
//! the person, posed in the true world, disagrees. With `person`, every frame's mid-exposure twist
//! is `g + ξ_k`: the frames' own twists `ξ_k` learn from every Gaussian but are kept to a zero
//! clip mean (the mean is removed after each step), and the clip-wide twist `g` learns from the
//! person's Gaussians alone — its gradient is the mid-exposure twist's with the rasterizer's
//! camera gradient summed over the person's Gaussians only (`rasterize_cpu::camera_pose_gradient`
//! is a sum over Gaussians), the room's pull on the common offset left out. It steps on every
//! step, a frame's twist once per pass over the frames, so its rates are the frames' divided by
//! the number of training frames (an Adam step moves a value by about its rate).

/// Values of one twist: ω (radians), then v (metres), camera coordinates.
pub const TWIST_VALUES: usize = 6;

/// Correction values per training frame: the mid-exposure twist and its change over the exposure.
pub const CAMERA_CORRECTION_VALUES: usize = 2 * TWIST_VALUES;

/// The twist of a frame's `correction` ([`CAMERA_CORRECTION_VALUES`] values) at exposure offset
/// `offset` (−½ … ½): `mid + offset · change`.
pub fn twist_at(correction: &[f32], offset: f32) -> [f64; TWIST_VALUES] {
    std::array::from_fn(|k| {
        f64::from(correction[k]) + f64::from(offset) * f64::from(correction[TWIST_VALUES + k])
    })
}

/// A tracker's error model as a prior on a frame's mid-exposure twist: `λ·(‖ω‖²/σ_ω² + ‖v‖²/σ_v²)`
/// (σ_ω radians, σ_v metres: the tracker's typical rotation and centre errors), so a correction
/// that the images cannot tell from another — a pitch against a vertical shift of a camera
/// looking into a shallow room — is settled in the proportion the tracker errs in. Returns the
/// value and adds its gradient to `grad` (the first [`TWIST_VALUES`] of a frame's row; the
/// exposure's change is left alone).
pub fn tracker_prior_terms<T: num_traits::Float>(
    row: &[T],
    (weight, sigma_rotation, sigma_shift): (T, T, T),
    grad: &mut [T],
) -> T {
    let two = T::one() + T::one();
    let mut value = T::zero();
    for (k, (g, &d)) in grad.iter_mut().zip(row).take(TWIST_VALUES).enumerate() {
        let sigma = if k < 3 { sigma_rotation } else { sigma_shift };
        let w = weight / (sigma * sigma);
        value = value + w * d * d;
        *g = *g + two * w * d;
    }
    value
}

/// The cross product matrix `[w]ₓ` (`[w]ₓ a = w × a`).
fn hat(w: [f64; 3]) -> [[f64; 3]; 3] {
    [[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]]
}

fn mat_mul(a: &[[f64; 3]; 3], b: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
    std::array::from_fn(|i| std::array::from_fn(|j| (0..3).map(|k| a[i][k] * b[k][j]).sum()))
}

/// `I + a·K + b·K²` with `K = [ω]ₓ`: the form of both Exp(ω) and J_l(ω).
fn rodrigues_form(omega: [f64; 3], a: f64, b: f64) -> [[f64; 3]; 3] {
    let k = hat(omega);
    let k2 = mat_mul(&k, &k);
    std::array::from_fn(|i| {
        std::array::from_fn(|j| f64::from(u8::from(i == j)) + a * k[i][j] + b * k2[i][j])
    })
}

/// The rotation `Exp(ω)` (Rodrigues' formula; a series below 1e-4 rad).
pub fn exp_so3(omega: [f64; 3]) -> [[f64; 3]; 3] {
    let t2 = omega.iter().map(|v| v * v).sum::<f64>();
    let t = t2.sqrt();
    let (a, b) = if t < 1e-4 {
        (1.0 - t2 / 6.0, 0.5 - t2 / 24.0)
    } else {
        (t.sin() / t, (1.0 - t.cos()) / t2)
    };
    rodrigues_form(omega, a, b)
}

/// The left Jacobian of SO(3): `Exp(ω + δ) = Exp(J_l(ω) δ) · Exp(ω)` to first order in δ.
pub fn left_jacobian_so3(omega: [f64; 3]) -> [[f64; 3]; 3] {
    let t2 = omega.iter().map(|v| v * v).sum::<f64>();
    let t = t2.sqrt();
    let (a, b) = if t < 1e-4 {
        (0.5 - t2 / 24.0, 1.0 / 6.0 - t2 / 120.0)
    } else {
        ((1.0 - t.cos()) / t2, (t - t.sin()) / (t2 * t))
    };
    rodrigues_form(omega, a, b)
}

/// `world_to_camera` corrected by `twist` = (ω, v): `[Exp(ω) | v] · world_to_camera` (row-major
/// 4×4 rigid transforms).
pub fn corrected_world_to_camera(
    world_to_camera: &[[f64; 4]; 4],
    twist: &[f64; TWIST_VALUES],
) -> [[f64; 4]; 4] {
    let r = exp_so3([twist[0], twist[1], twist[2]]);
    let mut out = [
        [0.0, 0.0, 0.0, 0.0],
        [0.0; 4],
        [0.0; 4],
        [0.0, 0.0, 0.0, 1.0],
    ];
    for i in 0..3 {
        for j in 0..4 {
            out[i][j] = (0..3).map(|k| r[i][k] * world_to_camera[k][j]).sum();
        }
        out[i][3] += twist[3 + i];
    }
    out
}

/// `dL/d(ω, v)` of a camera corrected by `twist` from `d_left`, dL/dξ of that corrected camera for a
/// further left twist (`rasterize_cpu::camera_pose_gradient`): `(J_l(ω)ᵀ (g_ω + g_v × v), g_v)`.
pub fn twist_backward(
    d_left: &[f64; TWIST_VALUES],
    twist: &[f64; TWIST_VALUES],
) -> [f64; TWIST_VALUES] {
    let (g_w, g_v) = (
        [d_left[0], d_left[1], d_left[2]],
        [d_left[3], d_left[4], d_left[5]],
    );
    let v = [twist[3], twist[4], twist[5]];
    let turn = [
        g_w[0] + g_v[1] * v[2] - g_v[2] * v[1],
        g_w[1] + g_v[2] * v[0] - g_v[0] * v[2],
        g_w[2] + g_v[0] * v[1] - g_v[1] * v[0],
    ];
    let j = left_jacobian_so3([twist[0], twist[1], twist[2]]);
    let mut out = [0.0; TWIST_VALUES];
    for a in 0..3 {
        out[a] = (0..3).map(|i| j[i][a] * turn[i]).sum();
        out[3 + a] = g_v[a];
    }
    out
}

/// Adds `dL/d correction` ([`CAMERA_CORRECTION_VALUES`] values) to `grad` from `d_twist`, dL/dξ of
/// the twist taken at exposure offset `offset` ([`twist_at`]).
pub fn correction_backward(d_twist: &[f64; TWIST_VALUES], offset: f32, grad: &mut [f64]) {
    let (mid, change) = grad.split_at_mut(TWIST_VALUES);
    for k in 0..TWIST_VALUES {
        mid[k] += d_twist[k];
        change[k] += f64::from(offset) * d_twist[k];
    }
}

/// Training frames a held-out frame's camera correction is fitted to
/// ([`fitted_camera_correction`]).
pub const HELD_OUT_FIT_FRAMES: usize = 8;

/// The mid-exposure correction of frame `index` ([`CAMERA_CORRECTION_VALUES`] values, the change
/// zero) from the training frames' (`frames`, ascending, one row of `corrections` each): a training
/// frame's own row; any other frame's is the value at `index` of the least-squares line, in frame
/// number, through the [`HELD_OUT_FIT_FRAMES`] training frames nearest to it (ties: the earlier
/// frame), each value on its own (one frame: its row). A tracker errs by a slow drift plus a
/// per-frame jitter; the line follows the drift and averages the jitter of the frames it is fitted
/// to, where joining the two frames around `index` would carry their jitter into it (and hold the
/// last one past the clip's ends). Empty when `corrections` is.
pub fn fitted_camera_correction(frames: &[u32], corrections: &[f32], index: u32) -> Vec<f32> {
    let n = CAMERA_CORRECTION_VALUES;
    if corrections.is_empty() || frames.is_empty() {
        return Vec::new();
    }
    let row = |k: usize| &corrections[k * n..(k + 1) * n];
    let mut out = vec![0.0f32; n];
    if let Ok(k) = frames.binary_search(&index) {
        out[..TWIST_VALUES].copy_from_slice(&row(k)[..TWIST_VALUES]);
        return out;
    }
    let offset = |k: usize| f64::from(frames[k]) - f64::from(index);
    let mut nearest: Vec<usize> = (0..frames.len()).collect();
    nearest.sort_by(|&a, &b| offset(a).abs().total_cmp(&offset(b).abs()).then(a.cmp(&b)));
    nearest.truncate(HELD_OUT_FIT_FRAMES);
    let count = nearest.len() as f64;
    let sum_d: f64 = nearest.iter().map(|&k| offset(k)).sum();
    let sum_dd: f64 = nearest.iter().map(|&k| offset(k) * offset(k)).sum();
    let det = count * sum_dd - sum_d * sum_d;
    for (v, o) in out[..TWIST_VALUES].iter_mut().enumerate() {
        let sum_y: f64 = nearest.iter().map(|&k| f64::from(row(k)[v])).sum();
        let sum_dy: f64 = nearest
            .iter()
            .map(|&k| offset(k) * f64::from(row(k)[v]))
            .sum();
        // The line's value at offset 0; one frame (det = 0) gives its own value.
        *o = if det > 0.0 {
            ((sum_dd * sum_y - sum_d * sum_dy) / det) as f32
        } else {
            (sum_y / count) as f32
        };
    }
    out
}

/// Training slot `slot`'s weights over the stored corrections of the `slots` training slots under
/// a Gaussian smoothing `sigma` slots wide (`TrainConfig::camera_correction_smoothing`): `(slot j,
/// K(slot, j))` for |j − slot| ≤ 3σ, K ∝ exp(−(j − slot)² / 2σ²), summing to 1. With σ = 0 the
/// slot's own value alone.
pub fn smoothing_weights(slot: usize, slots: usize, sigma: f32) -> Vec<(usize, f64)> {
    if sigma <= 0.0 || slots == 0 {
        return vec![(slot, 1.0)];
    }
    let sigma = f64::from(sigma);
    let radius = (3.0 * sigma).ceil() as usize;
    let range = slot.saturating_sub(radius)..(slot + radius + 1).min(slots);
    let raw: Vec<(usize, f64)> = range
        .map(|j| {
            let d = j as f64 - slot as f64;
            (j, (-0.5 * d * d / (sigma * sigma)).exp())
        })
        .collect();
    let total: f64 = raw.iter().map(|&(_, w)| w).sum();
    raw.into_iter().map(|(j, w)| (j, w / total)).collect()
}

/// The corrections the training slots' cameras take: the leading `smoothed` values of the
/// `stored` rows ([`CAMERA_CORRECTION_VALUES`] each) smoothed over the slots by
/// [`smoothing_weights`], the rest each slot's own (the stored rows themselves at σ = 0).
pub fn smoothed_corrections(
    stored: &[f32],
    sigma: f32,
    smoothed: usize,
) -> std::borrow::Cow<'_, [f32]> {
    let n = CAMERA_CORRECTION_VALUES;
    let slots = stored.len() / n;
    if sigma <= 0.0 {
        return std::borrow::Cow::Borrowed(stored);
    }
    let mut out = Vec::with_capacity(stored.len());
    for slot in 0..slots {
        out.extend(smoothed_row(stored, slot, sigma, smoothed));
    }
    std::borrow::Cow::Owned(out)
}

/// Slot `slot`'s row of [`smoothed_corrections`] (the stored row itself at σ = 0; empty past
/// the stored rows).
pub fn smoothed_row(stored: &[f32], slot: usize, sigma: f32, smoothed: usize) -> Vec<f32> {
    let n = CAMERA_CORRECTION_VALUES;
    let slots = stored.len() / n;
    if sigma <= 0.0 || slot >= slots {
        return stored.get(slot * n..(slot + 1) * n).unwrap_or(&[]).to_vec();
    }
    let mut row = [0.0f64; CAMERA_CORRECTION_VALUES];
    for (j, w) in smoothing_weights(slot, slots, sigma) {
        for (r, &v) in row.iter_mut().zip(&stored[j * n..j * n + smoothed]) {
            *r += w * f64::from(v);
        }
    }
    let own = &stored[slot * n..(slot + 1) * n];
    (0..n)
        .map(|k| if k < smoothed { row[k] as f32 } else { own[k] })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn det(m: &[[f64; 3]; 3]) -> f64 {
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    }

    #[test]
    fn exp_is_a_rotation_about_its_axis_and_the_series_joins_the_closed_form() {
        for omega in [[0.3, -0.2, 0.9], [1e-5, 2e-5, -1e-5], [0.0, 0.0, 2.0]] {
            let r = exp_so3(omega);
            let rtr = mat_mul(
                &std::array::from_fn(|i| std::array::from_fn(|j| r[j][i])),
                &r,
            );
            for (i, row) in rtr.iter().enumerate() {
                for (j, v) in row.iter().enumerate() {
                    assert!((v - f64::from(u8::from(i == j))).abs() < 1e-12, "{omega:?}");
                }
            }
            assert!((det(&r) - 1.0).abs() < 1e-12);
            // The axis is fixed.
            let axis: [f64; 3] = std::array::from_fn(|i| (0..3).map(|k| r[i][k] * omega[k]).sum());
            for k in 0..3 {
                assert!((axis[k] - omega[k]).abs() < 1e-12);
            }
        }
        // A quarter turn about z maps x to y.
        let r = exp_so3([0.0, 0.0, std::f64::consts::FRAC_PI_2]);
        assert!((r[1][0] - 1.0).abs() < 1e-12 && r[0][0].abs() < 1e-12);
        // Just below and above the series' switch: sin θ to rounding (the series' first dropped
        // term is θ⁵/120 ≈ 1e-22).
        for angle in [0.99e-4f64, 1.01e-4] {
            let r = exp_so3([0.0, 0.0, angle]);
            assert!(
                (r[1][0] - angle.sin()).abs() < 1e-18,
                "{angle}: {}",
                r[1][0]
            );
        }
    }

    #[test]
    fn the_left_jacobian_maps_a_change_of_the_vector_to_a_left_turn() {
        // Exp(ω + hδ) Exp(ω)ᵀ ≈ I + h [J_l δ]ₓ: central differences in h.
        let omega = [0.4, -0.7, 0.25];
        let j = left_jacobian_so3(omega);
        let r0 = exp_so3(omega);
        let r0t: [[f64; 3]; 3] = std::array::from_fn(|i| std::array::from_fn(|k| r0[k][i]));
        let h = 1e-6;
        for d in 0..3 {
            let shifted = |s: f64| {
                let mut w = omega;
                w[d] += s;
                mat_mul(&exp_so3(w), &r0t)
            };
            let (up, down) = (shifted(h), shifted(-h));
            let fd = [
                (up[2][1] - down[2][1]) / (2.0 * h),
                (up[0][2] - down[0][2]) / (2.0 * h),
                (up[1][0] - down[1][0]) / (2.0 * h),
            ];
            for a in 0..3 {
                // Central differences of smooth f64 functions at h = 1e-6: error ≈ h² + 1e-16/h.
                assert!((fd[a] - j[a][d]).abs() < 1e-8, "column {d} row {a}: {fd:?}");
            }
        }
    }

    #[test]
    fn a_zero_twist_keeps_the_camera_and_a_shift_moves_it_in_its_own_coordinates() {
        let m = [
            [0.0, 0.0, 1.0, 0.5],
            [1.0, 0.0, 0.0, -0.2],
            [0.0, 1.0, 0.0, 3.0],
            [0.0, 0.0, 0.0, 1.0],
        ];
        assert_eq!(corrected_world_to_camera(&m, &[0.0; 6]), m);
        let shifted = corrected_world_to_camera(&m, &[0.0, 0.0, 0.0, 0.01, 0.0, -0.02]);
        assert_eq!(shifted[0][3], 0.51);
        assert_eq!(shifted[2][3], 2.98);
        let c = [
            0.1f32, 0.2, 0.3, 0.4, 0.5, 0.6, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0,
        ];
        let t = twist_at(&c, -0.5);
        assert!((t[0] - (0.1f32 as f64 - 0.5)).abs() < 1e-12 && (t[5] + 2.4).abs() < 1e-6);
        let mut g = vec![0.0; 12];
        correction_backward(&[1.0, 0.0, 0.0, 0.0, 0.0, 2.0], 0.25, &mut g);
        assert_eq!((g[0], g[5], g[6], g[11]), (1.0, 2.0, 0.25, 0.5));
    }

    #[test]
    fn smoothing_weights_are_a_normalised_gaussian_and_zero_width_keeps_each_slot() {
        assert_eq!(smoothing_weights(3, 10, 0.0), vec![(3, 1.0)]);
        let w = smoothing_weights(0, 10, 1.0);
        assert_eq!(w.first().map(|p| p.0), Some(0));
        assert_eq!(w.last().map(|p| p.0), Some(3));
        assert!((w.iter().map(|p| p.1).sum::<f64>() - 1.0).abs() < 1e-12);
        assert!((w[1].1 / w[0].1 - (-0.5f64).exp()).abs() < 1e-12);
        // A constant is kept, a spike spread over its neighbours.
        let rows: Vec<f32> = (0..10)
            .flat_map(|_| [0.25f32; CAMERA_CORRECTION_VALUES])
            .collect();
        let smoothed = smoothed_corrections(&rows, 1.5, CAMERA_CORRECTION_VALUES);
        assert!(smoothed.iter().all(|&v| (v - 0.25).abs() < 1e-6));
        let mut spike = vec![0.0f32; 10 * CAMERA_CORRECTION_VALUES];
        spike[5 * CAMERA_CORRECTION_VALUES] = 1.0;
        let s = smoothed_corrections(&spike, 1.0, CAMERA_CORRECTION_VALUES);
        let at = |slot: usize| s[slot * CAMERA_CORRECTION_VALUES];
        assert!(at(5) < 1.0 && at(4) > 0.0 && at(4) == at(6) && at(9) == 0.0);
        assert!(matches!(
            smoothed_corrections(&spike, 0.0, CAMERA_CORRECTION_VALUES),
            std::borrow::Cow::Borrowed(_)
        ));
        // Smoothing the mid-exposure twist alone keeps each row's change over the exposure.
        let mut change = spike.clone();
        change[5 * CAMERA_CORRECTION_VALUES + TWIST_VALUES] = 0.5;
        let s = smoothed_corrections(&change, 1.0, TWIST_VALUES);
        assert!(s[4 * CAMERA_CORRECTION_VALUES] > 0.0);
        assert_eq!(s[5 * CAMERA_CORRECTION_VALUES + TWIST_VALUES], 0.5);
        assert_eq!(s[4 * CAMERA_CORRECTION_VALUES + TWIST_VALUES], 0.0);
    }

    #[test]
    fn the_smoothings_gradient_is_each_frames_gradient_spread_by_its_weights() {
        // f(z) = Σ_k c_k · ξ_k(z) is linear in the stored rows z: its central differences in one
        // stored value equal Σ_k K(k, j) c_k, the spread the trainer applies (f32 rows of order 1,
        // h = 1e-2: rounding error ≈ 1e-7 / h per term).
        let (slots, n, sigma) = (9usize, CAMERA_CORRECTION_VALUES, 1.3f32);
        let z: Vec<f32> = (0..slots * n)
            .map(|i| ((i * 37 % 11) as f32 - 5.0) * 0.1)
            .collect();
        let c: Vec<f64> = (0..slots * n)
            .map(|i| ((i * 13 % 7) as f64 - 3.0) * 0.2)
            .collect();
        for smoothed in [n, TWIST_VALUES] {
            let f = |z: &[f32]| -> f64 {
                let s = smoothed_corrections(z, sigma, smoothed);
                s.iter().zip(&c).map(|(&a, &b)| f64::from(a) * b).sum()
            };
            let mut spread = vec![0.0f64; slots * n];
            for k in 0..slots {
                for (j, w) in smoothing_weights(k, slots, sigma) {
                    for v in 0..smoothed {
                        spread[j * n + v] += w * c[k * n + v];
                    }
                }
                for v in smoothed..n {
                    spread[k * n + v] += c[k * n + v];
                }
            }
            let h = 1e-2f32;
            for i in [0, 5, 3 * n + 2, 8 * n + 11] {
                let (mut up, mut down) = (z.clone(), z.clone());
                up[i] += h;
                down[i] -= h;
                let fd = (f(&up) - f(&down)) / f64::from(up[i] - down[i]);
                assert!(
                    (fd - spread[i]).abs() < 1e-4,
                    "value {i}: {fd} vs {}",
                    spread[i]
                );
            }
            assert!(spread.iter().any(|&g| g != 0.0));
        }
    }

    /// Rows of `CAMERA_CORRECTION_VALUES` whose six mid-exposure values are `value(frame)` and
    /// whose change is 7.
    fn rows_of(frames: &[u32], value: impl Fn(u32) -> f32) -> Vec<f32> {
        frames
            .iter()
            .flat_map(|&f| [[value(f); TWIST_VALUES], [7.0; TWIST_VALUES]].concat())
            .collect()
    }

    /// A training frame keeps its own row; a held-out frame gets the fitted line's value at its
    /// frame number (exact for values on a line, inside the clip and past its ends), the change
    /// zero; one training frame gives its row, none an empty correction.
    #[test]
    fn held_out_frames_take_the_line_through_the_nearest_training_frames() {
        let frames: Vec<u32> = (0..30).filter(|f| f % 10 < 7).collect();
        let line = |f: u32| 0.25 + 0.125 * f as f32;
        let rows = rows_of(&frames, |f| line(f) + if f == 12 { 1.0 } else { 0.0 });
        let own = fitted_camera_correction(&frames, &rows, 12);
        assert_eq!(own[..TWIST_VALUES], [line(12) + 1.0; TWIST_VALUES]);
        assert!(own[TWIST_VALUES..].iter().all(|&v| v == 0.0));
        let rows = rows_of(&frames, line);
        for index in [8, 9, 18, 27, 29, 40] {
            let at = fitted_camera_correction(&frames, &rows, index);
            assert_eq!(at.len(), CAMERA_CORRECTION_VALUES);
            for &v in &at[..TWIST_VALUES] {
                assert!(
                    (v - line(index)).abs() < 1e-5,
                    "frame {index}: {v} against {}",
                    line(index)
                );
            }
            assert!(at[TWIST_VALUES..].iter().all(|&v| v == 0.0));
        }
        assert_eq!(fitted_camera_correction(&[4], &rows[..12], 9)[0], line(0));
        assert!(fitted_camera_correction(&frames, &[], 3).is_empty());
    }

    /// The line averages the jitter of the frames it is fitted to: two neighbours 0.2 above a
    /// line move a held-out frame between them by 0.4 / 8 (the eight frames sit symmetrically
    /// about it), where joining the two neighbours would move it by the whole 0.2.
    #[test]
    fn a_held_out_frame_averages_its_neighbours_jitter() {
        let frames: Vec<u32> = (6..15).filter(|&f| f != 10).collect();
        let line = |f: u32| -0.5 + 0.0625 * f as f32;
        let rows = rows_of(&frames, |f| {
            line(f) + if f == 9 || f == 11 { 0.2 } else { 0.0 }
        });
        let at = fitted_camera_correction(&frames, &rows, 10);
        assert!(
            (at[0] - (line(10) + 0.05)).abs() < 1e-6,
            "{} against {}",
            at[0],
            line(10) + 0.05
        );
    }

    /// The tracker prior's gradient against f64 central differences of its value (h = 1e-6; the
    /// value is quadratic, so the differences are exact to rounding: |Δ| ≤ 1e-9 relative), on
    /// random rows; it fails with the rotation's and the shift's σ swapped, and leaves the
    /// exposure's change alone.
    #[test]
    fn the_tracker_prior_gradient_matches_its_differences_and_weighs_each_part_by_its_sigma() {
        let mut rng = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = || {
            rng ^= rng << 13;
            rng ^= rng >> 7;
            rng ^= rng << 17;
            (rng >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let params = (0.3, 0.5f64.to_radians(), 0.01);
        for _ in 0..16 {
            let row: Vec<f64> = (0..CAMERA_CORRECTION_VALUES)
                .map(|_| 0.02 * next())
                .collect();
            let mut grad = vec![0.0; CAMERA_CORRECTION_VALUES];
            tracker_prior_terms(&row, params, &mut grad);
            for k in 0..CAMERA_CORRECTION_VALUES {
                let h = 1e-6;
                let at = |d: f64| {
                    let mut r = row.clone();
                    r[k] += d;
                    tracker_prior_terms(&r, params, &mut [0.0; CAMERA_CORRECTION_VALUES])
                };
                let numeric = (at(h) - at(-h)) / (2.0 * h);
                let tol = 1e-9 * numeric.abs().max(grad[k].abs()) + 1e-12;
                assert!(
                    (numeric - grad[k]).abs() <= tol,
                    "{k}: {numeric} vs {}",
                    grad[k]
                );
                if k >= TWIST_VALUES {
                    assert_eq!(grad[k], 0.0);
                }
            }
            let swapped = (params.0, params.2, params.1);
            let mut other = vec![0.0; CAMERA_CORRECTION_VALUES];
            tracker_prior_terms(&row, swapped, &mut other);
            assert!((0..TWIST_VALUES).all(|k| (other[k] - grad[k]).abs() > 1e-6 * grad[k].abs()));
        }
    }
}
