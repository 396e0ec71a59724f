//! The E-Sem3DGS optimisation loop (paper §4.5 without the event-flow term): one set of semantic
//! Gaussians, posed per training frame by [`crate::posing`], rendered in one rasterization with the human
//! probability as a fourth channel, and optimised with L1 + λ·D-SSIM, the skinning loss and the AIAP
//! losses; Adam per parameter group, the 3DGS position-rate decay, density control on its schedule,
//! opacity resets, atomic checkpoints that resume bit for bit, and a NaN guard.
//!
//! One step = one training frame from a seeded shuffled order (reshuffled each epoch). Everything that
//! influences the parameters is deterministic for a seed and independent of the thread count; only the
//! reported stage timings vary.

use crate::checkpoint::{rng_from_strings, rng_to_strings, CheckpointReader, CheckpointWriter};
use crate::colour::{ColourNet, ColourNetConfig};
use crate::config::{FlowGradient, FlowMeasure, TrainConfig};
use crate::data::Dataset;
use crate::event_loss::pair_event_loss;
use crate::fit::{accumulate_screen_stats, exponential_rate, on_schedule};
use crate::flow_loss::{
    network_target, pair_flow_loss, pair_warp_loss, prepare_target, FlowTarget,
};
use crate::image_loss::{l1, psnr, ssim, ImageShape};
use crate::init::{initialise, InitConfig};
use crate::posing::{
    pose_frame_backward, pose_frame_gated, FrameCotangents, FrameInputs, GaussianParams, ModelNets,
    PosedFrame,
};
use crate::TrainError;
use flow::SpyNet;
use gaussians::adam::{AdamConfig, GaussianAdam, GaussianLearningRates};
use gaussians::covariance::{covariance_3d, covariance_3d_backward};
use gaussians::density::{densify_and_prune, reset_opacity, DensifyConfig, DensityStats};
use gaussians::GaussianSet;
use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rasterize_cpu::{
    render_cov, render_cov_backward, Camera, Cotangents, CovSplats, Gradients, RenderOutput,
    RenderSettings,
};
use scene::Split;
use smpl_deform::deform_net::{pose_code, skinning_loss, NonRigidNet, SkinningField};
use smpl_deform::math::Affine;
use smpl_deform::{BodyModel, CanonicalBody, SmplParams};
use std::path::Path;
use std::time::Instant;

/// Identifier stored in every checkpoint of this trainer.
pub const CHECKPOINT_FORMAT: &str = "e-sem3dgs-trainer-v1";

/// Checkpoint names of the network optimisers, in the order of their step counts in the metadata.
const NET_OPTIMISERS: [&str; 5] = [
    "nonrigid",
    "skinning",
    "human_colour",
    "scene_colour",
    "latent",
];

/// Number of rendered channels: linear RGB and the human probability.
pub const RENDER_CHANNELS: usize = 4;

/// A body pose prepared for the model: the pose feature and the canonical-to-frame bone transforms.
#[derive(Clone, Debug, PartialEq)]
pub struct PreparedPose {
    /// The 207-value pose feature (R[1:] − I).
    pub pose_code: Vec<f32>,
    /// `frame_from_canonical` per bone (24, row-major 3×4).
    pub bones: Vec<Affine<f32>>,
    /// World position of the root joint (m).
    pub root: [f32; 3],
}

/// The body in canonical space, able to prepare any SMPL pose for the model.
#[derive(Clone, Debug)]
pub struct Body {
    /// The body model.
    pub model: BodyModel,
    /// Its canonical (Da-) pose.
    pub canonical: CanonicalBody,
    /// Shape parameters used for every pose.
    pub betas: Vec<f32>,
}

impl Body {
    /// Loads the canonical body of `model` with `betas`.
    pub fn new(model: BodyModel, betas: Vec<f32>) -> Result<Self, TrainError> {
        let canonical = CanonicalBody::new(&model, &betas)?;
        Ok(Self {
            model,
            canonical,
            betas,
        })
    }

    /// Pose feature and bone transforms of SMPL parameters (`params.betas` is replaced by the body's).
    pub fn prepare(&self, params: &SmplParams) -> Result<PreparedPose, TrainError> {
        let params = SmplParams {
            betas: self.betas.clone(),
            ..params.clone()
        };
        let posed = self.model.pose(&params)?;
        Ok(PreparedPose {
            pose_code: pose_code(&posed.local_rotations),
            bones: self.canonical.frame_from_canonical(&posed),
            root: posed.joints.first().copied().unwrap_or(params.transl),
        })
    }
}

/// One training frame as the loop uses it.
#[derive(Clone, Debug)]
pub struct TrainingFrame {
    /// Frame number in `scene.json`.
    pub index: u32,
    /// Observed (blurred) image, planar (3, H, W) linear RGB.
    pub image: Vec<f32>,
    /// The frame's pose.
    pub pose: PreparedPose,
}

/// Flow supervision of one training frame k: the next training frame and the target flow k → k+1.
#[derive(Clone, Debug)]
pub struct FlowPair {
    /// Slot (position in [`TrainContext::frames`]) of frame k+1.
    pub next_slot: usize,
    /// The supervising flow at the network's resolution, with its mask.
    pub target: FlowTarget<f32>,
}

/// Event supervision of one training frame k: the next training frame and C·E per pixel (C the
/// contrast threshold, E the signed event count of [t_k, t_{k+1})), row-major H × W.
#[derive(Clone, Debug)]
pub struct EventPair {
    /// Slot (position in [`TrainContext::frames`]) of frame k+1.
    pub next_slot: usize,
    /// Expected log-intensity change per pixel.
    pub expected: Vec<f32>,
}

/// Everything fixed during training: camera, training frames, body and skinning-loss samples.
#[derive(Clone, Debug)]
pub struct TrainContext {
    /// The fixed camera.
    pub camera: Camera,
    /// Training frames in time order (their position is the latent slot).
    pub frames: Vec<TrainingFrame>,
    /// The body.
    pub body: Body,
    /// Canonical surface samples for the skinning loss and their body weights (N × 24).
    pub skin_points: Vec<[f32; 3]>,
    /// Body skinning weights of `skin_points`, row-major (N, 24).
    pub skin_weights: Vec<f32>,
    /// Per training slot, the flow supervision of the pair (k, k+1) (empty unless
    /// [`TrainContext::enable_flow`] was called; `None` for a frame whose next frame is not a training
    /// frame).
    pub flow_pairs: Vec<Option<FlowPair>>,
    /// The frozen flow network of the flow loss.
    pub flow_net: Option<SpyNet<f32>>,
    /// Per training slot, the event supervision of the pair (k, k+1) (empty unless
    /// [`TrainContext::enable_events`] was called).
    pub event_pairs: Vec<Option<EventPair>>,
}

