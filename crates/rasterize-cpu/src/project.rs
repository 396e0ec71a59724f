//! EWA projection of one Gaussian to the image plane (INRIA 3DGS `preprocess`), and its analytic
//! backward. Generic over [`Real`] so the same code runs in f32 (rendering) and f64 (gradient checks).
//!
//! Rules: cull when the view depth z ≤ near; the Jacobian uses x/z and y/z clamped to gsplat's
//! asymmetric limits `[−cx/fx − 0.3·W/(2fx), (W−cx)/fx + 0.3·W/(2fx)]` (INRIA's ±1.3·tan(fov/2) for a
//! centred principal point) with the x/y gradient zeroed where clamped; +0.3 px² dilation; cull
//! det = 0; radius = ceil(3·√λmax), λ = mid ± √max(0.1, mid² − det); 16×16 tile rectangle as INRIA's
//! `getRect` (an empty rectangle culls). Additionally, and without changing any pixel, a Gaussian with
//! opacity < 1/255 is culled (its alpha can never reach the 1/255 cut). Never allocates.

use gaussians::covariance::{covariance_3d, covariance_3d_backward, Mat3};

use crate::{lit, Real, TILE_SIZE};

/// Camera constants in the working precision, derived once per render.
#[derive(Clone, Copy, Debug)]
pub struct CameraParams<T> {
    /// World-to-camera rotation part (rows).
    pub r: Mat3<T>,
    /// World-to-camera translation.
    pub t: [T; 3],
    /// Focal lengths (pixels).
    pub fx: T,
    /// Focal length y (pixels).
    pub fy: T,
    /// Principal point (pixels).
    pub cx: T,
    /// Principal point y (pixels).
    pub cy: T,
    /// Jacobian clamp: x/z ≥ −lim_x_neg.
    pub lim_x_neg: T,
    /// Jacobian clamp: x/z ≤ lim_x_pos.
    pub lim_x_pos: T,
    /// Jacobian clamp: y/z ≥ −lim_y_neg.
    pub lim_y_neg: T,
    /// Jacobian clamp: y/z ≤ lim_y_pos.
    pub lim_y_pos: T,
    /// Near plane (metres of view depth).
    pub near: T,
    /// Tile grid size (tiles).
    pub grid: [u32; 2],
}

impl<T: Real> CameraParams<T> {
    /// Converts a camera to working precision with the given near plane.
    pub fn new(cam: &crate::Camera, near: f64) -> Self {
        let m = &cam.world_to_camera;
        let (w, h) = (f64::from(cam.width), f64::from(cam.height));
        let tan_x = 0.5 * w / cam.fx;
        let tan_y = 0.5 * h / cam.fy;
        Self {
            r: [0, 1, 2].map(|i| [0, 1, 2].map(|j| lit(m[i][j]))),
            t: [lit(m[0][3]), lit(m[1][3]), lit(m[2][3])],
            fx: lit(cam.fx),
            fy: lit(cam.fy),
            cx: lit(cam.cx),
            cy: lit(cam.cy),
            lim_x_neg: lit(cam.cx / cam.fx + 0.3 * tan_x),
            lim_x_pos: lit((w - cam.cx) / cam.fx + 0.3 * tan_x),
            lim_y_neg: lit(cam.cy / cam.fy + 0.3 * tan_y),
            lim_y_pos: lit((h - cam.cy) / cam.fy + 0.3 * tan_y),
            near: lit(near),
            grid: [
                cam.width.div_ceil(TILE_SIZE as u32),
                cam.height.div_ceil(TILE_SIZE as u32),
            ],
        }
    }
}

/// A projected (visible) Gaussian: everything the tile kernels need.
#[derive(Clone, Copy, Debug)]
pub struct Projected<T> {
    /// Screen-space mean (pixels, pixel centres at i + 0.5).
    pub mean2d: [T; 2],
    /// Inverse of the dilated 2D covariance (a, b, c): power = −½(a dx² + c dy²) − b dx dy.
    pub conic: [T; 3],
    /// View depth z (metres).
    pub depth: T,
    /// Opacity (sigmoid of the logit).
    pub opacity: T,
    /// Half extents (pixels) of the region where alpha can reach 1/255, with a safety margin.
    pub extent: [T; 2],
    /// Tile rectangle [x0, y0, x1, y1) in tiles.
    pub rect: [u32; 4],
    /// INRIA screen radius (pixels).
    pub radius: u32,
}

