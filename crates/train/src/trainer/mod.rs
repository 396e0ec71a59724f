//! The E-Sem3DGS optimisation loop (paper §4.5): a [`Model`], its [`Optimisers`], the density
//! statistics, the frame-order RNG and the AIAP neighbourhoods. [`Trainer::step`] renders the frame
//! passes a step needs (frame k, and frame k+1 when a pair loss applies), takes their losses — L1 +
//! λ·D-SSIM, the optional LPIPS term, the pair losses, the skinning and AIAP regularisers — runs one backward per pass, guards
//! against non-finite values and steps the optimisers; [`Trainer::refine`] is density control and
//! the opacity reset on their schedules. Checkpoints (`checkpoint.rs`) resume bit for bit.
//!
//! One step = one training frame from a seeded shuffled order (reshuffled each epoch). Everything that
//! influences the parameters is deterministic for a seed and independent of the thread count; only the
//! reported stage timings vary.

mod camera;
mod checkpoint;
mod correction;
mod report;
mod step;
mod surfaces;
mod terms;

pub use report::{StageTimes, StepReport};
pub use surfaces::person_box;
pub use terms::warm_up_skinning;

use crate::config::{CameraCorrectionBasis, ExposureMotion, TrainConfig};
use crate::data::TrainingData;
use crate::density::{DensityStrategy, StepStatistics};
use crate::init::{initialise_people, BodySurface, InitConfig};
use crate::model::{Model, ModelConfig};
use crate::optimisers::{Optimisers, PoseRateScales};
use crate::pose::camera_basis::BASIS_VALUES;
use crate::pose::posing::ModelGradients;
use crate::schedule::{correction_rate_scale, exponential_rate};
use crate::TrainError;
use gaussians::adam::GaussianLearningRates;
use gaussians::density::DensityStats;
use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use terms::AiapNeighbours;

/// Identifier stored in every checkpoint of this trainer.
pub const CHECKPOINT_FORMAT: &str = "e-sem3dgs-trainer-v1";

/// All state of a reconstruction: the model, its optimisers, density statistics, the frame-order
/// RNG and the step count. Saving and loading it resumes a run bit for bit.
#[derive(Clone, Debug)]
pub struct Trainer {
    /// What is learned.
    pub model: Model,
    /// The hyper-parameters (the model keeps its own part, [`ModelConfig`]).
    config: TrainConfig,
    /// Steps taken.
    pub step: usize,
    optimisers: Optimisers,
    stats: DensityStats,
    rng: ChaCha8Rng,
    order: Vec<usize>,
    aiap: AiapNeighbours,
    /// With several people: how many times a Gaussian's most probable person changed in an
    /// update, over the whole run (checkpointed); a Gaussian never moves between people by
    /// densification, whose children inherit their parent's logits.
    pub person_changes: u64,
}

/// Scene extent of an initial cube: half its diagonal.
fn extent_of(cube: &([f32; 3], [f32; 3])) -> f32 {
    let (lo, hi) = cube;
    let d2: f32 = (0..3).map(|a| (hi[a] - lo[a]).powi(2)).sum();
    (0.5 * d2.sqrt()).max(1e-3)
}