impl TrainContext {
    /// Prepares the training split of `data` with `body` (surface samples drawn with `seed`).
    pub fn new(data: &Dataset, body: Body, seed: u64) -> Result<Self, TrainError> {
        let mut frames = Vec::new();
        for f in data.frames.iter().filter(|f| f.split == Split::Train) {
            frames.push(TrainingFrame {
                index: f.index,
                image: f.image.clone(),
                pose: body.prepare(&f.smpl)?,
            });
        }
        if frames.is_empty() {
            return Err(TrainError::Config(format!(
                "{}: the scene has no training frames",
                data.dir.display()
            )));
        }
        let samples = smpl_deform::sample_surface(
            &body.canonical.posed.vertices,
            &body.model.faces,
            &body.model.weights,
            16_384,
            seed ^ 0x5c1_0000,
        );
        Ok(Self {
            camera: data.camera.clone(),
            frames,
            body,
            skin_points: samples.points,
            skin_weights: samples.weights,
            flow_pairs: Vec::new(),
            flow_net: None,
            event_pairs: Vec::new(),
        })
    }

    /// Slots of consecutive training frames: `(slot of k, position of k in data.frames)` for every
    /// training frame whose next frame in `scene.json` is also a training frame (slot k+1 = slot k + 1).
    fn consecutive_training_pairs(data: &Dataset) -> Vec<(usize, usize)> {
        let mut out = Vec::new();
        let mut slot = 0usize;
        for (p, f) in data.frames.iter().enumerate() {
            if f.split != Split::Train {
                continue;
            }
            if data
                .frames
                .get(p + 1)
                .is_some_and(|n| n.split == Split::Train)
            {
                out.push((slot, p));
            }
            slot += 1;
        }
        out
    }

    /// Prepares the event-generation loss: for every pair of consecutive training frames, reads frame
    /// k's `events` file (the events of [t_k, t_{k+1})) and turns it into C·E per pixel
    /// (`config.event_threshold`). A pair whose frame has no events file, or whose events file cannot
    /// be read, is an error naming the frame and the file — refused here, not mid-training.
    pub fn enable_events(
        &mut self,
        data: &Dataset,
        config: &TrainConfig,
    ) -> Result<(), TrainError> {
        let (w, h) = (self.camera.width, self.camera.height);
        let sensor = events::SensorSize::new(w, h);
        let mut pairs = vec![None; self.frames.len()];
        let found = Self::consecutive_training_pairs(data);
        for &(slot, p) in &found {
            let f = &data.frames[p];
            let Some(rel) = &data.scene.frames[p].events else {
                return Err(TrainError::Config(format!(
                    "{}: frame {} has no events file (needed by the event loss)",
                    data.dir.display(),
                    f.index
                )));
            };
            let path = scene::Scene::resolve(&data.dir, rel);
            let stream = events::read_events(&path)
                .map_err(|e| TrainError::Config(format!("{}: {e}", path.display())))?;
            let counts = events::count_frame(&stream.as_slice(), sensor, events::CountMode::Signed);
            pairs[slot] = Some(EventPair {
                next_slot: slot + 1,
                expected: counts.iter().map(|c| c * config.event_threshold).collect(),
            });
        }
        if found.is_empty() {
            return Err(TrainError::Config(format!(
                "{}: no two consecutive frames are both training frames, so the event loss has \
                 nothing to supervise",
                data.dir.display()
            )));
        }
        self.event_pairs = pairs;
        Ok(())
    }

    /// Prepares the flow loss: for every training frame whose next frame in `scene.json` is also a
    /// training frame, reads the flow of `config.flow_source` (and its validity mask) and resizes it
    /// to the network's resolution (`config.flow_scale`, τ = `config.flow_tau`) — or, for
    /// `sharp-network`, runs `net` on the two sharp references at that resolution
    /// ([`network_target`]). A pair without that flow (or without sharp references), or with a flow
    /// of the wrong size, is an error naming the frame and the file — refused here, not
    /// mid-training. Frames whose next frame is a test frame (or the last frame) have no pair.
    pub fn enable_flow(
        &mut self,
        data: &Dataset,
        config: &TrainConfig,
        net: SpyNet<f32>,
    ) -> Result<(), TrainError> {
        let (w, h) = (self.camera.width as usize, self.camera.height as usize);
        let h_out = ((h as f64 * config.flow_scale as f64).round() as usize).max(1);
        let w_out = ((w as f64 * config.flow_scale as f64).round() as usize).max(1);
        let mut pairs = vec![None; self.frames.len()];
        for (slot, p) in Self::consecutive_training_pairs(data) {
            let target = match config.flow_source.kind() {
                Some(kind) => file_flow_target(data, p, kind, config, (h, w), (h_out, w_out))?,
                None => {
                    let (f, next) = (&data.frames[p], &data.frames[p + 1]);
                    let (Some(first), Some(second)) = (&f.sharp, &next.sharp) else {
                        return Err(TrainError::Config(format!(
                            "{}: frame {} or its next training frame {} has no sharp reference \
                             (needed by the flow loss with flow source sharp-net)",
                            data.dir.display(),
                            f.index,
                            next.index
                        )));
                    };
                    network_target(&net, first, second, h, w, h_out, w_out, config.flow_tau)?
                }
            };
            pairs[slot] = Some(FlowPair {
                next_slot: slot + 1,
                target,
            });
        }
        if pairs.iter().all(Option::is_none) {
            return Err(TrainError::Config(format!(
                "{}: no two consecutive frames are both training frames, so the flow loss has \
                 nothing to supervise",
                data.dir.display()
            )));
        }
        self.flow_pairs = pairs;
        self.flow_net = Some(net);
        Ok(())
    }

    /// Number of pixels per channel.
    pub fn pixels(&self) -> usize {
        self.camera.width as usize * self.camera.height as usize
    }
}

/// Wall-clock seconds per stage of one step (for the cost breakdown; not deterministic).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct StageTimes {
    /// Deformation, colour networks and blend.
    pub pose: f64,
    /// Rasterization forward.
    pub render: f64,
    /// Photometric loss and its gradient.
    pub loss: f64,
    /// Rasterization backward.
    pub render_backward: f64,
    /// Model backward (networks, blend, deformation) plus skinning and AIAP losses.
    pub model_backward: f64,
    /// Optimiser updates.
    pub adam: f64,
    /// Density control and opacity reset.
    pub density: f64,
    /// The pair losses (flow, events): posing and rendering frame k+1, the flow network forward and
    /// backward, the event loss, frame k+1's rasterizer and model backward (0 without a pair).
    pub flow: f64,
    /// The part of `flow` spent in the flow loss proper: resizing both renders, the frozen network's
    /// forward and input gradient, the masked L1 (0 without a flow pair).
    pub flow_network: f64,
}