/// Camera-space point `R p + t`.
#[inline]
pub fn to_camera<T: Real>(cam: &CameraParams<T>, p: [T; 3]) -> [T; 3] {
    let r = &cam.r;
    [
        r[0][0] * p[0] + r[0][1] * p[1] + r[0][2] * p[2] + cam.t[0],
        r[1][0] * p[0] + r[1][1] * p[1] + r[1][2] * p[2] + cam.t[1],
        r[2][0] * p[0] + r[2][1] * p[1] + r[2][2] * p[2] + cam.t[2],
    ]
}

/// Intermediate values shared by forward and backward.
struct Ewa<T> {
    p_cam: [T; 3],
    tx: T,
    ty: T,
    clamped: [bool; 2],
    jr: [[T; 3]; 2],
    sigma: Mat3<T>,
    cov: [T; 3],
}

#[inline]
fn ewa<T: Real>(cam: &CameraParams<T>, mean: [T; 3], sigma: Mat3<T>) -> Ewa<T> {
    let p = to_camera(cam, mean);
    let z = p[2];
    let xz = p[0] / z;
    let yz = p[1] / z;
    let cxz = xz.max(-cam.lim_x_neg).min(cam.lim_x_pos);
    let cyz = yz.max(-cam.lim_y_neg).min(cam.lim_y_pos);
    let clamped = [cxz != xz, cyz != yz];
    let tx = cxz * z;
    let ty = cyz * z;
    let z2 = z * z;
    let j00 = cam.fx / z;
    let j02 = -cam.fx * tx / z2;
    let j11 = cam.fy / z;
    let j12 = -cam.fy * ty / z2;
    // JR = J · R (2×3).
    let r = &cam.r;
    let mut jr = [[T::zero(); 3]; 2];
    for k in 0..3 {
        jr[0][k] = j00 * r[0][k] + j02 * r[2][k];
        jr[1][k] = j11 * r[1][k] + j12 * r[2][k];
    }
    let dil: T = lit(0.3);
    let [a, b, c] = quadratic_2d(&jr, &sigma);
    let (a, c) = (a + dil, c + dil);
    Ewa {
        p_cam: p,
        tx,
        ty,
        clamped,
        jr,
        sigma,
        cov: [a, b, c],
    }
}

/// M JR0 and M JR1, the products [`quadratic_2d`] and its backward share.
#[inline(always)]
fn times_rows<T: Real>(m: &Mat3<T>, jr: &[[T; 3]; 2]) -> [[T; 3]; 2] {
    jr.map(|row| [0, 1, 2].map(|k| m[k][0] * row[0] + m[k][1] * row[1] + m[k][2] * row[2]))
}

/// JR M JRᵀ of a 3×3 matrix `m` as (xx, xy, yy) — the screen-space covariance of the world
/// covariance `m` (without the dilation); xy is row 0 of JR against row 1.
#[inline(always)]
fn quadratic_2d<T: Real>(jr: &[[T; 3]; 2], m: &Mat3<T>) -> [T; 3] {
    let [s0, s1] = times_rows(m, jr);
    [
        jr[0][0] * s0[0] + jr[0][1] * s0[1] + jr[0][2] * s0[2],
        jr[0][0] * s1[0] + jr[0][1] * s1[1] + jr[0][2] * s1[2],
        jr[1][0] * s1[0] + jr[1][1] * s1[1] + jr[1][2] * s1[2],
    ]
}

/// Projects one Gaussian given by log-scales and a quaternion; `None` when it is culled (behind the
/// near plane, det = 0, opacity below 1/255, or an empty tile rectangle). Same as [`project_cov`]
/// with Σ = `covariance_3d(log_scale, quat)` (computed only when the cheap culls pass).
#[inline]
pub fn project<T: Real>(
    cam: &CameraParams<T>,
    mean: [T; 3],
    log_scale: [T; 3],
    quat: [T; 4],
    opacity_logit: T,
) -> Option<Projected<T>> {
    project_with(
        cam,
        mean,
        opacity_logit,
        || covariance_3d(log_scale, quat),
        None,
    )
}

