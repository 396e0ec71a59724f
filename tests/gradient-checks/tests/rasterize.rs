//! Checks of the `rasterize-cpu` backward pass and of its hard (non-differentiable) rules.
//!
//! Three independent lines of evidence, all in f64:
//! 1. A naive per-pixel oracle renderer written here (its own projection, a `std` sort of every
//!    Gaussian whose tile rectangle covers the pixel's tile, INRIA blending) must match the crate's
//!    forward to 1e-12, including the 0.99 clamp, the 1/255 cut and the early stop.
//! 2. The oracle's own backward (per pixel, back to front with T recovered by division, chained
//!    through a central-difference Jacobian of the oracle projection) must match the crate's backward
//!    for a random cotangent on image, alpha and depth — on the hard path, whatever the thresholds do.
//! 3. Central finite differences of the crate's forward must match the crate's backward. Finite
//!    differences are meaningless across the hard steps (1/255 cut, 0.99 clamp, early stop, tile
//!    rectangle, Jacobian clamp, near plane), so every probe is validated: the oracle records every
//!    discrete decision (per pixel and splat: power > 0, α < 1/255, clamped, stop; per Gaussian:
//!    visibility, tile rectangle, Jacobian clamp) and a probe whose x ± h decisions differ from x's is
//!    discarded (counted; at least 90% of a run's probes must be valid, `ProbeTally`).
//!
//! Tolerances. FD (h = 1e-6): the loss L = Σ cot·output is O(10); rounding error ε·|L|/h ≈ 1e-9, and
//! truncation error h²·|L'''|/6 where L''' w.r.t. a world-space mean scales like (f/z)³/σ³ ≈ 1e7 for
//! our smallest splats, i.e. ≈ 2e-6. Hence |num − ana| ≤ 1e-5 + 1e-5·max(|num|, |ana|). Oracle
//! backward: both sides analytic in the blending, the projection Jacobian by central differences
//! (relative error ≈ 1e-9), so 1e-7 + 1e-6·max.
//!
//! Proptest case counts (dev profile, ~seconds each): 48 oracle scenes, 24 FD scenes, 12 SH scenes.

use gaussians::covariance::{covariance_3d, covariance_3d_backward, Mat3};
use gradient_checks::{central_differences, rng, GradientChecker, ProbeTally, Tolerance};
use proptest::prelude::*;
use rand::Rng;
use rasterize_cpu::{
    camera_pose_gradient, render, render_backward, render_cov, render_cov_backward,
    render_cov_shared, render_cov_shared_backward, render_sh, render_sh_backward, Camera,
    CameraError, Cotangents, CovSplats, RasterError, RenderSettings, ShSplats, Splats,
};
use train::pose::camera_correction::{
    corrected_world_to_camera, correction_backward, exp_so3, twist_backward,
};

const NEAR: f64 = 0.2;
const FD_H: f64 = 1e-6;
const FD_TOL: Tolerance = Tolerance::new(1e-5, 1e-5);
const ORACLE_TOL: Tolerance = Tolerance::new(1e-7, 1e-6);

// ---------------------------------------------------------------------------------------------
// Scenes.

#[derive(Clone, Debug)]
struct Scene {
    cam: Camera,
    means: Vec<[f64; 3]>,
    log_scales: Vec<[f64; 3]>,
    quats: Vec<[f64; 4]>,
    logits: Vec<f64>,
    channels: Vec<f64>,
    c: usize,
    background: Vec<f64>,
    /// Precomputed covariances overriding (log_scales, quats) in the oracle; rendered with
    /// `render_cov` by [`cov_loss`].
    covs: Option<Vec<Mat3<f64>>>,
}

impl Scene {
    fn n(&self) -> usize {
        self.means.len()
    }
    fn splats(&self) -> Splats<'_, f64> {
        Splats {
            means: &self.means,
            log_scales: &self.log_scales,
            quats: &self.quats,
            opacity_logits: &self.logits,
            channels: &self.channels,
            num_channels: self.c,
        }
    }
    fn settings(&self) -> RenderSettings {
        RenderSettings {
            near_plane: NEAR,
            background: self.background.clone(),
        }
    }
    /// Parameters of Gaussian i as a flat vector: mean 3, log-scale 3, quat 4, logit 1, channels C.
    fn params(&self, i: usize) -> Vec<f64> {
        let mut v = Vec::new();
        v.extend_from_slice(&self.means[i]);
        v.extend_from_slice(&self.log_scales[i]);
        v.extend_from_slice(&self.quats[i]);
        v.push(self.logits[i]);
        v.extend_from_slice(&self.channels[i * self.c..(i + 1) * self.c]);
        v
    }
    fn set_params(&mut self, i: usize, p: &[f64]) {
        self.means[i] = [p[0], p[1], p[2]];
        self.log_scales[i] = [p[3], p[4], p[5]];
        self.quats[i] = [p[6], p[7], p[8], p[9]];
        self.logits[i] = p[10];
        let c = self.c;
        self.channels[i * c..(i + 1) * c].copy_from_slice(&p[11..11 + c]);
    }
}

fn rot_from_quat(q: [f64; 4]) -> [[f64; 3]; 3] {
    gaussians::covariance::rotation_from_quat(q)
}

/// A camera with an off-centre principal point and a random pose; image sizes are not multiples of
/// the tile size so edge tiles are partial.
fn random_camera(rng: &mut impl Rng) -> Camera {
    let w = rng.gen_range(20.0f64..52.0).floor();
    let h = rng.gen_range(18.0f64..44.0).floor();
    let fx = rng.gen_range(25.0..60.0);
    let fy = fx * rng.gen_range(0.85..1.15);
    let cx = w * 0.5 + rng.gen_range(-6.0..6.0);
    let cy = h * 0.5 + rng.gen_range(-6.0..6.0);
    let r = rot_from_quat([
        1.0,
        rng.gen_range(-0.3..0.3),
        rng.gen_range(-0.3..0.3),
        rng.gen_range(-0.3..0.3),
    ]);
    let t = [
        rng.gen_range(-0.5..0.5),
        rng.gen_range(-0.5..0.5),
        rng.gen_range(-0.5..0.5),
    ];
    let mut m = [[0.0; 4]; 4];
    for i in 0..3 {
        m[i][..3].copy_from_slice(&r[i]);
        m[i][3] = t[i];
    }
    m[3][3] = 1.0;
    match Camera::new(w as u64, h as u64, fx, fy, cx, cy, m) {
        Ok(c) => c,
        Err(e) => panic!("test camera invalid: {e}"),
    }
}

/// World point of pixel (u, v) at view depth z.
fn unproject(cam: &Camera, u: f64, v: f64, z: f64) -> [f64; 3] {
    let pc = [(u - cam.cx) / cam.fx * z, (v - cam.cy) / cam.fy * z, z];
    let m = &cam.world_to_camera;
    // p_world = Rᵀ (p_cam − t) for a rotation R.
    let d = [pc[0] - m[0][3], pc[1] - m[1][3], pc[2] - m[2][3]];
    [0, 1, 2].map(|j| m[0][j] * d[0] + m[1][j] * d[1] + m[2][j] * d[2])
}

/// Gaussian kinds, so every scene mixes the regimes the issue lists.
const KINDS: usize = 9;
/// Kind of the anchor Gaussian every scene starts with.
const ANCHOR: usize = 100;

/// A random scene; `kinds` picks each Gaussian's regime:
/// 0 ordinary, 1 tiny (sub-pixel, dilation-dominated), 2 huge (covers the image), 3 near plane
/// (mean just in front, extending behind it), 4 straddling a tile border, 5 opaque (hits the 0.99
/// clamp and, stacked, the early stop), 6 overlapping the previous one, 7 off-screen or behind,
/// 8 centred beyond the Jacobian clamp limits but large enough to reach the image.
fn random_scene(seed: u64, kinds: &[usize], c: usize) -> Scene {
    let mut rng = rng(seed);
    let cam = random_camera(&mut rng);
    let (w, h) = (f64::from(cam.width), f64::from(cam.height));
    let mut s = Scene {
        cam: cam.clone(),
        means: vec![],
        log_scales: vec![],
        quats: vec![],
        logits: vec![],
        channels: vec![],
        c,
        background: (0..c).map(|_| rng.gen_range(0.0..1.0)).collect(),
        covs: None,
    };
    let mut prev_uvz = (w * 0.5, h * 0.5, 2.0);
    // Kind 8 = an anchor: an ordinary Gaussian in the middle of the image, so every scene has
    // non-zero gradients whatever the drawn kinds.
    for &kind in std::iter::once(&ANCHOR).chain(kinds) {
        let mut u = rng.gen_range(-0.1 * w..1.1 * w);
        let mut v = rng.gen_range(-0.1 * h..1.1 * h);
        let mut z: f64 = rng.gen_range(1.0..4.0);
        // Log-scale giving a footprint of `px` pixels: σ_world ≈ px · z / f.
        let mut px = rng.gen_range(1.5..6.0);
        let mut logit = rng.gen_range(-2.0..2.5);
        match kind {
            1 => px = rng.gen_range(0.05..0.4),
            2 => px = rng.gen_range(20.0..60.0),
            3 => {
                z = rng.gen_range(0.25..0.45);
                px = rng.gen_range(4.0..20.0);
            }
            4 => {
                u = 16.0 * (1.0 + (rng.gen_range(0.0..w / 16.0 - 1.0)).floor().max(0.0))
                    + rng.gen_range(-1.5..1.5);
                v = 16.0 * (rng.gen_range(0.0..h / 16.0)).floor() + rng.gen_range(-1.5..1.5);
            }
            5 => {
                logit = rng.gen_range(5.0..9.0);
                px = rng.gen_range(4.0..10.0);
                u = rng.gen_range(0.2 * w..0.8 * w);
                v = rng.gen_range(0.2 * h..0.8 * h);
            }
            6 => {
                u = prev_uvz.0 + rng.gen_range(-2.0..2.0);
                v = prev_uvz.1 + rng.gen_range(-2.0..2.0);
                z = prev_uvz.2 + rng.gen_range(0.05..0.5);
            }
            8 => {
                // Limits are at −0.15·W and 1.15·W for a centred principal point.
                u = if rng.gen_bool(0.5) {
                    -0.35 * w
                } else {
                    1.35 * w
                };
                px = rng.gen_range(0.3 * w..0.6 * w);
            }
            ANCHOR => {
                u = rng.gen_range(0.3 * w..0.7 * w);
                v = rng.gen_range(0.3 * h..0.7 * h);
            }
            7 => {
                if rng.gen_bool(0.5) {
                    z = rng.gen_range(-2.0..0.15);
                } else {
                    u = if rng.gen_bool(0.5) { -300.0 } else { w + 300.0 };
                }
            }
            _ => {}
        }
        prev_uvz = (u, v, z);
        let base = (px * z.abs().max(0.3) / cam.fx).ln();
        let means = unproject(&cam, u, v, z);
        s.means.push(means);
        s.log_scales.push([
            base + rng.gen_range(-0.7..0.7),
            base + rng.gen_range(-0.7..0.7),
            base + rng.gen_range(-0.7..0.7),
        ]);
        s.quats.push([
            rng.gen_range(-1.0..1.0),
            rng.gen_range(-1.0..1.0),
            rng.gen_range(-1.0..1.0),
            rng.gen_range(-1.0..1.0),
        ]);
        s.logits.push(logit);
        for _ in 0..c {
            s.channels.push(rng.gen_range(-0.5..1.5));
        }
    }
    s
}

