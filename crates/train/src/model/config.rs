//! What shapes a model and how it is posed and rendered: the part of the training options a model
//! keeps for its whole life. Learning rates, loss weights and schedules stay with the trainer.

use crate::blend::SemanticMode;
use crate::config::TrainConfig;
use crate::pose::camera_correction::{CAMERA_CORRECTION_VALUES, TWIST_VALUES};

/// The model's own settings, fixed when it is built (read from [`TrainConfig`]).
#[derive(Clone, Debug, PartialEq)]
pub struct ModelConfig {
    /// Semantic parameterisation: how many logits a Gaussian carries and how they blend.
    pub semantic: SemanticMode,
    /// Gaussians with human probability below this skip the human branch (`pose::posing`).
    pub semantic_gate: f32,
    /// Per-Gaussian colour-feature length.
    pub feature_dim: usize,
    /// Per-frame latent length of the human colour network.
    pub latent_dim: usize,
    /// Hidden width of the non-rigid network and of the skinning field.
    pub deform_hidden: usize,
    /// Seed of the networks' initial weights.
    pub seed: u64,
    /// Background colour (linear RGB) composited behind the Gaussians.
    pub background: [f32; 3],
    /// Near clipping plane of the rasterizer (m).
    pub near_plane: f64,
    /// The model's pose rows correct a fitter's poses (`TrainConfig::pose_correction`; what the
    /// reports call corrected poses).
    pub pose_correction: bool,
    /// The model carries learned per-knot pose rows (`TrainConfig::carries_pose_rows`: for pose
    /// correction or for the learned in-exposure motion alone).
    pub pose_rows: bool,
    /// Training frames per pose-row knot: `pose_correction_knot_every` with pose correction, else
    /// 1 (the learned in-exposure motion is per frame).
    pub pose_correction_knot_every: usize,
    /// The model carries learned per-training-frame camera corrections.
    pub camera_correction: bool,
    /// With camera correction, the model carries one clip-wide twist set by the person (the
    /// frames' twists then keep a zero clip mean; `TrainConfig::camera_gauge`).
    pub camera_gauge: bool,
    /// Width (training slots) of the Gaussian smoothing that turns the stored camera corrections
    /// into the twists the frames' cameras take (0: each frame's own; `TrainConfig::camera_correction_smoothing`).
    pub camera_correction_smoothing: f32,
    /// How many leading values of each stored camera-correction row the smoothing covers: all
    /// [`CAMERA_CORRECTION_VALUES`], or the mid-exposure twist's [`TWIST_VALUES`]
    /// (`TrainConfig::camera_correction_smooth_change` off).
    pub camera_correction_smoothed_values: usize,
    /// Whose skinning weights canonicalise the human colour network's view directions
    /// (`TrainConfig::view_rotation`).
    pub view_rotation: crate::config::ViewRotation,
}

impl From<&TrainConfig> for ModelConfig {
    fn from(config: &TrainConfig) -> Self {
        Self {
            semantic: config.semantic,
            semantic_gate: config.semantic_gate,
            feature_dim: config.feature_dim,
            latent_dim: config.latent_dim,
            deform_hidden: config.deform_hidden,
            seed: config.seed,
            background: config.background,
            near_plane: config.near_plane,
            pose_correction: config.pose_correction,
            pose_rows: config.carries_pose_rows(),
            pose_correction_knot_every: if config.pose_correction {
                config.pose_correction_knot_every
            } else {
                1
            },
            camera_correction: config.camera_correction,
            camera_gauge: config.camera_correction
                && config.camera_gauge == crate::config::CameraGauge::Person,
            camera_correction_smoothing: config.camera_correction_smoothing,
            camera_correction_smoothed_values: if config.camera_correction_smooth_change {
                CAMERA_CORRECTION_VALUES
            } else {
                TWIST_VALUES
            },
            view_rotation: config.view_rotation,
        }
    }
}
