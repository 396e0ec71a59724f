//! Every hyper-parameter of a reconstruction, with its documented default, as one serde structure
//! (TOML or JSON on disk). Two presets: [`Preset::Quick`] (the default: a useful result in minutes on
//! two cores) and [`Preset::Full`] (the longer schedule the benchmark numbers are also reported for).
//!
//! Learning rates follow 3DGS / 3DGS-Avatar (positions 1.6e-4 × scene extent decayed log-linearly to
//! 1 %, scales 5e-3, rotations 1e-3, opacity 5e-2, networks 1e-3); the loss weights follow 3DGS-Avatar
//! (skinning 10 for the first part of training, AIAP on positions 1 and on covariances 100, D-SSIM 0.2
//! as in 3DGS because LPIPS — 3DGS-Avatar's perceptual term — is not available without downloaded
//! weights).

use crate::blend::SemanticMode;
use crate::init::{InitMode, SemanticInit};
use crate::TrainError;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// A named set of defaults.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Preset {
    /// Short schedule, fewer Gaussians (the default of `cargo xtask reconstruct`).
    Quick,
    /// Longer schedule and more Gaussians.
    Full,
}

impl std::str::FromStr for Preset {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "quick" => Ok(Self::Quick),
            "full" => Ok(Self::Full),
            _ => Err(format!("unknown preset `{s}` (expected quick or full)")),
        }
    }
}

