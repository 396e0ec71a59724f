//! The named choices among the training options (which images, which blur model, which penalty,
//! …) and the command-line parsers of `on|off` and colour values.

use serde::{Deserialize, Serialize};

/// Which images are trained on (see [`TrainConfig::train_on`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum TrainOn {
    /// The observed (blurred) frames.
    #[default]
    Blurred,
    /// The sharp references (benchmarks only).
    Sharp,
    /// Every training frame deblurred on its own by EDI from its events (the 2-D cascade
    /// baseline, "deblur first, then reconstruct"; use with `blur_model = none`).
    Edi,
}

/// How a training frame's prediction is formed (see [`TrainConfig::blur_model`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum BlurModel {
    /// One render at the frame's mid-exposure pose (the paper).
    None,
    /// The mean of renders at sub-exposure poses: the physical model of motion blur.
    #[default]
    Exposure,
}

/// Which sub-exposure renders the event loss pairs (see [`TrainConfig::exposure_pairs`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum ExposurePairs {
    /// Consecutive renders.
    #[default]
    Consecutive,
    /// Every pair of renders.
    All,
    /// Consecutive renders, and every longer pair on the pixels silent across it.
    SilentSpans,
}

impl ExposurePairs {
    /// The event term's pairing of renders this choice names.
    pub fn render_pairs(self) -> crate::loss::photometric::RenderPairs {
        use crate::loss::photometric::RenderPairs;
        match self {
            Self::Consecutive => RenderPairs::Consecutive,
            Self::All => RenderPairs::All,
            Self::SilentSpans => RenderPairs::SilentSpans,
        }
    }
}

/// Network evaluations per exposure (see [`TrainConfig::exposure_networks`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum ExposureNetworks {
    /// Once per frame, at mid exposure; sub-exposure renders re-pose by LBS.
    #[default]
    Once,
    /// At every sub-exposure pose.
    PerSubframe,
}

/// Whose skinning weights turn a human Gaussian's view direction into the canonical frame for the
/// human colour network, d = Rᵀ (x_def − c) with R = Σ_b w_b R_b (see
/// [`TrainConfig::view_rotation`]). Both are differentiated exactly.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum ViewRotation {
    /// The skinning field at the canonical mean x: a second pass of the field beside the
    /// deformation's own (the project's choice until 2026-12-06).
    Canonical,
    /// The deformation's own weights, at the non-rigidly moved mean x + Δx: the rotation that
    /// posed the Gaussian, 3DGS-Avatar's `fwd_transform`; no second pass of the field.
    #[default]
    Moved,
}

/// What sets the clip's common camera offset under camera correction (see
/// [`TrainConfig::camera_gauge`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum CameraGauge {
    /// Every frame's correction learns from every Gaussian, its clip mean included.
    #[default]
    Free,
    /// The frames' corrections have no common part; one clip-wide twist learns from the person's
    /// Gaussians alone.
    Person,
}

/// The coordinates in which Adam steps the camera corrections' mid-exposure twists
/// ([`TrainConfig::camera_correction_basis`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum CameraCorrectionBasis {
    /// The twist's own values (radians, metres), at `lr_camera_rotation` / `lr_camera_translation`.
    #[default]
    Twist,
    /// Coordinates in which a unit step moves the scene's image by one pixel RMS in every
    /// direction (`train::pose::camera_basis`), at `lr_camera_pixels`.
    Image,
}

/// How a track's tangents at its keys (the frames) are estimated, for the cubic Hermite path
/// between them (a moving camera's: [`TrainConfig::camera_interpolation`]; the body's:
/// [`TrainConfig::body_interpolation`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum TrackTangents {
    /// A band-limited differentiator over the eight frames on each side (the ideal one of a
    /// signal below half the frame rate, windowed): follows a hand's 8–12 Hz tremor at 30 fps.
    #[default]
    BandLimited,
    /// Fourth-order central differences (second-order at the ends): the body's default rule.
    Local,
}

/// Where the body's motion inside each exposure comes from, with `blur_model = exposure` (see
/// [`TrainConfig::exposure_motion`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum ExposureMotion {
    /// The sub-exposure poses interpolated between the given frames' poses, as they are.
    #[default]
    Given,
    /// The interpolated poses plus a learned per-frame change over the exposure
    /// (`train::pose::correction`'s change part), the given pose kept at mid exposure.
    Learned,
}

/// Which screen-space gradient feeds densification (see [`TrainConfig::density_gradient`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum DensityGradient {
    /// ‖Σ_s g_s‖: the norm of the passes' summed gradient.
    #[default]
    Summed,
    /// Σ_s ‖g_s‖: the passes' norms summed.
    PerPass,
}

/// How the event loss holds a change to its events (see [`TrainConfig::event_penalty`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum EventPenaltyKind {
    /// (ΔL − C·E)²: ideal events.
    Squared,
    /// Counts as lower bounds, silence as a dead zone (a sensor with a refractory period).
    #[default]
    Bound,
}

/// Which renders the event-generation loss compares (see [`TrainConfig::event_pairs`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum EventPairs {
    /// Renders of consecutive training frames.
    Frames,
    /// Consecutive sub-exposure renders of one frame.
    #[default]
    Exposure,
}

/// Which parameters the flow loss's gradient reaches (see [`TrainConfig::flow_gradient`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
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
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
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

/// Source of the flow that supervises the flow loss.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum FlowSource {
    /// The generator's exact flow (`ground_truth` in `scene.json`; the paper's "ideal event flow").
    #[value(alias = "gt")]
    GroundTruth,
    /// Flow from the events alone by contrast maximisation (`events_cm`).
    Events,
    /// Flow made by another tool (`external`).
    File,
    /// The frozen flow network's own prediction between the *sharp reference* frames k and k+1 at
    /// the loss's resolution (`train::loss::optical_flow::network_target`): the paper's ZJU-MoCap-Blur
    /// protocol, which infers the target from the sharp frames with a pretrained network (RAFT
    /// there). Needs sharp references, so synthetic or reference data only; reads no flow file.
    #[value(alias = "sharp-net")]
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

/// Parses `on` / `off` (the command line's spelling of a switch).
pub fn parse_on_off(s: &str) -> Result<bool, String> {
    match s {
        "on" => Ok(true),
        "off" => Ok(false),
        _ => Err(format!("`{s}`: expected on or off")),
    }
}

/// Parses a linear RGB colour written `r,g,b`.
pub fn parse_rgb(s: &str) -> Result<[f32; 3], String> {
    let values: Vec<f32> = s
        .split(',')
        .map(|v| v.trim().parse::<f32>())
        .collect::<Result<_, _>>()
        .map_err(|e| format!("`{s}`: {e} (expected r,g,b)"))?;
    <[f32; 3]>::try_from(values).map_err(|_| format!("`{s}`: expected three values r,g,b"))
}