/// Kind of Gaussian i of a scene built from `kinds` (index 0 is the anchor).
fn kind_of(kinds: &[usize], i: usize) -> usize {
    if i == 0 {
        ANCHOR
    } else {
        kinds[i - 1]
    }
}

fn kinds_strategy(max: usize) -> impl Strategy<Value = Vec<usize>> {
    prop::collection::vec(0..KINDS, 1..=max)
}

// ---------------------------------------------------------------------------------------------
// The oracle.

#[derive(Clone, Copy, Debug, PartialEq)]
struct OracleGauss {
    visible: bool,
    uv: [f64; 2],
    conic: [f64; 3],
    opacity: f64,
    depth: f64,
    rect: [i64; 4],
    jac_clamp: [bool; 2],
}

/// INRIA `preprocess` written out plainly for one Gaussian; `cov` overrides Σ from the log-scales
/// and quaternion in `p`.
fn oracle_project(cam: &Camera, p: &[f64], cov: Option<&Mat3<f64>>) -> OracleGauss {
    let m = &cam.world_to_camera;
    let pc: [f64; 3] =
        [0, 1, 2].map(|i| m[i][0] * p[0] + m[i][1] * p[1] + m[i][2] * p[2] + m[i][3]);
    let invisible = OracleGauss {
        visible: false,
        uv: [0.0; 2],
        conic: [0.0; 3],
        opacity: 0.0,
        depth: pc[2],
        rect: [0; 4],
        jac_clamp: [false; 2],
    };
    if pc[2] <= NEAR {
        return invisible;
    }
    let (w, h) = (f64::from(cam.width), f64::from(cam.height));
    let (fx, fy, cx, cy) = (cam.fx, cam.fy, cam.cx, cam.cy);
    let z = pc[2];
    let (lxn, lxp) = (
        cx / fx + 0.3 * w / (2.0 * fx),
        (w - cx) / fx + 0.3 * w / (2.0 * fx),
    );
    let (lyn, lyp) = (
        cy / fy + 0.3 * h / (2.0 * fy),
        (h - cy) / fy + 0.3 * h / (2.0 * fy),
    );
    let xz = pc[0] / z;
    let yz = pc[1] / z;
    let txz = xz.clamp(-lxn, lxp);
    let tyz = yz.clamp(-lyn, lyp);
    let jac = [[fx / z, 0.0, -fx * txz / z], [0.0, fy / z, -fy * tyz / z]];
    let r: [[f64; 3]; 3] = [0, 1, 2].map(|i| [m[i][0], m[i][1], m[i][2]]);
    let sigma = match cov {
        Some(m) => *m,
        None => covariance_3d([p[3], p[4], p[5]], [p[6], p[7], p[8], p[9]]),
    };
    // T = J R; cov = T Σ Tᵀ.
    let mut t = [[0.0; 3]; 2];
    for a in 0..2 {
        for k in 0..3 {
            t[a][k] = (0..3).map(|mm| jac[a][mm] * r[mm][k]).sum();
        }
    }
    let mut cov = [[0.0; 2]; 2];
    for a in 0..2 {
        for b in 0..2 {
            let mut acc = 0.0;
            for k in 0..3 {
                for l in 0..3 {
                    acc += t[a][k] * sigma[k][l] * t[b][l];
                }
            }
            cov[a][b] = acc;
        }
    }
    let (a, b, c) = (cov[0][0] + 0.3, cov[0][1], cov[1][1] + 0.3);
    let det = a * c - b * b;
    if det == 0.0 {
        return invisible;
    }
    let mid = 0.5 * (a + c);
    let l1 = mid + (mid * mid - det).max(0.1).sqrt();
    let l2 = mid - (mid * mid - det).max(0.1).sqrt();
    let radius = (3.0 * l1.max(l2).sqrt()).ceil();
    let u = fx * pc[0] / z + cx;
    let v = fy * pc[1] / z + cy;
    let (gx, gy) = ((cam.width as i64 + 15) / 16, (cam.height as i64 + 15) / 16);
    let (pu, pv) = (u - 0.5, v - 0.5);
    let rect = [
        (((pu - radius) / 16.0) as i64).clamp(0, gx),
        (((pv - radius) / 16.0) as i64).clamp(0, gy),
        (((pu + radius + 15.0) / 16.0) as i64).clamp(0, gx),
        (((pv + radius + 15.0) / 16.0) as i64).clamp(0, gy),
    ];
    if (rect[2] - rect[0]) * (rect[3] - rect[1]) == 0 {
        return invisible;
    }
    OracleGauss {
        visible: true,
        uv: [u, v],
        conic: [c / det, -b / det, a / det],
        opacity: 1.0 / (1.0 + (-p[10]).exp()),
        depth: z,
        rect,
        jac_clamp: [txz != xz, tyz != yz],
    }
}

struct OracleOut {
    image: Vec<f64>,
    alpha: Vec<f64>,
    depth: Vec<f64>,
    /// Every discrete decision, for validating finite-difference probes.
    decisions: Vec<u64>,
    /// d L / d(u, v, conic a, b, c, opacity, depth) per Gaussian.
    d_proj: Vec<[f64; 7]>,
    d_channels: Vec<f64>,
}

