//! The camera corrections' image-motion basis (`TrainConfig::camera_correction_basis = image`).
//!
//! A frame's mid-exposure twist ξ = (ω, v) (radians, metres; `super::camera_correction`) has six
//! values the images tell apart only through the parallax between depths: a pitch ω_x and a
//! vertical shift v_y = ω_x · Z* move the image of everything at depth Z* by the same amount in
//! opposite directions, so their sum is nearly invisible to a camera looking into a shallow room.
//! Adam steps each stored value by about its rate, whatever the loss's curvature across values,
//! so along such a coupled direction it crawls (measured on `handheld-err`: the corrected
//! cameras' pitch drifts while the centre error it is traded for grows).
//!
//! With this basis Adam steps coordinates `u` of the twist `ξ = P u` instead, where
//! `P = M^{-1/2}` and `M` is the mean over the scene's points of `JᵀJ`, `J` the 2 × 6 derivative of
//! a point's pixel position for a left twist of the camera: a unit step of `u` along any direction
//! moves the scene's image by one pixel RMS. Eigenvalues of `M` below [`EIGENVALUE_FLOOR`] of the
//! largest are raised to it (a direction no point resolves is amplified at most
//! `EIGENVALUE_FLOOR^{-1/2}` times). Only the optimiser's coordinates change: the stored corrections,
//! the rendering and every gradient stay the twist's.

use gaussians::covariance::symmetric_eigen;
use rasterize_cpu::Camera;

use super::camera_correction::TWIST_VALUES;

/// Values of a basis: a row-major 6 × 6 matrix.
pub const BASIS_VALUES: usize = TWIST_VALUES * TWIST_VALUES;

/// Eigenvalues of the image-motion metric below this fraction of its largest are raised to it.
pub const EIGENVALUE_FLOOR: f64 = 1e-3;

/// A 6 × 6 matrix, row-major.
pub type Matrix6 = [[f64; TWIST_VALUES]; TWIST_VALUES];

/// ∂(pixel x, pixel y)/∂ξ of a camera-space point `p` (metres, in front of the camera) for a
/// further left twist ξ = (ω, v) of the camera, `p' = Exp(ω) p + v`, at ξ = 0: rows x and y,
/// columns ω then v.
pub fn pixel_jacobian(camera: &Camera, p: [f64; 3]) -> [[f64; TWIST_VALUES]; 2] {
    let [x, y, z] = p;
    // ∂p'/∂ω = −[p]ₓ, ∂p'/∂v = I; the projection's ∂(u, v)/∂p.
    let dp_dw = [[0.0, z, -y], [-z, 0.0, x], [y, -x, 0.0]];
    let proj = [
        [camera.fx / z, 0.0, -camera.fx * x / (z * z)],
        [0.0, camera.fy / z, -camera.fy * y / (z * z)],
    ];
    let mut j = [[0.0; TWIST_VALUES]; 2];
    for (row, d) in j.iter_mut().zip(&proj) {
        for a in 0..3 {
            row[a] = (0..3).map(|k| d[k] * dp_dw[k][a]).sum();
            row[3 + a] = d[a];
        }
    }
    j
}

/// M = Σ w JᵀJ / Σ w over the `points` (world, metres) with weights `weights` that lie in front of
/// `camera` (view depth above 1 cm) and project inside its image: pixels² per unit twist². `None`
/// when no point with a positive weight qualifies.
pub fn image_motion_metric(
    camera: &Camera,
    points: &[[f32; 3]],
    weights: &[f32],
) -> Option<Matrix6> {
    let m = &camera.world_to_camera;
    let (w_px, h_px) = (f64::from(camera.width), f64::from(camera.height));
    let mut metric = [[0.0; TWIST_VALUES]; TWIST_VALUES];
    let mut total = 0.0;
    for (point, &weight) in points.iter().zip(weights) {
        let weight = f64::from(weight);
        let q = point.map(f64::from);
        let p: [f64; 3] =
            std::array::from_fn(|r| (0..3).map(|k| m[r][k] * q[k]).sum::<f64>() + m[r][3]);
        if !(weight > 0.0 && p[2] > 0.01) {
            continue;
        }
        let (u, v) = (
            camera.fx * p[0] / p[2] + camera.cx,
            camera.fy * p[1] / p[2] + camera.cy,
        );
        if !((0.0..w_px).contains(&u) && (0.0..h_px).contains(&v)) {
            continue;
        }
        let j = pixel_jacobian(camera, p);
        for (a, row) in metric.iter_mut().enumerate() {
            for (b, value) in row.iter_mut().enumerate() {
                *value += weight * (j[0][a] * j[0][b] + j[1][a] * j[1][b]);
            }
        }
        total += weight;
    }
    if total <= 0.0 {
        return None;
    }
    for value in metric.iter_mut().flatten() {
        *value /= total;
    }
    Some(metric)
}

