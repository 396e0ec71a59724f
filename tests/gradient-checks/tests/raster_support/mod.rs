//! Scenes, the naive oracle renderer and the helpers the rasterizer checks share
//! (`rasterize.rs`, `rasterize_cov.rs`, `rasterize_camera.rs`, `rasterize_shared.rs`); the tolerances
//! and their reasoning are in `rasterize.rs`. Each check uses some of them.

#![allow(dead_code, unused_imports)]

mod cases;

pub use cases::*;

pub use gaussians::covariance::{covariance_3d, covariance_3d_backward, Mat3};
pub use gradient_checks::{central_differences, rng, GradientChecker, ProbeTally, Tolerance};
pub use proptest::prelude::*;
pub use rand::Rng;
pub use rasterize_cpu::{
    camera_pose_gradient, render, render_backward, render_cov, render_cov_backward,
    render_cov_shared, render_cov_shared_backward, render_sh, render_sh_backward, Camera,
    CameraError, Cotangents, CovSplats, RasterError, RenderSettings, ShSplats, SharedOutputs,
    Splats,
};
pub use train::pose::camera_correction::{
    corrected_world_to_camera, correction_backward, exp_so3, twist_backward,
};

pub const NEAR: f64 = 0.2;
pub const FD_H: f64 = 1e-6;
pub const FD_TOL: Tolerance = Tolerance::new(1e-5, 1e-5);
pub const ORACLE_TOL: Tolerance = Tolerance::new(1e-7, 1e-6);

// ---------------------------------------------------------------------------------------------
// Scenes.

#[derive(Clone, Debug)]
pub struct Scene {
    pub cam: Camera,
    pub means: Vec<[f64; 3]>,
    pub log_scales: Vec<[f64; 3]>,
    pub quats: Vec<[f64; 4]>,
    pub logits: Vec<f64>,
    pub channels: Vec<f64>,
    pub c: usize,
    pub background: Vec<f64>,
    /// Precomputed covariances overriding (log_scales, quats) in the oracle; rendered with
    /// `render_cov` by [`cov_loss`].
    pub covs: Option<Vec<Mat3<f64>>>,
    /// Smears (world covariances of each Gaussian's motion over the render's time slice), with
    /// `covs` only: the oracle blurs each Gaussian by them; rendered with `render_cov`'s `smears`.
    pub smears: Option<Vec<Mat3<f64>>>,
}

impl Scene {
    pub fn n(&self) -> usize {
        self.means.len()
    }
    pub fn splats(&self) -> Splats<'_, f64> {
        Splats {
            means: &self.means,
            log_scales: &self.log_scales,
            quats: &self.quats,
            opacity_logits: &self.logits,
            channels: &self.channels,
            num_channels: self.c,
        }
    }
    pub fn settings(&self) -> RenderSettings {
        RenderSettings {
            near_plane: NEAR,
            background: self.background.clone(),
        }
    }
    /// Parameters of Gaussian i as a flat vector: mean 3, log-scale 3, quat 4, logit 1, channels C.
    pub fn params(&self, i: usize) -> Vec<f64> {
        let mut v = Vec::new();
        v.extend_from_slice(&self.means[i]);
        v.extend_from_slice(&self.log_scales[i]);
        v.extend_from_slice(&self.quats[i]);
        v.push(self.logits[i]);
        v.extend_from_slice(&self.channels[i * self.c..(i + 1) * self.c]);
        v
    }
    pub fn set_params(&mut self, i: usize, p: &[f64]) {
        self.means[i] = [p[0], p[1], p[2]];
        self.log_scales[i] = [p[3], p[4], p[5]];
        self.quats[i] = [p[6], p[7], p[8], p[9]];
        self.logits[i] = p[10];
        let c = self.c;
        self.channels[i * c..(i + 1) * c].copy_from_slice(&p[11..11 + c]);
    }
}

pub fn rot_from_quat(q: [f64; 4]) -> [[f64; 3]; 3] {
    gaussians::covariance::rotation_from_quat(q)
}