/// Naive per-pixel renderer and its backward (back to front, T recovered by division).
fn oracle(s: &Scene, cot: Option<(&[f64], &[f64], &[f64])>) -> OracleOut {
    let (w, h) = (s.cam.width as usize, s.cam.height as usize);
    let c = s.c;
    let gs: Vec<OracleGauss> = (0..s.n())
        .map(|i| oracle_project(&s.cam, &s.params(i), s.covs.as_ref().map(|c| &c[i])))
        .collect();
    let mut out = OracleOut {
        image: vec![0.0; c * w * h],
        alpha: vec![0.0; w * h],
        depth: vec![0.0; w * h],
        decisions: Vec::new(),
        d_proj: vec![[0.0; 7]; s.n()],
        d_channels: vec![0.0; s.n() * c],
    };
    for g in &gs {
        out.decisions.push(u64::from(g.visible));
        out.decisions.extend(g.rect.iter().map(|&v| v as u64));
        out.decisions
            .push(u64::from(g.jac_clamp[0]) + 2 * u64::from(g.jac_clamp[1]));
    }
    for py in 0..h {
        for px in 0..w {
            let (tx, ty) = ((px / 16) as i64, (py / 16) as i64);
            let mut list: Vec<usize> = (0..s.n())
                .filter(|&i| {
                    let g = &gs[i];
                    g.visible
                        && g.rect[0] <= tx
                        && tx < g.rect[2]
                        && g.rect[1] <= ty
                        && ty < g.rect[3]
                })
                .collect();
            list.sort_by(|&a, &b| gs[a].depth.total_cmp(&gs[b].depth).then(a.cmp(&b)));
            let (pcx, pcy) = (px as f64 + 0.5, py as f64 + 0.5);
            let mut t = 1.0;
            // (gaussian, alpha, raw, gauss, dx, dy, T before)
            let mut contrib = Vec::new();
            for &i in &list {
                let g = &gs[i];
                let (dx, dy) = (g.uv[0] - pcx, g.uv[1] - pcy);
                let power =
                    -0.5 * (g.conic[0] * dx * dx + g.conic[2] * dy * dy) - g.conic[1] * dx * dy;
                if power > 0.0 {
                    out.decisions.push(1);
                    continue;
                }
                let gauss = power.exp();
                let raw = g.opacity * gauss;
                let alpha = raw.min(0.99);
                if alpha < 1.0 / 255.0 {
                    out.decisions.push(2);
                    continue;
                }
                if t * (1.0 - alpha) < 1e-4 {
                    out.decisions.push(3);
                    break;
                }
                out.decisions.push(if raw < 0.99 { 4 } else { 5 });
                contrib.push((i, alpha, raw, gauss, dx, dy, t));
                let wgt = alpha * t;
                for ch in 0..c {
                    out.image[ch * w * h + py * w + px] += wgt * s.channels[i * c + ch];
                }
                out.depth[py * w + px] += wgt * g.depth;
                t *= 1.0 - alpha;
            }
            out.decisions.push(99);
            for ch in 0..c {
                out.image[ch * w * h + py * w + px] += t * s.background[ch];
            }
            out.alpha[py * w + px] = 1.0 - t;
            let Some((ci, ca, cd)) = cot else { continue };
            let pix = py * w + px;
            let t_final = t;
            let mut behind: Vec<f64> = (0..c).map(|ch| t_final * s.background[ch]).collect();
            let mut behind_d = 0.0;
            let mut tt = t_final;
            for &(i, alpha, raw, gauss, dx, dy, _) in contrib.iter().rev() {
                let g = &gs[i];
                let t_i = tt / (1.0 - alpha);
                let mut d_alpha = 0.0;
                for ch in 0..c {
                    let gc = ci[ch * w * h + pix];
                    let col = s.channels[i * c + ch];
                    out.d_channels[i * c + ch] += alpha * t_i * gc;
                    d_alpha += gc * (t_i * col - behind[ch] / (1.0 - alpha));
                    behind[ch] += alpha * t_i * col;
                }
                d_alpha += cd[pix] * (t_i * g.depth - behind_d / (1.0 - alpha));
                out.d_proj[i][6] += alpha * t_i * cd[pix];
                behind_d += alpha * t_i * g.depth;
                d_alpha += ca[pix] * t_final / (1.0 - alpha);
                if raw < 0.99 {
                    let dp = alpha * d_alpha;
                    let d = &mut out.d_proj[i];
                    d[0] += dp * -(g.conic[0] * dx + g.conic[1] * dy);
                    d[1] += dp * -(g.conic[2] * dy + g.conic[1] * dx);
                    d[2] += dp * -0.5 * dx * dx;
                    d[3] += dp * -dx * dy;
                    d[4] += dp * -0.5 * dy * dy;
                    d[5] += gauss * d_alpha;
                }
                tt = t_i;
            }
        }
    }
    out
}

/// Oracle gradient of Gaussian i's 11 geometric parameters: central-difference Jacobian of the
/// oracle projection, transposed, times dL/d(projection).
fn oracle_param_grad(s: &Scene, i: usize, d_proj: &[f64; 7]) -> Vec<f64> {
    let p = s.params(i);
    let mut g = vec![0.0; 11];
    let flat = |o: &OracleGauss| {
        [
            o.uv[0], o.uv[1], o.conic[0], o.conic[1], o.conic[2], o.opacity, o.depth,
        ]
    };
    let mut probe = p.clone();
    for k in 0..11 {
        let h = 1e-6;
        probe[k] = p[k] + h;
        let plus = flat(&oracle_project(&s.cam, &probe, None));
        probe[k] = p[k] - h;
        let minus = flat(&oracle_project(&s.cam, &probe, None));
        probe[k] = p[k];
        g[k] = (0..7)
            .map(|j| d_proj[j] * (plus[j] - minus[j]) / (2.0 * h))
            .sum();
    }
    g
}

/// A random cotangent on image, alpha and depth; for odd seeds, rows 2, 3, 6, 7, ... are zero (a
/// loss that reads some rows only, as the flow loss's resize does), which the rasterizer's
/// backward skips.
fn random_cotangent(s: &Scene, seed: u64) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let mut rng = rng(seed ^ 0xC0FFEE);
    let (w, hw) = (s.cam.width as usize, (s.cam.width * s.cam.height) as usize);
    let mut ci: Vec<f64> = (0..s.c * hw).map(|_| rng.gen_range(-1.0..1.0)).collect();
    let mut ca: Vec<f64> = (0..hw).map(|_| rng.gen_range(-1.0..1.0)).collect();
    let mut cd: Vec<f64> = (0..hw).map(|_| rng.gen_range(-0.3..0.3)).collect();
    if seed % 2 == 1 {
        let dead = |p: usize| (p % hw) / w % 4 >= 2;
        for (p, v) in ci.iter_mut().enumerate() {
            if dead(p) {
                *v = 0.0;
            }
        }
        for (p, (a, d)) in ca.iter_mut().zip(cd.iter_mut()).enumerate() {
            if dead(p) {
                (*a, *d) = (0.0, 0.0);
            }
        }
    }
    (ci, ca, cd)
}

fn loss(s: &Scene, cot: &(Vec<f64>, Vec<f64>, Vec<f64>)) -> f64 {
    let out = match render(&s.cam, &s.splats(), &s.settings()) {
        Ok(o) => o,
        Err(e) => panic!("render failed: {e}"),
    };
    dot(&out.image, &cot.0) + dot(&out.alpha, &cot.1) + dot(&out.depth, &cot.2)
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// Crate gradient of Gaussian i in the flat parameter layout of [`Scene::params`].
fn crate_param_grad(g: &rasterize_cpu::Gradients<f64>, i: usize, c: usize) -> Vec<f64> {
    let mut v = Vec::new();
    v.extend_from_slice(&g.means[i]);
    v.extend_from_slice(&g.log_scales[i]);
    v.extend_from_slice(&g.quats[i]);
    v.push(g.opacity_logits[i]);
    v.extend_from_slice(&g.channels[i * c..(i + 1) * c]);
    v
}

fn crate_backward(
    s: &Scene,
    cot: &(Vec<f64>, Vec<f64>, Vec<f64>),
) -> (
    rasterize_cpu::RenderOutput<f64>,
    rasterize_cpu::Gradients<f64>,
) {
    let out = render(&s.cam, &s.splats(), &s.settings()).unwrap_or_else(|e| panic!("render: {e}"));
    let g = render_backward(
        &s.cam,
        &s.splats(),
        &s.settings(),
        &out,
        &Cotangents {
            image: &cot.0,
            alpha: Some(&cot.1),
            depth: Some(&cot.2),
        },
    )
    .unwrap_or_else(|e| panic!("backward: {e}"));
    (out, g)
}

// ---------------------------------------------------------------------------------------------
// Oracle comparisons (hard path).

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    #[test]
    fn forward_and_backward_match_the_naive_oracle(
        seed in any::<u64>(),
        kinds in kinds_strategy(10),
        c in 0usize..4,
    ) {
        let s = random_scene(seed, &kinds, c);
        let cot = random_cotangent(&s, seed);
        let (out, g) = crate_backward(&s, &cot);
        let o = oracle(&s, Some((&cot.0, &cot.1, &cot.2)));
        let mut checker = GradientChecker::new();
        // Forward: same sums in the same order up to the pixel-box restriction ⇒ ~1e-15; allow 1e-12.
        let fwd_tol = Tolerance::new(1e-12, 1e-12);
        checker.check("image vs oracle", &o.image, &out.image, fwd_tol);
        checker.check("alpha vs oracle", &o.alpha, &out.alpha, fwd_tol);
        checker.check("depth vs oracle", &o.depth, &out.depth, fwd_tol);
        for i in 0..s.n() {
            let mut want = oracle_param_grad(&s, i, &o.d_proj[i]);
            want.extend_from_slice(&o.d_channels[i * c..(i + 1) * c]);
            checker.check(&format!("gaussian {i} (kind {}) vs oracle", kind_of(&kinds, i)), &want, &crate_param_grad(&g, i, c), ORACLE_TOL);
            checker.check(&format!("gaussian {i} mean2d vs oracle"), &o.d_proj[i][..2], &g.means_2d[i], ORACLE_TOL);
        }
        checker.finish();
    }
}

#[test]
fn oracle_scenes_exercise_every_hard_rule() {
    // Across a fixed sweep of scenes the decisions must include every rule, so the proptest above
    // really covers the clamp, the cut, the early stop and invisible Gaussians.
    // power > 0 is not on the list: the conic is positive definite, so only rounding could make it
    // positive. Index 1 records a Jacobian clamp on a visible Gaussian instead.
    let mut seen = [false; 6];
    for seed in 0..40u64 {
        let kinds: Vec<usize> = (0..10)
            .map(|k| ((seed as usize) * 7 + k * 3) % KINDS)
            .collect();
        let s = random_scene(seed, &kinds, 3);
        let o = oracle(&s, None);
        for &d in &o.decisions[s.n() * 6..] {
            if (2..=5).contains(&d) {
                seen[d as usize] = true;
            }
        }
        for g in o.decisions.chunks(6).take(s.n()) {
            seen[0] |= g[0] == 0;
            seen[1] |= g[0] == 1 && g[5] != 0;
        }
    }
    assert_eq!(
        seen, [true; 6],
        "rules seen: [invisible, Jacobian clamp, α<1/255, stop, blend, 0.99 clamp]"
    );
}