/// All hyper-parameters of a reconstruction.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TrainConfig {
    /// Optimisation steps (one training frame each).
    pub steps: usize,
    /// Seed of the initial samples, the networks, the frame order and the density-control splits.
    pub seed: u64,
    /// Semantic parameterisation (`one-hot`, `scalar`, `none`).
    pub semantic: SemanticMode,
    /// Initial points (`smpl+cube`, `random`, `smpl-only`).
    pub init: InitMode,
    /// Initial semantic logits (`one-hot`, `half`).
    pub semantic_init: SemanticInit,
    /// Initial human Gaussians (on and just inside the canonical body surface).
    pub human_gaussians: usize,
    /// Initial scene Gaussians (uniform in the visible part of the scene cube).
    pub scene_gaussians: usize,
    /// Density control never grows the set beyond this many Gaussians.
    pub max_gaussians: usize,
    /// λ_logit, the magnitude of the initial one-hot logits (paper: 3).
    pub logit_magnitude: f32,
    /// Initial opacity of every Gaussian (3DGS-Avatar: 0.1).
    pub initial_opacity: f32,
    /// Upper bound on the initial (kNN) scale of a Gaussian, metres.
    pub max_initial_scale: f32,
    /// Per-Gaussian colour-feature length (paper: 32).
    pub feature_dim: usize,
    /// Per-frame latent length of the human colour network (paper: 16).
    pub latent_dim: usize,
    /// Hidden width of the non-rigid network and of the skinning field.
    pub deform_hidden: usize,
    /// Gaussians with human probability below this skip the human branch (see `train::posing`).
    pub semantic_gate: f32,
    /// Background colour (linear RGB) composited behind the Gaussians.
    pub background: [f32; 3],
    /// Near clipping plane of the rasterizer (m): Gaussians closer to the camera are not drawn.
    pub near_plane: f64,
    /// Weight λ of D-SSIM in (1 − λ)·L1 + λ·(1 − SSIM).
    pub ssim_weight: f32,
    /// Weight of the skinning loss (learned weights vs the body's, on surface samples).
    pub skinning_weight: f32,
    /// The skinning loss is applied before this step only.
    pub skinning_until: usize,
    /// Surface samples per step for the skinning loss.
    pub skinning_samples: usize,
    /// Adam steps fitting the skinning field to the body's weights before training starts (a freshly
    /// initialised field blends all 24 bones almost uniformly, which would pose every human Gaussian
    /// with the mean bone transform until the skinning loss catches up).
    pub skinning_warmup_steps: usize,
    /// Weight of the AIAP loss on human Gaussians' positions.
    pub aiap_position_weight: f32,
    /// Weight of the AIAP loss on human Gaussians' covariances.
    pub aiap_covariance_weight: f32,
    /// Position learning rate at step 0 (× scene extent), metres per step.
    pub lr_means: f32,
    /// Final position rate as a fraction of the initial one.
    pub lr_means_final_fraction: f32,
    /// Log-scale learning rate.
    pub lr_log_scales: f32,
    /// Quaternion learning rate.
    pub lr_quats: f32,
    /// Opacity-logit learning rate.
    pub lr_opacity: f32,
    /// Colour-feature learning rate.
    pub lr_features: f32,
    /// Semantic-logit learning rate.
    pub lr_semantic: f32,
    /// Non-rigid network learning rate.
    pub lr_nonrigid: f32,
    /// Skinning-field learning rate.
    pub lr_skinning: f32,
    /// Learning rate of both colour networks.
    pub lr_colour: f32,
    /// Per-frame latent learning rate.
    pub lr_latent: f32,
    /// The non-rigid network is frozen (its zero-initialised output stays zero) before this step.
    pub nonrigid_from: usize,
    /// First step of density control.
    pub densify_from: usize,
    /// Last step of density control.
    pub densify_until: usize,
    /// Steps between density-control passes.
    pub densify_every: usize,
    /// Mean screen-space (NDC) gradient above which a Gaussian is densified (3DGS: 2e-4).
    pub densify_grad_threshold: f32,
    /// Gaussians with opacity below this are pruned (3DGS-Avatar: 0.05, 3DGS: 0.005).
    pub prune_min_opacity: f32,
    /// Steps between opacity resets (0: never).
    pub opacity_reset_every: usize,
    /// Steps between checkpoints (0: only at the end).
    pub checkpoint_every: usize,
    /// Event-flow supervision (paper §4.4): on steps whose frame k has a next training frame k+1 with
    /// a flow of `flow_source`, frame k+1 is rendered too and the frozen flow network's prediction
    /// between the two renders is pulled towards that flow (see `train::flow_loss`).
    pub flow_loss: bool,
    /// Which flow supervises: a flow of `scene.json` (`ground-truth`, `events`, `file`) or the
    /// network's own flow between the sharp references (`sharp-network`).
    pub flow_source: FlowSource,
    /// λ_flow, the weight of L_flow in the step's loss (default 0.015, chosen by a sweep on the
    /// default benchmark, `quick` preset, with `sharp-network` targets: 0.005 / 0.015 / 0.03 / 0.05
    /// gave +0.12 / +0.20 / +0.03 / −0.30 dB in the human box against no flow loss;
    /// `docs/BENCHMARKS.md`, event supervision). With `ground-truth` or `events` targets every λ
    /// tried lowers PSNR, which is why `flow_loss` is off by default.
    pub flow_weight: f32,
    /// τ: pixels whose target flow is at most this long (pixels at the network's resolution) are not
    /// supervised (default 0.25 px; not swept).
    pub flow_tau: f32,
    /// The renders and the flow are resized by this factor before the network (paper: 0.25).
    pub flow_scale: f32,
    /// Which parameters the flow loss's gradient reaches: `all` (the paper) or `geometry` (only the
    /// posed means and covariances, and through them positions, shapes and the deformation; not
    /// colours, opacities or semantics). `geometry` is a deviation from the paper, for an ablation.
    pub flow_gradient: FlowGradient,
    /// How the renders' flow is compared with the target: `network` (the paper: the frozen flow
    /// network's prediction between the renders) or `warp` (an ideal flow estimator: render k
    /// against render k+1 warped back by the target flow, `train::flow_loss::pair_warp_loss`; an
    /// ablation outside the paper that measures what the flow constraint can give without any
    /// network's error). λ_flow weighs either; their units differ (pixels of flow vs intensity).
    pub flow_measure: FlowMeasure,
    /// SPyNet-style weights (safetensors) of the frozen flow network; `None`: the project's shipped
    /// weights (`data-fixtures/flow/spynet-synthetic.safetensors`, resolved by the driver).
    pub flow_network: Option<std::path::PathBuf>,
    /// The event-generation loss of EventNeRF / E-NeRF (the paper's Table 6 alternative to the flow
    /// loss, see `train::event_loss`), on the same pairs of consecutive training frames, from each
    /// frame's `events` file.
    pub event_loss: bool,
    /// Weight of the event-generation loss: 3, the best of a sweep over 0.3 / 1 / 3 / 10 on the
    /// default benchmark's `quick` preset (human-box PSNR 25.05 / 25.60 / 25.89 / 25.27 dB;
    /// `docs/BENCHMARKS.md`, event supervision).
    pub event_weight: f32,
    /// Contrast threshold C of the camera (log-intensity units; the benchmark's simulator: 0.2).
    pub event_threshold: f32,
    /// ε of log(Y + ε) (the benchmark's simulator: 1e-3).
    pub event_log_eps: f32,
}

