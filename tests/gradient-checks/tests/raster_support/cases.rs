//! The covariance-path, camera-twist, f32 and shared-render cases the rasterizer checks build.

use super::*;

pub fn cov_splats<'a>(s: &'a Scene, covs: &'a [Mat3<f64>]) -> CovSplats<'a, f64> {
    CovSplats {
        means: &s.means,
        covariances: covs,
        opacity_logits: &s.logits,
        channels: &s.channels,
        num_channels: s.c,
        smears: s.smears.as_deref(),
    }
}

/// A scene with its covariances, a cotangent of (image, alpha, depth), and the render's gradients.
pub type CovCase = (
    Scene,
    Vec<Mat3<f64>>,
    (Vec<f64>, Vec<f64>, Vec<f64>),
    rasterize_cpu::Gradients<f64>,
);

/// A random scene (seed, kinds, channels) with its covariances set, a random cotangent, and
/// `render_cov_backward`'s gradients of L = Σ cot · (image, alpha, depth).
pub fn cov_scene_and_gradients(seed: u64, kinds: &[usize], c: usize) -> CovCase {
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
pub fn cov_gradients(
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
pub fn cov_loss(s: &Scene, cot: &(Vec<f64>, Vec<f64>, Vec<f64>)) -> f64 {
    let covs = s
        .covs
        .as_deref()
        .unwrap_or_else(|| panic!("scene has no covariances"));
    let out = render_cov(&s.cam, &cov_splats(s, covs), &s.settings())
        .unwrap_or_else(|e| panic!("render_cov: {e}"));
    dot(&out.image, &cot.0) + dot(&out.alpha, &cot.1) + dot(&out.depth, &cot.2)
}

/// `camera` moved by the twist ξ = (ω, v) on the left: exp(ξ^)·world_to_camera (ω by Rodrigues).
pub fn moved_camera(camera: &Camera, xi: [f64; 6]) -> Camera {
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

/// The inverse of the rigid transform `[Exp(ω) | v]` of `twist`, composed with `world_to_camera`:
/// the camera that `twist` corrects into `world_to_camera`.
pub fn uncorrected(world_to_camera: &[[f64; 4]; 4], twist: &[f64; 6]) -> [[f64; 4]; 4] {
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

#[allow(clippy::type_complexity)]
pub fn f32_scene(
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
pub fn render_f32(
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
pub fn f32_cotangents(cam: &Camera) -> (Vec<f32>, Vec<f32>) {
    let hw = (cam.width * cam.height) as usize;
    let ci: Vec<f32> = (0..3 * hw)
        .map(|i| ((i * 7919) % 1000) as f32 / 1000.0 - 0.5)
        .collect();
    let ca: Vec<f32> = (0..hw)
        .map(|i| ((i * 104_729) % 997) as f32 / 997.0 - 0.5)
        .collect();
    (ci, ca)
}

/// Renders of one scene whose Gaussians with `i % 3 == 1` move: render r shifts their means by r
/// times a fixed world offset (r = 0 is the scene itself).
pub fn moving_renders(s: &Scene, renders: usize) -> (Vec<Scene>, Vec<bool>) {
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

/// Three f32 renders of one 100×76 camera over [`f32_scene`]'s 3000 Gaussians (seed 7), the ones
/// left of x = −0.3 moving 1 cm to the right per render: the shared renders' checks' scene.
pub struct F32Renders {
    pub cam: Camera,
    /// Each render's means.
    pub means: Vec<Vec<[f32; 3]>>,
    pub covs: Vec<Mat3<f32>>,
    pub opacity_logits: Vec<f32>,
    /// Three channels per Gaussian.
    pub channels: Vec<f32>,
    pub moving: Vec<bool>,
}

impl F32Renders {
    pub fn new() -> Self {
        let (cam, m, ls, q, op, ch) = f32_scene(3000, 100, 76, 7);
        let covs = ls
            .iter()
            .zip(&q)
            .map(|(l, r)| covariance_3d(*l, *r))
            .collect();
        let moving: Vec<bool> = m.iter().map(|p| p[0] < -0.3).collect();
        let means = (0..3)
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
        Self {
            cam,
            means,
            covs,
            opacity_logits: op,
            channels: ch,
            moving,
        }
    }

    /// The three renders' inputs.
    pub fn splats(&self) -> Vec<CovSplats<'_, f32>> {
        self.means
            .iter()
            .map(|means| CovSplats {
                means,
                covariances: &self.covs,
                opacity_logits: &self.opacity_logits,
                channels: &self.channels,
                num_channels: 3,
                smears: None,
            })
            .collect()
    }

    /// The near plane of the checks and a background of (0.1, 0.2, 0.3).
    pub fn settings(&self) -> RenderSettings {
        RenderSettings {
            near_plane: NEAR,
            background: vec![0.1, 0.2, 0.3],
        }
    }
}

/// Whether a probe is discarded, from the perturbed scenes (as a function of the parameter's
/// value) and the parameter's value.
pub type ProbeDiscard<'a> = dyn Fn(&dyn Fn(f64) -> Vec<Scene>, f64) -> bool + 'a;

/// One Gaussian's probes in shared renders: the central differences of `loss` and the analytic
/// gradients `g` (one per render) of Gaussian `i`'s mean, opacity logit and `c` channels in render
/// `r` — a static Gaussian's parameter moved in every render at once against the renders' summed
/// gradient, a moving one's in render `r` alone against that render's. A probe is discarded when
/// `discard(perturbed, x)` says so (`perturbed(v)`: the scenes with the parameter at v; `x` its
/// value). Returns (numeric, analytic, probes, valid probes).
#[allow(clippy::too_many_arguments)]
pub fn shared_render_probes(
    scenes: &[Scene],
    moving: &[bool],
    i: usize,
    r: usize,
    c: usize,
    g: &[rasterize_cpu::Gradients<f64>],
    loss: &dyn Fn(&[Scene]) -> f64,
    discard: &ProbeDiscard<'_>,
) -> (Vec<f64>, Vec<f64>, usize, usize) {
    let x = scenes[r].params(i);
    let (mut num, mut ana, mut probes, mut valid) = (Vec::new(), Vec::new(), 0, 0);
    for k in [0usize, 1, 2, 10].into_iter().chain(11..11 + c) {
        probes += 1;
        let perturbed = |v: f64| -> Vec<Scene> {
            let mut sc = scenes.to_vec();
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
        if discard(&perturbed, x[k]) {
            continue;
        }
        valid += 1;
        num.push(central_differences(|v| loss(&perturbed(v[0])), &[x[k]], FD_H)[0]);
        let sum = |f: &dyn Fn(&rasterize_cpu::Gradients<f64>) -> f64| -> f64 {
            if moving[i] {
                f(&g[r])
            } else {
                g.iter().map(f).sum()
            }
        };
        ana.push(match k {
            0..=2 => sum(&|gr| gr.means[i][k]),
            10 => sum(&|gr| gr.opacity_logits[i]),
            _ => sum(&|gr| gr.channels[i * c + k - 11]),
        });
    }
    (num, ana, probes, valid)
}