// ---------------------------------------------------------------------------------------------
// Finite differences of the crate's own forward.

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    #[test]
    fn gradients_match_finite_differences(
        seed in any::<u64>(),
        kinds in kinds_strategy(6),
        c in 1usize..4,
    ) {
        let s = random_scene(seed, &kinds, c);
        let cot = random_cotangent(&s, seed);
        let (_, g) = crate_backward(&s, &cot);
        let base = oracle(&s, None).decisions;
        let mut checker = GradientChecker::new();
        let (mut probes, mut valid) = (0usize, 0usize);
        for i in 0..s.n() {
            let x = s.params(i);
            let ana = crate_param_grad(&g, i, c);
            let mut num = Vec::new();
            let mut ana_kept = Vec::new();
            for k in 0..x.len() {
                probes += 1;
                let mut same = true;
                for sign in [-1.0, 1.0] {
                    let mut p = x.clone();
                    p[k] += sign * FD_H;
                    let mut s2 = s.clone();
                    s2.set_params(i, &p);
                    same &= oracle(&s2, None).decisions == base;
                }
                if !same {
                    continue;
                }
                valid += 1;
                let d = central_differences(
                    |p| {
                        let mut s2 = s.clone();
                        let mut full = x.clone();
                        full[k] = p[0];
                        s2.set_params(i, &full);
                        loss(&s2, &cot)
                    },
                    &[x[k]],
                    FD_H,
                );
                num.push(d[0]);
                ana_kept.push(ana[k]);
            }
            checker.check(&format!("gaussian {i} (kind {}) vs FD", kind_of(&kinds, i)), &num, &ana_kept, FD_TOL);
        }
        static TALLY: ProbeTally = ProbeTally::new(200);
        let tally = TALLY.add(probes, valid);
        prop_assert!(tally.is_ok(), "{}", tally.unwrap_err());
        checker.finish();
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(12))]

    #[test]
    fn sh_render_gradients_match_finite_differences(
        seed in any::<u64>(),
        kinds in prop::collection::vec(0usize..6, 1..=5),
        degree in 0usize..=3,
    ) {
        // Colours from SH (view dependent): the means also get the view-direction gradient.
        let s = random_scene(seed, &kinds, 0);
        let k = gaussians::sh::num_sh_coeffs(degree);
        let mut rng = rng(seed ^ 0x5151);
        // DC keeps colours near 0.5 and higher bands small, away from the clamp at 0.
        let sh: Vec<f64> = (0..s.n() * k * 3)
            .map(|j| if (j / 3) % k == 0 { rng.gen_range(-0.3..0.3) } else { rng.gen_range(-0.1..0.1) })
            .collect();
        let (ci, _, _) = random_cotangent(&s, seed);
        let hw = (s.cam.width * s.cam.height) as usize;
        let ci: Vec<f64> = ci.into_iter().chain(std::iter::repeat(0.5)).take(3 * hw).collect();
        let settings = RenderSettings { near_plane: NEAR, background: vec![0.1, 0.2, 0.3] };
        let sh_loss = |means: &[[f64; 3]], sh: &[f64]| -> f64 {
            let splats = ShSplats { means, log_scales: &s.log_scales, quats: &s.quats, opacity_logits: &s.logits, sh, sh_degree: degree };
            let r = render_sh(&s.cam, &splats, &settings).unwrap_or_else(|e| panic!("render_sh: {e}"));
            dot(&r.output.image, &ci)
        };
        let splats = ShSplats { means: &s.means, log_scales: &s.log_scales, quats: &s.quats, opacity_logits: &s.logits, sh: &sh, sh_degree: degree };
        let fwd = render_sh(&s.cam, &splats, &settings).unwrap_or_else(|e| panic!("render_sh: {e}"));
        let g = render_sh_backward(&s.cam, &splats, &settings, &fwd, &Cotangents { image: &ci, alpha: None, depth: None })
            .unwrap_or_else(|e| panic!("render_sh_backward: {e}"));
        let base = oracle(&s, None).decisions;
        let mut checker = GradientChecker::new();
        let (mut probes, mut valid) = (0usize, 0usize);
        for i in 0..s.n() {
            // Means: probe validity as above (counted; at least 90% of the run's must be valid).
            let mut num = Vec::new();
            let mut ana = Vec::new();
            for a in 0..3 {
                probes += 1;
                let mut ok = true;
                for sign in [-1.0, 1.0] {
                    let mut s2 = s.clone();
                    s2.means[i][a] += sign * FD_H;
                    ok &= oracle(&s2, None).decisions == base;
                }
                if ok {
                    valid += 1;
                    let d = central_differences(|p| { let mut m = s.means.clone(); m[i][a] = p[0]; sh_loss(&m, &sh) }, &[s.means[i][a]], FD_H);
                    num.push(d[0]);
                    ana.push(g.means[i][a]);
                }
            }
            checker.check(&format!("gaussian {i} means (SH deg {degree})"), &num, &ana, FD_TOL);
            // SH coefficients never change a discrete decision (colours stay positive).
            let range = i * k * 3..(i + 1) * k * 3;
            let num_sh = central_differences(|p| { let mut c = sh.clone(); c[range.clone()].copy_from_slice(p); sh_loss(&s.means, &c) }, &sh[range.clone()], FD_H);
            checker.check(&format!("gaussian {i} sh (deg {degree})"), &num_sh, &g.sh[range.clone()], FD_TOL);
        }
        static TALLY: ProbeTally = ProbeTally::new(25);
        let tally = TALLY.add(probes, valid);
        prop_assert!(tally.is_ok(), "{}", tally.unwrap_err());
        checker.finish();
    }
}

// ---------------------------------------------------------------------------------------------
// Precomputed-covariance path (`render_cov`).

fn cov_splats<'a>(s: &'a Scene, covs: &'a [Mat3<f64>]) -> CovSplats<'a, f64> {
    CovSplats {
        means: &s.means,
        covariances: covs,
        opacity_logits: &s.logits,
        channels: &s.channels,
        num_channels: s.c,
    }
}

/// A scene with its covariances, a cotangent of (image, alpha, depth), and the render's gradients.
type CovCase = (
    Scene,
    Vec<Mat3<f64>>,
    (Vec<f64>, Vec<f64>, Vec<f64>),
    rasterize_cpu::Gradients<f64>,
);

/// A random scene (seed, kinds, channels) with its covariances set, a random cotangent, and
/// `render_cov_backward`'s gradients of L = Σ cot · (image, alpha, depth).
fn cov_scene_and_gradients(seed: u64, kinds: &[usize], c: usize) -> CovCase {
    let mut s = random_scene(seed, kinds, c);
    let covs: Vec<Mat3<f64>> = (0..s.n())
        .map(|i| covariance_3d(s.log_scales[i], s.quats[i]))
        .collect();
    s.covs = Some(covs.clone());
    let cot = random_cotangent(&s, seed);
    let g = cov_gradients(&s, &covs, &cot);
    (s, covs, cot, g)
}

/// `render_cov_backward`'s gradients of L = Σ cot · (image, alpha, depth) for the scene `s` with
/// covariances `covs`.
fn cov_gradients(
    s: &Scene,
    covs: &[Mat3<f64>],
    cot: &(Vec<f64>, Vec<f64>, Vec<f64>),
) -> rasterize_cpu::Gradients<f64> {
    let settings = s.settings();
    let fwd = render_cov(&s.cam, &cov_splats(s, covs), &settings)
        .unwrap_or_else(|e| panic!("render_cov: {e}"));
    render_cov_backward(
        &s.cam,
        &cov_splats(s, covs),
        &settings,
        &fwd,
        &Cotangents {
            image: &cot.0,
            alpha: Some(&cot.1),
            depth: Some(&cot.2),
        },
    )
    .unwrap_or_else(|e| panic!("render_cov_backward: {e}"))
}