/// Which parameters the flow loss's gradient reaches (see [`TrainConfig::flow_gradient`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum FlowGradient {
    /// Every parameter the two renders depend on (the paper).
    #[default]
    All,
    /// Only the rasterizer's mean and covariance inputs: colours, opacities and semantic
    /// probabilities get no share of the flow loss's gradient.
    Geometry,
}

/// How the flow loss compares the renders' motion with the target (see
/// [`TrainConfig::flow_measure`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum FlowMeasure {
    /// The frozen flow network's prediction between the two renders, masked L1 against the target
    /// flow (the paper).
    #[default]
    Network,
    /// Brightness constancy along the target flow: masked L1 between render k and render k+1 warped
    /// back by the target (what a perfect flow estimator would enforce; not in the paper).
    Warp,
}

impl std::str::FromStr for FlowMeasure {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "network" => Ok(Self::Network),
            "warp" => Ok(Self::Warp),
            _ => Err(format!(
                "unknown flow measure `{s}` (expected network or warp)"
            )),
        }
    }
}

/// Source of the flow that supervises the flow loss.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum FlowSource {
    /// The generator's exact flow (`ground_truth` in `scene.json`; the paper's "ideal event flow").
    GroundTruth,
    /// Flow from the events alone by contrast maximisation (`events_cm`).
    Events,
    /// Flow made by another tool (`external`).
    File,
    /// The frozen flow network's own prediction between the *sharp reference* frames k and k+1 at
    /// the loss's resolution (`train::flow_loss::network_target`): the paper's ZJU-MoCap-Blur
    /// protocol, which infers the target from the sharp frames with a pretrained network (RAFT
    /// there). Needs sharp references, so synthetic or reference data only; reads no flow file.
    SharpNetwork,
}

impl FlowSource {
    /// The `scene.json` flow kind this source reads; `None` for [`FlowSource::SharpNetwork`],
    /// which reads the sharp reference frames instead.
    pub fn kind(self) -> Option<scene::FlowKind> {
        match self {
            Self::GroundTruth => Some(scene::FlowKind::GroundTruth),
            Self::Events => Some(scene::FlowKind::EventsCm),
            Self::File => Some(scene::FlowKind::External),
            Self::SharpNetwork => None,
        }
    }
}

impl std::str::FromStr for FlowSource {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "gt" | "ground-truth" => Ok(Self::GroundTruth),
            "events" => Ok(Self::Events),
            "file" => Ok(Self::File),
            "sharp-net" | "sharp-network" => Ok(Self::SharpNetwork),
            _ => Err(format!(
                "unknown flow source `{s}` (expected gt, events, file or sharp-net)"
            )),
        }
    }
}

impl Default for TrainConfig {
    fn default() -> Self {
        Self::preset(Preset::Quick)
    }
}

