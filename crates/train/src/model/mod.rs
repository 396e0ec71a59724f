//! The learned E-Sem3DGS model — everything a reconstruction learns, and nothing about how it is
//! optimised: the semantic Gaussian set, the four networks (non-rigid deformation, skinning field,
//! human colour, scene colour), the per-training-frame latents and pose corrections, and the
//! settings that shape its rendering (semantic mode, gate, background, near plane, all in
//! [`TrainConfig`]).
//!
//! [`Model::forward`] poses the Gaussians for one frame (see [`crate::pose::posing`]) and rasterizes them
//! with the human probability as a fourth channel; the returned [`FramePass`] keeps what its backward
//! needs, so one training step can hold any number of passes (one today, two with the pair losses, S
//! with an exposure model) and differentiate each. Eval, export and rendering take a `Model`, never a
//! trainer.

use crate::blend::SemanticMode;
use crate::pose::body::PreparedPose;
use crate::pose::camera_correction::CAMERA_CORRECTION_VALUES;
use crate::pose::correction::{knot_slots, CORRECTION_VALUES};
use crate::pose::posing::{
    pose_frame_backward_with, pose_frame_gated, FrameCache, FrameCotangents, FrameInputs,
    GaussianParams, ModelGradients, ModelNets, PosedFrame, ViewRotation,
};
use crate::pose::reposing::{repose_frame, repose_frame_backward, ReposeCotangents, ReposedCache};
use crate::TrainError;

mod camera;
mod config;
mod correction;
mod exposure;
mod networks;
mod pass;
pub use camera::{corrected_camera, PassCamera};
pub use config::ModelConfig;
use gaussians::covariance::Mat3;
use gaussians::GaussianSet;
pub use networks::{CAMERA_CORRECTIONS_TENSOR, CAMERA_GAUGE_TENSOR, NETWORK_GROUPS};
use rasterize_cpu::{
    camera_pose_gradient, render_cov, render_cov_backward, render_cov_shared,
    render_cov_shared_backward, Camera, Cotangents, CovSplats, Gradients, RenderOutput,
    RenderSettings, SharedOutputs, TileSharing,
};
use rayon::prelude::*;
use smpl_deform::math::Affine;
use std::time::Instant;

/// Number of rendered channels of a model of one person: linear RGB and the human probability.
/// A model of several people renders each person's probability after them
/// ([`Model::render_channels`]).
pub const RENDER_CHANNELS: usize = 4;

/// What a reconstruction learned.
#[derive(Clone, Debug)]
pub struct Model {
    /// What shapes the model and how it is posed and rendered.
    pub config: ModelConfig,
    /// The Gaussians (human ones in canonical space, scene ones in world space).
    pub set: GaussianSet,
    /// The four networks.
    pub nets: ModelNets<f32>,
    /// Per-training-frame latents, (frames, latent_dim).
    pub latents: Vec<f32>,
    /// Frame number of each latent slot (the training frames in time order).
    pub frame_indices: Vec<u32>,
    /// Per-knot pose corrections, (knots, [`CORRECTION_VALUES`]) (`train::pose::correction`): the
    /// fitter's correction and/or the learned in-exposure motion; empty without either
    /// (`ModelConfig::pose_rows`).
    pub pose_corrections: Vec<f32>,
    /// Per-training-frame camera corrections, (frames, [`CAMERA_CORRECTION_VALUES`])
    /// (`train::pose::camera_correction`); empty when `camera_correction` is off.
    pub camera_corrections: Vec<f32>,
    /// With `camera_gauge`: the clip-wide twist every frame's correction adds at mid exposure
    /// ([`CAMERA_CORRECTION_VALUES`] values, the change half zero), learned from the person's
    /// Gaussians alone; the frames' own twists then keep a zero clip mean. Empty otherwise.
    pub camera_gauge: Vec<f32>,
    /// Scene extent (m): scales the position rate and the density thresholds.
    pub scene_extent: f32,
}