/// L = Σ cot · (image, alpha, depth) of `render_cov` with the scene's covariances.
fn cov_loss(s: &Scene, cot: &(Vec<f64>, Vec<f64>, Vec<f64>)) -> f64 {
    let covs = s
        .covs
        .as_deref()
        .unwrap_or_else(|| panic!("scene has no covariances"));
    let out = render_cov(&s.cam, &cov_splats(s, covs), &s.settings())
        .unwrap_or_else(|e| panic!("render_cov: {e}"));
    dot(&out.image, &cot.0) + dot(&out.alpha, &cot.1) + dot(&out.depth, &cot.2)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    /// dL/dΣ of `render_cov_backward` against central differences of `render_cov`, every one of the
    /// nine entries perturbed on its own (so Σ is briefly non-symmetric, which `render_cov` accepts up
    /// to 1e-4 relative). The step is relative: Σ_kl ± h·s with s = max_k Σ_kk and h = FD_H, and the
    /// compared quantity is s·dL/dΣ_kl, which has the units and size of L; the FD_TOL argument above
    /// then holds unchanged (the log-scales spread by ±0.7, so Σ's eigenvalues differ from s by at
    /// most e^2.8 ≈ 16 and a probe moves cov2d by ≤ 16·h relative: truncation ≈ (16h)², rounding
    /// ε·|L|/h ≈ 1e-9). Means, opacity logits and channels are checked on the same path too. Probes
    /// whose ± steps flip any discrete decision of the oracle (run on the same covariances) are
    /// discarded; at least 90% must remain.
    #[test]
    fn cov_gradients_match_finite_differences(
        seed in any::<u64>(),
        kinds in kinds_strategy(6),
        c in 1usize..4,
    ) {
        let (s, covs, cot, g) = cov_scene_and_gradients(seed, &kinds, c);
        prop_assert_eq!(g.covariances.len(), s.n());
        prop_assert!(g.log_scales.is_empty() && g.quats.is_empty());
        let base = oracle(&s, None).decisions;
        let mut checker = GradientChecker::new();
        let (mut probes, mut valid) = (0usize, 0usize);
        for i in 0..s.n() {
            let scale = covs[i][0][0].max(covs[i][1][1]).max(covs[i][2][2]);
            // Σ entries (relative step), then mean, logit, channels (the Scene::params layout).
            let mut num = Vec::new();
            let mut ana = Vec::new();
            for kl in 0..9 {
                let (k, l) = (kl / 3, kl % 3);
                probes += 1;
                let perturbed = |t: f64| {
                    let mut s2 = s.clone();
                    if let Some(cv) = s2.covs.as_mut() {
                        cv[i][k][l] = covs[i][k][l] + t * scale;
                    }
                    s2
                };
                if oracle(&perturbed(FD_H), None).decisions != base
                    || oracle(&perturbed(-FD_H), None).decisions != base
                {
                    continue;
                }
                valid += 1;
                let d = central_differences(|t| cov_loss(&perturbed(t[0]), &cot), &[0.0], FD_H);
                num.push(d[0]);
                ana.push(scale * g.covariances[i][k][l]);
            }
            checker.check(&format!("gaussian {i} (kind {}) s*dL/dSigma vs FD", kind_of(&kinds, i)), &num, &ana, FD_TOL);
            let x = s.params(i);
            let mut num = Vec::new();
            let mut ana = Vec::new();
            let others = [0usize, 1, 2, 10].into_iter().chain(11..11 + c);
            for k in others {
                probes += 1;
                let perturbed = |v: f64| {
                    let mut p = x.clone();
                    p[k] = v;
                    let mut s2 = s.clone();
                    s2.set_params(i, &p);
                    s2
                };
                if oracle(&perturbed(x[k] + FD_H), None).decisions != base
                    || oracle(&perturbed(x[k] - FD_H), None).decisions != base
                {
                    continue;
                }
                valid += 1;
                let d = central_differences(|v| cov_loss(&perturbed(v[0]), &cot), &[x[k]], FD_H);
                num.push(d[0]);
                ana.push(match k {
                    0..=2 => g.means[i][k],
                    10 => g.opacity_logits[i],
                    _ => g.channels[i * c + k - 11],
                });
            }
            checker.check(&format!("gaussian {i} (kind {}) cov path mean/logit/channels vs FD", kind_of(&kinds, i)), &num, &ana, FD_TOL);
        }
        static TALLY: ProbeTally = ProbeTally::new(200);
        let tally = TALLY.add(probes, valid);
        prop_assert!(tally.is_ok(), "{}", tally.unwrap_err());
        checker.finish();
    }
}

/// `camera` moved by the twist ξ = (ω, v) on the left: exp(ξ^)·world_to_camera (ω by Rodrigues).
fn moved_camera(camera: &Camera, xi: [f64; 6]) -> Camera {
    let [wx, wy, wz, vx, vy, vz] = xi;
    let angle = (wx * wx + wy * wy + wz * wz).sqrt();
    let k = [[0.0, -wz, wy], [wz, 0.0, -wx], [-wy, wx, 0.0]];
    let (a, b) = if angle > 0.0 {
        (angle.sin() / angle, (1.0 - angle.cos()) / (angle * angle))
    } else {
        (1.0, 0.5)
    };
    let k2 = |i: usize, j: usize| (0..3).map(|l| k[i][l] * k[l][j]).sum::<f64>();
    let rot = |i: usize, j: usize| f64::from(u8::from(i == j)) + a * k[i][j] + b * k2(i, j);
    let v = [vx, vy, vz];
    let w = camera.world_to_camera;
    let mut moved = camera.clone();
    for i in 0..3 {
        for j in 0..4 {
            moved.world_to_camera[i][j] =
                (0..3).map(|l| rot(i, l) * w[l][j]).sum::<f64>() + if j == 3 { v[i] } else { 0.0 };
        }
    }
    moved
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    /// `camera_pose_gradient` (dL/dξ of the camera, from `render_cov_backward`'s world gradients)
    /// against central differences of `render_cov` from the camera moved by ±h along each of the
    /// six twist components (h = FD_H in radians or metres; the scene is 1-6 m away, so a probe
    /// moves a splat by ≤ 6·h relative, as a mean probe does: the FD_TOL argument above holds).
    /// Probes whose ± steps flip any discrete decision of the oracle are discarded.
    #[test]
    fn camera_pose_gradient_matches_finite_differences(
        seed in any::<u64>(),
        kinds in kinds_strategy(6),
        c in 1usize..4,
    ) {
        let (s, covs, cot, g) = cov_scene_and_gradients(seed, &kinds, c);
        let ana = camera_pose_gradient(&s.cam, &s.means, &covs, &g.means, &g.covariances)
            .unwrap_or_else(|e| panic!("camera_pose_gradient: {e}"));
        let base = oracle(&s, None).decisions;
        let (mut probes, mut valid) = (0usize, 0usize);
        let (mut num, mut kept) = (Vec::new(), Vec::new());
        for k in 0..6 {
            probes += 1;
            let moved = |t: f64| {
                let mut xi = [0.0; 6];
                xi[k] = t;
                let mut s2 = s.clone();
                s2.cam = moved_camera(&s.cam, xi);
                s2
            };
            if oracle(&moved(FD_H), None).decisions != base
                || oracle(&moved(-FD_H), None).decisions != base
            {
                continue;
            }
            valid += 1;
            num.push(central_differences(|t| cov_loss(&moved(t[0]), &cot), &[0.0], FD_H)[0]);
            kept.push(ana[k]);
        }
        let mut checker = GradientChecker::new();
        checker.check("camera twist (ω, v) vs FD", &num, &kept, FD_TOL);
        static TALLY: ProbeTally = ProbeTally::new(30);
        let tally = TALLY.add(probes, valid);
        prop_assert!(tally.is_ok(), "{}", tally.unwrap_err());
        checker.finish();
    }
}

/// The inverse of the rigid transform `[Exp(ω) | v]` of `twist`, composed with `world_to_camera`:
/// the camera that `twist` corrects into `world_to_camera`.
fn uncorrected(world_to_camera: &[[f64; 4]; 4], twist: &[f64; 6]) -> [[f64; 4]; 4] {
    let r = exp_so3([twist[0], twist[1], twist[2]]);
    let mut out = *world_to_camera;
    for i in 0..3 {
        for j in 0..4 {
            let shifted =
                |k: usize| world_to_camera[k][j] - if j == 3 { twist[3 + k] } else { 0.0 };
            out[i][j] = (0..3).map(|k| r[k][i] * shifted(k)).sum();
        }
    }
    out
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    /// A frame's learned camera correction (`train::pose::camera_correction`: twist
    /// ξ = mid + o·change, camera [Exp(ω) | v]·T) through the render: `camera_pose_gradient`
    /// chained by `twist_backward` and `correction_backward`, against central differences of
    /// `render_cov` over the 12 correction values. The corrections are large (ω up to 0.3 rad,
    /// v up to 0.2 m) so that the left Jacobian and the v × g_v term matter; the base camera is
    /// chosen so that the corrected one is the scene's (its Gaussians stay in view). A probe
    /// moves the camera by at most h (radians, metres), as in the twist check above: FD_TOL holds.
    /// Probes whose ± steps flip any discrete decision of the oracle are discarded.
    #[test]
    fn camera_correction_gradient_matches_finite_differences(
        seed in any::<u64>(),
        kinds in kinds_strategy(6),
        c in 1usize..4,
    ) {
        let (s, covs, cot, _) = cov_scene_and_gradients(seed, &kinds, c);
        let mut r = rng(seed ^ 0x00ca_3e7a);
        let limits = [0.3, 0.3, 0.3, 0.2, 0.2, 0.2, 0.2, 0.2, 0.2, 0.1, 0.1, 0.1];
        let correction: Vec<f64> = limits.iter().map(|&l| r.gen_range(-l..l)).collect();
        let offset = f64::from(r.gen_range(-0.5f32..0.5));
        let twist = |c: &[f64]| -> [f64; 6] { std::array::from_fn(|k| c[k] + offset * c[6 + k]) };
        let base = uncorrected(&s.cam.world_to_camera, &twist(&correction));
        let scene_at = |c: &[f64]| {
            let mut s2 = s.clone();
            s2.cam.world_to_camera = corrected_world_to_camera(&base, &twist(c));
            s2
        };
        let s0 = scene_at(&correction);
        let g = cov_gradients(&s0, &covs, &cot);
        let d_left = camera_pose_gradient(&s0.cam, &s0.means, &covs, &g.means, &g.covariances)
            .unwrap_or_else(|e| panic!("camera_pose_gradient: {e}"));
        let mut ana = vec![0.0; 12];
        correction_backward(&twist_backward(&d_left, &twist(&correction)), offset as f32, &mut ana);
        let base_decisions = oracle(&s0, None).decisions;
        let (mut probes, mut valid) = (0usize, 0usize);
        let (mut num, mut kept) = (Vec::new(), Vec::new());
        for k in 0..12 {
            probes += 1;
            let moved = |t: f64| {
                let mut c = correction.clone();
                c[k] += t;
                scene_at(&c)
            };
            if oracle(&moved(FD_H), None).decisions != base_decisions
                || oracle(&moved(-FD_H), None).decisions != base_decisions
            {
                continue;
            }
            valid += 1;
            num.push(central_differences(|t| cov_loss(&moved(t[0]), &cot), &[0.0], FD_H)[0]);
            kept.push(ana[k]);
        }
        let mut checker = GradientChecker::new();
        checker.check("camera correction (mid ω, v; change ω, v) vs FD", &num, &kept, FD_TOL);
        static TALLY: ProbeTally = ProbeTally::new(60);
        let tally = TALLY.add(probes, valid);
        prop_assert!(tally.is_ok(), "{}", tally.unwrap_err());
        checker.finish();
    }
}

