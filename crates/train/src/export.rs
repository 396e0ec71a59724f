//! Saving and loading a trained model (a directory), and baking a posed frame into a standard 3DGS PLY.
//!
//! Layout of a model directory (`docs/FORMATS.md`):
//! - `canonical.ply` — every Gaussian in the 3DGS layout with `feature_*` (colour features) and
//!   `semantic_*` (logits) extra properties; human Gaussians are in canonical body space, scene
//!   Gaussians in world space;
//! - `networks.safetensors` — float32 tensors `nonrigid`, `skinning`, `human_colour`, `scene_colour`
//!   (flat parameter vectors in `nn::Mlp` order) and `latents` (frames × latent_dim);
//! - `model.json` — [`ModelManifest`]: the configuration (network sizes, semantics), body model and
//!   betas, camera, the frame number of each latent and the scene extent;
//! - `poses_corrected.json` (with pose correction) — [`CorrectedPoses`]: every frame's corrected
//!   SMPL parameters in `scene.json`'s layout.

use crate::checkpoint::{CheckpointReader, CheckpointWriter};
use crate::config::TrainConfig;
use crate::model::{Model, ModelConfig};
use crate::pose::body::{resolve_reference, Body};
use crate::pose::posing::PosedFrame;
use crate::TrainError;
use gaussians::covariance::decompose_covariance;
use gaussians::GaussianSet;
use serde::{Deserialize, Serialize};
use smpl_deform::BodyRef;
use std::path::Path;

/// Identifier in `model.json`.
pub const MODEL_FORMAT: &str = "e-sem3dgs-model-v1";

/// Contents of `model.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelManifest {
    /// [`MODEL_FORMAT`].
    pub format: String,
    /// Hyper-parameters the model was trained with (decide the network shapes).
    pub config: TrainConfig,
    /// Body model reference (`builtin:makehuman` or an SMPL `.npz` path).
    pub body_model: String,
    /// Shape parameters.
    pub betas: Vec<f32>,
    /// The other people's shape parameters, the scene's person order (absent with one person:
    /// the body model is everyone's, each person with its own betas).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub other_betas: Vec<Vec<f32>>,
    /// The training camera, stored as `scene.json` stores it (`scene::camera_json`).
    #[serde(with = "scene::camera_json")]
    pub camera: scene::Camera,
    /// Frame number of each latent slot.
    pub frame_indices: Vec<u32>,
    /// Scene extent (m).
    pub scene_extent: f32,
    /// Optimisation steps taken.
    pub steps: usize,
}

/// A model loaded from a directory.
pub struct LoadedModel {
    /// The description.
    pub manifest: ModelManifest,
    /// The learned model.
    pub model: Model,
    /// The canonical body (of the first person, with several).
    pub body: Body,
    /// The other people's canonical bodies (empty with one person).
    pub others: Vec<Body>,
    /// The manifest's camera, checked for rendering (`Camera::validate`).
    pub camera: rasterize_cpu::Camera,
}

impl LoadedModel {
    /// The people the model is posed with.
    pub fn cast(&self) -> crate::pose::body::Cast<'_> {
        crate::pose::body::Cast {
            first: &self.body,
            others: &self.others,
        }
    }
}

fn io_err(path: &Path, e: impl std::fmt::Display) -> TrainError {
    TrainError::Checkpoint {
        path: path.to_path_buf(),
        message: e.to_string(),
    }
}