impl TrainConfig {
    /// The defaults of a preset.
    pub fn preset(preset: Preset) -> Self {
        let quick = Self {
            steps: 1200,
            seed: 0,
            semantic: SemanticMode::OneHot,
            init: InitMode::SmplCube,
            semantic_init: SemanticInit::OneHot,
            human_gaussians: 6_000,
            scene_gaussians: 20_000,
            max_gaussians: 45_000,
            logit_magnitude: 3.0,
            initial_opacity: 0.1,
            max_initial_scale: 0.03,
            feature_dim: 32,
            latent_dim: 16,
            deform_hidden: 64,
            semantic_gate: 0.01,
            background: [0.0; 3],
            near_plane: 0.2,
            ssim_weight: 0.2,
            skinning_weight: 10.0,
            skinning_until: 500,
            skinning_samples: 512,
            skinning_warmup_steps: 400,
            aiap_position_weight: 1.0,
            aiap_covariance_weight: 100.0,
            lr_means: 1.6e-4,
            lr_means_final_fraction: 0.01,
            lr_log_scales: 5e-3,
            lr_quats: 1e-3,
            lr_opacity: 5e-2,
            lr_features: 1e-3,
            lr_semantic: 1e-2,
            lr_nonrigid: 1e-3,
            lr_skinning: 1e-3,
            lr_colour: 1e-3,
            lr_latent: 1e-3,
            nonrigid_from: 300,
            densify_from: 200,
            densify_until: 900,
            densify_every: 100,
            densify_grad_threshold: 2e-4,
            prune_min_opacity: 0.005,
            opacity_reset_every: 0,
            checkpoint_every: 500,
            flow_loss: false,
            flow_source: FlowSource::Events,
            flow_weight: 0.015,
            flow_tau: 0.25,
            flow_scale: 0.25,
            flow_gradient: FlowGradient::All,
            flow_measure: FlowMeasure::Network,
            flow_network: None,
            event_loss: false,
            event_weight: 3.0,
            event_threshold: 0.2,
            event_log_eps: 1e-3,
        };
        match preset {
            Preset::Quick => quick,
            Preset::Full => Self {
                steps: 6000,
                human_gaussians: 10_000,
                scene_gaussians: 40_000,
                max_gaussians: 150_000,
                deform_hidden: 128,
                skinning_until: 1500,
                nonrigid_from: 1000,
                densify_from: 500,
                densify_until: 4000,
                opacity_reset_every: 3000,
                checkpoint_every: 1000,
                ..quick
            },
        }
    }

