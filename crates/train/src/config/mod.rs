//! Every hyper-parameter of a reconstruction, with its documented default, as one serde structure
//! (TOML or JSON on disk). Two presets: [`Preset::Quick`] (the default: a useful result in minutes on
//! two cores) and [`Preset::Full`] (the longer schedule the benchmark numbers are also reported for).
//!
//! Learning rates follow 3DGS / 3DGS-Avatar (positions 1.6e-4 × scene extent decayed log-linearly to
//! 1 %, scales 5e-3, rotations 1e-3, opacity 5e-2, networks 1e-3); the loss weights follow 3DGS-Avatar
//! (skinning 10 for the first part of training, AIAP on positions 1 and on covariances 100, D-SSIM 0.2
//! as in 3DGS). 3DGS-Avatar's perceptual term, LPIPS, is available (`lpips_weight`) but off by
//! default until its effect on the benchmark is measured.

mod choices;
mod events;
mod files;
mod stored;
mod validate;

pub use choices::*;

use crate::blend::SemanticMode;
use crate::init::{InitMode, SceneInit, SemanticInit};
use crate::TrainError;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// A named set of defaults.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum Preset {
    /// Short schedule, fewer Gaussians (the default of `cargo xtask reconstruct`).
    Quick,
    /// Longer schedule and more Gaussians.
    Full,
}

impl Preset {
    /// The preset's name as typed on the command line (and in default run directories).
    pub fn name(self) -> &'static str {
        match self {
            Preset::Quick => "quick",
            Preset::Full => "full",
        }
    }
}

