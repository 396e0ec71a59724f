//! Initialisation of the single semantic Gaussian set (paper §4.2, ablations of Tables 7–8).
//!
//! One stored mean serves both branches: for human Gaussians it is a canonical-space position (deformed
//! per frame), for scene Gaussians a world position (static); the semantic blend mixes the two readings.
//! - `smpl+cube` (default): human Gaussians sampled on the canonical body surface and up to
//!   `surface_inside_depth` below it (along the inward normal), plus scene Gaussians uniform in a cube
//!   enclosing the visible scene and kept only if some training camera sees them.
//! - `random`: the same total count uniform in the scene cube, with no label (semantic logits "half").
//! - `smpl-only`: only the human Gaussians.
//!
//! Semantic logits follow the paper: ±λ_logit (λ = 3) for the labelled class (human (−3, +3), scene
//! (+3, −3)); `--semantic-init half` starts every Gaussian at p = 0.5 instead. The scalar ablation
//! stores a single logit initialised to 0 (p = sigmoid(0) = 0.5) for every Gaussian, as the issue
//! defines it ("one sigmoid value initialised 0.5"), whatever `--semantic-init` says. Scales come from the 3-nearest-neighbour rule, rotations are the
//! identity, opacity 0.1, features small random values, and the SH DC colour (used only for previews
//! before the colour networks are trained) is white for human and grey for scene Gaussians.

use crate::blend::SemanticMode;
use gaussians::init::knn_log_scales;
use gaussians::sh::rgb_to_sh_dc;
use gaussians::GaussianSet;
use rand::{Rng, SeedableRng};
use rasterize_cpu::Camera;

pub mod stereo;

/// Where the initial Gaussians come from (`--init`).
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize, clap::ValueEnum,
)]
#[serde(rename_all = "kebab-case")]
pub enum InitMode {
    /// Body surface samples plus a scene cube (the paper).
    #[serde(rename = "smpl+cube")]
    #[value(name = "smpl+cube")]
    SmplCube,
    /// Uniform in the scene cube, unlabelled.
    Random,
    /// Body surface samples only.
    SmplOnly,
}

/// Where the scene's initial Gaussians are drawn (`--scene-init`).
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize, clap::ValueEnum,
)]
#[serde(rename_all = "kebab-case")]
pub enum SceneInit {
    /// Uniform in the visible part of the scene cube (the paper).
    Volume,
    /// Half on the surfaces a plane sweep over the training frames finds (`init::stereo`; needs a
    /// moving camera, and is the cube alone without one), half in the cube.
    Stereo,
}

/// Initial semantic logits (`--semantic-init`).
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize, clap::ValueEnum,
)]
#[serde(rename_all = "kebab-case")]
pub enum SemanticInit {
    /// ±λ_logit for the labelled class.
    OneHot,
    /// Every Gaussian at p = 0.5.
    Half,
}

/// Settings of [`initialise`].
#[derive(Clone, Debug, PartialEq)]
pub struct InitConfig {
    /// Source of the initial points.
    pub mode: InitMode,
    /// Semantic parameterisation (decides the number of logits).
    pub semantic: SemanticMode,
    /// Initial logits.
    pub semantic_init: SemanticInit,
    /// Human Gaussians (3DGS-Avatar: 50k at 512²).
    pub human_count: usize,
    /// Scene Gaussians.
    pub scene_count: usize,
    /// λ_logit (paper: 3).
    pub logit_magnitude: f32,
    /// Largest depth below the body surface of human samples (m).
    pub surface_inside_depth: f32,
    /// The scene cube extends from the cameras to this multiple of the farthest camera–body distance.
    pub scene_depth_factor: f32,
    /// Upper bound on the initial scale (m): kNN scales of sparse scene samples can reach tens of
    /// centimetres, and each such Gaussian then overlaps thousands of pixels, which makes the first
    /// steps cost more than the rest of training. `f32::INFINITY` keeps the plain kNN scales.
    pub max_initial_scale: f32,
    /// Per-Gaussian colour-feature length.
    pub feature_dim: usize,
    /// Initial opacity (3DGS-Avatar: 0.1).
    pub opacity: f32,
    /// Seed of every sample.
    pub seed: u64,
    /// Points on the static scene's surfaces (world, m; [`stereo::surface_points`]): up to half of
    /// the scene samples are taken from them, evenly through the list, the rest drawn in the cube.
    /// Empty: every scene sample from the cube.
    pub scene_surface: Vec<[f32; 3]>,
}