#[test]
fn render_cov_of_scale_rotation_covariances_equals_render_bit_for_bit() {
    // Same covariance_3d, same projection and raster code ⇒ identical bits, forward and backward; the
    // cov-path dΣ chained through covariance_3d_backward gives render_backward's log-scale and
    // quaternion gradients bit for bit (render_backward does exactly that chaining).
    let (cam, m, ls, q, op, ch) = f32_scene(3000, 100, 76, 7);
    let (o1, g1) = render_f32(&cam, &m, &ls, &q, &op, &ch);
    let covs: Vec<Mat3<f32>> = ls
        .iter()
        .zip(&q)
        .map(|(l, r)| covariance_3d(*l, *r))
        .collect();
    let splats = CovSplats {
        means: &m,
        covariances: &covs,
        opacity_logits: &op,
        channels: &ch,
        num_channels: 3,
    };
    let settings = RenderSettings {
        near_plane: 0.2,
        background: vec![0.2, 0.3, 0.4],
    };
    let o2 = render_cov(&cam, &splats, &settings).unwrap_or_else(|e| panic!("{e}"));
    let (ci, ca) = f32_cotangents(&cam);
    let g2 = render_cov_backward(
        &cam,
        &splats,
        &settings,
        &o2,
        &Cotangents {
            image: &ci,
            alpha: Some(&ca),
            depth: Some(&ca),
        },
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert!(
        o1.num_pairs > 3000,
        "scene too sparse: {} pairs",
        o1.num_pairs
    );
    assert_eq!(o1.radii, o2.radii);
    assert_eq!(bits(&o1.image), bits(&o2.image));
    assert_eq!(bits(&o1.alpha), bits(&o2.alpha));
    assert_eq!(bits(&o1.depth), bits(&o2.depth));
    assert!(g1.covariances.is_empty());
    assert!(g2.log_scales.is_empty() && g2.quats.is_empty());
    assert_eq!(g2.covariances.len(), m.len());
    assert!(g2.covariances.iter().any(|s| s[0][1] != 0.0));
    let fmt = |g: &rasterize_cpu::Gradients<f32>| {
        format!(
            "{:?}",
            (
                &g.means,
                &g.opacity_logits,
                &g.channels,
                &g.means_2d,
                &g.background
            )
        )
    };
    assert_eq!(fmt(&g1), fmt(&g2));
    for i in 0..m.len() {
        let (dls, dq) = if o2.radii[i] == 0 {
            ([0.0; 3], [0.0; 4])
        } else {
            covariance_3d_backward(ls[i], q[i], &g2.covariances[i])
        };
        assert_eq!(
            dls.map(f32::to_bits),
            g1.log_scales[i].map(f32::to_bits),
            "gaussian {i}"
        );
        assert_eq!(
            dq.map(f32::to_bits),
            g1.quats[i].map(f32::to_bits),
            "gaussian {i}"
        );
    }
}

#[test]
fn bad_covariances_give_typed_errors() {
    let cam = Camera::looking_down_z(32, 24, 30.0, 30.0).unwrap_or_else(|e| panic!("{e}"));
    let good: Mat3<f32> = [
        [0.01, 0.002, 0.0],
        [0.002, 0.02, 0.001],
        [0.0, 0.001, 0.015],
    ];
    let means = [[0.0f32, 0.0, 2.0], [0.1, 0.0, 2.0]];
    let settings = RenderSettings::default();
    let with = |bad: Mat3<f32>| {
        let covs = [good, bad];
        let splats = CovSplats {
            means: &means,
            covariances: &covs,
            opacity_logits: &[0.0, 0.0],
            channels: &[],
            num_channels: 0,
        };
        render_cov(&cam, &splats, &settings).map(|o| o.alpha)
    };
    let mut nan = good;
    nan[2][1] = f32::NAN;
    assert!(matches!(
        with(nan),
        Err(RasterError::NonFiniteParameter {
            index: 1,
            field: "covariances"
        })
    ));
    let mut inf = good;
    inf[0][0] = f32::INFINITY;
    assert!(matches!(
        with(inf),
        Err(RasterError::NonFiniteParameter {
            index: 1,
            field: "covariances"
        })
    ));
    let mut skew = good;
    skew[0][2] = 0.005;
    assert!(matches!(
        with(skew),
        Err(RasterError::NonSymmetricCovariance {
            index: 1,
            row: 0,
            col: 2,
            ..
        })
    ));
    // Rounding-level asymmetry (far below 1e-4 relative) is accepted and renders finitely.
    let mut rounded = good;
    rounded[1][0] = 0.002 * (1.0 + 4.0 * f32::EPSILON);
    let alpha = with(rounded).unwrap_or_else(|e| panic!("{e}"));
    assert!(alpha.iter().all(|a| a.is_finite()) && alpha.iter().any(|&a| a > 0.0));
    let covs = [good];
    let short = CovSplats {
        means: &means,
        covariances: &covs,
        opacity_logits: &[0.0, 0.0],
        channels: &[],
        num_channels: 0,
    };
    assert!(matches!(
        render_cov(&cam, &short, &settings),
        Err(RasterError::LengthMismatch {
            field: "covariances",
            got: 1,
            expected: 2
        })
    ));
}

// ---------------------------------------------------------------------------------------------
// Invariances and determinism.

#[allow(clippy::type_complexity)]
fn f32_scene(
    n: usize,
    w: u32,
    h: u32,
    seed: u64,
) -> (
    Camera,
    Vec<[f32; 3]>,
    Vec<[f32; 3]>,
    Vec<[f32; 4]>,
    Vec<f32>,
    Vec<f32>,
) {
    let cam = Camera::looking_down_z(w, h, f64::from(w) * 0.9, f64::from(w) * 0.9)
        .unwrap_or_else(|e| panic!("{e}"));
    let mut rng = rng(seed);
    let mut means = Vec::new();
    let mut ls = Vec::new();
    let mut q = Vec::new();
    let mut op = Vec::new();
    let mut ch = Vec::new();
    for _ in 0..n {
        let z = rng.gen_range(1.0..5.0);
        let p = unproject(
            &cam,
            rng.gen_range(-5.0..f64::from(w) + 5.0),
            rng.gen_range(-5.0..f64::from(h) + 5.0),
            z,
        );
        means.push(p.map(|v| v as f32));
        let base = (rng.gen_range(0.5..8.0) * z / cam.fx).ln();
        ls.push([0, 1, 2].map(|_| (base + rng.gen_range(-0.5..0.5)) as f32));
        q.push([0, 1, 2, 3].map(|_| rng.gen_range(-1.0..1.0) as f32));
        op.push(rng.gen_range(-2.0..6.0) as f32);
        for _ in 0..3 {
            ch.push(rng.gen_range(0.0..1.0) as f32);
        }
    }
    (cam, means, ls, q, op, ch)
}

#[allow(clippy::type_complexity)]
fn render_f32(
    cam: &Camera,
    m: &[[f32; 3]],
    ls: &[[f32; 3]],
    q: &[[f32; 4]],
    op: &[f32],
    ch: &[f32],
) -> (
    rasterize_cpu::RenderOutput<f32>,
    rasterize_cpu::Gradients<f32>,
) {
    let splats = Splats {
        means: m,
        log_scales: ls,
        quats: q,
        opacity_logits: op,
        channels: ch,
        num_channels: 3,
    };
    let settings = RenderSettings {
        near_plane: 0.2,
        background: vec![0.2, 0.3, 0.4],
    };
    let out = render(cam, &splats, &settings).unwrap_or_else(|e| panic!("{e}"));
    let (ci, ca) = f32_cotangents(cam);
    let g = render_backward(
        cam,
        &splats,
        &settings,
        &out,
        &Cotangents {
            image: &ci,
            alpha: Some(&ca),
            depth: Some(&ca),
        },
    )
    .unwrap_or_else(|e| panic!("{e}"));
    (out, g)
}

/// Fixed pseudo-random cotangents (image with 3 channels, and alpha/depth) for f32 scenes.
fn f32_cotangents(cam: &Camera) -> (Vec<f32>, Vec<f32>) {
    let hw = (cam.width * cam.height) as usize;
    let ci: Vec<f32> = (0..3 * hw)
        .map(|i| ((i * 7919) % 1000) as f32 / 1000.0 - 0.5)
        .collect();
    let ca: Vec<f32> = (0..hw)
        .map(|i| ((i * 104_729) % 997) as f32 / 997.0 - 0.5)
        .collect();
    (ci, ca)
}

#[test]
fn one_and_two_threads_are_bit_identical() {
    let (cam, m, ls, q, op, ch) = f32_scene(3000, 100, 76, 7);
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap_or_else(|e| panic!("{e}"));
        pool.install(|| render_f32(&cam, &m, &ls, &q, &op, &ch))
    };
    let (o1, g1) = run(1);
    let (o2, g2) = run(2);
    let (o3, g3) = run(2);
    assert!(
        o1.num_pairs > 3000,
        "scene too sparse: {} pairs",
        o1.num_pairs
    );
    assert!(g1.means.iter().any(|v| v[0] != 0.0));
    let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&o1.image), bits(&o2.image));
    assert_eq!(bits(&o1.alpha), bits(&o2.alpha));
    assert_eq!(bits(&o1.depth), bits(&o2.depth));
    assert_eq!(bits(&o2.image), bits(&o3.image));
    assert_eq!(format!("{g1:?}"), format!("{g2:?}"));
    assert_eq!(format!("{g2:?}"), format!("{g3:?}"));
}