/// Projects one Gaussian given by its world-frame 3D covariance `sigma` (m², row-major, all nine
/// entries used as given: cov2d = J W Σ Wᵀ Jᵀ); `None` when it is culled (see [`project`]).
#[inline]
pub fn project_cov<T: Real>(
    cam: &CameraParams<T>,
    mean: [T; 3],
    sigma: &Mat3<T>,
    opacity_logit: T,
) -> Option<Projected<T>> {
    project_with(cam, mean, opacity_logit, || *sigma, None)
}

/// [`project_cov`] of a Gaussian that moves during the render's time slice, rendered as its time
/// average: `smear` is the world covariance of its positions over the slice (m²; a displacement u
/// at constant speed gives u uᵀ/12). The screen covariance gains J W smear Wᵀ Jᵀ and the opacity is
/// scaled by √(det cov2d / det cov2d′) (both dilated), so that the splat's screen-space mass is
/// kept — a Gaussian blurred by its motion, as a box-filtered moving Gaussian is to second order.
/// A zero `smear` gives [`project_cov`]'s bits.
#[inline]
pub fn project_cov_smeared<T: Real>(
    cam: &CameraParams<T>,
    mean: [T; 3],
    sigma: &Mat3<T>,
    smear: &Mat3<T>,
    opacity_logit: T,
) -> Option<Projected<T>> {
    project_with(cam, mean, opacity_logit, || *sigma, Some(smear))
}

/// Shared body of [`project`] and [`project_cov`]; `sigma` is evaluated after the depth and opacity
/// culls.
#[inline(always)]
fn project_with<T: Real>(
    cam: &CameraParams<T>,
    mean: [T; 3],
    opacity_logit: T,
    sigma: impl FnOnce() -> Mat3<T>,
    smear: Option<&Mat3<T>>,
) -> Option<Projected<T>> {
    let p = to_camera(cam, mean);
    if !(p[2] > cam.near) {
        return None;
    }
    let opacity = T::one() / (T::one() + (-opacity_logit).exp());
    let cut: T = lit(1.0 / 255.0);
    if !(opacity >= cut) {
        return None;
    }
    let e = ewa(cam, mean, sigma());
    let ([a, b, c], opacity) = match smear {
        None => (e.cov, opacity),
        Some(smear) => smeared(&e, smear, opacity)?,
    };
    let det = a * c - b * b;
    if !(det > T::zero()) {
        return None;
    }
    let inv_det = T::one() / det;
    let conic = [c * inv_det, -b * inv_det, a * inv_det];
    let half: T = lit(0.5);
    let mid = half * (a + c);
    let disc = (mid * mid - det).max(lit(0.1)).sqrt();
    let lambda1 = mid + disc;
    let lambda2 = mid - disc;
    let three: T = lit(3.0);
    let radius_t = (three * lambda1.max(lambda2).sqrt()).ceil();
    let z = e.p_cam[2];
    let u = cam.fx * e.p_cam[0] / z + cam.cx;
    let v = cam.fy * e.p_cam[1] / z + cam.cy;
    // INRIA getRect on INRIA's pixel coordinates (centres at integers), computed in T like the CUDA
    // code computes it in f32; the int cast truncates toward zero, then clamps to [0, grid].
    let ts: T = lit(TILE_SIZE as f64);
    let ts1: T = lit(TILE_SIZE as f64 - 1.0);
    let pu = u - half;
    let pv = v - half;
    let to_tile = |val: T, max: u32| -> u32 {
        let i = val.to_f64().map_or(0, |f| f as i64);
        i.clamp(0, i64::from(max)) as u32
    };
    let rect = [
        to_tile((pu - radius_t) / ts, cam.grid[0]),
        to_tile((pv - radius_t) / ts, cam.grid[1]),
        to_tile((pu + radius_t + ts1) / ts, cam.grid[0]),
        to_tile((pv + radius_t + ts1) / ts, cam.grid[1]),
    ];
    if rect[2] <= rect[0] || rect[3] <= rect[1] {
        return None;
    }
    // alpha ≥ 1/255 needs power ≥ −ln(255·o); the ellipse dᵀ conic d ≤ 2 ln(255 o) has half extents
    // √(2 ln(255 o) · cov_xx) and √(… · cov_yy). Margin: relative 1e-3 plus 0.05 px (far above any
    // rounding of the power), so that restricting the pixel loop to it never changes the image.
    let t = (opacity * lit(255.0)).ln().max(T::zero());
    let two: T = lit(2.0);
    let rel: T = lit(1.001);
    let abs: T = lit(0.05);
    let extent = [
        (two * t * a).sqrt() * rel + abs,
        (two * t * c).sqrt() * rel + abs,
    ];
    Some(Projected {
        mean2d: [u, v],
        conic,
        depth: z,
        opacity,
        extent,
        rect,
        radius: radius_t.to_u32().unwrap_or(0),
    })
}