/// The whitening basis P = V diag(max(λ, floor · λ_max)^{-1/2}) Vᵀ of a symmetric positive
/// semi-definite `metric` (V its eigenvectors, λ its eigenvalues; floor [`EIGENVALUE_FLOOR`]),
/// rounded to f32 so that a checkpoint stores it exactly. `None` when the metric is zero or not
/// finite.
pub fn whitening_basis(metric: &Matrix6) -> Option<[f32; BASIS_VALUES]> {
    let mut a = *metric;
    let (values, vectors) = symmetric_eigen(&mut a);
    let largest = values.iter().fold(0.0f64, |m, &v| m.max(v));
    if !(largest.is_finite() && largest > 0.0) {
        return None;
    }
    let scale = values.map(|l| 1.0 / l.max(EIGENVALUE_FLOOR * largest).sqrt());
    Some(std::array::from_fn(|k| {
        let (r, c) = (k / TWIST_VALUES, k % TWIST_VALUES);
        let v: f64 = (0..TWIST_VALUES)
            .map(|e| vectors[r][e] * scale[e] * vectors[c][e])
            .sum();
        v as f32
    }))
}

/// `basis · u` (or `basisᵀ · u` when `transpose`): a step of the basis' coordinates as a step of
/// the twist (or a twist's gradient as the coordinates').
pub fn apply_basis(basis: &[f32; BASIS_VALUES], u: &[f64], transpose: bool) -> [f64; TWIST_VALUES] {
    std::array::from_fn(|r| {
        (0..TWIST_VALUES)
            .map(|c| {
                let k = if transpose {
                    c * TWIST_VALUES + r
                } else {
                    r * TWIST_VALUES + c
                };
                f64::from(basis[k]) * u[c]
            })
            .sum()
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pose::camera_correction::corrected_world_to_camera;

    fn camera() -> Camera {
        Camera {
            width: 256,
            height: 192,
            fx: 230.0,
            fy: 225.0,
            cx: 128.0,
            cy: 96.0,
            world_to_camera: [
                [1.0, 0.0, 0.0, 0.1],
                [0.0, 1.0, 0.0, -0.2],
                [0.0, 0.0, 1.0, 0.3],
                [0.0, 0.0, 0.0, 1.0],
            ],
        }
    }

    fn pixel(camera: &Camera, world_to_camera: &[[f64; 4]; 4], q: [f64; 3]) -> [f64; 2] {
        let p: [f64; 3] = std::array::from_fn(|r| {
            (0..3).map(|k| world_to_camera[r][k] * q[k]).sum::<f64>() + world_to_camera[r][3]
        });
        [
            camera.fx * p[0] / p[2] + camera.cx,
            camera.fy * p[1] / p[2] + camera.cy,
        ]
    }

    /// The Jacobian is the central difference of the pixel position under the correction's own
    /// twist (`corrected_world_to_camera`), column by column; a wrong sign or a missing term of
    /// either part fails (relative 1e-6: the differences' truncation error at h = 1e-6 is ~1e-10).
    #[test]
    fn the_pixel_jacobian_is_the_difference_of_the_corrected_cameras_projection() {
        let cam = camera();
        for q in [[0.3, -0.1, 2.0], [-0.8, 0.5, 3.5], [0.05, 0.9, 1.2]] {
            let p: [f64; 3] = std::array::from_fn(|r| {
                (0..3)
                    .map(|k| cam.world_to_camera[r][k] * q[k])
                    .sum::<f64>()
                    + cam.world_to_camera[r][3]
            });
            let j = pixel_jacobian(&cam, p);
            let h = 1e-6;
            for c in 0..TWIST_VALUES {
                let mut plus = [0.0; TWIST_VALUES];
                plus[c] = h;
                let minus = plus.map(|x| -x);
                let a = pixel(
                    &cam,
                    &corrected_world_to_camera(&cam.world_to_camera, &plus),
                    q,
                );
                let b = pixel(
                    &cam,
                    &corrected_world_to_camera(&cam.world_to_camera, &minus),
                    q,
                );
                for axis in 0..2 {
                    let fd = (a[axis] - b[axis]) / (2.0 * h);
                    let tol = 1e-6 * fd.abs().max(1.0);
                    assert!(
                        (fd - j[axis][c]).abs() < tol,
                        "point {q:?}, axis {axis}, column {c}: analytic {} against {fd}",
                        j[axis][c]
                    );
                }
            }
        }
    }

    /// Points spread in depth: Pᵀ M P is the identity (no eigenvalue floored), and a pitch against
    /// the vertical shift that cancels it at the points' mean depth is nearly invisible in the
    /// metric (the direction the basis amplifies).
    #[test]
    fn the_basis_whitens_the_metric_of_a_shallow_room_with_a_near_null_direction() {
        let cam = camera();
        let mut points = Vec::new();
        for i in 0..200 {
            let t = i as f32 / 200.0;
            let depth = 2.0 + 1.5 * (t * 7.3).fract();
            points.push([
                (t * 13.7).fract() * 1.6 - 0.8,
                (t * 5.1).fract() * 1.2 - 0.4,
                depth - 0.3,
            ]);
        }
        let weights = vec![1.0; points.len()];
        let metric = image_motion_metric(&cam, &points, &weights).expect("points are seen");
        let basis = whitening_basis(&metric).expect("a metric");
        for r in 0..TWIST_VALUES {
            for c in 0..TWIST_VALUES {
                let col: [f64; TWIST_VALUES] = std::array::from_fn(|k| f64::from(basis[k * 6 + c]));
                let m_col: [f64; TWIST_VALUES] =
                    std::array::from_fn(|a| (0..6).map(|b| metric[a][b] * col[b]).sum());
                let v: f64 = (0..6).map(|a| f64::from(basis[a * 6 + r]) * m_col[a]).sum();
                let want = if r == c { 1.0 } else { 0.0 };
                assert!((v - want).abs() < 1e-4, "(PᵀMP)[{r}][{c}] = {v}");
            }
        }
        // A pitch with the vertical shift that cancels it at the points' mean depth (2.75 m) moves
        // their image by under a tenth of what the pitch alone does, per unit of twist.
        let motion = |d: [f64; 6]| {
            let n2: f64 = d.iter().map(|x| x * x).sum();
            (0..6)
                .map(|a| (0..6).map(|b| d[a] * metric[a][b] * d[b]).sum::<f64>())
                .sum::<f64>()
                / n2
        };
        let (null, pitch) = (
            [1.0, 0.0, 0.0, 0.0, 2.75, 0.0],
            [1.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        );
        assert!(
            motion(null) < 1e-2 * motion(pitch),
            "{} against {}",
            motion(null),
            motion(pitch)
        );
    }

    /// No point in front of the camera: no metric; a zero metric: no basis.
    #[test]
    fn nothing_seen_gives_no_basis() {
        let cam = camera();
        assert!(image_motion_metric(&cam, &[[0.0, 0.0, -5.0]], &[1.0]).is_none());
        assert!(image_motion_metric(&cam, &[[0.0, 0.0, 2.0]], &[0.0]).is_none());
        assert!(whitening_basis(&[[0.0; 6]; 6]).is_none());
    }
}