/// What one step did.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct StepReport {
    /// 0-based step index.
    pub step: usize,
    /// Frame number trained on.
    pub frame: u32,
    /// Total loss.
    pub loss: f32,
    /// The L1 term.
    pub l1: f32,
    /// SSIM (not 1 − SSIM).
    pub ssim: f32,
    /// The weighted skinning loss.
    pub skinning: f32,
    /// The weighted AIAP loss (positions + covariances).
    pub aiap: f32,
    /// The weighted flow loss λ_flow·L_flow (0 on steps without a flow pair).
    pub flow: f32,
    /// The weighted event-generation loss (0 on steps without an event pair).
    pub event: f32,
    /// PSNR (dB) of the render against the (blurred) training frame.
    pub psnr: f64,
    /// Gaussians with human probability ≥ 0.5 after the step.
    pub gaussians_human: usize,
    /// Other Gaussians after the step.
    pub gaussians_scene: usize,
    /// Gaussians whose human branch was evaluated.
    pub active: usize,
    /// Stage timings.
    pub times: StageTimes,
}

/// A rendered frame of the model.
#[derive(Clone, Debug)]
pub struct Rendered {
    /// Linear RGB, planar (3, H, W).
    pub rgb: Vec<f32>,
    /// Rendered human probability (H, W) (alpha-composited, 0 where nothing is drawn).
    pub human: Vec<f32>,
    /// The posed per-Gaussian attributes.
    pub posed: PosedFrame<f32>,
}

/// Splits the rasterizer's per-Gaussian channel gradients (`RENDER_CHANNELS` interleaved) into the
/// colour gradients (N × 3) and the human-probability gradients (N).
fn split_channel_cotangents(channels: &[f32]) -> (Vec<f32>, Vec<f32>) {
    let per = channels.chunks_exact(RENDER_CHANNELS);
    let colours = per.clone().flat_map(|c| c[..3].iter().copied()).collect();
    let prob = per.map(|c| c[3]).collect();
    (colours, prob)
}

/// Rasterizer backward of one frame's image cotangent `d_image` ((C, H, W)) plus, when given, the
/// flow loss's cotangent `d_flow` on its RGB planes, of which only the geometric share is kept: the
/// gradients w.r.t. the means, covariances and screen-space means (`FlowGradient::Geometry`). The
/// backward is linear in the cotangent, so this is exactly the gradient of all losses with the
/// flow loss's colour, opacity and semantic terms removed.
fn backward_with_geometric_flow(
    camera: &Camera,
    splats: &CovSplats<'_, f32>,
    settings: &RenderSettings,
    out: &RenderOutput<f32>,
    d_image: &[f32],
    d_flow: Option<&[f32]>,
) -> Result<Gradients<f32>, TrainError> {
    let backward = |image: &[f32]| {
        render_cov_backward(
            camera,
            splats,
            settings,
            out,
            &Cotangents {
                image,
                alpha: None,
                depth: None,
            },
        )
    };
    let Some(d_flow) = d_flow else {
        return Ok(backward(d_image)?);
    };
    let mut padded = vec![0.0f32; d_image.len()];
    padded[..d_flow.len()].copy_from_slice(d_flow);
    let flow = backward(&padded)?;
    if d_image.iter().all(|&v| v == 0.0) {
        // Only the flow loss reaches this frame (frame k+1 without the event loss): one backward.
        return Ok(Gradients {
            opacity_logits: vec![0.0; flow.opacity_logits.len()],
            channels: vec![0.0; flow.channels.len()],
            background: vec![0.0; flow.background.len()],
            ..flow
        });
    }
    let mut grads = backward(d_image)?;
    let add = |a: &mut [f32], b: &[f32]| a.iter_mut().zip(b).for_each(|(x, &y)| *x += y);
    add(grads.means.as_flattened_mut(), flow.means.as_flattened());
    add(
        grads.means_2d.as_flattened_mut(),
        flow.means_2d.as_flattened(),
    );
    for (a, b) in grads.covariances.iter_mut().zip(&flow.covariances) {
        add(a.as_flattened_mut(), b.as_flattened());
    }
    Ok(grads)
}

/// All state of a reconstruction: parameters, optimiser moments, density statistics, the frame-order
/// RNG and the step count. Saving and loading it resumes a run bit for bit.
#[derive(Clone, Debug)]
pub struct Trainer {
    /// Hyper-parameters.
    pub config: TrainConfig,
    /// The Gaussians (human ones in canonical space, scene ones in world space).
    pub set: GaussianSet,
    /// The four networks.
    pub nets: ModelNets<f32>,
    /// Per-training-frame latents, (frames, latent_dim).
    pub latents: Vec<f32>,
    /// Frame number of each latent slot (the training frames in time order).
    pub frame_indices: Vec<u32>,
    /// Steps taken.
    pub step: usize,
    /// Scene extent (m): scales the position rate and the density thresholds.
    pub scene_extent: f32,
    adam: GaussianAdam,
    nonrigid_adam: nn::Adam<f32>,
    skinning_adam: nn::Adam<f32>,
    human_colour_adam: nn::Adam<f32>,
    scene_colour_adam: nn::Adam<f32>,
    latent_adam: nn::Adam<f32>,
    stats: DensityStats,
    rng: ChaCha8Rng,
    order: Vec<usize>,
    aiap_index: Vec<usize>,
    aiap_neighbours: Vec<u32>,
}

fn net_adam(lr: f32, len: usize) -> nn::Adam<f32> {
    nn::Adam::new(
        len,
        nn::AdamConfig {
            lr: f64::from(lr),
            ..nn::AdamConfig::default()
        },
    )
}

fn adam_config(lr: f32) -> nn::AdamConfig {
    nn::AdamConfig {
        lr: f64::from(lr),
        ..nn::AdamConfig::default()
    }
}

/// Builds the four networks of `config` for the canonical body `vertices`.
pub fn build_nets(
    config: &TrainConfig,
    vertices: &[[f32; 3]],
) -> Result<ModelNets<f32>, TrainError> {
    let mut human = ColourNetConfig::human();
    human.feature_dim = config.feature_dim;
    human.latent_dim = config.latent_dim;
    let mut scene = ColourNetConfig::scene();
    scene.feature_dim = config.feature_dim;
    Ok(ModelNets {
        nonrigid: NonRigidNet::new(vertices, config.deform_hidden, config.seed ^ 0x11)?,
        skinning: SkinningField::new(vertices, config.deform_hidden, config.seed ^ 0x22)?,
        human_colour: ColourNet::new(human, config.seed ^ 0x33)?,
        scene_colour: ColourNet::new(scene, config.seed ^ 0x44)?,
    })
}