#[test]
fn permuting_inputs_permutes_gradients_and_keeps_the_image() {
    let (cam, m, ls, q, op, ch) = f32_scene(800, 64, 48, 11);
    let (o1, g1) = render_f32(&cam, &m, &ls, &q, &op, &ch);
    let n = m.len();
    let perm: Vec<usize> = (0..n).map(|i| (i * 389 + 17) % n).collect();
    let pm: Vec<_> = perm.iter().map(|&i| m[i]).collect();
    let pls: Vec<_> = perm.iter().map(|&i| ls[i]).collect();
    let pq: Vec<_> = perm.iter().map(|&i| q[i]).collect();
    let pop: Vec<_> = perm.iter().map(|&i| op[i]).collect();
    let pch: Vec<_> = perm
        .iter()
        .flat_map(|&i| ch[i * 3..i * 3 + 3].to_vec())
        .collect();
    let (o2, g2) = render_f32(&cam, &pm, &pls, &pq, &pop, &pch);
    assert_eq!(o1.image, o2.image);
    assert_eq!(o1.alpha, o2.alpha);
    assert_eq!(o1.depth, o2.depth);
    for (j, &i) in perm.iter().enumerate() {
        assert_eq!(g1.means[i], g2.means[j]);
        assert_eq!(g1.quats[i], g2.quats[j]);
        assert_eq!(g1.opacity_logits[i], g2.opacity_logits[j]);
    }
}

#[test]
fn off_screen_and_behind_camera_gaussians_change_nothing() {
    let (cam, mut m, mut ls, mut q, mut op, mut ch) = f32_scene(500, 64, 48, 5);
    let (o1, g1) = render_f32(&cam, &m, &ls, &q, &op, &ch);
    // Behind the camera, at the near plane, far off to the side, and transparent.
    for p in [
        [0.0f32, 0.0, -1.0],
        [0.0, 0.0, 0.1],
        [60.0, 0.0, 2.0],
        [0.0, -80.0, 3.0],
    ] {
        m.push(p);
        ls.push([-1.0; 3]);
        q.push([1.0, 0.0, 0.0, 0.0]);
        op.push(5.0);
        ch.extend_from_slice(&[1.0, 1.0, 1.0]);
    }
    let (o2, g2) = render_f32(&cam, &m, &ls, &q, &op, &ch);
    assert_eq!(o1.image, o2.image);
    assert_eq!(o1.alpha, o2.alpha);
    assert_eq!(o1.depth, o2.depth);
    assert_eq!(g1.means[..], g2.means[..500]);
    assert_eq!(g1.log_scales[..], g2.log_scales[..500]);
    assert!(g2.means[500..].iter().all(|v| *v == [0.0; 3]));
    assert!(g2.opacity_logits[500..].iter().all(|v| *v == 0.0));
    assert!(o2.radii[500..].iter().all(|&r| r == 0));
}

#[test]
fn f32_render_agrees_with_f64() {
    let (cam, m, ls, q, op, ch) = f32_scene(400, 48, 40, 3);
    let (o32, _) = render_f32(&cam, &m, &ls, &q, &op, &ch);
    let w = |v: &[f32]| v.iter().map(|&x| f64::from(x)).collect::<Vec<_>>();
    let (m64, ls64, q64, op64, ch64) = (
        m.iter().map(|p| p.map(f64::from)).collect::<Vec<_>>(),
        ls.iter().map(|p| p.map(f64::from)).collect::<Vec<_>>(),
        q.iter().map(|p| p.map(f64::from)).collect::<Vec<_>>(),
        w(&op),
        w(&ch),
    );
    let splats = Splats {
        means: &m64,
        log_scales: &ls64,
        quats: &q64,
        opacity_logits: &op64,
        channels: &ch64,
        num_channels: 3,
    };
    let settings = RenderSettings {
        near_plane: 0.2,
        background: vec![0.2, 0.3, 0.4],
    };
    let o64 = render(&cam, &splats, &settings).unwrap_or_else(|e| panic!("{e}"));
    // f32 rounding moves a handful of pixel/splat pairs across the 1/255 cut or the stop; the rest
    // agree to f32 precision.
    let far = o32
        .image
        .iter()
        .zip(&o64.image)
        .filter(|(a, b)| (f64::from(**a) - **b).abs() > 1e-4)
        .count();
    assert!(
        far * 100 <= o64.image.len(),
        "{far} of {} pixels differ by > 1e-4",
        o64.image.len()
    );
}

// ---------------------------------------------------------------------------------------------
// Bad input.

#[test]
fn bad_cameras_and_requests_give_typed_errors() {
    let eye = [
        [1.0, 0.0, 0.0, 0.0],
        [0.0, 1.0, 0.0, 0.0],
        [0.0, 0.0, 1.0, 0.0],
        [0.0, 0.0, 0.0, 1.0],
    ];
    let mut singular = eye;
    singular[2][2] = 0.0;
    assert!(matches!(
        Camera::new(64, 48, 50.0, 50.0, 32.0, 24.0, singular),
        Err(CameraError::SingularMatrix { .. })
    ));
    assert!(matches!(
        Camera::new(0, 48, 50.0, 50.0, 32.0, 24.0, eye),
        Err(CameraError::InvalidImageSize { .. })
    ));
    assert!(matches!(
        Camera::new(64, 48, f64::NAN, 50.0, 32.0, 24.0, eye),
        Err(CameraError::NonFinite { .. })
    ));
    let mut nan_m = eye;
    nan_m[1][3] = f64::NAN;
    assert!(matches!(
        Camera::new(64, 48, 50.0, 50.0, 32.0, 24.0, nan_m),
        Err(CameraError::NonFinite { .. })
    ));
    assert!(matches!(
        Camera::new(20000, 48, 50.0, 50.0, 32.0, 24.0, eye),
        Err(CameraError::InvalidImageSize { .. })
    ));
    assert!(matches!(
        Camera::new(16385, 16385, 50.0, 50.0, 32.0, 24.0, eye),
        Err(CameraError::InvalidImageSize { .. })
    ));
    let mut too_big = match Camera::new(64, 48, 50.0, 50.0, 32.0, 24.0, eye) {
        Ok(c) => c,
        Err(e) => panic!("{e}"),
    };
    too_big.width = 16385;
    too_big.height = 16385;
    let splats = Splats::<f32> {
        means: &[[0.0, 0.0, 2.0]],
        log_scales: &[[-3.0; 3]],
        quats: &[[1.0, 0.0, 0.0, 0.0]],
        opacity_logits: &[0.0],
        channels: &[],
        num_channels: 0,
    };
    assert!(matches!(
        render(&too_big, &splats, &RenderSettings::default()),
        Err(RasterError::Camera(CameraError::InvalidImageSize { .. }))
    ));
    let cam = match Camera::new(64, 48, 50.0, 50.0, 32.0, 24.0, eye) {
        Ok(c) => c,
        Err(e) => panic!("{e}"),
    };
    let zero_q = Splats::<f32> {
        quats: &[[0.0; 4]],
        ..splats
    };
    assert!(matches!(
        render(&cam, &zero_q, &RenderSettings::default()),
        Err(RasterError::ZeroQuaternion { index: 0 })
    ));
    let nan_mean = Splats::<f32> {
        means: &[[f32::NAN, 0.0, 2.0]],
        ..splats
    };
    assert!(matches!(
        render(&cam, &nan_mean, &RenderSettings::default()),
        Err(RasterError::NonFiniteParameter {
            index: 0,
            field: "means"
        })
    ));
    let short = Splats::<f32> {
        opacity_logits: &[],
        ..splats
    };
    assert!(matches!(
        render(&cam, &short, &RenderSettings::default()),
        Err(RasterError::LengthMismatch {
            field: "opacity_logits",
            ..
        })
    ));
    let ok = render(&cam, &splats, &RenderSettings::default()).unwrap_or_else(|e| panic!("{e}"));
    assert!(ok.alpha.iter().all(|a| a.is_finite()) && ok.alpha.iter().any(|&a| a > 0.0));
}

// ---------------------------------------------------------------------------------------------
// Renders that share their static Gaussians (`render_cov_shared`).