impl Default for InitConfig {
    fn default() -> Self {
        Self {
            mode: InitMode::SmplCube,
            semantic: SemanticMode::OneHot,
            semantic_init: SemanticInit::OneHot,
            human_count: 10_000,
            scene_count: 20_000,
            logit_magnitude: 3.0,
            surface_inside_depth: 0.01,
            scene_depth_factor: 2.0,
            max_initial_scale: f32::INFINITY,
            feature_dim: 32,
            opacity: 0.1,
            seed: 0,
            scene_surface: Vec::new(),
        }
    }
}

/// The initial set and how many of its leading Gaussians were labelled human.
#[derive(Clone, Debug, PartialEq)]
pub struct InitialModel {
    /// The Gaussians: the first `human` are human samples, the rest scene samples.
    pub set: GaussianSet,
    /// Number of human-labelled Gaussians at the front of `set`.
    pub human: usize,
    /// Scene cube (min corner, max corner), world metres.
    pub cube: ([f32; 3], [f32; 3]),
}

/// An axis-aligned box around every camera centre and the part of the world the cameras see up to
/// `factor` × the farthest camera-to-body distance, including the body trajectory.
pub fn scene_cube(
    cameras: &[Camera],
    body_positions: &[[f32; 3]],
    factor: f32,
) -> ([f32; 3], [f32; 3]) {
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    let mut grow = |p: [f32; 3]| {
        for a in 0..3 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    };
    let mut far = 1.0f32;
    for cam in cameras {
        let c = cam.center_world().map(|v| v as f32);
        for b in body_positions {
            let d = ((b[0] - c[0]).powi(2) + (b[1] - c[1]).powi(2) + (b[2] - c[2]).powi(2)).sqrt();
            far = far.max(d);
        }
    }
    let depth = far * factor;
    for cam in cameras {
        grow(cam.center_world().map(|v| v as f32));
        for (u, v) in [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)] {
            let px = u * f64::from(cam.width);
            let py = v * f64::from(cam.height);
            grow(unproject(cam, px, py, f64::from(depth)).map(|v| v as f32));
        }
    }
    for &b in body_positions {
        grow(b.map(|v| v - 1.0));
        grow(b.map(|v| v + 1.0));
    }
    (lo, hi)
}

/// World point at view depth `z` (m) behind pixel position (x, y) (pixels, the image's corner at
/// (0, 0)).
fn unproject(cam: &Camera, x: f64, y: f64, z: f64) -> [f64; 3] {
    let p_cam = [(x - cam.cx) / cam.fx * z, (y - cam.cy) / cam.fy * z, z];
    let m = &cam.world_to_camera;
    // p_world = Rᵀ (p_cam − t).
    let d = [p_cam[0] - m[0][3], p_cam[1] - m[1][3], p_cam[2] - m[2][3]];
    std::array::from_fn(|a| m[0][a] * d[0] + m[1][a] * d[1] + m[2][a] * d[2])
}