/// Writes `model`, trained with `config` for `steps` steps on the scene `data`, to `dir` (created);
/// `model.json` keeps the whole `config`. Refuses a `config` the model was not built with. Files are
/// written atomically. A relative SMPL path of the scene is stored resolved against the scene
/// directory (as an absolute path), so the model loads from anywhere.
pub fn save_model(
    dir: &Path,
    model: &Model,
    config: &TrainConfig,
    steps: usize,
    data: &crate::data::Dataset,
) -> Result<(), TrainError> {
    if ModelConfig::from(config) != model.config {
        return Err(TrainError::Config(format!(
            "{}: the training options given do not match the model's own ({:?})",
            dir.display(),
            model.config
        )));
    }
    let body = &data.scene.body;
    let body_model = match resolve_reference(&body.model, &data.dir)? {
        BodyRef::SmplFile(p) => std::path::absolute(&p)
            .map_err(|e| io_err(&p, e))?
            .display()
            .to_string(),
        BodyRef::BuiltinMakehuman => body.model.clone(),
    };
    std::fs::create_dir_all(dir).map_err(|e| io_err(dir, e))?;
    let ply = dir.join("canonical.ply");
    let bytes = gaussians::ply::write_ply_bytes(&model.set).map_err(|e| io_err(&ply, e))?;
    gaussians::ply::write_atomically(&ply, &bytes).map_err(|e| io_err(&ply, e))?;
    let mut w = CheckpointWriter::default();
    model.push_networks(&mut w);
    w.write(&dir.join("networks.safetensors"), MODEL_FORMAT)?;
    let manifest = ModelManifest {
        format: MODEL_FORMAT.into(),
        config: config.clone(),
        body_model,
        betas: body.betas.clone(),
        other_betas: data.scene.people.iter().map(|p| p.betas.clone()).collect(),
        camera: data.scene.camera.clone(),
        frame_indices: model.frame_indices.clone(),
        scene_extent: model.scene_extent,
        steps,
    };
    let json = dir.join("model.json");
    let text = serde_json::to_string_pretty(&manifest).map_err(|e| io_err(&json, e))?;
    gaussians::ply::write_atomically(&json, text.as_bytes()).map_err(|e| io_err(&json, e))
}

/// Name of the corrected poses' file in a model directory ([`write_corrected_poses`]).
pub const CORRECTED_POSES_FILE: &str = "poses_corrected.json";

/// One frame of [`CorrectedPoses`]: its SMPL parameters at mid exposure, in `scene.json`'s layout.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CorrectedFramePose {
    /// The frame's `index` in `scene.json`.
    pub index: u32,
    /// Mid-exposure time (seconds).
    pub time_s: f64,
    /// `train`: the correction was learned on this frame; `test`: interpolated from the training
    /// frames around it, never fitted to its image.
    pub split: scene::Split,
    /// 24 axis-angle rotations (radians), joint 0 the global orientation (world frame), each
    /// joint's rotation in its parent's frame.
    pub pose: Vec<[f32; 3]>,
    /// SMPL translation (metres, world frame).
    pub transl: [f32; 3],
}

/// Contents of `poses_corrected.json`: every frame's SMPL parameters as the model poses it, the
/// scene's estimate plus the learned pose correction (`TrainConfig::pose_correction`). The
/// per-frame `pose` and `transl` have `scene.json`'s layout, so they can replace a scene's poses.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CorrectedPoses {
    /// Always 1.
    pub format_version: u32,
    /// One entry per frame of the scene, in time order.
    pub frames: Vec<CorrectedFramePose>,
}

/// The corrected mid-exposure poses of every frame of `data` (training frames' learned, held-out
/// frames' interpolated; the scene's own when `model` has no pose correction).
pub fn corrected_poses(model: &Model, data: &crate::data::Dataset) -> CorrectedPoses {
    let frames = data
        .frames
        .iter()
        .map(|f| {
            let p = model.corrected_params(f.index, &f.smpl);
            CorrectedFramePose {
                index: f.index,
                time_s: f.time_s,
                split: f.split,
                pose: p.pose.chunks_exact(3).map(|r| [r[0], r[1], r[2]]).collect(),
                transl: p.transl,
            }
        })
        .collect();
    CorrectedPoses {
        format_version: 1,
        frames,
    }
}

/// Writes [`corrected_poses`] to `dir/poses_corrected.json` (atomically, pretty JSON).
pub fn write_corrected_poses(
    dir: &Path,
    model: &Model,
    data: &crate::data::Dataset,
) -> Result<(), TrainError> {
    let path = dir.join(CORRECTED_POSES_FILE);
    let text = serde_json::to_string_pretty(&corrected_poses(model, data))
        .map_err(|e| io_err(&path, e))?;
    gaussians::ply::write_atomically(&path, format!("{text}\n").as_bytes())
        .map_err(|e| io_err(&path, e))
}