/// Fits the skinning field to the body's skinning weights on the context's canonical surface samples
/// (`config.skinning_warmup_steps` Adam steps of the skinning loss, 2048 samples each, its own
/// optimiser state, deterministic).
pub fn warm_up_skinning(
    field: &mut SkinningField<f32>,
    ctx: &TrainContext,
    config: &TrainConfig,
) -> Result<(), TrainError> {
    let pool = ctx.skin_points.len();
    if config.skinning_warmup_steps == 0 || pool == 0 {
        return Ok(());
    }
    let nb = ctx.skin_weights.len() / pool;
    let m = 2048.min(pool);
    let mut adam = net_adam(config.lr_skinning.max(1e-3) * 5.0, field.mlp.num_params());
    for step in 0..config.skinning_warmup_steps {
        let start = (step * m) % pool;
        let idx: Vec<usize> = (0..m).map(|j| (start + j) % pool).collect();
        let pts: Vec<[f32; 3]> = idx.iter().map(|&j| ctx.skin_points[j]).collect();
        let target: Vec<f32> = idx
            .iter()
            .flat_map(|&j| ctx.skin_weights[j * nb..(j + 1) * nb].iter().copied())
            .collect();
        let (pred, cache) = field.forward(&pts)?;
        let (_, d_pred) = skinning_loss(&pred, &target);
        let mut grads = vec![0.0f32; field.mlp.num_params()];
        field.backward(&cache, &d_pred, &mut grads)?;
        adam.step(&mut field.mlp.params, &grads)?;
    }
    Ok(())
}

/// Scene extent of an initial cube: half its diagonal.
fn extent_of(cube: &([f32; 3], [f32; 3])) -> f32 {
    let (lo, hi) = cube;
    let d2: f32 = (0..3).map(|a| (hi[a] - lo[a]).powi(2)).sum();
    (0.5 * d2.sqrt()).max(1e-3)
}

impl Trainer {
    /// Initialises the model (paper §4.2) for `ctx` and fresh optimiser state.
    pub fn new(ctx: &TrainContext, config: TrainConfig) -> Result<Self, TrainError> {
        config.validate()?;
        let vertices = &ctx.body.canonical.posed.vertices;
        let roots: Vec<[f32; 3]> = ctx.frames.iter().map(|f| f.pose.root).collect();
        let init = initialise(
            vertices,
            &ctx.body.model.faces,
            &ctx.body.model.weights,
            std::slice::from_ref(&ctx.camera),
            &roots,
            &InitConfig {
                mode: config.init,
                semantic: config.semantic,
                semantic_init: config.semantic_init,
                human_count: config.human_gaussians,
                scene_count: config.scene_gaussians,
                logit_magnitude: config.logit_magnitude,
                feature_dim: config.feature_dim,
                opacity: config.initial_opacity,
                max_initial_scale: config.max_initial_scale,
                seed: config.seed,
                ..InitConfig::default()
            },
        );
        let mut nets = build_nets(&config, vertices)?;
        warm_up_skinning(&mut nets.skinning, ctx, &config)?;
        let latents = vec![0.0; ctx.frames.len() * config.latent_dim];
        let frame_indices = ctx.frames.iter().map(|f| f.index).collect();
        Self::from_parts(
            config,
            init.set,
            nets,
            latents,
            frame_indices,
            extent_of(&init.cube),
        )
    }

    /// A trainer (fresh optimiser state) around existing parameters, e.g. a saved model.
    pub fn from_parts(
        config: TrainConfig,
        set: GaussianSet,
        nets: ModelNets<f32>,
        latents: Vec<f32>,
        frame_indices: Vec<u32>,
        scene_extent: f32,
    ) -> Result<Self, TrainError> {
        config.validate()?;
        let k = config.semantic.logits_per_gaussian();
        if set.semantic_logits.len() != set.len() * k || set.feature_dim != config.feature_dim {
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
        let adam = GaussianAdam::new(&set, AdamConfig::default());
        let mut t = Self {
            nonrigid_adam: net_adam(config.lr_nonrigid, nets.nonrigid.mlp.num_params()),
            skinning_adam: net_adam(config.lr_skinning, nets.skinning.mlp.num_params()),
            human_colour_adam: net_adam(config.lr_colour, nets.human_colour.mlp.num_params()),
            scene_colour_adam: net_adam(config.lr_colour, nets.scene_colour.mlp.num_params()),
            latent_adam: net_adam(config.lr_latent, latents.len()),
            stats: DensityStats::new(set.len()),
            rng: ChaCha8Rng::seed_from_u64(config.seed ^ 0x0dde_0000),
            order: Vec::new(),
            aiap_index: Vec::new(),
            aiap_neighbours: Vec::new(),
            adam,
            config,
            set,
            nets,
            latents,
            frame_indices,
            step: 0,
            scene_extent,
        };
        t.refresh_neighbours();
        Ok(t)
    }

    /// Human probability of Gaussian `i`.
    pub fn probability(&self, i: usize) -> f32 {
        let k = self.config.semantic.logits_per_gaussian();
        self.config
            .semantic
            .probability(&self.set.semantic_logits[i * k..(i + 1) * k])
    }

    /// Number of Gaussians with human probability ≥ 0.5.
    pub fn human_count(&self) -> usize {
        (0..self.set.len())
            .filter(|&i| self.probability(i) >= 0.5)
            .count()
    }

    /// Recomputes the AIAP neighbourhoods (K nearest human Gaussians in canonical space).
    fn refresh_neighbours(&mut self) {
        self.aiap_index = (0..self.set.len())
            .filter(|&i| self.probability(i) >= 0.5)
            .collect();
        let points: Vec<[f32; 3]> = self.aiap_index.iter().map(|&i| self.set.means[i]).collect();
        self.aiap_neighbours = if points.len() > crate::aiap::AIAP_NEIGHBOURS {
            gaussians::init::knn_indices(&points, crate::aiap::AIAP_NEIGHBOURS)
        } else {
            Vec::new()
        };
    }

    fn params(&self) -> GaussianParams<'_, f32> {
        GaussianParams {
            means: &self.set.means,
            log_scales: &self.set.log_scales,
            quats: &self.set.quats,
            features: &self.set.features,
            semantic_logits: &self.set.semantic_logits,
        }
    }