/// True when some camera sees `p` in front of its near plane and inside its image.
fn visible(cameras: &[Camera], p: [f32; 3]) -> bool {
    cameras.iter().any(|cam| {
        let m = &cam.world_to_camera;
        let q = p.map(f64::from);
        let c: [f64; 3] =
            std::array::from_fn(|r| m[r][0] * q[0] + m[r][1] * q[1] + m[r][2] * q[2] + m[r][3]);
        if c[2] <= 0.2 {
            return false;
        }
        let (u, v) = (cam.fx * c[0] / c[2] + cam.cx, cam.fy * c[1] / c[2] + cam.cy);
        (0.0..f64::from(cam.width)).contains(&u) && (0.0..f64::from(cam.height)).contains(&v)
    })
}

/// One person's canonical body mesh, as the initialisation samples it.
#[derive(Clone, Copy, Debug)]
pub struct BodySurface<'a> {
    /// Canonical vertices (m).
    pub vertices: &'a [[f32; 3]],
    /// Triangles.
    pub faces: &'a [[u32; 3]],
    /// Skinning weights N_v × 24 (only used by the surface sampler's interpolation).
    pub weights: &'a [f32],
}

/// Builds the initial set of one person. `canonical_vertices`/`faces`/`skinning_weights` describe
/// the canonical body mesh (weights N_v × 24, only used by the surface sampler's interpolation),
/// `cameras` the training cameras and `body_positions` the body's root position per training frame
/// (world).
pub fn initialise(
    canonical_vertices: &[[f32; 3]],
    faces: &[[u32; 3]],
    skinning_weights: &[f32],
    cameras: &[Camera],
    body_positions: &[[f32; 3]],
    config: &InitConfig,
) -> InitialModel {
    let body = BodySurface {
        vertices: canonical_vertices,
        faces,
        weights: skinning_weights,
    };
    initialise_people(&[body], cameras, body_positions, config)
}