/// The smeared screen covariance and opacity of [`project_cov_smeared`]; `None` (culled) when
/// either covariance is degenerate.
#[inline(always)]
fn smeared<T: Real>(e: &Ewa<T>, smear: &Mat3<T>, opacity: T) -> Option<([T; 3], T)> {
    let [a, b, c] = e.cov;
    let [sa, sb, sc] = quadratic_2d(&e.jr, smear);
    let cov = [a + sa, b + sb, c + sc];
    let det = a * c - b * b;
    let det_smeared = cov[0] * cov[2] - cov[1] * cov[1];
    if !(det > T::zero() && det_smeared > T::zero()) {
        return None;
    }
    Some((cov, opacity * (det / det_smeared).sqrt()))
}

/// Gradients arriving at one projected Gaussian from the tile kernels.
#[derive(Clone, Copy, Debug, Default)]
pub struct ProjectedGrad<T> {
    /// dL/d screen-space mean (per pixel).
    pub mean2d: [T; 2],
    /// dL/d conic (a, b, c) as used in the power.
    pub conic: [T; 3],
    /// dL/d opacity.
    pub opacity: T,
    /// dL/d view depth (from the depth output).
    pub depth: T,
}

/// Backward of [`project`] for a visible Gaussian: returns dL/d(mean, log-scale, quaternion,
/// opacity logit).
#[inline]
pub fn project_backward<T: Real>(
    cam: &CameraParams<T>,
    mean: [T; 3],
    log_scale: [T; 3],
    quat: [T; 4],
    opacity_logit: T,
    g: &ProjectedGrad<T>,
) -> ([T; 3], [T; 3], [T; 4], T) {
    let sigma = covariance_3d(log_scale, quat);
    let (d_mean, d_sigma, d_logit) = project_cov_backward(cam, mean, &sigma, opacity_logit, g);
    let (d_log_scale, d_quat) = covariance_3d_backward(log_scale, quat, &d_sigma);
    (d_mean, d_log_scale, d_quat, d_logit)
}

/// Backward of [`project_cov`] for a visible Gaussian: returns dL/d(mean, Σ, opacity logit), where
/// dL/dΣ treats the nine entries of Σ as independent variables of cov2d = J W Σ Wᵀ Jᵀ (it is not
/// symmetrised; a caller building Σ from its own parameters chains it entry by entry).
#[inline]
pub fn project_cov_backward<T: Real>(
    cam: &CameraParams<T>,
    mean: [T; 3],
    sigma: &Mat3<T>,
    opacity_logit: T,
    g: &ProjectedGrad<T>,
) -> ([T; 3], Mat3<T>, T) {
    let e = ewa(cam, mean, *sigma);
    let d_cov = conic_backward(e.cov, g.conic);
    let (d_mean, d_sigma) = covariance_backward(cam, &e, d_cov, None, g);
    let o = T::one() / (T::one() + (-opacity_logit).exp());
    let d_logit = g.opacity * o * (T::one() - o);
    (d_mean, d_sigma, d_logit)
}