    /// The rasterizer's view of a posed frame: its means and covariances with the set's opacities and
    /// the interleaved render channels.
    fn splats<'a>(&'a self, posed: &'a PosedFrame<f32>, channels: &'a [f32]) -> CovSplats<'a, f32> {
        CovSplats {
            means: &posed.means,
            covariances: &posed.covariances,
            opacity_logits: &self.set.opacity_logits,
            channels,
            num_channels: RENDER_CHANNELS,
        }
    }

    fn settings(&self) -> RenderSettings {
        let mut background: Vec<f64> = self
            .config
            .background
            .iter()
            .map(|&v| f64::from(v))
            .collect();
        background.push(0.0);
        RenderSettings {
            near_plane: 0.2,
            background,
        }
    }

    /// Renders the model in `pose` with the frame latent `latent` from `camera`.
    pub fn render(
        &self,
        camera: &Camera,
        pose: &PreparedPose,
        latent: &[f32],
    ) -> Result<Rendered, TrainError> {
        let (posed, _, out) = self.forward(camera, pose, latent)?;
        let hw = camera.width as usize * camera.height as usize;
        Ok(Rendered {
            rgb: out.image[..3 * hw].to_vec(),
            human: out.image[3 * hw..4 * hw].to_vec(),
            posed,
        })
    }

    /// The latent of the training frame nearest in frame number to `index` (for unseen frames).
    pub fn latent_for(&self, index: u32) -> &[f32] {
        let d = self.config.latent_dim;
        let slot = self
            .frame_indices
            .iter()
            .enumerate()
            .min_by_key(|(_, &f)| (i64::from(f) - i64::from(index)).abs())
            .map_or(0, |(s, _)| s);
        &self.latents[slot * d..(slot + 1) * d]
    }

    #[allow(clippy::type_complexity)]
    fn forward(
        &self,
        camera: &Camera,
        pose: &PreparedPose,
        latent: &[f32],
    ) -> Result<
        (
            PosedFrame<f32>,
            crate::posing::FrameCache<f32>,
            RenderOutput<f32>,
        ),
        TrainError,
    > {
        let centre = camera.center_world().map(|v| v as f32);
        let frame = FrameInputs {
            pose_code: &pose.pose_code,
            bones: &pose.bones,
            camera_centre: centre,
            latent,
        };
        let (posed, cache) = pose_frame_gated(
            &self.nets,
            self.config.semantic,
            self.config.semantic_gate,
            &self.params(),
            &frame,
        )?;
        let channels = interleave_channels(&posed);
        let splats = self.splats(&posed, &channels);
        let out = render_cov(camera, &splats, &self.settings())?;
        Ok((posed, cache, out))
    }

    /// Runs steps until `self.step == until`, calling `on_step` after each.
    pub fn run(
        &mut self,
        ctx: &TrainContext,
        until: usize,
        mut on_step: impl FnMut(&Self, &StepReport) -> Result<(), TrainError>,
    ) -> Result<(), TrainError> {
        while self.step < until {
            let report = self.train_step(ctx)?;
            on_step(self, &report)?;
        }
        Ok(())
    }

    /// One optimisation step on the next training frame of the seeded order. On a non-finite loss or
    /// gradient nothing is updated and [`TrainError::NonFinite`] is returned.
    pub fn train_step(&mut self, ctx: &TrainContext) -> Result<StepReport, TrainError> {
        let config = self.config.clone();
        let step = self.step;
        if self.order.is_empty() {
            self.order = (0..ctx.frames.len()).collect();
            self.order.shuffle(&mut self.rng);
        }
        let slot = self.order.pop().unwrap_or(0) % ctx.frames.len();
        let frame = &ctx.frames[slot];
        let camera = &ctx.camera;
        let hw = ctx.pixels();
        let d = config.latent_dim;
        let latent = self.latents[slot * d..(slot + 1) * d].to_vec();
        let mut times = StageTimes::default();

        let t0 = Instant::now();
        let centre = camera.center_world().map(|v| v as f32);
        let frame_inputs = FrameInputs {
            pose_code: &frame.pose.pose_code,
            bones: &frame.pose.bones,
            camera_centre: centre,
            latent: &latent,
        };
        let (posed, cache) = pose_frame_gated(
            &self.nets,
            config.semantic,
            config.semantic_gate,
            &self.params(),
            &frame_inputs,
        )?;
        let channels = interleave_channels(&posed);
        times.pose = t0.elapsed().as_secs_f64();

        let t0 = Instant::now();
        let splats = self.splats(&posed, &channels);
        let settings = self.settings();
        let out = render_cov(camera, &splats, &settings)?;
        times.render = t0.elapsed().as_secs_f64();

        let t0 = Instant::now();
        let rgb = &out.image[..3 * hw];
        let shape = ImageShape {
            channels: 3,
            height: camera.height as usize,
            width: camera.width as usize,
        };
        let mut d_l1 = vec![0.0f32; 3 * hw];
        let mut d_ssim = vec![0.0f32; 3 * hw];
        let l1_value = l1(rgb, &frame.image, Some(&mut d_l1));
        let ssim_value = ssim(rgb, &frame.image, shape, Some(&mut d_ssim));
        let w = config.ssim_weight;
        let photometric = (1.0 - w) * l1_value + w * (1.0 - ssim_value);
        let mut d_image = vec![0.0f32; RENDER_CHANNELS * hw];
        for (o, (&a, &b)) in d_image.iter_mut().zip(d_l1.iter().zip(&d_ssim)) {
            *o = (1.0 - w) * a - w * b;
        }
        times.loss = t0.elapsed().as_secs_f64();

        // Flow loss on the pair (k, k+1): render frame k+1 too; L_flow's gradient w.r.t. frame k's
        // render joins the photometric one, frame k+1's goes back through its own render and pose.
        let t_flow = Instant::now();
        let flow_pair = match (config.flow_loss, ctx.flow_net.as_ref()) {
            (true, Some(net)) => ctx
                .flow_pairs
                .get(slot)
                .and_then(Option::as_ref)
                .map(|p| (net, p)),
            _ => None,
        };
        let event_pair = if config.event_loss {
            ctx.event_pairs.get(slot).and_then(Option::as_ref)
        } else {
            None
        };
        let next_slot = flow_pair
            .map(|(_, p)| p.next_slot)
            .or(event_pair.map(|p| p.next_slot));
        let (mut flow_value, mut event_value) = (0.0f32, 0.0f32);
        // With `FlowGradient::Geometry`, the flow loss's image cotangents (RGB of frames k and k+1),
        // kept apart from the other losses' so that only their geometric share is used.
        let (mut d_flow_first, mut d_flow_second) = (None, None);
        let mut second = None;
        if let Some(next_slot) = next_slot {
            let next = &ctx.frames[next_slot];
            let latent2 = self.latents[next_slot * d..(next_slot + 1) * d].to_vec();
            let (posed2, cache2, out2) = self.forward(camera, &next.pose, &latent2)?;
            let rgb2 = &out2.image[..3 * hw];
            let mut d_image2 = vec![0.0f32; RENDER_CHANNELS * hw];
            if let Some((net, pair)) = flow_pair {
                let t_network = Instant::now();
                let (height, width) = (camera.height as usize, camera.width as usize);
                let (fl_loss, fl_d_first, fl_d_second) = match config.flow_measure {
                    FlowMeasure::Network => {
                        let fl = pair_flow_loss(net, rgb, rgb2, height, width, &pair.target)?;
                        (fl.loss, fl.d_first, fl.d_second)
                    }
                    FlowMeasure::Warp => {
                        let wl = pair_warp_loss(rgb, rgb2, height, width, &pair.target)?;
                        (wl.loss, wl.d_first, wl.d_second)
                    }
                };
                times.flow_network = t_network.elapsed().as_secs_f64();
                let lambda = config.flow_weight;
                flow_value = lambda * fl_loss;
                let scaled = |g: &[f32]| g.iter().map(|&v| lambda * v).collect::<Vec<f32>>();
                match config.flow_gradient {
                    FlowGradient::All => {
                        for (o, &g) in d_image[..3 * hw].iter_mut().zip(&fl_d_first) {
                            *o += lambda * g;
                        }
                        for (o, &g) in d_image2[..3 * hw].iter_mut().zip(&fl_d_second) {
                            *o += lambda * g;
                        }
                    }
                    FlowGradient::Geometry => {
                        d_flow_first = Some(scaled(&fl_d_first));
                        d_flow_second = Some(scaled(&fl_d_second));
                    }
                }
            }
            if let Some(pair) = event_pair {
                let el = pair_event_loss(rgb, rgb2, &pair.expected, config.event_log_eps);
                let lambda = config.event_weight;
                event_value = lambda * el.loss;
                for (o, &g) in d_image[..3 * hw].iter_mut().zip(&el.d_first) {
                    *o += lambda * g;
                }
                for (o, &g) in d_image2[..3 * hw].iter_mut().zip(&el.d_second) {
                    *o += lambda * g;
                }
            }
            second = Some((next_slot, latent2, posed2, cache2, out2, d_image2));
        }
        times.flow = t_flow.elapsed().as_secs_f64();

        let t0 = Instant::now();
        let rg = backward_with_geometric_flow(
            camera,
            &splats,
            &settings,
            &out,
            &d_image,
            d_flow_first.as_deref(),
        )?;
        times.render_backward = t0.elapsed().as_secs_f64();

        let t0 = Instant::now();
        let (d_colours, d_prob) = split_channel_cotangents(&rg.channels);
        let mut d_posed_means = rg.means.clone();
        let mut d_posed_covs = rg.covariances.clone();
        // AIAP on the human Gaussians: canonical vs posed positions and covariances.
        let mut d_canon_means = vec![[0.0f32; 3]; self.aiap_index.len()];
        let mut d_canon_covs = vec![[0.0f32; 6]; self.aiap_index.len()];
        let mut aiap_value = 0.0f32;
        if !self.aiap_neighbours.is_empty()
            && (config.aiap_position_weight > 0.0 || config.aiap_covariance_weight > 0.0)
        {
            let k = crate::aiap::AIAP_NEIGHBOURS;
            let idx = &self.aiap_index;
            let canon_x: Vec<[f32; 3]> = idx.iter().map(|&i| self.set.means[i]).collect();
            let posed_x: Vec<[f32; 3]> = idx.iter().map(|&i| posed.means[i]).collect();
            let mut d_posed_x = vec![[0.0f32; 3]; idx.len()];
            aiap_value += crate::aiap::aiap_loss(
                &canon_x,
                &posed_x,
                &self.aiap_neighbours,
                k,
                config.aiap_position_weight,
                Some(&mut d_canon_means),
                Some(&mut d_posed_x),
            );
            let canon_c: Vec<[f32; 6]> = idx
                .iter()
                .map(|&i| {
                    crate::aiap::upper_triangle(&covariance_3d(
                        self.set.log_scales[i],
                        self.set.quats[i],
                    ))
                })
                .collect();
            let posed_c: Vec<[f32; 6]> = idx
                .iter()
                .map(|&i| crate::aiap::upper_triangle(&posed.covariances[i]))
                .collect();
            let mut d_posed_c = vec![[0.0f32; 6]; idx.len()];
            aiap_value += crate::aiap::aiap_loss(
                &canon_c,
                &posed_c,
                &self.aiap_neighbours,
                k,
                config.aiap_covariance_weight,
                Some(&mut d_canon_covs),
                Some(&mut d_posed_c),
            );
            for (a, &i) in idx.iter().enumerate() {
                for ax in 0..3 {
                    d_posed_means[i][ax] += d_posed_x[a][ax];
                }
                let g = crate::aiap::upper_triangle_backward(&d_posed_c[a]);
                for r in 0..3 {
                    for c in 0..3 {
                        d_posed_covs[i][r][c] += g[r][c];
                    }
                }
            }
        }
        let mut grads = pose_frame_backward(
            &self.nets,
            config.semantic,
            &self.params(),
            &frame_inputs,
            &cache,
            &FrameCotangents {
                means: &d_posed_means,
                covariances: &d_posed_covs,
                colours: &d_colours,
                human_probability: &d_prob,
            },
        )?;
        for (a, &i) in self.aiap_index.iter().enumerate() {
            for ax in 0..3 {
                grads.means[i][ax] += d_canon_means[a][ax];
            }
            let g = crate::aiap::upper_triangle_backward(&d_canon_covs[a]);
            let (ds, dq) = covariance_3d_backward(self.set.log_scales[i], self.set.quats[i], &g);
            for ax in 0..3 {
                grads.log_scales[i][ax] += ds[ax];
            }
            for ax in 0..4 {
                grads.quats[i][ax] += dq[ax];
            }
        }
        // Frame k+1 of the flow pair: its rasterizer and model backward, accumulated.
        let mut opacity_grads = rg.opacity_logits.clone();
        let mut second_latent = None;
        let mut second_backward_seconds = 0.0;
        if let Some((next_slot, latent2, posed2, cache2, out2, d_image2)) = second {
            let t_flow = Instant::now();
            let channels2 = interleave_channels(&posed2);
            let splats2 = self.splats(&posed2, &channels2);
            let rg2 = backward_with_geometric_flow(
                camera,
                &splats2,
                &settings,
                &out2,
                &d_image2,
                d_flow_second.as_deref(),
            )?;
            let (d_colours2, d_prob2) = split_channel_cotangents(&rg2.channels);
            let next = &ctx.frames[next_slot];
            let inputs2 = FrameInputs {
                pose_code: &next.pose.pose_code,
                bones: &next.pose.bones,
                camera_centre: centre,
                latent: &latent2,
            };
            let grads2 = pose_frame_backward(
                &self.nets,
                config.semantic,
                &self.params(),
                &inputs2,
                &cache2,
                &FrameCotangents {
                    means: &rg2.means,
                    covariances: &rg2.covariances,
                    colours: &d_colours2,
                    human_probability: &d_prob2,
                },
            )?;
            grads.add_shared(&grads2);
            for (o, &g) in opacity_grads.iter_mut().zip(&rg2.opacity_logits) {
                *o += g;
            }
            second_latent = Some((next_slot, grads2.latent));
            second_backward_seconds = t_flow.elapsed().as_secs_f64();
            times.flow += second_backward_seconds;
        }
        // Skinning loss on canonical surface samples (a window of the pool that moves every step).
        let mut skinning_value = 0.0f32;
        if step < config.skinning_until
            && config.skinning_weight > 0.0
            && !ctx.skin_points.is_empty()
        {
            let m = config.skinning_samples.min(ctx.skin_points.len()).max(1);
            let pool = ctx.skin_points.len();
            let start = (step * m) % pool;
            let nb = ctx.skin_weights.len() / pool;
            let idx: Vec<usize> = (0..m).map(|j| (start + j) % pool).collect();
            let pts: Vec<[f32; 3]> = idx.iter().map(|&j| ctx.skin_points[j]).collect();
            let target: Vec<f32> = idx
                .iter()
                .flat_map(|&j| ctx.skin_weights[j * nb..(j + 1) * nb].iter().copied())
                .collect();
            let (pred, skin_cache) = self.nets.skinning.forward(&pts)?;
            let (value, mut d_pred) = skinning_loss(&pred, &target);
            for g in &mut d_pred {
                *g *= config.skinning_weight;
            }
            skinning_value = value * config.skinning_weight;
            self.nets
                .skinning
                .backward(&skin_cache, &d_pred, &mut grads.skinning)?;
        }
        // (Frame k+1's backward ran inside this interval; it is counted under `flow`.)
        times.model_backward = t0.elapsed().as_secs_f64() - second_backward_seconds;

        let loss = photometric + aiap_value + skinning_value + flow_value + event_value;
        let finite = loss.is_finite()
            && opacity_grads.iter().all(|v| v.is_finite())
            && second_latent
                .as_ref()
                .is_none_or(|(_, g)| g.iter().all(|v| v.is_finite()))
            && grads.means.iter().flatten().all(|v| v.is_finite())
            && grads.log_scales.iter().flatten().all(|v| v.is_finite())
            && grads.quats.iter().flatten().all(|v| v.is_finite())
            && grads.features.iter().all(|v| v.is_finite())
            && grads.semantic_logits.iter().all(|v| v.is_finite())
            && grads.nonrigid.iter().all(|v| v.is_finite())
            && grads.skinning.iter().all(|v| v.is_finite())
            && grads.human_colour.iter().all(|v| v.is_finite())
            && grads.scene_colour.iter().all(|v| v.is_finite())
            && grads.latent.iter().all(|v| v.is_finite());
        if !finite {
            return Err(TrainError::NonFinite { step });
        }

        let t0 = Instant::now();
        let mut set_grads = self.set.zeros_like();
        set_grads.means = grads.means;
        set_grads.log_scales = grads.log_scales;
        set_grads.quats = grads.quats;
        set_grads.opacity_logits = opacity_grads;
        set_grads.features = grads.features;
        set_grads.semantic_logits = grads.semantic_logits;
        let rates = GaussianLearningRates {
            means: exponential_rate(
                config.lr_means * self.scene_extent,
                config.lr_means_final_fraction,
                step,
                config.steps,
            ),
            log_scales: config.lr_log_scales,
            quats: config.lr_quats,
            opacity_logits: config.lr_opacity,
            sh_dc: 0.0,
            sh_rest: 0.0,
            features: config.lr_features,
            semantic_logits: config.lr_semantic,
        };
        self.adam
            .step(&mut self.set, &set_grads, &rates)
            .map_err(|e| TrainError::Config(e.to_string()))?;
        if step >= config.nonrigid_from {
            self.nonrigid_adam
                .step(&mut self.nets.nonrigid.mlp.params, &grads.nonrigid)?;
        }
        self.skinning_adam
            .step(&mut self.nets.skinning.mlp.params, &grads.skinning)?;
        self.human_colour_adam
            .step(&mut self.nets.human_colour.mlp.params, &grads.human_colour)?;
        self.scene_colour_adam
            .step(&mut self.nets.scene_colour.mlp.params, &grads.scene_colour)?;
        let mut latent_grads = vec![0.0f32; self.latents.len()];
        latent_grads[slot * d..(slot + 1) * d].copy_from_slice(&grads.latent);
        if let Some((next_slot, g)) = &second_latent {
            latent_grads[next_slot * d..(next_slot + 1) * d].copy_from_slice(g);
        }
        self.latent_adam.step(&mut self.latents, &latent_grads)?;
        times.adam = t0.elapsed().as_secs_f64();

        let t0 = Instant::now();
        accumulate_screen_stats(&mut self.stats, camera, &rg.means_2d, &out.radii);
        let done = step + 1;
        if on_schedule(
            done,
            config.densify_from,
            config.densify_until,
            config.densify_every,
        ) {
            let densify = DensifyConfig {
                grad_threshold: config.densify_grad_threshold,
                scene_extent: self.scene_extent,
                min_opacity: config.prune_min_opacity,
                max_gaussians: config.max_gaussians,
                ..DensifyConfig::default()
            };
            densify_and_prune(
                &mut self.set,
                &mut self.adam,
                &mut self.stats,
                &densify,
                config.seed ^ (done as u64).wrapping_mul(0x9e37_79b9),
            );
            self.refresh_neighbours();
        }
        if config.opacity_reset_every > 0
            && done.is_multiple_of(config.opacity_reset_every)
            && done < config.steps
        {
            reset_opacity(&mut self.set, &mut self.adam, 0.01);
        }
        times.density = t0.elapsed().as_secs_f64();
        self.step = done;
        let human = self.human_count();
        Ok(StepReport {
            step,
            frame: frame.index,
            loss,
            l1: l1_value,
            ssim: ssim_value,
            skinning: skinning_value,
            aiap: aiap_value,
            flow: flow_value,
            event: event_value,
            psnr: psnr(rgb, &frame.image),
            gaussians_human: human,
            gaussians_scene: self.set.len() - human,
            active: cache.active().len(),
            times,
        })
    }

    /// Writes the whole state to one safetensors file atomically (temporary sibling + rename).
    pub fn save_checkpoint(&self, path: &Path) -> Result<(), TrainError> {
        let mut w = CheckpointWriter::default();
        w.push_set("set", &self.set);
        let adam_steps = w.push_gaussian_adam("adam", &self.adam);
        w.push("nonrigid", self.nets.nonrigid.mlp.params.clone());
        w.push("skinning", self.nets.skinning.mlp.params.clone());
        w.push("human_colour", self.nets.human_colour.mlp.params.clone());
        w.push("scene_colour", self.nets.scene_colour.mlp.params.clone());
        w.push("latents", self.latents.clone());
        let net_adam_steps: Vec<u64> = NET_OPTIMISERS
            .iter()
            .zip([
                &self.nonrigid_adam,
                &self.skinning_adam,
                &self.human_colour_adam,
                &self.scene_colour_adam,
                &self.latent_adam,
            ])
            .map(|(name, adam)| w.push_adam(&format!("{name}_adam"), adam))
            .collect();
        w.push_stats("stats", &self.stats);
        // Indices as float32: exact below 2^24, which `TrainConfig::validate` bounds the count by.
        w.push(
            "aiap.index",
            self.aiap_index.iter().map(|&i| i as f32).collect(),
        );
        w.push(
            "aiap.neighbours",
            self.aiap_neighbours.iter().map(|&i| i as f32).collect(),
        );
        let (rng_seed, rng_word_pos) = rng_to_strings(&self.rng);
        let meta = CheckpointMeta {
            format: CHECKPOINT_FORMAT.into(),
            config: self.config.clone(),
            step: self.step,
            scene_extent: self.scene_extent,
            sh_degree: self.set.sh_degree,
            adam_steps,
            net_adam_steps,
            rng_seed,
            rng_word_pos,
            order: self.order.clone(),
        };
        let json = serde_json::to_string(&meta).map_err(|e| TrainError::Checkpoint {
            path: path.to_path_buf(),
            message: e.to_string(),
        })?;
        w.write(path, &json)
    }

    /// Restores a trainer saved by [`Trainer::save_checkpoint`] for the context `ctx` (which supplies the
    /// canonical body the networks normalise by). The stored configuration is used.
    pub fn load_checkpoint(path: &Path, ctx: &TrainContext) -> Result<Self, TrainError> {
        let r = CheckpointReader::open(path)?;
        let meta: CheckpointMeta =
            serde_json::from_str(&r.metadata).map_err(|e| r.error(format!("metadata: {e}")))?;
        if meta.format != CHECKPOINT_FORMAT {
            return Err(r.error(format!("unknown checkpoint format `{}`", meta.format)));
        }
        let config = meta.config;
        config.validate()?;
        let k = config.semantic.logits_per_gaussian();
        let set = r.set("set", meta.sh_degree, config.feature_dim, k)?;
        let mut nets = build_nets(&config, &ctx.body.canonical.posed.vertices)?;
        let load = |name: &str, params: &mut Vec<f32>| -> Result<(), TrainError> {
            *params = r.get_len(name, params.len())?;
            Ok(())
        };
        load("nonrigid", &mut nets.nonrigid.mlp.params)?;
        load("skinning", &mut nets.skinning.mlp.params)?;
        load("human_colour", &mut nets.human_colour.mlp.params)?;
        load("scene_colour", &mut nets.scene_colour.mlp.params)?;
        let latents = r.get_len("latents", ctx.frames.len() * config.latent_dim)?;
        let frame_indices = ctx.frames.iter().map(|f| f.index).collect();
        let mut t = Self::from_parts(config, set, nets, latents, frame_indices, meta.scene_extent)?;
        r.gaussian_adam("adam", &mut t.adam, &meta.adam_steps)?;
        if meta.net_adam_steps.len() != NET_OPTIMISERS.len() {
            return Err(r.error(format!(
                "expected {} network optimiser step counts",
                NET_OPTIMISERS.len()
            )));
        }
        let c = &t.config;
        let rates = [
            c.lr_nonrigid,
            c.lr_skinning,
            c.lr_colour,
            c.lr_colour,
            c.lr_latent,
        ];
        let load = |k: usize, len: usize| {
            r.adam(
                &format!("{}_adam", NET_OPTIMISERS[k]),
                adam_config(rates[k]),
                len,
                meta.net_adam_steps[k],
            )
        };
        t.nonrigid_adam = load(0, t.nets.nonrigid.mlp.num_params())?;
        t.skinning_adam = load(1, t.nets.skinning.mlp.num_params())?;
        t.human_colour_adam = load(2, t.nets.human_colour.mlp.num_params())?;
        t.scene_colour_adam = load(3, t.nets.scene_colour.mlp.num_params())?;
        t.latent_adam = load(4, t.latents.len())?;
        t.stats = r.stats("stats", t.set.len())?;
        let n = t.set.len();
        let index = r.get("aiap.index")?;
        let neighbours = r.get("aiap.neighbours")?;
        let bad = |v: &f32, bound: usize| !(*v >= 0.0 && (*v as usize) < bound && v.fract() == 0.0);
        if index.iter().any(|v| bad(v, n))
            || neighbours.iter().any(|v| bad(v, index.len()))
            || neighbours.len() != index.len() * crate::aiap::AIAP_NEIGHBOURS
                && !neighbours.is_empty()
        {
            return Err(r.error("AIAP neighbourhoods do not match the Gaussians"));
        }
        t.aiap_index = index.iter().map(|&v| v as usize).collect();
        t.aiap_neighbours = neighbours.iter().map(|&v| v as u32).collect();
        t.rng = rng_from_strings(&meta.rng_seed, &meta.rng_word_pos).map_err(|e| r.error(e))?;
        t.order = meta.order;
        t.step = meta.step;
        Ok(t)
    }
}