/// A rendered frame of the model.
#[derive(Clone, Debug)]
pub struct Rendered {
    /// Linear RGB, planar (3, H, W).
    pub rgb: Vec<f32>,
    /// Rendered human probability (H, W) (alpha-composited, 0 where nothing is drawn).
    pub human: Vec<f32>,
    /// With several people, each person's rendered probability (H, W) (empty with one).
    pub people: Vec<Vec<f32>>,
    /// The posed per-Gaussian attributes.
    pub posed: PosedFrame<f32>,
}

/// Wall-clock seconds of a forward pass's two stages (not deterministic; for the step breakdown).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PassTiming {
    /// Deformation, colour networks and blend.
    pub pose: f64,
    /// Rasterization.
    pub render: f64,
}

/// What a pass's posing backward needs: a pass posed by the networks, or one re-posed from another
/// pass of the same frame ([`Model::forward_passes`]).
enum PassCache {
    Frame(Box<FrameCache<f32>>),
    Reposed(ReposedCache<f32>),
}

/// One frame rendered by a model, with what its backward needs.
pub struct FramePass<'a> {
    model: &'a Model,
    camera: &'a Camera,
    /// The camera centre the colours were viewed from (world, metres; see [`PassCamera`]).
    view_centre: [f32; 3],
    pose: &'a PreparedPose,
    latent: &'a [f32],
    cache: PassCache,
    channels: Vec<f32>,
    /// Each Gaussian's smear over the pass's time slice (`crate::pose::smear`), or `None`.
    smears: Option<Vec<Mat3<f32>>>,
    /// The posed per-Gaussian attributes (the rasterizer's inputs).
    pub posed: PosedFrame<f32>,
    /// The rasterizer's output: (RGB, human probability) planes and per-Gaussian screen data.
    pub out: RenderOutput<f32>,
    /// Stage timings of the forward.
    pub timing: PassTiming,
}

/// How [`Model::forward_passes`] renders one frame's passes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PassPlan {
    /// Evaluate the networks once, at the reference pass, and re-pose it for the others.
    pub reposed: bool,
    /// Blend the tiles only static Gaussians reach once for every pass.
    pub share_static_tiles: bool,
    /// With `share_static_tiles`: the passes are differentiated only together
    /// ([`Model::shared_render_backward`]), so the shared tiles are binned by the reference pass
    /// alone (`rasterize_cpu::SharedOutputs::OwnerLists`); a pass's own backward is then refused.
    pub joint_backward_only: bool,
    /// With `joint_backward_only`: the static Gaussians behind every moving one are blended once,
    /// as a layer behind each pass (`rasterize_cpu::SharedOutputs::Layered`).
    pub static_layer: bool,
    /// With several passes from one camera: each pass renders its time slice's average, every
    /// Gaussian smeared by its motion (`crate::pose::smear`; differentiate the passes' smears
    /// with [`Model::add_smear_gradients`]).
    pub smear: bool,
}

/// One frame's passes, and the tiles they share when rendered together.
pub struct ExposurePasses<'a> {
    /// The passes, in pose order.
    pub passes: Vec<FramePass<'a>>,
    /// The tiles blended once, by the reference pass (`None`: every pass blended every tile).
    pub sharing: Option<TileSharing>,
}

/// A pass posed but not yet rendered.
struct PosedPass<'a> {
    view_centre: [f32; 3],
    pose: &'a PreparedPose,
    latent: &'a [f32],
    cache: PassCache,
    channels: Vec<f32>,
    smears: Option<Vec<Mat3<f32>>>,
    posed: PosedFrame<f32>,
    pose_seconds: f64,
}

impl<'a> PosedPass<'a> {
    fn rendered(
        self,
        model: &'a Model,
        camera: &'a Camera,
        out: RenderOutput<f32>,
        render_seconds: f64,
    ) -> FramePass<'a> {
        FramePass {
            model,
            camera,
            view_centre: self.view_centre,
            pose: self.pose,
            latent: self.latent,
            cache: self.cache,
            channels: self.channels,
            smears: self.smears,
            posed: self.posed,
            out,
            timing: PassTiming {
                pose: self.pose_seconds,
                render: render_seconds,
            },
        }
    }
}