/// Backward of [`project_cov_smeared`] for a visible Gaussian: returns dL/d(mean, Σ, smear,
/// opacity logit), Σ's and the smear's nine entries independent (as [`project_cov_backward`]).
#[inline]
pub fn project_cov_smeared_backward<T: Real>(
    cam: &CameraParams<T>,
    mean: [T; 3],
    sigma: &Mat3<T>,
    smear: &Mat3<T>,
    opacity_logit: T,
    g: &ProjectedGrad<T>,
) -> ([T; 3], Mat3<T>, Mat3<T>, T) {
    let e = ewa(cam, mean, *sigma);
    let [a, b, c] = e.cov;
    let o = T::one() / (T::one() + (-opacity_logit).exp());
    let half: T = lit(0.5);
    let two: T = lit(2.0);
    if smear.iter().flatten().all(|&v| v == T::zero()) {
        // cov′ = cov and o′ = o: [`project_cov_backward`]'s bits, and dL/d smear from dL/dcov′,
        // which adds to dL/dcov the opacity's share through det′ (−o / (2 det) ∂det′).
        let (d_mean, d_sigma, d_logit) = project_cov_backward(cam, mean, sigma, opacity_logit, g);
        let [ca, cb, cc] = conic_backward(e.cov, g.conic);
        let g_det = g.opacity * o * half / (a * c - b * b);
        let d_smeared = [ca - c * g_det, cb + two * b * g_det, cc - a * g_det];
        let d_smear = quadratic_2d_backward_matrix(&e.jr, d_smeared);
        return (d_mean, d_sigma, d_smear, d_logit);
    }
    let [sa, sb, sc] = quadratic_2d(&e.jr, smear);
    let cov = [a + sa, b + sb, c + sc];
    let det = a * c - b * b;
    let det_smeared = cov[0] * cov[2] - cov[1] * cov[1];
    let scale = (det / det_smeared).sqrt();
    // o′ = o √(det / det′): ∂o′/∂det = o′ / (2 det), ∂o′/∂det′ = −o′ / (2 det′); det = a c − b².
    let g_det = g.opacity * o * scale * half / det;
    let g_det_smeared = -(g.opacity * o * scale * half / det_smeared);
    let [ca, cb, cc] = conic_backward(cov, g.conic);
    let d_smeared = [
        ca + cov[2] * g_det_smeared,
        cb - two * cov[1] * g_det_smeared,
        cc + cov[0] * g_det_smeared,
    ];
    let d_cov = [
        d_smeared[0] + c * g_det,
        d_smeared[1] - two * b * g_det,
        d_smeared[2] + a * g_det,
    ];
    let d_smear = quadratic_2d_backward_matrix(&e.jr, d_smeared);
    let d_jr = quadratic_2d_backward_jr(&e.jr, smear, d_smeared);
    let (d_mean, d_sigma) = covariance_backward(cam, &e, d_cov, Some(d_jr), g);
    let d_logit = g.opacity * scale * o * (T::one() - o);
    (d_mean, d_sigma, d_smear, d_logit)
}

/// dL/d(a, b, c) of the screen covariance from dL/d its conic (c, −b, a)/det.
#[inline(always)]
fn conic_backward<T: Real>([a, b, c]: [T; 3], [ga, gb, gc]: [T; 3]) -> [T; 3] {
    let det = a * c - b * b;
    let det2 = det * det;
    let two: T = lit(2.0);
    [
        (-ga * c * c + gb * b * c - gc * b * b) / det2,
        (ga * two * b * c - gb * (a * c + b * b) + gc * two * a * b) / det2,
        (-ga * b * b + gb * a * b - gc * a * a) / det2,
    ]
}

/// dL/dM of [`quadratic_2d`] (JR M JRᵀ) from dL/d(xx, xy, yy), M's entries independent:
/// dM_kl = d_xx JR0k JR0l + d_xy JR0k JR1l + d_yy JR1k JR1l.
#[inline(always)]
fn quadratic_2d_backward_matrix<T: Real>(jr: &[[T; 3]; 2], [da, db, dc]: [T; 3]) -> Mat3<T> {
    let mut d = [[T::zero(); 3]; 3];
    for k in 0..3 {
        for l in 0..3 {
            d[k][l] =
                da * jr[0][k] * jr[0][l] + db * jr[0][k] * jr[1][l] + dc * jr[1][k] * jr[1][l];
        }
    }
    d
}