    /// Reads a TOML (`.toml`) or JSON (anything else) file; fields it omits keep `base`'s values.
    pub fn load_over(path: &Path, base: &Self) -> Result<Self, TrainError> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| TrainError::Config(format!("config {}: {e}", path.display())))?;
        // Merge: serialise the base, overlay the file's keys, deserialise the result (unknown keys
        // are rejected by `deny_unknown_fields`).
        let mut merged =
            serde_json::to_value(base).map_err(|e| TrainError::Config(format!("config: {e}")))?;
        let overlay: serde_json::Value = if path.extension().is_some_and(|e| e == "toml") {
            let v: toml::Value = toml::from_str(&text)
                .map_err(|e| TrainError::Config(format!("config {}: {e}", path.display())))?;
            serde_json::to_value(v).map_err(|e| TrainError::Config(format!("config: {e}")))?
        } else {
            serde_json::from_str(&text)
                .map_err(|e| TrainError::Config(format!("config {}: {e}", path.display())))?
        };
        let (Some(m), serde_json::Value::Object(o)) = (merged.as_object_mut(), overlay) else {
            return Err(TrainError::Config(format!(
                "config {}: the top level must be a table of settings",
                path.display()
            )));
        };
        for (k, v) in o {
            m.insert(k, v);
        }
        let config: Self = serde_json::from_value(merged)
            .map_err(|e| TrainError::Config(format!("config {}: {e}", path.display())))?;
        config.validate()?;
        Ok(config)
    }

    /// Rejects settings that cannot be trained with, naming the field.
    pub fn validate(&self) -> Result<(), TrainError> {
        let bad =
            |field: &str, why: &str| Err(TrainError::Config(format!("config `{field}`: {why}")));
        if self.steps == 0 {
            return bad("steps", "must be at least 1");
        }
        if self.human_gaussians + self.scene_gaussians == 0 {
            return bad("human_gaussians", "no Gaussians to initialise");
        }
        if self.max_gaussians >= 1 << 24 {
            return bad("max_gaussians", "must be below 2^24 (16,777,216)");
        }
        if self.max_gaussians < self.human_gaussians + self.scene_gaussians {
            return bad("max_gaussians", "smaller than the initial count");
        }
        if self.feature_dim == 0 || self.deform_hidden == 0 {
            return bad("feature_dim", "network sizes must be positive");
        }
        if !(0.0..1.0).contains(&self.semantic_gate) {
            return bad("semantic_gate", "must be in [0, 1)");
        }
        if !(0.0..=1.0).contains(&self.ssim_weight) {
            return bad("ssim_weight", "must be in [0, 1]");
        }
        if !(self.flow_weight >= 0.0 && self.flow_weight.is_finite()) {
            return bad("flow_weight", "must be a finite number ≥ 0");
        }
        if !(self.flow_tau >= 0.0 && self.flow_tau.is_finite()) {
            return bad("flow_tau", "must be a finite number ≥ 0");
        }
        if !(self.flow_scale > 0.0 && self.flow_scale <= 1.0) {
            return bad("flow_scale", "must be in (0, 1]");
        }
        if !(self.event_weight >= 0.0 && self.event_weight.is_finite()) {
            return bad("event_weight", "must be a finite number ≥ 0");
        }
        if !(self.event_threshold > 0.0 && self.event_threshold.is_finite()) {
            return bad("event_threshold", "must be a finite number > 0");
        }
        if !(self.event_log_eps > 0.0 && self.event_log_eps.is_finite()) {
            return bad("event_log_eps", "must be a finite number > 0");
        }
        if !(self.max_initial_scale > 0.0) {
            return bad("max_initial_scale", "must be positive");
        }
        if !(self.initial_opacity > 0.0 && self.initial_opacity < 1.0) {
            return bad("initial_opacity", "must be in (0, 1)");
        }
        let rates = [
            ("lr_means", self.lr_means),
            ("lr_log_scales", self.lr_log_scales),
            ("lr_quats", self.lr_quats),
            ("lr_opacity", self.lr_opacity),
            ("lr_features", self.lr_features),
            ("lr_semantic", self.lr_semantic),
            ("lr_nonrigid", self.lr_nonrigid),
            ("lr_skinning", self.lr_skinning),
            ("lr_colour", self.lr_colour),
            ("lr_latent", self.lr_latent),
            ("skinning_weight", self.skinning_weight),
            ("aiap_position_weight", self.aiap_position_weight),
            ("aiap_covariance_weight", self.aiap_covariance_weight),
        ];
        for (name, v) in rates {
            if !(v.is_finite() && v >= 0.0) {
                return bad(name, "must be a finite non-negative number");
            }
        }
        if !(self.near_plane > 0.0 && self.near_plane.is_finite()) {
            return bad("near_plane", "must be a finite number > 0 (metres)");
        }
        if self.background.iter().any(|v| !v.is_finite()) {
            return bad("background", "must be finite");
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_file_overrides_only_its_keys_and_unknown_keys_are_rejected() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("c.toml");
        std::fs::write(
            &p,
            "steps = 7\nsemantic = \"scalar\"\ninit = \"smpl+cube\"\n",
        )
        .unwrap();
        let base = TrainConfig::preset(Preset::Full);
        let c = TrainConfig::load_over(&p, &base).unwrap();
        assert_eq!(c.steps, 7);
        assert_eq!(c.semantic, SemanticMode::Scalar);
        assert_eq!(c.scene_gaussians, base.scene_gaussians);
        std::fs::write(&p, "stpes = 7\n").unwrap();
        let e = TrainConfig::load_over(&p, &base).unwrap_err().to_string();
        assert!(e.contains("stpes"), "{e}");
        let j = dir.path().join("c.json");
        std::fs::write(&j, "{\"ssim_weight\": 2.0}").unwrap();
        let e = TrainConfig::load_over(&j, &base).unwrap_err().to_string();
        assert!(e.contains("ssim_weight"), "{e}");
    }

    #[test]
    fn presets_are_valid_and_round_trip_through_json() {
        for p in [Preset::Quick, Preset::Full] {
            let c = TrainConfig::preset(p);
            c.validate().unwrap();
            let back: TrainConfig =
                serde_json::from_str(&serde_json::to_string(&c).unwrap()).unwrap();
            assert_eq!(back, c);
        }
    }
}