/// Builds the initial set of one or more people: `config.human_count` samples on each person's
/// canonical body (`bodies`, the model's person order), labelled with that person's class (with
/// one-hot semantics and several people, K = 1 + P logits), then the scene samples.
/// `body_positions` are every person's root positions over the training frames (world).
pub fn initialise_people(
    bodies: &[BodySurface<'_>],
    cameras: &[Camera],
    body_positions: &[[f32; 3]],
    config: &InitConfig,
) -> InitialModel {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(config.seed);
    let cube = scene_cube(cameras, body_positions, config.scene_depth_factor);
    let mut points = Vec::new();
    let mut person_of = Vec::new();
    let human_n = match config.mode {
        InitMode::SmplCube | InitMode::SmplOnly => config.human_count,
        InitMode::Random => 0,
    };
    for (j, body) in bodies.iter().enumerate().filter(|_| human_n > 0) {
        // The first person's samples are those of a one-person model, bit for bit.
        let seed = config.seed ^ 0x5eed ^ ((j as u64) << 40);
        let samples =
            smpl_deform::sample_surface(body.vertices, body.faces, body.weights, human_n, seed);
        for (p, n) in samples.points.iter().zip(&samples.normals) {
            let depth = rng.gen_range(0.0..=config.surface_inside_depth);
            points.push([
                p[0] - n[0] * depth,
                p[1] - n[1] * depth,
                p[2] - n[2] * depth,
            ]);
            person_of.push(j);
        }
    }
    let human = points.len();
    let scene_n = match config.mode {
        InitMode::SmplCube => config.scene_count,
        InitMode::Random => config.scene_count + config.human_count,
        InitMode::SmplOnly => 0,
    };
    // Rejection sampling of visible points, with a bounded number of tries so a degenerate camera
    // setup cannot loop forever.
    let mut tries = 0usize;
    let max_tries = scene_n.saturating_mul(200).max(1000);
    let on_surfaces = (scene_n / 2).min(config.scene_surface.len());
    points.extend(
        (0..on_surfaces)
            .map(|k| config.scene_surface[k * config.scene_surface.len() / on_surfaces]),
    );
    let (lo, hi) = cube;
    while points.len() < human + scene_n && tries < max_tries {
        tries += 1;
        let p: [f32; 3] = std::array::from_fn(|a| rng.gen_range(lo[a]..=hi[a].max(lo[a])));
        if cameras.is_empty() || visible(cameras, p) {
            points.push(p);
        }
    }
    let n = points.len();
    let k = config.semantic.logits_for(bodies.len());
    let mut set = GaussianSet::zeros(n, 0, config.feature_dim, k);
    let cap = config.max_initial_scale.ln();
    set.log_scales = knn_log_scales(&points)
        .into_iter()
        .map(|s| s.map(|v| v.min(cap)))
        .collect();
    set.means = points;
    set.quats = vec![[1.0, 0.0, 0.0, 0.0]; n];
    set.opacity_logits = vec![gaussians::inverse_sigmoid(config.opacity); n];
    for f in &mut set.features {
        *f = rng.gen_range(-0.01..0.01);
    }
    let l = config.logit_magnitude;
    for i in 0..n {
        let is_human = i < human;
        let grey = if is_human { 1.0 } else { 0.5 };
        for c in 0..3 {
            set.sh[i * 3 + c] = rgb_to_sh_dc(grey);
        }
        let logits = &mut set.semantic_logits[i * k..(i + 1) * k];
        let labelled =
            config.semantic_init == SemanticInit::OneHot && config.mode != InitMode::Random;
        match (config.semantic, labelled) {
            (SemanticMode::OneHot, true) => {
                // The labelled class +λ, every other −λ (scene, then one class per person).
                let class = if is_human { 1 + person_of[i] } else { 0 };
                for (c, v) in logits.iter_mut().enumerate() {
                    *v = if c == class { l } else { -l };
                }
            }
            _ => logits.iter_mut().for_each(|v| *v = 0.0),
        }
    }
    InitialModel { set, human, cube }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A unit cube mesh (12 outward-facing triangles) standing in for a body.
    fn cube_mesh() -> (Vec<[f32; 3]>, Vec<[u32; 3]>, Vec<f32>) {
        let v: Vec<[f32; 3]> = (0..8)
            .map(|i| {
                [
                    (i & 1) as f32 - 0.5,
                    ((i >> 1) & 1) as f32 - 0.5,
                    ((i >> 2) & 1) as f32 - 0.5,
                ]
            })
            .collect();
        let f = vec![
            [0, 2, 1],
            [1, 2, 3],
            [4, 5, 6],
            [5, 7, 6],
            [0, 1, 4],
            [1, 5, 4],
            [2, 6, 3],
            [3, 6, 7],
            [0, 4, 2],
            [2, 4, 6],
            [1, 3, 5],
            [3, 7, 5],
        ];
        let mut w = vec![0.0; 8 * 24];
        for i in 0..8 {
            w[i * 24] = 1.0;
        }
        (v, f, w)
    }

    fn camera() -> Camera {
        let mut m = [[0.0; 4]; 4];
        for (i, row) in m.iter_mut().enumerate() {
            row[i] = 1.0;
        }
        m[2][3] = 4.0; // body 4 m in front of the camera
        Camera::new(64, 48, 60.0, 60.0, 32.0, 24.0, m).expect("valid camera")
    }

    #[test]
    fn smpl_cube_init_labels_and_places_points() {
        let (v, f, w) = cube_mesh();
        let config = InitConfig {
            human_count: 300,
            scene_count: 500,
            feature_dim: 4,
            ..InitConfig::default()
        };
        let model = initialise(&v, &f, &w, &[camera()], &[[0.0, 0.0, 0.0]], &config);
        assert_eq!(model.human, 300);
        assert_eq!(model.set.len(), 800);
        model.set.validate().expect("valid set");
        for i in 0..model.set.len() {
            let l = &model.set.semantic_logits[i * 2..i * 2 + 2];
            let want = if i < 300 { [-3.0, 3.0] } else { [3.0, -3.0] };
            assert_eq!(l, want);
        }
        // Human samples lie on or just inside the cube surface (max |coordinate| within 1 cm of 0.5).
        for p in &model.set.means[..300] {
            let m = p.iter().fold(0.0f32, |a, v| a.max(v.abs()));
            assert!((0.49 - 1e-4..=0.5 + 1e-4).contains(&m), "{p:?}");
        }
        // Scene samples are visible from the camera.
        assert!(model.set.means[300..]
            .iter()
            .all(|&p| visible(&[camera()], p)));
    }

    #[test]
    fn surface_points_take_half_the_scene_samples_and_leave_the_rest_as_before() {
        let (v, f, w) = cube_mesh();
        let base = InitConfig {
            human_count: 30,
            scene_count: 40,
            feature_dim: 2,
            ..InitConfig::default()
        };
        let plain = initialise(&v, &f, &w, &[camera()], &[[0.0; 3]], &base);
        let surface: Vec<[f32; 3]> = (0..100).map(|k| [0.01 * k as f32, 0.0, 1.0]).collect();
        let config = InitConfig {
            scene_surface: surface.clone(),
            ..base.clone()
        };
        let model = initialise(&v, &f, &w, &[camera()], &[[0.0; 3]], &config);
        assert_eq!(model.set.len(), plain.set.len());
        // The human samples are untouched; 20 scene samples come from the list, evenly (every 5th).
        assert_eq!(model.set.means[..30], plain.set.means[..30]);
        let taken: Vec<[f32; 3]> = (0..20).map(|k| surface[5 * k]).collect();
        assert_eq!(model.set.means[30..50], taken[..]);
        // The other 20 are drawn in the cube as the first 20 draws of the plain init.
        assert_eq!(model.set.means[50..], plain.set.means[30..50]);
        // Fewer points than half the budget: all of them, the rest from the cube.
        let few = InitConfig {
            scene_surface: surface[..3].to_vec(),
            ..base
        };
        let model = initialise(&v, &f, &w, &[camera()], &[[0.0; 3]], &few);
        assert_eq!(model.set.means[30..33], surface[..3]);
        assert_eq!(model.set.len(), 70);
    }

    #[test]
    fn ablation_modes_change_counts_and_logits() {
        let (v, f, w) = cube_mesh();
        let base = InitConfig {
            human_count: 50,
            scene_count: 70,
            feature_dim: 2,
            ..InitConfig::default()
        };
        let init_with =
            |config: InitConfig| initialise(&v, &f, &w, &[camera()], &[[0.0; 3]], &config);
        let random = init_with(InitConfig {
            mode: InitMode::Random,
            ..base.clone()
        });
        assert_eq!((random.human, random.set.len()), (0, 120));
        assert!(random.set.semantic_logits.iter().all(|&l| l == 0.0));
        let only = init_with(InitConfig {
            mode: InitMode::SmplOnly,
            ..base.clone()
        });
        assert_eq!((only.human, only.set.len()), (50, 50));
        let half = init_with(InitConfig {
            semantic_init: SemanticInit::Half,
            ..base.clone()
        });
        assert!(half.set.semantic_logits.iter().all(|&l| l == 0.0));
        let scalar = init_with(InitConfig {
            semantic: SemanticMode::Scalar,
            ..base.clone()
        });
        assert_eq!(scalar.set.semantic_classes, 1);
        assert!(scalar.set.semantic_logits.iter().all(|&l| l == 0.0));
        let none = init_with(InitConfig {
            semantic: SemanticMode::None,
            ..base
        });
        assert_eq!(none.set.semantic_classes, 0);
    }

    #[test]
    fn same_seed_same_model() {
        let (v, f, w) = cube_mesh();
        let config = InitConfig {
            human_count: 40,
            scene_count: 40,
            feature_dim: 2,
            ..InitConfig::default()
        };
        let a = initialise(&v, &f, &w, &[camera()], &[[0.0; 3]], &config);
        let b = initialise(&v, &f, &w, &[camera()], &[[0.0; 3]], &config);
        assert_eq!(a, b);
    }
}