/// Loads a model directory written by [`save_model`].
pub fn load_model(dir: &Path) -> Result<LoadedModel, TrainError> {
    let json = dir.join("model.json");
    let text = std::fs::read_to_string(&json).map_err(|e| io_err(&json, e))?;
    let mut manifest: ModelManifest = serde_json::from_str(&text).map_err(|e| io_err(&json, e))?;
    let stored: serde_json::Value = serde_json::from_str(&text).map_err(|e| io_err(&json, e))?;
    manifest.config.pin_options_missing_from(&stored["config"]);
    if manifest.format != MODEL_FORMAT {
        return Err(io_err(
            &json,
            format!("unknown model format `{}`", manifest.format),
        ));
    }
    // `save_model` stores SMPL paths absolute; a hand-edited relative one is taken relative to `dir`.
    let body = Body::load(&manifest.body_model, manifest.betas.clone(), dir)?;
    let others = manifest
        .other_betas
        .iter()
        .map(|betas| Body::new(body.model.clone(), betas.clone()))
        .collect::<Result<Vec<_>, _>>()?;
    let ply = dir.join("canonical.ply");
    let set = gaussians::ply::read_ply(&ply).map_err(|e| io_err(&ply, e))?;
    manifest.config.validate()?;
    let model_config = ModelConfig::from(&manifest.config);
    let nets = Model::build_networks(&model_config, &body.canonical.posed.vertices)?;
    let latents = vec![0.0; manifest.frame_indices.len() * manifest.config.latent_dim];
    let mut model = Model::new(
        model_config,
        set,
        nets,
        latents,
        manifest.frame_indices.clone(),
        manifest.scene_extent,
    )?;
    if model.people() != 1 + others.len() {
        return Err(io_err(
            &json,
            format!(
                "canonical.ply has the semantic classes of {} people, model.json the betas of {}",
                model.people(),
                1 + others.len()
            ),
        ));
    }
    model.read_networks(&CheckpointReader::open(&dir.join("networks.safetensors"))?)?;
    manifest.camera.validate()?;
    let camera = manifest.camera.clone();
    Ok(LoadedModel {
        manifest,
        model,
        body,
        others,
        camera,
    })
}

/// Zeroth-order SH coefficient Y₀⁰ = 1 / (2√π).
const SH_C0: f32 = 0.282_094_8;

/// SH degree of posed sets: 3, the layout INRIA's viewers and loaders read as fixed 62-float rows.
const POSED_SH_DEGREE: usize = 3;

/// The posed Gaussians of a frame as a standard 3DGS set in exactly INRIA's degree-3 layout (62
/// floats per Gaussian, what SIBR's viewer and INRIA's `load_ply` read): world means, the posed
/// covariance decomposed into log-scales and a rotation, the trained opacity, colours baked into the
/// SH DC term (linear RGB c = 0.5 + C0·f_dc, the INRIA convention) with zero higher-order
/// coefficients. Semantic logits and colour features are not posed; they stay in `canonical.ply`.
pub fn posed_set(model: &Model, posed: &PosedFrame<f32>) -> GaussianSet {
    let n = posed.means.len();
    let coefficients = (POSED_SH_DEGREE + 1) * (POSED_SH_DEGREE + 1);
    let mut set = GaussianSet::zeros(n, POSED_SH_DEGREE, 0, 0);
    set.means = posed.means.clone();
    for i in 0..n {
        let sigma = posed.covariances[i].map(|r| r.map(f64::from));
        let (s, q) = decompose_covariance(&sigma, 1e-14);
        set.log_scales[i] = s;
        set.quats[i] = q;
        for c in 0..3 {
            set.sh[i * coefficients * 3 + c] = (posed.colours[i * 3 + c] - 0.5) / SH_C0;
        }
    }
    set.opacity_logits = model.set.opacity_logits.clone();
    set
}