/// Declares every training option once — its documentation (which is also its `--help` text), its
/// type, its `quick`-preset default and any clap attribute — and generates from that one list
/// [`TrainConfig`] (the complete, serde-(de)serialisable configuration), [`TrainOptions`] (one
/// optional `--kebab-case` flag per field, flattened into `cargo xtask reconstruct` and used by
/// `ablate` to describe its runs) and [`TrainConfig::apply`]. Adding a training option means adding
/// one entry here.
macro_rules! training_options {
    ($(
        $(#[doc = $doc:literal])*
        $(#[arg($($arg:tt)*)])?
        $name:ident: $ty:ty = $default:expr,
    )*) => {
        /// All hyper-parameters of a reconstruction.
        #[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
        #[serde(default, deny_unknown_fields)]
        pub struct TrainConfig {
            $($(#[doc = $doc])* pub $name: $ty,)*
        }

        /// Overrides of a [`TrainConfig`]: every field optional, `None` keeping the preset's (or the
        /// config file's) value. As command-line flags, each is `--field-name` with the field's
        /// documentation as its help.
        #[derive(Clone, Debug, Default, PartialEq, clap::Args, Serialize, Deserialize)]
        #[serde(default, deny_unknown_fields)]
        pub struct TrainOptions {
            $(
                $(#[doc = $doc])*
                #[arg(long $(, $($arg)*)?)]
                #[serde(skip_serializing_if = "Option::is_none")]
                pub $name: Option<$ty>,
            )*
        }

        impl TrainOptions {
            /// These options with every field that `later` sets taken from `later`.
            pub fn overridden_by(&self, later: &TrainOptions) -> TrainOptions {
                TrainOptions {
                    $($name: later.$name.clone().or_else(|| self.$name.clone()),)*
                }
            }
        }

        impl TrainConfig {
    /// Whether the model carries pose-correction rows (`train::pose::correction`): for the
    /// fitter's `pose_correction`, or for the change part alone with `exposure_motion = learned`.
    pub fn carries_pose_rows(&self) -> bool {
        self.pose_correction || self.exposure_motion == ExposureMotion::Learned
    }

            /// The `quick` preset: every option's declared default.
            fn quick() -> Self {
                Self { $($name: $default,)* }
            }

            /// Overwrites every field that `options` sets.
            pub fn apply(&mut self, options: &TrainOptions) {
                $(if let Some(v) = &options.$name {
                    self.$name = v.clone();
                })*
            }
        }
    };
}

training_options! {
    /// Optimisation steps (one training frame each).
    steps: usize = 1200,
    /// Seed of the initial samples, the networks, the frame order and the density-control splits.
    seed: u64 = 0,
    /// Semantic parameterisation (`one-hot`, `scalar`, `none`).
    semantic: SemanticMode = SemanticMode::OneHot,
    /// Initial points (`smpl+cube`, `random`, `smpl-only`).
    init: InitMode = InitMode::SmplCube,
    /// Initial semantic logits (`one-hot`, `half`).
    semantic_init: SemanticInit = SemanticInit::OneHot,
    /// Initial human Gaussians (on and just inside the canonical body surface).
    human_gaussians: usize = 6_000,
    /// Initial scene Gaussians (uniform in the visible part of the scene cube).
    scene_gaussians: usize = 20_000,
    /// Where the initial scene Gaussians start (`volume`: uniform in the scene cube; `stereo`: half
    /// on the surfaces a plane sweep over the training frames finds, which needs a moving camera).
    /// `cargo xtask reconstruct` chooses `stereo` when the scene's camera moves.
    scene_init: SceneInit = SceneInit::Volume,
    /// Density control never grows the set beyond this many Gaussians.
    max_gaussians: usize = 45_000,
    /// λ_logit, the magnitude of the initial one-hot logits (paper: 3).
    logit_magnitude: f32 = 3.0,
    /// Initial opacity of every Gaussian (3DGS-Avatar: 0.1).
    initial_opacity: f32 = 0.1,
    /// Upper bound on the initial (kNN) scale of a Gaussian, metres.
    max_initial_scale: f32 = 0.03,
    /// Per-Gaussian colour-feature length (paper: 32).
    feature_dim: usize = 32,
    /// Per-frame latent length of the human colour network (paper: 16).
    latent_dim: usize = 16,
    /// Hidden width of the non-rigid network and of the skinning field.
    deform_hidden: usize = 64,
    /// Gaussians with human probability below this skip the human branch (see `train::pose::posing`).
    semantic_gate: f32 = 0.01,
    /// Background colour (linear RGB) composited behind the Gaussians.
    #[arg(value_parser = parse_rgb, value_name = "R,G,B")]
    background: [f32; 3] = [0.0; 3],
    /// Near clipping plane of the rasterizer (m): Gaussians closer to the camera are not drawn.
    near_plane: f64 = rasterize_cpu::DEFAULT_NEAR_PLANE,
    /// Weight λ of D-SSIM in (1 − λ)·L1 + λ·(1 − SSIM).
    ssim_weight: f32 = 0.2,
    /// λ's decay over the event weight's window: log-linear to this fraction of `ssim_weight` at
    /// the last step (1, the default: constant). 0.1 at `full`: +0.05 dB, not kept
    /// (`docs/notes/2026-12-05-full-gap-and-new-default-reruns.md`).
    ssim_weight_final_fraction: f32 = 1.0,
    /// Weight μ of the image-gradient term added to the photometric loss: the L1 distance between
    /// the finite differences (right and down neighbours) of the frame's prediction and of the
    /// observed frame (`train::loss::image_gradient`). The blur averages the sharp image's fine
    /// structure along the motion, so the photometric residual in it is small; this term weighs
    /// the residual by its differences. 0 = off (the default): 0.5 gives +0.07 dB in the human
    /// box at `quick` and −0.21 at `full` (`docs/notes/2026-12-07-image-gradient-term.md`).
    image_gradient_weight: f32 = 0.0,
    /// Weight of the perceptual loss: LPIPS (AlexNet, v0.1, on sRGB-encoded images) of the frame's
    /// prediction (the mean of its sub-exposure renders) against the observed frame
    /// (`train::loss::perceptual`; 3DGS-Avatar's third term). 0 = off (no LPIPS work at all).
    lpips_weight: f32 = 0.0,
    /// Weight of the skinning loss (learned weights vs the body's, on surface samples).
    skinning_weight: f32 = 10.0,
    /// The skinning loss is applied before this step only.
    skinning_until: usize = 500,
    /// Surface samples per step for the skinning loss.
    skinning_samples: usize = 512,
    /// Adam steps fitting the skinning field to the body's weights before training starts (a freshly
    /// initialised field blends all 24 bones almost uniformly, which would pose every human Gaussian
    /// with the mean bone transform until the skinning loss catches up).
    skinning_warmup_steps: usize = 400,
    /// Weight of the AIAP loss on human Gaussians' positions.
    aiap_position_weight: f32 = 1.0,
    /// Weight of the AIAP loss on human Gaussians' covariances.
    aiap_covariance_weight: f32 = 100.0,
    /// Weight of the prior on the human Gaussians' size (mean sum of axis scales, cm). 0 = off.
    size_prior_weight: f32 = 0.0,
    /// Weight of the prior on the human Gaussians' opacity: mean binary entropy (nats). 0 = off.
    opacity_entropy_weight: f32 = 0.0,
    /// Position learning rate at step 0 (× scene extent), metres per step: 4.8e-4, three times
    /// 3DGS's 1.6e-4 (both presets since 2026-12-05; `full` had 1.6e-4): at `quick`, +0.04 /
    /// +0.28 / +0.31 dB in the human box on seeds 0 / 1 / 2 of the default benchmark, +0.26 on
    /// `handheld` (`docs/notes/2026-12-05-learned-motion-default.md`).
    lr_means: f32 = 4.8e-4,
    /// Final position rate as a fraction of the initial one.
    lr_means_final_fraction: f32 = 0.01,
    /// Log-scale learning rate.
    lr_log_scales: f32 = 5e-3,
    /// Quaternion learning rate.
    lr_quats: f32 = 1e-3,
    /// Opacity-logit learning rate.
    lr_opacity: f32 = 5e-2,
    /// Colour-feature learning rate.
    lr_features: f32 = 1e-3,
    /// Semantic-logit learning rate.
    lr_semantic: f32 = 1e-2,
    /// Non-rigid network learning rate.
    lr_nonrigid: f32 = 1e-3,
    /// Skinning-field learning rate.
    lr_skinning: f32 = 1e-3,
    /// Learning rate of both colour networks.
    lr_colour: f32 = 1e-3,
    /// Per-frame latent learning rate.
    lr_latent: f32 = 1e-3,
    /// The non-rigid network is frozen (its zero-initialised output stays zero) before this step.
    nonrigid_from: usize = 300,
    /// First step of density control.
    densify_from: usize = 200,
    /// Last step of density control.
    densify_until: usize = 900,
    /// Steps between density-control passes.
    densify_every: usize = 100,
    /// Mean screen-space (NDC) gradient above which a Gaussian is densified (3DGS: 2e-4).
    densify_grad_threshold: f32 = 2e-4,
    /// The screen-space gradient a step adds to a Gaussian's densification statistic with
    /// `blur_model = exposure`: `summed` (the norm of the sum of the sub-exposure passes' gradients:
    /// a moving Gaussian's partly cancel) or `per-pass` (the sum of each pass's norm, as if every
    /// pass were a view of its own, scaled like one render).
    density_gradient: DensityGradient = DensityGradient::Summed,
    /// Gaussians with opacity below this are pruned (3DGS-Avatar: 0.05, 3DGS: 0.005).
    prune_min_opacity: f32 = 0.005,
    /// Steps between opacity resets (0: never). `full` resets at step 3000, which its default
    /// needs: without it 38.73 / 34.09 dB (full frame / human box, −0.51 in the box); a reset at
    /// `quick`'s step 600 costs its default 0.22 dB and its sharp-trained ceiling 0.51
    /// (`docs/notes/2026-12-07-opacity-reset-and-decay-start.md`).
    opacity_reset_every: usize = 0,
    /// Steps between checkpoints (0: only at the end).
    checkpoint_every: usize = 500,
    /// Which images are trained on: `blurred` (the observed frames), `sharp` (the sharp references
    /// of a synthetic benchmark: the ceiling a model of the blur can chase; not for real data) or
    /// `edi` (each frame deblurred on its own by the event double integral from its events, the
    /// 2-D cascade baseline; with `--blur-model none --event-loss off`).
    train_on: TrainOn = TrainOn::Blurred,
    /// Steps, from step 0, that train on the EDI-deblurred frames (each frame deblurred on its own
    /// by the event double integral, as `train_on = edi`) with one render at mid exposure and no
    /// event term, before the blur model, the event terms and the observed frames take over: a
    /// start near the sharp solution, which the exposure model's loss prefers but its gradients
    /// reach slowly. 0: off. Frames whose events do not cover their exposure keep their observed
    /// image.
    edi_warmup: usize = 0,
    /// How a training frame's prediction is formed: `exposure` (the default: the mean, in linear
    /// intensity, of `subframes` renders at poses spread over the frame's exposure;
    /// `train::pose::exposure`) or `none` (one render at mid exposure, the paper). On the default benchmark's
    /// `quick` preset the exposure model scores 33.24 / 28.75 dB (full frame / human box) against
    /// 29.23 / 24.65 without it and 29.32 / 24.68 for the blurred input (`docs/BENCHMARKS.md`).
    blur_model: BlurModel = BlurModel::Exposure,
    /// Renders per exposure with `blur_model = exposure` (midpoint rule over the exposure). `quick`
    /// takes 9: with the events' cap and mixed pixels unconstrained, 35.81 / 31.47 dB (full frame /
    /// human box) against 34.79 / 30.38 with 5, in 8 min 28 s of wall time against 5 min 12 s
    /// (AMD Zen 5, 2 cores; `docs/BENCHMARKS.md`). `full` takes 9 too since 2026-12-05 (with 5 and
    /// twice the network width it scored 37.18 / 32.54 dB in 92 min; 9 gave 38.25 / 33.62).
    subframes: usize = 9,
    /// With `blur_model = exposure`, one camera per exposure and no camera correction: each
    /// sub-exposure render stands for its time slice, every Gaussian smeared by its motion over
    /// it (`train::pose::smear`), S streaks instead of S copies. `off`: point-in-time renders.
    #[arg(value_parser = parse_on_off, value_name = "on|off")]
    exposure_smear: bool = false,
    /// Network evaluations per exposure with `blur_model = exposure`: `once` (the non-rigid offsets,
    /// skinning weights and both colours are evaluated at the mid-exposure pose and each
    /// sub-exposure render re-poses them by linear blend skinning alone, `train::pose::reposing`) or
    /// `per-subframe` (every sub-exposure render evaluates the networks at its own pose).
    exposure_networks: ExposureNetworks = ExposureNetworks::Once,
    /// Whose skinning weights canonicalise the human colour network's view directions: `moved`
    /// (the deformation's own, at x + Δx, as 3DGS-Avatar's `fwd_transform`; no second pass of
    /// the skinning field) or `canonical` (a second pass at the canonical mean; the default until
    /// 2026-12-06, and what a stored model that does not name the option was trained with).
    /// `moved` scores 36.67 / 32.34 dB (full frame / human box) against 36.63 / 32.30, with a
    /// step 8 % shorter (AMD Zen 3; docs/notes/2026-12-06-view-rotation-and-step.md).
    view_rotation: ViewRotation = ViewRotation::Moved,
    /// With `blur_model = exposure`: the tiles that only static Gaussians (human probability
    /// below `semantic_gate`, the same in every sub-exposure render) reach are blended once per
    /// frame and replayed once in the backward with the renders' summed cotangent
    /// (`rasterize_cpu::render_cov_shared`). The renders are the same bits; the gradients differ
    /// by the rounding of summing cotangents before the backward instead of gradients after it.
    /// `off`: every render blends every tile (the bits of runs before 2026-11-27's twenty-seventh
    /// session). Not used with `density_gradient = per-pass` or the flow loss's `geometry`
    /// gradient, which need each render's own gradients.
    #[arg(value_parser = parse_on_off, value_name = "on|off")]
    share_static_tiles: bool = true,
    /// With `share_static_tiles` and the passes differentiated only together: in the tiles a
    /// moving Gaussian reaches, the static Gaussians behind every moving one are blended once per
    /// frame, as a layer each render composites behind its own list, and replayed once in the
    /// backward (`rasterize_cpu::SharedOutputs::Layered`). The renders differ from blending each
    /// alone only where a pixel's transmittance would fall below 1e-4 inside that layer; `off`:
    /// the bits of runs before 2026-12-05's layer.
    #[arg(value_parser = parse_on_off, value_name = "on|off")]
    static_layer: bool = true,
    /// Event-flow supervision (paper §4.4): on steps whose frame k has a next training frame k+1 with
    /// a flow of `flow_source`, frame k+1 is rendered too and the frozen flow network's prediction
    /// between the two renders is pulled towards that flow (see `train::loss::optical_flow`).
    #[arg(value_parser = parse_on_off, value_name = "on|off")]
    flow_loss: bool = false,
    /// Which flow supervises: a flow of `scene.json` (`ground-truth`, `events`, `file`) or the
    /// network's own flow between the sharp references (`sharp-network`).
    flow_source: FlowSource = FlowSource::Events,
    /// λ_flow, the weight of L_flow in the step's loss (default 0.015, chosen by a sweep on the
    /// default benchmark, `quick` preset, with `sharp-network` targets: 0.005 / 0.015 / 0.03 / 0.05
    /// gave +0.12 / +0.20 / +0.03 / −0.30 dB in the human box against no flow loss;
    /// `docs/notes/benchmarks-history.md`, "Flow targets from the network on the sharp frames"). With `ground-truth` or `events` targets every λ
    /// tried lowers PSNR, which is why `loss::optical_flow` is off by default.
    flow_weight: f32 = 0.015,
    /// τ: pixels whose target flow is at most this long (pixels at the network's resolution) are not
    /// supervised (default 0.25 px; not swept).
    flow_tau: f32 = 0.25,
    /// The renders and the flow are resized by this factor before the network (paper: 0.25).
    flow_scale: f32 = 0.25,
    /// Which parameters the flow loss's gradient reaches: `all` (the paper) or `geometry` (only the
    /// posed means and covariances, and through them positions, shapes and the deformation; not
    /// colours, opacities or semantics). `geometry` is a deviation from the paper, for an ablation.
    flow_gradient: FlowGradient = FlowGradient::All,
    /// How the renders' flow is compared with the target: `network` (the paper: the frozen flow
    /// network's prediction between the renders) or `warp` (an ideal flow estimator: render k
    /// against render k+1 warped back by the target flow, `train::loss::optical_flow::pair_warp_loss`; an
    /// ablation outside the paper that measures what the flow constraint can give without any
    /// network's error). λ_flow weighs either; their units differ (pixels of flow vs intensity).
    flow_measure: FlowMeasure = FlowMeasure::Network,
    /// SPyNet-style weights (safetensors) of the frozen flow network; unset: the project's shipped
    /// weights (`data-fixtures/flow/spynet-synthetic.safetensors`, resolved by the driver).
    flow_network: Option<std::path::PathBuf> = None,
    /// The event-generation loss of EventNeRF / E-NeRF (see `train::loss::event`) on the pairs of
    /// renders `event_pairs` names, from each frame's `events` file. Off in a bare configuration;
    /// `cargo xtask reconstruct` turns it on (between sub-exposure renders) when the blur model is
    /// `exposure` and the scene has events, unless `--event-loss` or the config file sets it.
    #[arg(value_parser = parse_on_off, value_name = "on|off")]
    event_loss: bool = false,
    /// Which renders the event-generation loss compares: `exposure` (consecutive sub-exposure
    /// renders of each frame against the events between their times; needs `blur_model =
    /// exposure`) or `frames` (the renders of consecutive training frames against the events of
    /// [t_k, t_{k+1}), EventNeRF's pairing and the paper's Table 6 comparison).
    event_pairs: EventPairs = EventPairs::Exposure,
    /// With `event_pairs = exposure`: which pairs of sub-exposure renders (s, s′), s < s′, the
    /// event loss compares against the events of [t_s, t_s′): `consecutive` (s′ = s + 1, S − 1
    /// pairs), `all` (every pair, S(S − 1)/2; a longer interval's counts sum its consecutive ones)
    /// or `silent-spans` (consecutive, and every longer pair on the pixels silent across it).
    exposure_pairs: ExposurePairs = ExposurePairs::Consecutive,
    /// Weight of the event-generation loss: 2. With the cap, mixed pixels free and 9 renders, 2
    /// gives 35.99 / 31.66 dB (full frame / human box) against 35.81 / 31.47 with 1 (`quick`,
    /// 2026-11-29). Before the cap, with the `bound` penalty, 1 was the best of 0.3 / 1 / 3
    /// (human box 29.64 / 29.74 / 29.43 dB). With the `squared` penalty
    /// (the previous default) 0.3 was the best of 0.3 / 1 / 3 (28.89 / 28.58 / 27.88 dB): pulled to
    /// the under-counted changes of a refractory sensor, more weight blurred more. With `frames`
    /// pairs and the squared penalty the best of 0.3 / 1 / 3 / 10 was 3 (human box 25.05 / 25.60 /
    /// 25.89 / 25.27 dB; `docs/notes/benchmarks-history.md`, "Event-generation loss, `quick`
    /// preset").
    event_weight: f32 = 2.0,
    /// The event weight's decay: from `event_weight_decay_from` to the last step it falls
    /// log-linearly to this fraction of `event_weight` (1: a constant weight). Early
    /// on the events lead the renders towards sharpness and drive the person's densification;
    /// their optimum at the end is blurrier than the photometric term's (the loss audit of
    /// `docs/notes/2026-12-02-event-weight-decay.md`). Both presets take 0.1 from the end of
    /// their densification (`quick` step 900, `full` step 4000): +0.57 dB in the human box at
    /// `full` (34.03 → 34.60), +0.18 / +0.48 / +0.29 dB on seeds 0 / 1 / 2 at `quick` (LPIPS
    /// 3–5 % higher; 1 before; `docs/notes/2026-12-05-burst-reading-and-full-audit.md`).
    event_weight_final_fraction: f32 = 0.1,
    /// The step where the event weight starts to decay (see `event_weight_final_fraction`). At
    /// `full` from step 2000 instead of 4000: 38.53 / 33.89 dB (−0.71 in the human box;
    /// `docs/notes/2026-12-07-opacity-reset-and-decay-start.md`).
    event_weight_decay_from: usize = 900,
    /// Contrast threshold C of the camera (log-intensity units): 0.2, the benchmark simulator's;
    /// `cargo xtask reconstruct` takes the one the scene's generator recorded
    /// (`generator.config.event_threshold` in scene.json) unless this option or the config file
    /// sets it.
    event_threshold: f32 = 0.2,
    /// Negative contrast threshold C− (log-intensity units, a positive number) when it differs from
    /// C+ (`event_threshold`); unset: C− = C+. `cargo xtask reconstruct` takes the generator's
    /// (`generator.config.event_threshold_neg`) when the scene records one.
    event_threshold_neg: Option<f32> = None,
    /// The log-intensity change one event stands for, in the sensor's thresholds (C±): every use
    /// of the events (the event loss's counts, margin, dead zone and cap, and the events'
    /// modulation; not the EDI cascade's frames, a baseline at the sensor's thresholds) reads an
    /// event as this many times C± (`TrainConfig::event_thresholds`). 1 in a bare configuration.
    /// A sensor with a refractory period drops the crossings that come too soon after a pixel's
    /// last event while its reference level moves on (on the benchmark's 1 ms sensor a moving
    /// edge's count recovers 22–54 % of its change), so `cargo xtask reconstruct` reads each event
    /// as 1.25 thresholds unless the scene's generator recorded a sensor without a refractory
    /// period, the camera moves (its events are mostly the room's slower edges, where 1.25 cost
    /// the room 0.5 dB on `handheld`) or this option is given. Default benchmark, `quick`, seeds
    /// 0–3: 1.25 gives the human box a mean of 31.99 dB and LPIPS 0.0283 against 31.89 and 0.0337
    /// with 1 (the box's LPIPS lower on every seed; 1.125, 1.375 and 1.5 lose on seed 0;
    /// `docs/notes/2026-12-05-event-threshold-scale.md`).
    event_threshold_scale: f32 = 1.0,
    /// ε of log(Y + ε) (the benchmark's simulator: 1e-3).
    event_log_eps: f32 = 1e-3,
    /// Hot pixels — pixels whose event count (or net count, n⁺ − n⁻) over the whole recording
    /// towers over their neighbours' (`events::hot_pixels`) — are found before training and their
    /// events are not used (event loss and EDI frames); off: every event is used.
    #[arg(value_parser = parse_on_off, value_name = "on|off")]
    event_hot_pixel_filter: bool = true,
    /// How a pixel's log-intensity change is held to its events (`train::loss::event`): `bound`
    /// (the default: a count is a lower bound on the change with the events' sign, as on a sensor
    /// with a refractory period; no events, a change within the dead zone) or `squared` ((ΔL −
    /// C·E)², EventNeRF / E-NeRF and the paper's event loss: every crossing fired; the default
    /// before 2026-11-27, with `--event-weight 0.3`; `docs/BENCHMARKS.md`).
    event_penalty: EventPenaltyKind = EventPenaltyKind::Bound,
    /// m of the `bound` penalty (0–2): n events bound the change by (n − m) thresholds; 2 is what a
    /// sensor with a refractory period guarantees, 1 what `reconstruct` takes without one.
    event_bound_margin: f32 = 0.5,
    /// z of the `bound` penalty: a pixel without events changes freely within ±z thresholds.
    event_dead_zone: f32 = 1.0,
    /// o of the `bound` penalty: the weight of a change's squared overshoot past its count by
    /// more than m thresholds (0: counts are pure lower bounds; the refractory period hides
    /// crossings, so a count is never too high, but a count at a slowly changing pixel is exact).
    event_overshoot_weight: f32 = 0.0,
    /// The cap of the `bound` penalty, in thresholds (the mean of C±): a pixel's event cost is
    /// capped at τ² with τ this many thresholds (0: no cap), so a pixel whose count the sensor's
    /// refractory period turned into the wrong sign or size stops pulling (a truncated
    /// quadratic; `train::loss::event`; +1.27 dB in the box at `quick`, `docs/BENCHMARKS.md`).
    event_residual_cap: f32 = 1.0,
    /// The cap's Huber form: beyond the cap a pixel's event cost grows linearly (a constant pull)
    /// instead of staying flat; off, the default: on costs 0.52 / 0.66 dB in the box at `quick` on
    /// the default benchmark / with ideal events (`docs/BENCHMARKS.md`).
    #[arg(value_parser = parse_on_off, value_name = "on|off")]
    event_residual_cap_huber: bool = false,
    /// With the squared penalty between sub-exposure renders: block side K of its K×K mean (1: per pixel).
    event_pool: u32 = 1,
    /// Between sub-exposure renders: a pixel whose events sum to one sign is held through the
    /// pixel within this many pixels of it whose change meets its bound best (the largest change
    /// for a positive count, the smallest for a negative one), so an edge the model places a
    /// fraction of a pixel off is not charged at the pixel that fired (`train::loss::event::
    /// pair_event_loss_reach`); pixels without events stay per pixel. 0 (the default): per pixel.
    /// Reach 1 loses 0.87 dB in the box with ideal events at `quick` (`docs/notes/2026-12-03-…`).
    event_reach: u32 = 0,
    /// A pixel that fired events of both polarities within an interval says nothing about its net
    /// change there: on a sensor with a refractory period, texture crossing the pixel both ways
    /// drops crossings of either sign, so the net count's sign and size are arbitrary. On: such a
    /// pixel is unconstrained by the event loss in that interval (`train::loss::event`); off:
    /// held to its net count like any other (the default before 2026-11-29). At `quick`: +0.28 dB
    /// in the human box with 9 renders per exposure (35.81 / 31.47 dB against 35.54 / 31.19),
    /// +0.06 dB with 5 (`docs/BENCHMARKS.md`). `reconstruct` turns it off for a scene whose
    /// generator recorded a sensor without a refractory period (`refractory_us = 0`), whose counts
    /// are exact: +0.46 dB in the box there (31.40 against 30.94 dB at weight 1).
    #[arg(value_parser = parse_on_off, value_name = "on|off")]
    event_ignore_mixed: bool = true,
    /// Between sub-exposure renders, the sensor's refractory period (µs): a pixel silent in an
    /// interval but that fired less than this long before it is unconstrained there (its silence
    /// may be the refractory period's). 0: every silent pixel is held to the dead zone.
    event_refractory_us: f32 = 0.0,
    /// With `blur_model = exposure` and a scene with events: each sub-exposure render stands for
    /// its 1/S slice of the exposure modulated per pixel by the events inside that slice — the
    /// event double integral (EDI) over the slice, anchored at the render's time — instead of
    /// standing for the slice unchanged (`train::loss::photometric`). The events then describe
    /// what happens between the renders (a thin stripe passing a pixel between two renders leaves
    /// a net count of zero but a dip in the slice's mean), so the mean of S renders matches a
    /// continuous blur. Independent of `event_loss`. Off in a bare configuration; `cargo xtask
    /// reconstruct` turns it on when the blur model is `exposure` and the scene has events, unless
    /// `--event-modulation` or the config file sets it. Default benchmark, `quick`: 34.35 / 29.92
    /// dB (full frame / human box) against 34.11 / 29.67 without (`docs/BENCHMARKS.md`).
    #[arg(value_parser = parse_on_off, value_name = "on|off")]
    event_modulation: bool = false,
    /// Learned pose correction (`train::pose::correction`), for poses estimated by a fitter: per
    /// training frame, additive corrections of the 24 joint rotations (axis-angle, radians) and the
    /// translation (m) at mid exposure and, with `blur_model = exposure`, of their change over the
    /// exposure, regularised towards zero and towards the neighbouring frames' corrections.
    /// Held-out frames take corrections interpolated from their neighbouring training frames. Off
    /// by default (the default benchmark's poses are exact): on the `realistic` benchmark it
    /// recovers about a quarter of the PSNR a fitter's pose error costs (`docs/BENCHMARKS.md`,
    /// "Estimated poses and learned pose correction"); turn it on for poses from a fitter.
    #[arg(value_parser = parse_on_off, value_name = "on|off")]
    pose_correction: bool = false,
    /// Adam learning rate of the body joints' corrections (radians), per step of a knot (the
    /// corrections step lazily, knot by knot). With knots every 3 frames, 1e-2 (a third of the
    /// best per-frame rate, 3e-2) is the best measured on the `realistic` benchmark's `quick`
    /// preset (`docs/BENCHMARKS.md`, "Estimated poses and learned pose correction").
    lr_pose_correction: f32 = 1e-2,
    /// Adam learning rate of the root's corrections (global orientation, radians; translation,
    /// metres). Faster root rates push the body out of the frame (`docs/BENCHMARKS.md`).
    lr_pose_correction_root: f32 = 3e-3,
    /// λ₀ of the pose-correction prior: weight of ‖δ_k‖² (radians², m²) pulling each training
    /// frame's correction towards zero.
    pose_correction_zero_weight: f32 = 1e-3,
    /// λ_s of the pose-correction prior: weight of ‖δ_k − δ_{k±1}‖² between consecutive knots'
    /// corrections (`pose_correction_knot_every`); 1e-2 against 1e-3: +0.07 dB in the box on
    /// `realistic`, `quick` (a correction per frame).
    pose_correction_smooth_weight: f32 = 1e-2,
    /// Whether pose correction also learns the change of the pose over each exposure (with
    /// `blur_model = exposure`); off (the default): the sub-exposure poses keep their given spread
    /// and only shift with the mid-exposure correction. Off scores 23.36 dB in the box on
    /// `realistic`, `quick` (a correction per frame), against 23.12 on: the learned change is
    /// noise (`docs/BENCHMARKS.md`).
    #[arg(value_parser = parse_on_off, value_name = "on|off")]
    pose_correction_change: bool = false,
    /// Whether pose correction learns each frame's mid-exposure correction; off: only the change
    /// over the exposure is learned (with `pose_correction_change` or `exposure_motion =
    /// learned`), so the given poses stay the poses at mid exposure. `--exposure-motion learned`
    /// alone is `--pose-correction on --pose-correction-mid off --pose-correction-change on
    /// --pose-correction-knot-every 1` at its own rates, bit for bit.
    #[arg(value_parser = parse_on_off, value_name = "on|off")]
    pose_correction_mid: bool = true,
    /// Whether pose correction also corrects the root (global orientation and translation); off:
    /// only the 23 body joints are corrected.
    #[arg(value_parser = parse_on_off, value_name = "on|off")]
    pose_correction_root: bool = true,
    /// The pose corrections stay zero before this step (while the model is still a blur of
    /// Gaussians, its gradients do not say where the limbs are; 100 against 300: +0.13 dB in the
    /// box on `realistic`, `quick`).
    pose_correction_from: usize = 100,
    /// Pose corrections are learned on knots every this many training frames (and on the last),
    /// and each frame's is interpolated linearly in frame number between the knots around it
    /// (`train::pose::correction::KnotSpan`): 1, a correction per training frame; larger, each
    /// learned value hears several frames' gradients and the correction is smooth in time. 3 with
    /// the default rates: +0.17 dB in the box on `realistic` (`quick`) against a correction per
    /// frame at three times the rates, and on exact poses it costs 1.78 dB instead of 3.72
    /// (`docs/BENCHMARKS.md`, "Estimated poses and learned pose correction").
    pose_correction_knot_every: usize = 3,
    /// The pose corrections' rates decay log-linearly from `pose_correction_from` to the last step,
    /// to this fraction of `lr_pose_correction` / `lr_pose_correction_root` (1: constant rates).
    /// A frame's Adam step is about its rate whatever its gradient's size, so the rate is the
    /// corrections' noise floor; the decay lets them settle.
    lr_pose_correction_final_fraction: f32 = 1.0,
    /// With `blur_model = exposure`: whether the body's motion inside each exposure is the given
    /// poses' interpolation (`given`) or that plus a change over the exposure learned per training
    /// frame (`learned`: the change part of `train::pose::correction`, with its prior, from
    /// `pose_correction_from`; the given pose stays the pose at mid exposure, so held-out frames
    /// and reports are unchanged). It reshapes the motion the interpolation misses between
    /// frames. `cargo xtask reconstruct` chooses `learned` when the blur model is `exposure` and
    /// the scene has one person, unless `--exposure-motion` or the config file sets it; the
    /// library default is `given` (the previous default, and the paper's configuration). At
    /// `quick`, mean of seeds 0–2: 36.05 / 31.72 dB full frame / human box on the default
    /// benchmark against 35.93 / 31.60 given (better box PSNR in 8 of 9 paired runs over three
    /// benchmarks, lower box LPIPS in all 9; `docs/notes/2026-12-04-seed-spread.md`). With
    /// `pose_correction` the change lives on the correction's knots; one person only.
    exposure_motion: ExposureMotion = ExposureMotion::Given,
    /// Adam learning rate of the learned in-exposure motion's body joints (radians of change over
    /// an exposure, per step of a frame).
    lr_exposure_motion: f32 = 1e-2,
    /// Adam learning rate of the learned in-exposure motion's root (global orientation, radians;
    /// translation, metres).
    lr_exposure_motion_root: f32 = 1e-3,
    /// The learned in-exposure motion's rates decay log-linearly from `pose_correction_from` to
    /// the last step, to this fraction of `lr_exposure_motion` / `lr_exposure_motion_root`.
    lr_exposure_motion_final_fraction: f32 = 0.1,
    /// Learned camera correction (`train::pose::camera_correction`), for a moving camera whose
    /// poses come from a tracker (SLAM, SfM, COLMAP): per training frame a rigid twist of its
    /// camera at mid exposure (rotation about the camera centre, radians; shift, metres; camera
    /// coordinates) and, with `blur_model = exposure`, its change over the exposure (the camera's
    /// path inside the exposure, which the frames' cameras sample too coarsely to follow a hand's
    /// tremor), regularised towards zero and towards the neighbouring frames'. Held-out frames take
    /// the twist of a least-squares line through the 8 nearest training frames. Off in the presets;
    /// `cargo xtask reconstruct` turns it on when the scene's camera moves: on the `handheld`
    /// benchmark (`quick`) it recovers 7 dB full frame of a tracker's 0.5° / 1 cm camera error, and
    /// with exact cameras it lifts the room outside the person's box by 0.6 dB for 0.9 dB inside
    /// it (0.45 dB full frame; `docs/BENCHMARKS.md`).
    #[arg(value_parser = parse_on_off, value_name = "on|off")]
    camera_correction: bool = false,
    /// Adam learning rate of the camera corrections' rotations (radians per step of a frame; a
    /// frame's correction steps only when that frame trains). On the `handheld` benchmark
    /// (`quick`), 3e-3 for both rates scores +0.32 dB full frame over 1e-3 with estimated cameras
    /// (0.5°, 1 cm) but −0.87 dB with exact ones, whose corrections it only shakes
    /// (`docs/BENCHMARKS.md`, "A moving camera").
    lr_camera_rotation: f32 = 1e-3,
    /// Adam learning rate of the camera corrections' shifts (metres per step of a frame).
    lr_camera_translation: f32 = 1e-3,
    /// The camera corrections' rates decay log-linearly from `camera_correction_from` to the last
    /// step, to this fraction (1: constant rates; a lazy Adam's rate is its noise floor). 0.03
    /// scores +0.38 dB full frame over 0.1 with estimated cameras on `handheld-err` (`quick`;
    /// `docs/notes/2026-12-02-body-tangents-and-serial-step.md`); together with
    /// `camera_correction_change` off it costs exact cameras 0.43 dB in the human box.
    lr_camera_final_fraction: f32 = 0.1,
    /// λ₀ of the camera-correction prior: weight of ‖ξ_k‖² (radians², m²) pulling each training
    /// frame's twists towards zero.
    camera_correction_zero_weight: f32 = 1e-3,
    /// λ_s of the camera-correction prior: weight of ‖ξ_k − ξ_{k±1}‖² between consecutive training
    /// frames' twists.
    camera_correction_smooth_weight: f32 = 1e-2,
    /// λ of a prior on each training frame's mid-exposure camera twist in the tracker's units,
    /// λ·(‖ω‖²/σ_ω² + ‖v‖²/σ_v²) with σ_ω = `camera_tracker_error_deg` and σ_v =
    /// `camera_tracker_error_cm` (`train::pose::camera_correction::tracker_prior_terms`): a
    /// correction the images cannot tell from another is settled in the proportion the tracker
    /// errs in. 0 (the default): no such prior. 10⁻³ on `handheld-err` (`quick`, with the best
    /// estimated-camera settings): cameras closer to the truth (centre 0.95 → 0.74 cm RMS), images
    /// 1.23 dB worse full frame (30.07 against 31.30 dB;
    /// `docs/notes/2026-12-03-oracle-motion-reach-tracker-prior.md`).
    camera_tracker_prior_weight: f32 = 0.0,
    /// σ_ω of the tracker prior: the tracker's typical rotation error (degrees).
    camera_tracker_error_deg: f32 = 0.5,
    /// σ_v of the tracker prior: the tracker's typical camera-centre error (centimetres).
    camera_tracker_error_cm: f32 = 1.0,
    /// λ of a prior on the scale of the corrected camera path (`train::pose::camera_scale`): the
    /// mean square, in units of `camera_tracker_error_cm`, of the part of the corrections' shifts
    /// that follows the given camera centres' own deviation from their clip mean, per camera
    /// axis. A tracker errs by drift and jitter, not by rescaling the path it tracks; without the
    /// prior the corrected cameras rise and fall a quarter less than the truth on `handheld-err`
    /// while the room sits deeper (`docs/notes/2026-12-07-camera-height-drift.md`). 0 (the
    /// default): no such prior. On `handheld-err` (`quick`, the estimated-camera settings of
    /// `docs/BENCHMARKS.md`): 0.01 keeps the images (31.85 dB full frame against 31.84) with
    /// cameras nearer the truth (centre 0.98 → 0.76 cm RMS, the path's vertical scale 0.72 →
    /// 0.81); 0.1 gives 0.67 cm and 0.93 but 31.47 dB
    /// (`docs/notes/2026-12-07-camera-scale-prior.md`).
    camera_scale_prior_weight: f32 = 0.0,
    /// Whether camera correction also learns each exposure's change of the camera (with
    /// `blur_model = exposure`); off: the sub-exposure cameras keep the interpolated path and only
    /// move with the mid-exposure twist (+0.10 dB full frame with estimated cameras on
    /// `handheld-err`, `quick`; see `lr_camera_final_fraction` for exact cameras).
    #[arg(value_parser = parse_on_off, value_name = "on|off")]
    camera_correction_change: bool = true,
    /// Whether camera correction learns each frame's mid-exposure twist; off: the given cameras
    /// stay the mid-exposure cameras and only their change over each exposure is learned (the
    /// camera's in-exposure motion, for exact cameras).
    #[arg(value_parser = parse_on_off, value_name = "on|off")]
    camera_correction_mid: bool = true,
    /// The coordinates in which Adam steps the camera corrections' mid-exposure twists: `twist`
    /// (radians and metres, at `lr_camera_rotation` / `lr_camera_translation`) or `image`
    /// (`train::pose::camera_basis`: whitened by the scene's image motion, so that a step moves
    /// the image by about `lr_camera_pixels` pixels along every direction, a pitch traded for a
    /// vertical shift as fast as a roll; the basis is fixed at the start from the initial scene
    /// and the first training frame's camera). Only the optimiser's coordinates change. On
    /// `handheld-err` (`quick`, with the best estimated-camera settings) `image` at 0.5 px scores
    /// 31.63 dB full frame against 31.40 (LPIPS 0.0370 against 0.0414; 0.2 / 1 px: 31.50 / 31.49;
    /// `docs/notes/2026-12-06-camera-basis.md`).
    camera_correction_basis: CameraCorrectionBasis = CameraCorrectionBasis::Twist,
    /// Adam learning rate of the camera corrections' mid-exposure twists with
    /// `camera_correction_basis = image` (pixels of RMS image motion per step of a frame).
    lr_camera_pixels: f32 = 0.5,
    /// With camera correction, what sets the offset common to every frame's camera — a gauge the
    /// static room cannot see, since it can turn with the cameras and fit the images as well:
    /// `free` (every frame's twist learns from every Gaussian) or `person` (the frames' twists are
    /// kept to a zero clip mean and one clip-wide twist learns from the person's Gaussians alone,
    /// whose poses are in the true world, at the camera rates divided by the training frames, since
    /// it steps on every step; `train::pose::camera_correction`).
    camera_gauge: CameraGauge = CameraGauge::Free,
    /// Width σ (training frames, in time order) of a Gaussian smoothing of the camera corrections:
    /// the twist a frame's camera takes is the normalised kernel-weighted sum of the stored
    /// values of the frames within 3σ, so each stored value learns from its neighbours' gradients
    /// too (a tracker's drift is slow; a frame's own correction steps only when it trains). 0, the
    /// default: each frame's own.
    camera_correction_smoothing: f32 = 0.0,
    /// With `camera_correction_smoothing`: whether the smoothing covers each exposure's change of
    /// the camera too (on, the default) or only the mid-exposure twist (off: each frame keeps its
    /// own change over the exposure, where a hand's tremor is).
    #[arg(value_parser = parse_on_off, value_name = "on|off")]
    camera_correction_smooth_change: bool = true,
    /// With a moving camera and `blur_model = exposure`: how the camera's path inside each
    /// exposure is interpolated between the frames' mid-exposure cameras (a cubic Hermite curve
    /// either way, C¹, through every frame's camera). `band-limited` (the default) takes the
    /// tangents from a windowed band-limited differentiator over 8 frames on each side, exact for
    /// motion below half the frame rate (a hand's tremor, 8–12 Hz at 30 fps) and for constant
    /// motion: on the `handheld` benchmark's path it misses 4 % of the in-exposure motion where
    /// `local` (fourth-order central differences, the body's rule and the default before
    /// 2026-12-02) misses 37 % (`docs/BENCHMARKS.md`, "A moving camera").
    camera_interpolation: TrackTangents = TrackTangents::BandLimited,
    /// With `blur_model = exposure`: how the body's joint rotations and root translation are
    /// interpolated inside each exposure between the frames' poses (cubic Hermite curves through
    /// every frame's pose, as for the camera). `band-limited` (the default since 2026-12-05): the
    /// camera's windowed band-limited differentiator over 8 frames on each side, which on the
    /// generator's motion lowers the sub-frame joint error from 0.230° to 0.193° mean and moves
    /// the human box by +0.07 dB on ideal events, +0.02 on the default benchmark (`quick`;
    /// `docs/notes/2026-12-02-body-tangents-and-serial-step.md`); `local` (the default before):
    /// fourth-order central differences.
    body_interpolation: TrackTangents = TrackTangents::BandLimited,
    /// The camera corrections stay zero before this step (the first steps' model is a blur of
    /// Gaussians whose gradients do not yet say where the room's edges are).
    camera_correction_from: usize = 100,
}

impl Default for TrainConfig {
    fn default() -> Self {
        Self::preset(Preset::Quick)
    }
}

impl TrainConfig {
    /// The defaults of a preset.
    pub fn preset(preset: Preset) -> Self {
        let quick = Self::quick();
        match preset {
            Preset::Quick => quick,
            Preset::Full => Self {
                steps: 6000,
                human_gaussians: 10_000,
                scene_gaussians: 40_000,
                // With at most 100k Gaussians (150k before 2026-12-05) the nine renders per
                // exposure and `quick`'s rates and widths fit the 90-minute budget: 5000 steps
                // took 46 min on Zen 5 (`docs/notes/2026-12-05-full-preset-in-budget.md`).
                max_gaussians: 100_000,
                skinning_until: 1500,
                nonrigid_from: 1000,
                densify_from: 500,
                densify_until: 4000,
                // The event weight falls to a tenth from the end of densification, as at `quick`.
                event_weight_decay_from: 4000,
                opacity_reset_every: 3000,
                checkpoint_every: 1000,
                ..quick
            },
        }
    }

    /// The configuration of a run: the preset's defaults, then the fields of the config file `file`
    /// (TOML or JSON), then the fields `options` sets; validated.
    pub fn resolve(
        preset: Preset,
        file: Option<&Path>,
        options: &TrainOptions,
    ) -> Result<Self, TrainError> {
        let mut config = Self::preset(preset);
        if let Some(path) = file {
            config = Self::load_over(path, &config)?;
        }
        config.apply(options);
        config.validate()?;
        Ok(config)
    }
}

#[cfg(test)]
mod tests;