/// Renders of one scene whose Gaussians with `i % 3 == 1` move: render r shifts their means by r
/// times a fixed world offset (r = 0 is the scene itself).
fn moving_renders(s: &Scene, renders: usize) -> (Vec<Scene>, Vec<bool>) {
    let moving: Vec<bool> = (0..s.n()).map(|i| i % 3 == 1).collect();
    let scenes = (0..renders)
        .map(|r| {
            let mut s2 = s.clone();
            for (m, _) in s2.means.iter_mut().zip(&moving).filter(|(_, &mv)| mv) {
                m[0] += 0.03 * r as f64;
                m[1] -= 0.02 * r as f64;
            }
            s2
        })
        .collect();
    (scenes, moving)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(12))]

    /// `render_cov_shared_backward` against central differences of L = Σ_r cot_r · render_r over
    /// three renders from one camera: a static Gaussian's parameter is perturbed in every render at
    /// once and compared with the sum of the renders' gradients (its shared tiles' share reaches
    /// only the owner's); a moving Gaussian's in one render, against that render's gradient.
    /// Probes flipping a discrete decision of the oracle in any render are discarded (≥ 90% must
    /// remain); tolerance FD_TOL, as for one render (the loss is a sum of three such losses).
    #[test]
    fn shared_render_gradients_match_finite_differences(
        seed in any::<u64>(),
        kinds in kinds_strategy(6),
        c in 1usize..4,
    ) {
        let mut s = random_scene(seed, &kinds, c);
        s.covs = Some((0..s.n()).map(|i| covariance_3d(s.log_scales[i], s.quats[i])).collect());
        let (scenes, moving) = moving_renders(&s, 3);
        let cots: Vec<_> = (0..3).map(|r| random_cotangent(&s, seed ^ (r as u64 + 1))).collect();
        let settings = s.settings();
        let covs = s.covs.clone().unwrap_or_default();
        let splats: Vec<CovSplats<'_, f64>> = scenes.iter().map(|sc| cov_splats(sc, &covs)).collect();
        let fwd = render_cov_shared(&s.cam, &splats, &moving, 1, &settings)
            .unwrap_or_else(|e| panic!("render_cov_shared: {e}"));
        let cot_refs: Vec<Cotangents<'_, f64>> = cots
            .iter()
            .map(|c| Cotangents { image: &c.0, alpha: Some(&c.1), depth: Some(&c.2) })
            .collect();
        let outs: Vec<_> = fwd.outputs.iter().collect();
        let g = render_cov_shared_backward(&s.cam, &splats, &settings, &outs, &fwd.sharing, &cot_refs)
            .unwrap_or_else(|e| panic!("render_cov_shared_backward: {e}"));
        let base: Vec<_> = scenes.iter().map(|sc| oracle(sc, None).decisions).collect();
        let total = |sc: &[Scene]| -> f64 { sc.iter().zip(&cots).map(|(x, c)| cov_loss(x, c)).sum() };
        let mut checker = GradientChecker::new();
        let (mut probes, mut valid) = (0usize, 0usize);
        for i in 0..s.n() {
            // Σ (one slice for every render, so every render's gradient counts), relative step.
            let scale = covs[i][0][0].max(covs[i][1][1]).max(covs[i][2][2]);
            let (mut num, mut ana) = (Vec::new(), Vec::new());
            for kl in 0..9 {
                let (k, l) = (kl / 3, kl % 3);
                probes += 1;
                let perturbed = |t: f64| -> Vec<Scene> {
                    let mut sc = scenes.clone();
                    for x2 in &mut sc {
                        if let Some(cv) = x2.covs.as_mut() {
                            cv[i][k][l] = covs[i][k][l] + t * scale;
                        }
                    }
                    sc
                };
                let flips = |t: f64| {
                    perturbed(t).iter().zip(&base).any(|(sc, b)| &oracle(sc, None).decisions != b)
                };
                if flips(FD_H) || flips(-FD_H) {
                    continue;
                }
                valid += 1;
                num.push(central_differences(|t| total(&perturbed(t[0])), &[0.0], FD_H)[0]);
                ana.push(scale * g.iter().map(|gr| gr.covariances[i][k][l]).sum::<f64>());
            }
            checker.check(&format!("gaussian {i} (kind {}) s*dL/dSigma", kind_of(&kinds, i)), &num, &ana, FD_TOL);
            for r in 0..3 {
                if !moving[i] && r > 0 {
                    continue;
                }
                let x = scenes[r].params(i);
                let (mut num, mut ana) = (Vec::new(), Vec::new());
                for k in [0usize, 1, 2, 10].into_iter().chain(11..11 + c) {
                    probes += 1;
                    let perturbed = |v: f64| -> Vec<Scene> {
                        let mut sc = scenes.clone();
                        for (q, x2) in sc.iter_mut().enumerate() {
                            if moving[i] && q != r {
                                continue;
                            }
                            let mut p = x2.params(i);
                            p[k] = v;
                            x2.set_params(i, &p);
                        }
                        sc
                    };
                    let flips = |v: f64| {
                        perturbed(v).iter().zip(&base).any(|(sc, b)| &oracle(sc, None).decisions != b)
                    };
                    if flips(x[k] + FD_H) || flips(x[k] - FD_H) {
                        continue;
                    }
                    valid += 1;
                    num.push(central_differences(|v| total(&perturbed(v[0])), &[x[k]], FD_H)[0]);
                    let sum = |f: &dyn Fn(&rasterize_cpu::Gradients<f64>) -> f64| -> f64 {
                        if moving[i] { f(&g[r]) } else { g.iter().map(f).sum() }
                    };
                    ana.push(match k {
                        0..=2 => sum(&|gr| gr.means[i][k]),
                        10 => sum(&|gr| gr.opacity_logits[i]),
                        _ => sum(&|gr| gr.channels[i * c + k - 11]),
                    });
                }
                checker.check(
                    &format!("gaussian {i} (kind {}, moving {}) render {r}", kind_of(&kinds, i), moving[i]),
                    &num,
                    &ana,
                    FD_TOL,
                );
            }
        }
        static TALLY: ProbeTally = ProbeTally::new(200);
        let tally = TALLY.add(probes, valid);
        prop_assert!(tally.is_ok(), "{}", tally.unwrap_err());
        checker.finish();
    }
}

#[test]
fn shared_renders_equal_separate_renders_and_share_tiles() {
    // f32 scene large enough for static tiles and moving tiles: the outputs are bit-identical to
    // rendering each alone, the moving Gaussians' gradients bit-identical per render, and the
    // static ones' summed gradients equal the separate sum up to rounding.
    let (cam, m, ls, q, op, ch) = f32_scene(3000, 100, 76, 7);
    let covs: Vec<Mat3<f32>> = ls
        .iter()
        .zip(&q)
        .map(|(l, r)| covariance_3d(*l, *r))
        .collect();
    let moving: Vec<bool> = m.iter().map(|p| p[0] < -0.3).collect();
    let means: Vec<Vec<[f32; 3]>> = (0..3)
        .map(|r| {
            m.iter()
                .zip(&moving)
                .map(|(p, &mv)| {
                    if mv {
                        [p[0] + 0.01 * r as f32, p[1], p[2]]
                    } else {
                        *p
                    }
                })
                .collect()
        })
        .collect();
    let splats: Vec<CovSplats<'_, f32>> = means
        .iter()
        .map(|mm| CovSplats {
            means: mm,
            covariances: &covs,
            opacity_logits: &op,
            channels: &ch,
            num_channels: 3,
        })
        .collect();
    let settings = RenderSettings {
        near_plane: NEAR,
        background: vec![0.1, 0.2, 0.3],
    };
    let shared = render_cov_shared(&cam, &splats, &moving, 1, &settings)
        .unwrap_or_else(|e| panic!("render_cov_shared: {e}"));
    let fraction = shared.sharing.shared_fraction();
    assert!(
        fraction > 0.1 && fraction < 0.9,
        "shared fraction {fraction}"
    );
    let hw = (cam.width * cam.height) as usize;
    let cots: Vec<Vec<f32>> = (0..3)
        .map(|r| {
            (0..3 * hw)
                .map(|p| ((p * 7 + r * 13) % 17) as f32 / 17.0 - 0.5)
                .collect()
        })
        .collect();
    let cot_refs: Vec<Cotangents<'_, f32>> = cots
        .iter()
        .map(|c| Cotangents {
            image: c,
            alpha: None,
            depth: None,
        })
        .collect();
    let outs: Vec<_> = shared.outputs.iter().collect();
    let g = render_cov_shared_backward(&cam, &splats, &settings, &outs, &shared.sharing, &cot_refs)
        .unwrap_or_else(|e| panic!("render_cov_shared_backward: {e}"));
    let mut sum_shared = vec![0.0f64; m.len()];
    let mut sum_separate = vec![0.0f64; m.len()];
    for r in 0..3 {
        let alone = render_cov(&cam, &splats[r], &settings).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(alone.image, shared.outputs[r].image, "render {r} image");
        assert_eq!(alone.alpha, shared.outputs[r].alpha, "render {r} alpha");
        let ga = render_cov_backward(&cam, &splats[r], &settings, &alone, &cot_refs[r])
            .unwrap_or_else(|e| panic!("{e}"));
        for i in 0..m.len() {
            if moving[i] {
                assert_eq!(
                    ga.means[i], g[r].means[i],
                    "moving Gaussian {i}, render {r}"
                );
            }
            sum_shared[i] += f64::from(g[r].means[i][0]);
            sum_separate[i] += f64::from(ga.means[i][0]);
        }
    }
    let scale = sum_separate.iter().fold(0.0f64, |a, v| a.max(v.abs()));
    for i in 0..m.len() {
        let err = (sum_shared[i] - sum_separate[i]).abs();
        assert!(
            err <= 1e-4 * scale,
            "Gaussian {i}: {} vs {}",
            sum_shared[i],
            sum_separate[i]
        );
    }
    // A static Gaussian whose inputs change between renders is refused, naming it.
    let mut bad = means[2].clone();
    let victim = moving.iter().position(|&mv| !mv).unwrap_or(0);
    bad[victim][2] += 0.5;
    let mut splats_bad = splats.clone();
    splats_bad[2].means = &bad;
    let err = render_cov_shared(&cam, &splats_bad, &moving, 1, &settings).map(|_| ());
    assert!(
        matches!(&err, Err(RasterError::InvalidSettings(m)) if m.contains(&format!("Gaussian {victim} "))),
        "{err:?}"
    );
}