impl PassCache {
    /// Indices of the Gaussians whose human branch was evaluated.
    fn active(&self) -> &[usize] {
        match self {
            PassCache::Frame(cache) => cache.active(),
            PassCache::Reposed(cache) => cache.active(),
        }
    }
}

/// ∂L/∂bones of one pass: one 3×4 per bone.
pub type BoneGradients = Vec<Affine<f32>>;

/// A loss's gradients with respect to a pass's rasterizer inputs.
#[derive(Clone, Debug)]
pub struct PosedGradients {
    /// dL/d posed means (world).
    pub means: Vec<[f32; 3]>,
    /// dL/d posed covariances.
    pub covariances: Vec<[[f32; 3]; 3]>,
    /// dL/d colours, N × 3.
    pub colours: Vec<f32>,
    /// dL/d human probability, N.
    pub human_probability: Vec<f32>,
    /// dL/d each person's probability, N × P with several people (else empty).
    pub person_probability: Vec<f32>,
    /// dL/d opacity logits (stored directly in the set: no model backward needed).
    pub opacity_logits: Vec<f32>,
    /// dL/d screen-space means (pixels), for density control.
    pub means_2d: Vec<[f32; 2]>,
    /// dL/d the pass's smears (entries independent; empty without smears), which
    /// [`Model::add_smear_gradients`] sends to the passes' means.
    pub smears: Vec<Mat3<f32>>,
}

impl Model {
    /// A model from its parts, checked against `config` (semantic logits, features, latents), with
    /// zero pose rows when `config.pose_rows` is on.
    pub fn new(
        config: ModelConfig,
        set: GaussianSet,
        nets: ModelNets<f32>,
        latents: Vec<f32>,
        frame_indices: Vec<u32>,
        scene_extent: f32,
    ) -> Result<Self, TrainError> {
        let k = config
            .semantic
            .logits_for(people_of(config.semantic, set.semantic_classes));
        if set.semantic_classes != k
            || set.semantic_logits.len() != set.len() * k
            || set.feature_dim != config.feature_dim
        {
            return Err(TrainError::Config(format!(
                "the Gaussians carry {} semantic logits and {} features each; the configuration needs {k} and {}",
                set.semantic_logits.len().checked_div(set.len()).unwrap_or(0),
                set.feature_dim,
                config.feature_dim
            )));
        }
        if frame_indices.is_empty() {
            return Err(TrainError::Config(
                "a model needs at least one training frame".into(),
            ));
        }
        if latents.len() != frame_indices.len() * config.latent_dim {
            return Err(TrainError::Shape {
                what: "frame latents".into(),
                expected: frame_indices.len() * config.latent_dim,
                found: latents.len(),
            });
        }
        let pose_corrections = if config.pose_rows {
            let knots = knot_slots(frame_indices.len(), config.pose_correction_knot_every);
            vec![0.0; knots.len() * CORRECTION_VALUES]
        } else {
            Vec::new()
        };
        let camera_corrections = if config.camera_correction {
            vec![0.0; frame_indices.len() * CAMERA_CORRECTION_VALUES]
        } else {
            Vec::new()
        };
        let camera_gauge = if config.camera_gauge {
            vec![0.0; CAMERA_CORRECTION_VALUES]
        } else {
            Vec::new()
        };
        Ok(Self {
            config,
            set,
            nets,
            latents,
            frame_indices,
            pose_corrections,
            camera_corrections,
            camera_gauge,
            scene_extent,
        })
    }

    /// The number of people the model reconstructs (one semantic class each).
    pub fn people(&self) -> usize {
        people_of(self.config.semantic, self.set.semantic_classes)
    }