/// Per-Gaussian render channels (r, g, b, p), N × 4 row-major.
fn interleave_channels(posed: &PosedFrame<f32>) -> Vec<f32> {
    let n = posed.means.len();
    let mut channels = Vec::with_capacity(n * RENDER_CHANNELS);
    for i in 0..n {
        channels.extend_from_slice(&posed.colours[i * 3..i * 3 + 3]);
        channels.push(posed.human_probability[i]);
    }
    channels
}

/// Non-tensor state of a checkpoint (JSON in the safetensors metadata).
#[derive(serde::Serialize, serde::Deserialize)]
struct CheckpointMeta {
    format: String,
    config: TrainConfig,
    step: usize,
    scene_extent: f32,
    sh_degree: usize,
    adam_steps: Vec<u64>,
    net_adam_steps: Vec<u64>,
    rng_seed: String,
    rng_word_pos: String,
    order: Vec<usize>,
}

/// The flow loss's target for the pair (frame `p`, frame `p + 1`) from the `kind` flow that
/// `scene.json` names for frame `p` (and its validity mask), resized to `size_out`. A missing flow,
/// an unreadable file or a flow or mask of the wrong size is an error naming the frame or the file.
fn file_flow_target(
    data: &Dataset,
    p: usize,
    kind: scene::FlowKind,
    config: &TrainConfig,
    (h, w): (usize, usize),
    (h_out, w_out): (usize, usize),
) -> Result<FlowTarget<f32>, TrainError> {
    let f = &data.frames[p];
    let Some(fr) = data.scene.frames[p].flow(kind) else {
        return Err(TrainError::Config(format!(
            "{}: frame {} has no `{}` flow to the next training frame {} (needed by \
             the flow loss with flow source {:?})",
            data.dir.display(),
            f.index,
            kind.as_str(),
            data.frames[p + 1].index,
            config.flow_source
        )));
    };
    let path = scene::Scene::resolve(&data.dir, &fr.path);
    let flow = events::read_flow(&path)
        .map_err(|e| TrainError::Config(format!("{}: {e}", path.display())))?;
    if (flow.width, flow.height) != (w, h) {
        return Err(TrainError::Config(format!(
            "{}: flow is {}x{}, the camera is {w}x{h}",
            path.display(),
            flow.width,
            flow.height
        )));
    }
    let valid = match &fr.valid_mask {
        Some(rel) => {
            let mp = scene::Scene::resolve(&data.dir, rel);
            let (mw, mh, m) = scene::read_mask(&mp)?;
            if (mw as usize, mh as usize) != (w, h) {
                return Err(TrainError::Config(format!(
                    "{}: mask is {mw}x{mh}, the camera is {w}x{h}",
                    mp.display()
                )));
            }
            Some(m)
        }
        None => None,
    };
    Ok(prepare_target(
        &flow.data,
        valid.as_deref(),
        h,
        w,
        h_out,
        w_out,
        config.flow_tau,
    )?)
}