/// A camera with an off-centre principal point and a random pose; image sizes are not multiples of
/// the tile size so edge tiles are partial.
pub fn random_camera(rng: &mut impl Rng) -> Camera {
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
pub fn unproject(cam: &Camera, u: f64, v: f64, z: f64) -> [f64; 3] {
    let pc = [(u - cam.cx) / cam.fx * z, (v - cam.cy) / cam.fy * z, z];
    let m = &cam.world_to_camera;
    // p_world = Rᵀ (p_cam − t) for a rotation R.
    let d = [pc[0] - m[0][3], pc[1] - m[1][3], pc[2] - m[2][3]];
    [0, 1, 2].map(|j| m[0][j] * d[0] + m[1][j] * d[1] + m[2][j] * d[2])
}

/// Gaussian kinds, so every scene mixes the regimes the issue lists.
pub const KINDS: usize = 9;
/// Kind of the anchor Gaussian every scene starts with.
pub const ANCHOR: usize = 100;

/// A random scene; `kinds` picks each Gaussian's regime:
/// 0 ordinary, 1 tiny (sub-pixel, dilation-dominated), 2 huge (covers the image), 3 near plane
/// (mean just in front, extending behind it), 4 straddling a tile border, 5 opaque (hits the 0.99
/// clamp and, stacked, the early stop), 6 overlapping the previous one, 7 off-screen or behind,
/// 8 centred beyond the Jacobian clamp limits but large enough to reach the image.
pub fn random_scene(seed: u64, kinds: &[usize], c: usize) -> Scene {
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
        smears: None,
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
pub fn kind_of(kinds: &[usize], i: usize) -> usize {
    if i == 0 {
        ANCHOR
    } else {
        kinds[i - 1]
    }
}

pub fn kinds_strategy(max: usize) -> impl Strategy<Value = Vec<usize>> {
    prop::collection::vec(0..KINDS, 1..=max)
}

// ---------------------------------------------------------------------------------------------
// The oracle.

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OracleGauss {
    pub visible: bool,
    pub uv: [f64; 2],
    pub conic: [f64; 3],
    pub opacity: f64,
    pub depth: f64,
    pub rect: [i64; 4],
    pub jac_clamp: [bool; 2],
}

/// INRIA `preprocess` written out plainly for one Gaussian; `cov` overrides Σ from the log-scales
/// and quaternion in `p`.
pub fn oracle_project(cam: &Camera, p: &[f64], cov: Option<&Mat3<f64>>) -> OracleGauss {
    oracle_project_smeared(cam, p, cov, None)
}

/// [`oracle_project`] of a Gaussian blurred by its motion: `smear` (a world covariance) is added to
/// Σ before the projection, and the opacity scaled by √(det cov2d / det cov2d′), the dilated screen
/// covariances without and with it, so that the splat's screen mass is kept.
pub fn oracle_project_smeared(
    cam: &Camera,
    p: &[f64],
    cov: Option<&Mat3<f64>>,
    smear: Option<&Mat3<f64>>,
) -> OracleGauss {
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
    let mut opacity = 1.0 / (1.0 + (-p[10]).exp());
    let (a, b, c) = match smear {
        None => (a, b, c),
        Some(smear) => {
            let project = |x: usize, y: usize| -> f64 {
                let mut acc = 0.0;
                for k in 0..3 {
                    for l in 0..3 {
                        acc += t[x][k] * (sigma[k][l] + smear[k][l]) * t[y][l];
                    }
                }
                acc
            };
            let (a2, b2, c2) = (project(0, 0) + 0.3, project(0, 1), project(1, 1) + 0.3);
            opacity *= ((a * c - b * b) / (a2 * c2 - b2 * b2)).sqrt();
            (a2, b2, c2)
        }
    };
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
        opacity,
        depth: z,
        rect,
        jac_clamp: [txz != xz, tyz != yz],
    }
}

pub struct OracleOut {
    pub image: Vec<f64>,
    pub alpha: Vec<f64>,
    pub depth: Vec<f64>,
    /// Every discrete decision, for validating finite-difference probes.
    pub decisions: Vec<u64>,
    /// d L / d(u, v, conic a, b, c, opacity, depth) per Gaussian.
    pub d_proj: Vec<[f64; 7]>,
    pub d_channels: Vec<f64>,
}

/// Naive per-pixel renderer and its backward (back to front, T recovered by division).
pub fn oracle(s: &Scene, cot: Option<(&[f64], &[f64], &[f64])>) -> OracleOut {
    let (w, h) = (s.cam.width as usize, s.cam.height as usize);
    let c = s.c;
    let gs: Vec<OracleGauss> = (0..s.n())
        .map(|i| {
            let smear = s.smears.as_ref().map(|m| &m[i]);
            oracle_project_smeared(&s.cam, &s.params(i), s.covs.as_ref().map(|c| &c[i]), smear)
        })
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
pub fn oracle_param_grad(s: &Scene, i: usize, d_proj: &[f64; 7]) -> Vec<f64> {
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
pub fn random_cotangent(s: &Scene, seed: u64) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
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

pub fn loss(s: &Scene, cot: &(Vec<f64>, Vec<f64>, Vec<f64>)) -> f64 {
    let out = match render(&s.cam, &s.splats(), &s.settings()) {
        Ok(o) => o,
        Err(e) => panic!("render failed: {e}"),
    };
    dot(&out.image, &cot.0) + dot(&out.alpha, &cot.1) + dot(&out.depth, &cot.2)
}

pub fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// Crate gradient of Gaussian i in the flat parameter layout of [`Scene::params`].
pub fn crate_param_grad(g: &rasterize_cpu::Gradients<f64>, i: usize, c: usize) -> Vec<f64> {
    let mut v = Vec::new();
    v.extend_from_slice(&g.means[i]);
    v.extend_from_slice(&g.log_scales[i]);
    v.extend_from_slice(&g.quats[i]);
    v.push(g.opacity_logits[i]);
    v.extend_from_slice(&g.channels[i * c..(i + 1) * c]);
    v
}

pub fn crate_backward(
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
