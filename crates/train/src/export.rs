//! Saving and loading a trained model (a directory), and baking a posed frame into a standard 3DGS PLY.
//!
//! Layout of a model directory (`docs/FORMATS.md`):
//! - `canonical.ply` — every Gaussian in the 3DGS layout with `f_feat_*` (colour features) and
//!   `semantic_*` (logits) extra properties; human Gaussians are in canonical body space, scene
//!   Gaussians in world space;
//! - `networks.safetensors` — float32 tensors `nonrigid`, `skinning`, `human_colour`, `scene_colour`
//!   (flat parameter vectors in `nn::Mlp` order) and `latents` (frames × latent_dim);
//! - `model.json` — [`ModelManifest`]: the configuration (network sizes, semantics), body model and
//!   betas, camera, the frame number of each latent and the scene extent.

use crate::checkpoint::{CheckpointReader, CheckpointWriter};
use crate::config::TrainConfig;
use crate::posing::PosedFrame;
use crate::trainer::{build_nets, Body, Trainer};
use crate::TrainError;
use gaussians::covariance::decompose_covariance;
use gaussians::GaussianSet;
use serde::{Deserialize, Serialize};
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
    /// The training camera (scene format v1 conventions).
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
    /// Parameters wrapped in a trainer (fresh optimiser state) so they can be rendered or fine-tuned.
    pub trainer: Trainer,
    /// The canonical body.
    pub body: Body,
    /// The camera as the rasterizer takes it.
    pub camera: rasterize_cpu::Camera,
}

fn io_err(path: &Path, e: impl std::fmt::Display) -> TrainError {
    TrainError::Checkpoint {
        path: path.to_path_buf(),
        message: e.to_string(),
    }
}

/// Writes `trainer` to `dir` (created). Files are written atomically.
pub fn save_model(
    dir: &Path,
    trainer: &Trainer,
    body_model: &str,
    betas: &[f32],
    camera: &scene::Camera,
) -> Result<(), TrainError> {
    std::fs::create_dir_all(dir).map_err(|e| io_err(dir, e))?;
    let ply = dir.join("canonical.ply");
    let bytes = gaussians::ply::write_ply_bytes(&trainer.set).map_err(|e| io_err(&ply, e))?;
    gaussians::ply::write_atomically(&ply, &bytes).map_err(|e| io_err(&ply, e))?;
    let mut w = CheckpointWriter::default();
    w.push("nonrigid", trainer.nets.nonrigid.mlp.params.clone());
    w.push("skinning", trainer.nets.skinning.mlp.params.clone());
    w.push("human_colour", trainer.nets.human_colour.mlp.params.clone());
    w.push("scene_colour", trainer.nets.scene_colour.mlp.params.clone());
    w.push("latents", trainer.latents.clone());
    w.write(&dir.join("networks.safetensors"), MODEL_FORMAT)?;
    let manifest = ModelManifest {
        format: MODEL_FORMAT.into(),
        config: trainer.config.clone(),
        body_model: body_model.into(),
        betas: betas.to_vec(),
        camera: camera.clone(),
        frame_indices: trainer.frame_indices.clone(),
        scene_extent: trainer.scene_extent,
        steps: trainer.step,
    };
    let json = dir.join("model.json");
    let text = serde_json::to_string_pretty(&manifest).map_err(|e| io_err(&json, e))?;
    gaussians::ply::write_atomically(&json, text.as_bytes()).map_err(|e| io_err(&json, e))
}

/// Loads a model directory written by [`save_model`].
pub fn load_model(dir: &Path) -> Result<LoadedModel, TrainError> {
    let json = dir.join("model.json");
    let text = std::fs::read_to_string(&json).map_err(|e| io_err(&json, e))?;
    let manifest: ModelManifest = serde_json::from_str(&text).map_err(|e| io_err(&json, e))?;
    if manifest.format != MODEL_FORMAT {
        return Err(io_err(
            &json,
            format!("unknown model format `{}`", manifest.format),
        ));
    }
    let body_model = smpl_deform::BodyRef::parse(&manifest.body_model)?.load()?;
    let body = Body::new(body_model, manifest.betas.clone())?;
    let ply = dir.join("canonical.ply");
    let set = gaussians::ply::read_ply(&ply).map_err(|e| io_err(&ply, e))?;
    let mut nets = build_nets(&manifest.config, &body.canonical.posed.vertices)?;
    let r = CheckpointReader::open(&dir.join("networks.safetensors"))?;
    nets.nonrigid.mlp.params = r.get_len("nonrigid", nets.nonrigid.mlp.params.len())?;
    nets.skinning.mlp.params = r.get_len("skinning", nets.skinning.mlp.params.len())?;
    nets.human_colour.mlp.params = r.get_len("human_colour", nets.human_colour.mlp.params.len())?;
    nets.scene_colour.mlp.params = r.get_len("scene_colour", nets.scene_colour.mlp.params.len())?;
    let latents = r.get_len(
        "latents",
        manifest.frame_indices.len() * manifest.config.latent_dim,
    )?;
    let mut trainer = Trainer::from_parts(
        manifest.config.clone(),
        set,
        nets,
        latents,
        manifest.frame_indices.clone(),
        manifest.scene_extent,
    )?;
    trainer.step = manifest.steps;
    let camera = crate::data::camera_of(&manifest.camera)?;
    Ok(LoadedModel {
        manifest,
        trainer,
        body,
        camera,
    })
}

/// Zeroth-order SH coefficient Y₀⁰ = 1 / (2√π).
const SH_C0: f32 = 0.282_094_8;

/// The posed Gaussians of a frame as a standard 3DGS set: world means, the posed covariance decomposed
/// into log-scales and a rotation, the trained opacity, colours baked into SH degree 0 (linear RGB
/// c = 0.5 + C0·f_dc, the INRIA convention), and the semantic logits kept as extra properties.
pub fn posed_set(trainer: &Trainer, posed: &PosedFrame<f32>) -> GaussianSet {
    let n = posed.means.len();
    let k = trainer.set.semantic_classes;
    let mut set = GaussianSet::zeros(n, 0, 0, k);
    set.means = posed.means.clone();
    for i in 0..n {
        let sigma = posed.covariances[i].map(|r| r.map(f64::from));
        let (s, q) = decompose_covariance(&sigma, 1e-14);
        set.log_scales[i] = s;
        set.quats[i] = q;
        for c in 0..3 {
            set.sh[i * 3 + c] = (posed.colours[i * 3 + c] - 0.5) / SH_C0;
        }
    }
    set.opacity_logits = trainer.set.opacity_logits.clone();
    set.semantic_logits = trainer.set.semantic_logits.clone();
    set
}