    /// The number of rendered channels: RGB, the human probability and, with several people,
    /// each person's probability.
    pub fn render_channels(&self) -> usize {
        match self.people() {
            1 => RENDER_CHANNELS,
            p => RENDER_CHANNELS + p,
        }
    }

    /// Gaussian `i`'s semantic logits.
    pub fn logits(&self, i: usize) -> &[f32] {
        let k = self.set.semantic_classes;
        &self.set.semantic_logits[i * k..(i + 1) * k]
    }

    /// Human probability of Gaussian `i`.
    pub fn probability(&self, i: usize) -> f32 {
        self.config.semantic.probability(self.logits(i))
    }

    /// The person (0-based) Gaussian `i` is most probably part of (0 with one person).
    pub fn person_of(&self, i: usize) -> usize {
        match self.people() {
            1 => 0,
            _ => crate::blend::most_probable_person(self.logits(i)),
        }
    }

    /// Number of Gaussians with human probability ≥ 0.5.
    pub fn human_count(&self) -> usize {
        (0..self.set.len())
            .filter(|&i| self.probability(i) >= 0.5)
            .count()
    }

    /// The latent of training slot `slot`.
    pub fn latent(&self, slot: usize) -> &[f32] {
        let d = self.config.latent_dim;
        &self.latents[slot * d..(slot + 1) * d]
    }

    /// The latent of the training frame nearest in frame number to `index` (for unseen frames).
    pub fn latent_for(&self, index: u32) -> &[f32] {
        let slot = self
            .frame_indices
            .iter()
            .enumerate()
            .min_by_key(|(_, &f)| (i64::from(f) - i64::from(index)).abs())
            .map_or(0, |(s, _)| s);
        self.latent(slot)
    }

    /// The stored per-Gaussian parameters as the posing functions take them.
    pub fn params(&self) -> GaussianParams<'_, f32> {
        GaussianParams {
            means: &self.set.means,
            log_scales: &self.set.log_scales,
            quats: &self.set.quats,
            features: &self.set.features,
            semantic_logits: &self.set.semantic_logits,
        }
    }

    /// The rasterizer settings: the background colour with 0 probability channels behind it and the
    /// configured near plane.
    pub fn render_settings(&self) -> RenderSettings {
        let mut background: Vec<f64> = self
            .config
            .background
            .iter()
            .map(|&v| f64::from(v))
            .collect();
        background.resize(self.render_channels(), 0.0);
        RenderSettings {
            near_plane: self.config.near_plane,
            background,
        }
    }

    /// Poses the model in `pose` with the frame latent `latent` and rasterizes it from `camera`.
    pub fn forward<'a>(
        &'a self,
        camera: &'a Camera,
        pose: &'a PreparedPose,
        latent: &'a [f32],
    ) -> Result<FramePass<'a>, TrainError> {
        self.forward_from(PassCamera::of(camera), pose, latent)
    }

    /// [`Model::forward`] from a pass camera (rasterized from `camera.raster`, coloured as seen
    /// from `camera.view_centre`).
    pub fn forward_from<'a>(
        &'a self,
        camera: PassCamera<'a>,
        pose: &'a PreparedPose,
        latent: &'a [f32],
    ) -> Result<FramePass<'a>, TrainError> {
        let posed = self.posed_pass(camera.view_centre, pose, latent)?;
        self.rasterize(camera.raster, posed)
    }

    /// Poses the model in `pose` with the frame latent `latent`, its colours viewed from
    /// `view_centre` (networks, blend).
    fn posed_pass<'a>(
        &'a self,
        view_centre: [f32; 3],
        pose: &'a PreparedPose,
        latent: &'a [f32],
    ) -> Result<PosedPass<'a>, TrainError> {
        let t0 = Instant::now();
        let (posed, cache) = pose_frame_gated(
            &self.nets,
            self.config.semantic,
            self.config.semantic_gate,
            &self.params(),
            &frame_inputs(view_centre, pose, latent, self.config.view_rotation),
        )?;
        Ok(PosedPass {
            view_centre,
            pose,
            latent,
            cache: PassCache::Frame(Box::new(cache)),
            channels: interleave_channels(&posed),
            smears: None,
            posed,
            pose_seconds: t0.elapsed().as_secs_f64(),
        })
    }

    /// Rasterizes a posed frame into a pass.
    fn rasterize<'a>(
        &'a self,
        camera: &'a Camera,
        posed: PosedPass<'a>,
    ) -> Result<FramePass<'a>, TrainError> {
        let t0 = Instant::now();
        let out = render_cov(
            camera,
            &splats(self, &posed.posed, &posed.channels, posed.smears.as_deref()),
            &self.render_settings(),
        )?;
        Ok(posed.rendered(self, camera, out, t0.elapsed().as_secs_f64()))
    }

    /// Renders the model in `pose` with the frame latent `latent` from `camera`.
    pub fn render(
        &self,
        camera: &Camera,
        pose: &PreparedPose,
        latent: &[f32],
    ) -> Result<Rendered, TrainError> {
        let pass = self.forward(camera, pose, latent)?;
        Ok(Rendered {
            rgb: pass.rgb().to_vec(),
            human: pass.human().to_vec(),
            people: pass.people_planes(),
            posed: pass.posed,
        })
    }
}