/// dL/dJR of [`quadratic_2d`] for a symmetric M: dJR0 = 2 d_xx M JR0 + d_xy M JR1,
/// dJR1 = d_xy M JR0 + 2 d_yy M JR1.
#[inline(always)]
fn quadratic_2d_backward_jr<T: Real>(
    jr: &[[T; 3]; 2],
    m: &Mat3<T>,
    [da, db, dc]: [T; 3],
) -> [[T; 3]; 2] {
    let two: T = lit(2.0);
    let [mj0, mj1] = times_rows(m, jr);
    let mut djr = [[T::zero(); 3]; 2];
    for k in 0..3 {
        djr[0][k] = two * da * mj0[k] + db * mj1[k];
        djr[1][k] = db * mj0[k] + two * dc * mj1[k];
    }
    djr
}

/// The projection's backward from dL/d(a, b, c) of the screen covariance JR Σ JRᵀ + dilation
/// (plus `extra_jr`, a further dL/dJR, when given) and `g`'s screen mean and depth: dL/d(mean, Σ).
#[inline(always)]
fn covariance_backward<T: Real>(
    cam: &CameraParams<T>,
    e: &Ewa<T>,
    d_cov: [T; 3],
    extra_jr: Option<[[T; 3]; 2]>,
    g: &ProjectedGrad<T>,
) -> ([T; 3], Mat3<T>) {
    let two: T = lit(2.0);
    let d_sigma = quadratic_2d_backward_matrix(&e.jr, d_cov);
    let mut djr = quadratic_2d_backward_jr(&e.jr, &e.sigma, d_cov);
    if let Some(extra) = extra_jr {
        for (row, extra_row) in djr.iter_mut().zip(extra) {
            for (d, x) in row.iter_mut().zip(extra_row) {
                *d = *d + x;
            }
        }
    }
    // JR_rk = Σ_m J_rm R_mk  ⇒  dJ_rm = Σ_k dJR_rk R_mk; J has entries (0,0), (0,2), (1,1), (1,2).
    let r = &cam.r;
    let dot = |u: &[T; 3], v: &[T; 3]| u[0] * v[0] + u[1] * v[1] + u[2] * v[2];
    let dj00 = dot(&djr[0], &r[0]);
    let dj02 = dot(&djr[0], &r[2]);
    let dj11 = dot(&djr[1], &r[1]);
    let dj12 = dot(&djr[1], &r[2]);
    let [x, y, z] = e.p_cam;
    let z2 = z * z;
    let z3 = z2 * z;
    let (fx, fy) = (cam.fx, cam.fy);
    let mut dx = T::zero();
    let mut dy = T::zero();
    let mut dz = g.depth;
    dz = dz - dj00 * fx / z2 - dj11 * fy / z2
        + dj02 * two * fx * e.tx / z3
        + dj12 * two * fy * e.ty / z3;
    let dtx = -dj02 * fx / z2;
    let dty = -dj12 * fy / z2;
    // tx = z·clamp(x/z): where clamped, tx = z·limit (no x dependence, gradient zeroed).
    if e.clamped[0] {
        dz = dz + dtx * (e.tx / z);
    } else {
        dx = dx + dtx;
    }
    if e.clamped[1] {
        dz = dz + dty * (e.ty / z);
    } else {
        dy = dy + dty;
    }
    // Screen mean u = fx x/z + cx, v = fy y/z + cy.
    let [gu, gv] = g.mean2d;
    dx = dx + gu * fx / z;
    dy = dy + gv * fy / z;
    dz = dz - gu * fx * x / z2 - gv * fy * y / z2;
    // p_cam = R p + t ⇒ dp = Rᵀ dp_cam.
    let d_mean = [
        r[0][0] * dx + r[1][0] * dy + r[2][0] * dz,
        r[0][1] * dx + r[1][1] * dy + r[2][1] * dz,
        r[0][2] * dx + r[1][2] * dy + r[2][2] * dz,
    ];
    (d_mean, d_sigma)
}