impl Trainer {
    /// Initialises the model (paper §4.2) for `data` and fresh optimiser state.
    pub fn new(data: &TrainingData, config: TrainConfig) -> Result<Self, TrainError> {
        config.validate()?;
        if config.carries_pose_rows() && !data.others.is_empty() {
            let what = if config.pose_correction {
                "pose correction (--pose-correction on) corrects"
            } else {
                "the learned in-exposure motion (--exposure-motion learned) moves"
            };
            return Err(TrainError::Config(format!(
                "{what} one person; the scene has {}",
                data.cast().len()
            )));
        }
        let vertices = &data.body.canonical.posed.vertices;
        let mut roots: Vec<[f32; 3]> = data.frames.iter().map(|f| f.pose.prepared.root).collect();
        // The others' translations too, so that the scene cube holds every person's path.
        for f in &data.frames {
            roots.extend(f.pose.others.iter().map(|p| p.transl));
        }
        // The scene is sampled where any training frame's camera sees it.
        let cameras: Vec<_> = if data.frames.iter().all(|f| f.camera == data.camera) {
            vec![data.camera.clone()]
        } else {
            data.frames.iter().map(|f| f.camera.clone()).collect()
        };
        let bodies: Vec<BodySurface<'_>> = std::iter::once(&data.body)
            .chain(&data.others)
            .map(|b| BodySurface {
                vertices: &b.canonical.posed.vertices,
                faces: &b.model.faces,
                weights: &b.model.weights,
            })
            .collect();
        let init = initialise_people(
            &bodies,
            &cameras,
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
                scene_surface: surfaces::scene_surface(data, &config, &roots),
                ..InitConfig::default()
            },
        );
        let model_config = ModelConfig::from(&config);
        let mut nets = Model::build_networks(&model_config, vertices)?;
        warm_up_skinning(&mut nets.skinning, data, &config)?;
        let latents = vec![0.0; data.frames.len() * config.latent_dim];
        let frame_indices = data.frames.iter().map(|f| f.index).collect();
        let model = Model::new(
            model_config,
            init.set,
            nets,
            latents,
            frame_indices,
            extent_of(&init.cube),
        )?;
        let camera_basis = (config.camera_correction
            && config.camera_correction_basis == CameraCorrectionBasis::Image)
            .then(|| camera::image_motion_basis(&model, data))
            .transpose()?;
        Ok(Self::with_model(model, config, camera_basis))
    }

    /// A trainer with fresh optimiser state around `model`, built from `config` (`camera_basis`:
    /// the camera corrections' image-motion basis, [`Optimisers::new`]).
    fn with_model(
        model: Model,
        config: TrainConfig,
        camera_basis: Option<[f32; BASIS_VALUES]>,
    ) -> Self {
        Self {
            optimisers: Optimisers::new(&model, &config, camera_basis),
            stats: DensityStats::new(model.set.len()),
            rng: ChaCha8Rng::seed_from_u64(config.seed ^ 0x0dde_0000),
            config,
            order: Vec::new(),
            aiap: AiapNeighbours::of(&model),
            model,
            step: 0,
            person_changes: 0,
        }
    }

    /// Every Gaussian's most probable person with several people (empty with one).
    fn people_of_gaussians(&self) -> Vec<usize> {
        let model = &self.model;
        if model.people() == 1 {
            return Vec::new();
        }
        (0..model.set.len()).map(|i| model.person_of(i)).collect()
    }

    /// The Gaussians whose most probable person differs from `before` (of the same set), added to
    /// [`Trainer::person_changes`].
    fn count_person_changes(&mut self, before: &[usize]) -> usize {
        let model = &self.model;
        let changed = before
            .iter()
            .enumerate()
            .filter(|&(i, &p)| model.person_of(i) != p)
            .count();
        self.person_changes += changed as u64;
        changed
    }

    /// The hyper-parameters.
    pub fn config(&self) -> &TrainConfig {
        &self.config
    }

    /// Turns the sharing of static tiles between an exposure's renders on or off
    /// ([`TrainConfig::share_static_tiles`]; a speed option, e.g. for measuring a saved run both
    /// ways). The model is not changed.
    pub fn set_share_static_tiles(&mut self, share: bool) {
        self.config.share_static_tiles = share;
    }

    /// Turns the static layer behind an exposure's moving Gaussians on or off
    /// ([`TrainConfig::static_layer`]; a speed option that changes the renders only where a
    /// pixel's transmittance falls below 1e-4 inside the layer, e.g. for measuring a saved run
    /// both ways). The model is not changed.
    pub fn set_static_layer(&mut self, layer: bool) {
        self.config.static_layer = layer;
    }

    /// Sets whose skinning weights canonicalise the human colour network's view directions
    /// ([`TrainConfig::view_rotation`]) in the options and the model: to time a saved run's step
    /// both ways. Unlike the two speed options above it changes the function the model computes.
    pub fn set_view_rotation(&mut self, rotation: crate::config::ViewRotation) {
        self.config.view_rotation = rotation;
        self.model.config.view_rotation = rotation;
    }

    /// Runs steps until `self.step == until`, calling `on_step` after each.
    pub fn run(
        &mut self,
        data: &TrainingData,
        until: usize,
        mut on_step: impl FnMut(&Self, &StepReport) -> Result<(), TrainError>,
    ) -> Result<(), TrainError> {
        while self.step < until {
            let report = self.step(data)?;
            on_step(self, &report)?;
        }
        Ok(())
    }

    /// The training slot of the next step: the seeded order, reshuffled each epoch.
    fn next_slot(&mut self, frames: usize) -> usize {
        if self.order.is_empty() {
            self.order = (0..frames).collect();
            self.order.shuffle(&mut self.rng);
        }
        self.order.pop().unwrap_or(0) % frames
    }

    /// One optimiser step of every parameter group: the Gaussians (position rate decayed over the
    /// run), the networks (the non-rigid one only from `nonrigid_from` on), the latents of the
    /// step's frames and, when given, the pose corrections (their gradient and the knots to step).
    fn apply_gradients(
        &mut self,
        slot: usize,
        grads: ModelGradients<f32>,
        opacity_grads: Vec<f32>,
        second_latent: Option<(usize, Vec<f32>)>,
        correction_update: Option<(Vec<f32>, Vec<usize>)>,
        camera_update: Option<camera::CameraGradient>,
    ) -> Result<(), TrainError> {
        let config = &self.config;
        let step = self.step;
        let mut set_grads = self.model.set.zeros_like();
        set_grads.means = grads.means;
        set_grads.log_scales = grads.log_scales;
        set_grads.quats = grads.quats;
        set_grads.opacity_logits = opacity_grads;
        set_grads.features = grads.features;
        set_grads.semantic_logits = grads.semantic_logits;
        let rates = GaussianLearningRates {
            means: exponential_rate(
                config.lr_means * self.model.scene_extent,
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
        let d = config.latent_dim;
        let mut latent_grads = vec![0.0f32; self.model.latents.len()];
        latent_grads[slot * d..(slot + 1) * d].copy_from_slice(&grads.latent);
        if let Some((next_slot, g)) = &second_latent {
            latent_grads[next_slot * d..(next_slot + 1) * d].copy_from_slice(g);
        }
        let nonrigid_frozen = step < config.nonrigid_from;
        let pose_scale = |fraction| {
            correction_rate_scale(fraction, config.pose_correction_from, step, config.steps)
        };
        let mid = pose_scale(config.lr_pose_correction_final_fraction);
        let pose_scales = PoseRateScales {
            mid,
            change: if config.exposure_motion == ExposureMotion::Learned {
                pose_scale(config.lr_exposure_motion_final_fraction)
            } else {
                mid
            },
        };
        self.optimisers
            .step_gaussians(&mut self.model.set, &set_grads, &rates)?;
        let [nonrigid, skinning, human_colour, scene_colour, latents, corrections] =
            self.model.network_groups_mut();
        let no_correction = Vec::new();
        let groups = [
            ("nonrigid", nonrigid, &grads.nonrigid),
            ("skinning", skinning, &grads.skinning),
            ("human_colour", human_colour, &grads.human_colour),
            ("scene_colour", scene_colour, &grads.scene_colour),
            ("latent", latents, &latent_grads),
            (
                "pose_correction",
                corrections,
                correction_update
                    .as_ref()
                    .map_or(&no_correction, |(g, _)| g),
            ),
        ];
        for (name, params, g) in groups {
            if name == "nonrigid" && nonrigid_frozen {
                continue;
            }
            if name == "pose_correction" {
                if let Some((_, knots)) = &correction_update {
                    self.optimisers
                        .step_pose_corrections(params, g, knots, pose_scales)?;
                }
                continue;
            }
            self.optimisers.step_network(name, params, g)?;
        }
        if let Some(update) = camera_update {
            let rate_scale = correction_rate_scale(
                config.lr_camera_final_fraction,
                config.camera_correction_from,
                step,
                config.steps,
            );
            self.optimisers.step_camera_corrections(
                &mut self.model.camera_corrections,
                &update.values,
                &update.slots,
                rate_scale,
            )?;
            // The clip-wide twist steps on every step, a frame's twist once per pass over the
            // training frames: at 1 / frames the rate it moves per pass as far as one frame's.
            let frames = self.model.frame_indices.len().max(1) as f32;
            self.optimisers.step_camera_gauge(
                &mut self.model.camera_gauge,
                &update.gauge,
                rate_scale / frames,
            )?;
            self.model.centre_camera_corrections();
        }
        Ok(())
    }

    /// Density control after a step's update (`crate::density`): the step's screen-space
    /// statistics, densify and prune on the schedule (the AIAP neighbourhoods refreshed after),
    /// and the opacity reset.
    fn refine(&mut self, data: &TrainingData, step: &StepStatistics) {
        let strategy = DensityStrategy::of(&self.config, self.model.scene_extent);
        strategy.observe(&mut self.stats, &data.camera, step);
        let changed = strategy.refine(
            self.step + 1,
            &mut self.stats,
            &mut self.model.set,
            &mut self.optimisers.gaussians,
        );
        if changed {
            self.aiap = AiapNeighbours::of(&self.model);
        }
    }
}

/// `a += b`, element by element.
fn add_to(a: &mut [f32], b: &[f32]) {
    for (x, &y) in a.iter_mut().zip(b) {
        *x += y;
    }
}

/// True when every gradient of `g` is finite.
fn all_finite(g: &ModelGradients<f32>) -> bool {
    g.means.iter().flatten().all(|v| v.is_finite())
        && g.log_scales.iter().flatten().all(|v| v.is_finite())
        && g.quats.iter().flatten().all(|v| v.is_finite())
        && g.features.iter().all(|v| v.is_finite())
        && g.semantic_logits.iter().all(|v| v.is_finite())
        && g.nonrigid.iter().all(|v| v.is_finite())
        && g.skinning.iter().all(|v| v.is_finite())
        && g.human_colour.iter().all(|v| v.is_finite())
        && g.scene_colour.iter().all(|v| v.is_finite())
        && g.latent.iter().all(|v| v.is_finite())
}