/// The people of a set of `classes` semantic classes under `mode`: one per class after the scene's
/// with one-hot semantics, else one.
fn people_of(mode: SemanticMode, classes: usize) -> usize {
    match mode {
        SemanticMode::OneHot => classes.saturating_sub(1).max(1),
        _ => 1,
    }
}

fn frame_inputs<'a>(
    view_centre: [f32; 3],
    pose: &'a PreparedPose,
    latent: &'a [f32],
    view_rotation: ViewRotation,
) -> FrameInputs<'a, f32> {
    FrameInputs {
        pose_code: &pose.pose_code,
        bones: &pose.bones,
        camera_centre: view_centre,
        latent,
        view_rotation,
    }
}

/// The centre of `camera` (world, metres) in the posing's precision.
fn view_centre(camera: &Camera) -> [f32; 3] {
    camera.center_world().map(|v| v as f32)
}

/// The rasterizer's view of a posed frame: its means and covariances with the set's opacities,
/// the interleaved render channels and the pass's smears, if any.
fn splats<'a>(
    model: &'a Model,
    posed: &'a PosedFrame<f32>,
    channels: &'a [f32],
    smears: Option<&'a [Mat3<f32>]>,
) -> CovSplats<'a, f32> {
    CovSplats {
        means: &posed.means,
        covariances: &posed.covariances,
        opacity_logits: &model.set.opacity_logits,
        channels,
        num_channels: model.render_channels(),
        smears,
    }
}

/// Per-Gaussian render channels (r, g, b, p), N × 4 row-major, with each person's probability
/// after p when the frame has several people (N × (4 + P)).
fn interleave_channels(posed: &PosedFrame<f32>) -> Vec<f32> {
    let n = posed.means.len();
    let people = posed.person_probability.len().checked_div(n).unwrap_or(0);
    let mut channels = Vec::with_capacity(n * (RENDER_CHANNELS + people));
    for i in 0..n {
        channels.extend_from_slice(&posed.colours[i * 3..i * 3 + 3]);
        channels.push(posed.human_probability[i]);
        channels.extend_from_slice(&posed.person_probability[i * people..(i + 1) * people]);
    }
    channels
}

/// The exposure model's prediction: the mean of the passes' RGB renders, (3, H, W) (the render
/// itself for one pass; `crate::loss::photometric::mean_image`).
pub fn mean_rgb(passes: &[FramePass<'_>]) -> Vec<f32> {
    let renders: Vec<&[f32]> = passes.iter().map(FramePass::rgb).collect();
    crate::loss::photometric::mean_image(&renders, renders.first().map_or(0, |r| r.len()))
}
