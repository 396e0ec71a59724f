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

mod checkpoint;
mod correction;
mod report;
mod terms;

pub use checkpoint::CHECKPOINT_FORMAT;
use correction::CorrectedPoses;
pub use report::{StageTimes, StepReport};
pub use terms::warm_up_skinning;

use crate::body::PreparedPose;
use crate::config::{BlurModel, DensityGradient, ExposureNetworks, ExposurePairs, TrainConfig};
use crate::data::TrainingData;
use crate::eval::psnr;
use crate::init::{initialise, InitConfig};
use crate::loss::image::ImageShape;
use crate::loss::perceptual::perceptual_term;
use crate::loss::photometric::{exposure_loss, ExposureEvents};
use crate::model::{FramePass, Model, PosedGradients, RENDER_CHANNELS};
use crate::optimisers::Optimisers;
use crate::posing::ModelGradients;
use crate::schedule::{
    accumulate_screen_stats, correction_rate_scale, exponential_rate, on_schedule,
};
use crate::TrainError;
use gaussians::adam::GaussianLearningRates;
use gaussians::density::{densify_and_prune, reset_opacity, DensifyConfig, DensityStats};
use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use std::time::Instant;
use terms::{
    add_aiap_canonical, aiap_terms, pair_terms, skinning_term, AiapNeighbours, PairSupervision,
};

/// All state of a reconstruction: the model, its optimisers, density statistics, the frame-order
/// RNG and the step count. Saving and loading it resumes a run bit for bit.
#[derive(Clone, Debug)]
pub struct Trainer {
    /// What is learned.
    pub model: Model,
    /// Steps taken.
    pub step: usize,
    optimisers: Optimisers,
    stats: DensityStats,
    rng: ChaCha8Rng,
    order: Vec<usize>,
    aiap: AiapNeighbours,
}

/// Scene extent of an initial cube: half its diagonal.
fn extent_of(cube: &([f32; 3], [f32; 3])) -> f32 {
    let (lo, hi) = cube;
    let d2: f32 = (0..3).map(|a| (hi[a] - lo[a]).powi(2)).sum();
    (0.5 * d2.sqrt()).max(1e-3)
}

/// What the densify/refine stage needs of a step's first pass.
struct RefineInputs {
    means_2d: Vec<[f32; 2]>,
    radii: Vec<u32>,
    /// With `density_gradient = per-pass`: Σ_s ‖g_s‖ per Gaussian, in NDC units.
    pass_norms: Option<Vec<f32>>,
}

impl Trainer {
    /// Initialises the model (paper §4.2) for `data` and fresh optimiser state.
    pub fn new(data: &TrainingData, config: TrainConfig) -> Result<Self, TrainError> {
        config.validate()?;
        let vertices = &data.body.canonical.posed.vertices;
        let roots: Vec<[f32; 3]> = data.frames.iter().map(|f| f.pose.root).collect();
        let init = initialise(
            vertices,
            &data.body.model.faces,
            &data.body.model.weights,
            std::slice::from_ref(&data.camera),
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
        let mut nets = Model::build_networks(&config, vertices)?;
        warm_up_skinning(&mut nets.skinning, data, &config)?;
        let latents = vec![0.0; data.frames.len() * config.latent_dim];
        let frame_indices = data.frames.iter().map(|f| f.index).collect();
        let model = Model::new(
            config,
            init.set,
            nets,
            latents,
            frame_indices,
            extent_of(&init.cube),
        )?;
        Ok(Self::with_model(model))
    }

    /// Refuses a configuration that needs data `data` was not prepared with: the exposure model
    /// without sub-exposure poses ([`TrainingData::enable_exposure`]), events inside exposures
    /// without their counts ([`TrainingData::enable_exposure_events`]), the perceptual loss without
    /// its network ([`TrainingData::enable_lpips`]).
    pub fn check_data(config: &TrainConfig, data: &TrainingData) -> Result<(), TrainError> {
        if config.blur_model == BlurModel::Exposure && data.exposure_poses.is_empty() {
            return Err(TrainError::Config(
                "blur_model = exposure, but the training data has no sub-exposure poses \
                 (TrainingData::enable_exposure)"
                    .into(),
            ));
        }
        if config.event_loss
            && config.event_pairs == crate::config::EventPairs::Exposure
            && data.exposure_events.is_empty()
        {
            return Err(TrainError::Config(
                "event_pairs = exposure, but the training data has no events inside exposures \
                 (TrainingData::enable_exposure_events)"
                    .into(),
            ));
        }
        if config.lpips_weight > 0.0 && data.lpips.is_none() {
            return Err(TrainError::Config(
                "lpips_weight > 0, but the training data has no LPIPS network \
                 (TrainingData::enable_lpips)"
                    .into(),
            ));
        }
        Ok(())
    }

    /// A trainer with fresh optimiser state around `model` (e.g. to fine-tune a saved model).
    pub fn with_model(model: Model) -> Self {
        Self {
            optimisers: Optimisers::new(&model),
            stats: DensityStats::new(model.set.len()),
            rng: ChaCha8Rng::seed_from_u64(model.config.seed ^ 0x0dde_0000),
            order: Vec::new(),
            aiap: AiapNeighbours::of(&model),
            model,
            step: 0,
        }
    }

    /// The hyper-parameters.
    pub fn config(&self) -> &TrainConfig {
        &self.model.config
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

    /// One optimisation step on the next training frame of the seeded order, then [`Trainer::refine`].
    /// On a non-finite loss or gradient nothing is updated and [`TrainError::NonFinite`] is returned.
    pub fn step(&mut self, data: &TrainingData) -> Result<StepReport, TrainError> {
        let config = self.model.config.clone();
        Self::check_data(&config, data)?;
        let step = self.step;
        let slot = self.next_slot(data.frames.len());
        let frame = &data.frames[slot];
        let camera = &data.camera;
        let (height, width) = (camera.height as usize, camera.width as usize);
        let mut times = StageTimes::default();
        let model = &self.model;

        // Frame k: its passes (one at mid exposure, or one per sub-exposure pose with the exposure
        // model; poses corrected by the frame's pose correction once it learns) and the photometric
        // loss of their mean.
        let exposure = config.blur_model == BlurModel::Exposure;
        let correcting = config.pose_correction && step >= config.pose_correction_from;
        let corrected = if correcting {
            Some(CorrectedPoses::of(model, data, slot, exposure)?)
        } else {
            None
        };
        let poses: Vec<&PreparedPose> = match (&corrected, data.exposure_poses.get(slot)) {
            (Some(c), _) => c.prepared.iter().collect(),
            (None, Some(sub)) if exposure && !sub.is_empty() => sub.iter().collect(),
            _ => vec![&frame.pose],
        };
        let mid = poses.len() / 2;
        // With `exposure_networks = once` the sub-exposure passes re-pose the mid pass's networks.
        let reposed = poses.len() > 1 && config.exposure_networks == ExposureNetworks::Once;
        let passes = if reposed {
            model.forward_reposed(camera, &poses, mid, model.latent(slot))?
        } else {
            poses
                .iter()
                .map(|pose| model.forward(camera, pose, model.latent(slot)))
                .collect::<Result<Vec<_>, _>>()?
        };
        for pass in &passes {
            times.pose += pass.timing.pose;
            times.render += pass.timing.render;
        }
        let t0 = Instant::now();
        let shape = ImageShape {
            channels: 3,
            height,
            width,
        };
        // The photometric loss of the passes' mean (its cotangent reaches every pass scaled by 1/S)
        // and the events between consecutive sub-exposure renders.
        let renders: Vec<&[f32]> = passes.iter().map(FramePass::rgb).collect();
        let events = match data.exposure_events.get(slot) {
            Some(expected) if config.event_loss && passes.len() > 1 => Some(ExposureEvents {
                expected,
                weight: config.event_weight,
                penalty: config.event_penalty(),
                log_eps: config.event_log_eps,
                all_pairs: config.exposure_pairs == ExposurePairs::All,
            }),
            _ => None,
        };
        let photo = exposure_loss(
            &renders,
            &frame.image,
            shape,
            config.ssim_weight,
            events,
            RENDER_CHANNELS,
            data.grey,
        );
        let exposure_events = photo.events;
        let prediction = photo.prediction;
        let mut d_images = photo.d_renders;
        times.loss = t0.elapsed().as_secs_f64();
        // The perceptual loss of the same prediction: its cotangent reaches every pass scaled like
        // the photometric one (1/S; unscaled for one render).
        let t0 = Instant::now();
        let lpips_value = match &data.lpips {
            Some(net) if config.lpips_weight > 0.0 => perceptual_term(
                net,
                &prediction,
                &frame.image,
                height,
                width,
                config.lpips_weight,
                &mut d_images,
                data.grey,
            )?,
            _ => 0.0,
        };
        times.lpips = t0.elapsed().as_secs_f64();
        let first = &passes[mid];

        // Frame k+1 when a pair loss applies: its forward and the pair losses of both renders.
        let t_pair = Instant::now();
        let pair = PairSupervision::of(data, &config, slot);
        let next_corrected = match &pair {
            Some(pair) if correcting => {
                Some(CorrectedPoses::of(model, data, pair.next_slot, false)?)
            }
            _ => None,
        };
        let second = match &pair {
            Some(pair) => {
                let next = &data.frames[pair.next_slot];
                let pose = next_corrected
                    .as_ref()
                    .map_or(&next.pose, |c| &c.prepared[0]);
                let pass = model.forward(camera, pose, model.latent(pair.next_slot))?;
                let terms = pair_terms(
                    pair,
                    &config,
                    first.rgb(),
                    pass.rgb(),
                    (height, width),
                    &mut d_images[mid],
                )?;
                times.flow_network = terms.flow_network_seconds;
                Some((pair.next_slot, pass, terms))
            }
            None => None,
        };
        times.flow = t_pair.elapsed().as_secs_f64();
        let (d_geometric_first, d_geometric_second) = match &second {
            Some((_, _, terms)) => match &terms.d_flow_geometric {
                Some((a, b)) => (Some(a.as_slice()), Some(b.as_slice())),
                None => (None, None),
            },
            None => (None, None),
        };

        // Frame k: backward of the mid pass, with the AIAP regulariser on its posed human Gaussians,
        // then of the other sub-exposure passes, accumulated.
        let t0 = Instant::now();
        let mut posed_grads = first.render_backward(&d_images[mid], d_geometric_first)?;
        times.render_backward = t0.elapsed().as_secs_f64();
        let t0 = Instant::now();
        let (aiap_value, aiap_canonical) =
            aiap_terms(&self.aiap, model, &first.posed, &config, &mut posed_grads);
        let mut sub_render_backward_seconds = 0.0;
        let mut pass_norms = (config.density_gradient == DensityGradient::PerPass
            && passes.len() > 1)
            .then(|| vec![0.0f32; first.out.radii.len()]);
        // Per pass, ∂L/∂bones and ∂L/∂pose code (for the pose correction).
        let mut pass_bones = vec![Vec::new(); passes.len()];
        let mut pass_codes = vec![Vec::new(); passes.len()];
        let (mut grads, mut opacity_grads, means_2d) = if reposed {
            // One backward through the networks for every sub-exposure pass.
            let mut opacity_grads = std::mem::take(&mut posed_grads.opacity_logits);
            let mut means_2d = std::mem::take(&mut posed_grads.means_2d);
            if let Some(norms) = pass_norms.as_mut() {
                add_ndc_norms(norms, &means_2d, camera);
            }
            let mut subs = Vec::with_capacity(passes.len() - 1);
            for (s, pass) in passes.iter().enumerate().filter(|&(s, _)| s != mid) {
                let t = Instant::now();
                let sub = pass.render_backward(&d_images[s], None)?;
                sub_render_backward_seconds += t.elapsed().as_secs_f64();
                if let Some(norms) = pass_norms.as_mut() {
                    add_ndc_norms(norms, &sub.means_2d, camera);
                }
                add_to(&mut opacity_grads, &sub.opacity_logits);
                add_to(means_2d.as_flattened_mut(), sub.means_2d.as_flattened());
                subs.push(sub);
            }
            let mut all: Vec<&PosedGradients> = subs.iter().collect();
            all.insert(mid, &posed_grads);
            let (mut grads, bones) = model.reposed_backward(&passes, mid, &all)?;
            pass_bones = bones;
            pass_codes[mid] = grads.pose_code.clone();
            add_aiap_canonical(&self.aiap, model, &aiap_canonical, &mut grads);
            (grads, opacity_grads, means_2d)
        } else {
            let mut grads = first.model_backward(&posed_grads)?;
            pass_bones[mid] = grads.bones.clone();
            pass_codes[mid] = grads.pose_code.clone();
            add_aiap_canonical(&self.aiap, model, &aiap_canonical, &mut grads);
            let mut opacity_grads = posed_grads.opacity_logits;
            let mut means_2d = posed_grads.means_2d;
            if let Some(norms) = pass_norms.as_mut() {
                add_ndc_norms(norms, &means_2d, camera);
            }
            for (s, pass) in passes.iter().enumerate().filter(|&(s, _)| s != mid) {
                let t = Instant::now();
                let sub = pass.render_backward(&d_images[s], None)?;
                sub_render_backward_seconds += t.elapsed().as_secs_f64();
                if let Some(norms) = pass_norms.as_mut() {
                    add_ndc_norms(norms, &sub.means_2d, camera);
                }
                let g = pass.model_backward(&sub)?;
                grads.add_shared(&g);
                add_to(&mut grads.latent, &g.latent);
                pass_bones[s] = g.bones;
                pass_codes[s] = g.pose_code;
                add_to(&mut opacity_grads, &sub.opacity_logits);
                add_to(means_2d.as_flattened_mut(), sub.means_2d.as_flattened());
            }
            (grads, opacity_grads, means_2d)
        };
        times.render_backward += sub_render_backward_seconds;
        // The pose corrections' gradient: frame k's passes, frame k+1's below, and the prior.
        let mut correction_grads = corrected.as_ref().map(|c| {
            let mut g = vec![0.0f32; model.pose_corrections.len()];
            let bones: Vec<&[_]> = pass_bones.iter().map(Vec::as_slice).collect();
            let codes: Vec<&[f32]> = pass_codes.iter().map(Vec::as_slice).collect();
            c.add_gradient(
                &data.body,
                config.pose_correction_root,
                &bones,
                &codes,
                &mut g,
            );
            g
        });

        // Frame k+1: backward, accumulated into the shared gradients.
        let (mut flow_value, mut event_value) = (0.0f32, 0.0f32);
        let mut second_latent = None;
        let mut second_backward_seconds = 0.0;
        if let Some((next_slot, pass, terms)) = &second {
            let t = Instant::now();
            let posed2 = pass.render_backward(&terms.d_second, d_geometric_second)?;
            let grads2 = pass.model_backward(&posed2)?;
            grads.add_shared(&grads2);
            if let (Some(next), Some(g)) = (&next_corrected, correction_grads.as_mut()) {
                next.add_gradient(
                    &data.body,
                    config.pose_correction_root,
                    &[&grads2.bones],
                    &[&grads2.pose_code],
                    g,
                );
            }
            for (o, &g) in opacity_grads.iter_mut().zip(&posed2.opacity_logits) {
                *o += g;
            }
            second_latent = Some((*next_slot, grads2.latent));
            (flow_value, event_value) = (terms.flow, terms.event);
            second_backward_seconds = t.elapsed().as_secs_f64();
            times.flow += second_backward_seconds;
        }
        let skinning_value = skinning_term(
            &model.nets.skinning,
            data,
            &config,
            step,
            &mut grads.skinning,
        )?;
        // (Frame k+1's backward ran inside this interval; it is counted under `flow`.)
        times.model_backward =
            t0.elapsed().as_secs_f64() - second_backward_seconds - sub_render_backward_seconds;

        // The knots the step's frames are interpolated from: frame k's (which the prior's step
        // covers), and k + 1's when rendered.
        let mut trained_knots = corrected
            .as_ref()
            .map(CorrectedPoses::knots)
            .unwrap_or_default();
        let pose_prior = match correction_grads.as_mut() {
            Some(g) => correction::add_prior(model, &trained_knots, g),
            None => 0.0,
        };
        if let (Some(_), Some(next)) = (&second, &next_corrected) {
            for k in next.knots() {
                if !trained_knots.contains(&k) {
                    trained_knots.push(k);
                }
            }
        }
        let event_value = event_value + exposure_events;
        let loss = photo.photometric
            + lpips_value
            + aiap_value
            + skinning_value
            + flow_value
            + event_value
            + pose_prior;
        let finite = loss.is_finite()
            && correction_grads
                .as_ref()
                .is_none_or(|g| g.iter().all(|v| v.is_finite()))
            && opacity_grads.iter().all(|v| v.is_finite())
            && second_latent
                .as_ref()
                .is_none_or(|(_, g)| g.iter().all(|v| v.is_finite()))
            && all_finite(&grads);
        if !finite {
            return Err(TrainError::NonFinite { step });
        }
        let psnr_value = psnr(&prediction, &frame.image);
        let active = first.active().len();
        let refine_inputs = RefineInputs {
            means_2d,
            radii: first.out.radii.clone(),
            pass_norms,
        };
        drop(second);
        drop(passes);

        let t0 = Instant::now();
        let correction_update = correction_grads.map(|g| (g, trained_knots));
        self.apply_gradients(slot, grads, opacity_grads, second_latent, correction_update)?;
        times.adam = t0.elapsed().as_secs_f64();
        let t0 = Instant::now();
        self.refine(data, &refine_inputs);
        times.density = t0.elapsed().as_secs_f64();
        let human = self.model.human_count();
        Ok(StepReport {
            step,
            frame: frame.index,
            loss,
            l1: photo.l1,
            ssim: photo.ssim,
            lpips: lpips_value,
            skinning: skinning_value,
            aiap: aiap_value,
            flow: flow_value,
            event: event_value,
            pose_prior,
            psnr: psnr_value,
            gaussians_human: human,
            gaussians_scene: self.model.set.len() - human,
            active,
            times,
        })
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
    ) -> Result<(), TrainError> {
        let config = &self.model.config;
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
        let rate_scale = correction_rate_scale(
            config.lr_pose_correction_final_fraction,
            config.pose_correction_from,
            step,
            config.steps,
        );
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
                        .step_pose_corrections(params, g, knots, rate_scale)?;
                }
                continue;
            }
            self.optimisers.step_network(name, params, g)?;
        }
        Ok(())
    }

    /// Density control after a step: the step's screen-space statistics, densify and prune on the
    /// schedule (AIAP neighbourhoods refreshed after), and the opacity reset; advances the step count.
    fn refine(&mut self, data: &TrainingData, inputs: &RefineInputs) {
        let config = self.model.config.clone();
        match &inputs.pass_norms {
            Some(norms) => {
                let radius: Vec<f32> = inputs.radii.iter().map(|&r| r as f32).collect();
                self.stats.accumulate_norms(norms, &radius);
            }
            None => accumulate_screen_stats(
                &mut self.stats,
                &data.camera,
                &inputs.means_2d,
                &inputs.radii,
            ),
        }
        let done = self.step + 1;
        if on_schedule(
            done,
            config.densify_from,
            config.densify_until,
            config.densify_every,
        ) {
            let densify = DensifyConfig {
                grad_threshold: config.densify_grad_threshold,
                scene_extent: self.model.scene_extent,
                min_opacity: config.prune_min_opacity,
                max_gaussians: config.max_gaussians,
                ..DensifyConfig::default()
            };
            densify_and_prune(
                &mut self.model.set,
                &mut self.optimisers.gaussians,
                &mut self.stats,
                &densify,
                config.seed ^ (done as u64).wrapping_mul(0x9e37_79b9),
            );
            self.aiap = AiapNeighbours::of(&self.model);
        }
        if config.opacity_reset_every > 0
            && done.is_multiple_of(config.opacity_reset_every)
            && done < config.steps
        {
            reset_opacity(&mut self.model.set, &mut self.optimisers.gaussians, 0.01);
        }
        self.step = done;
    }
}

/// `norms[i] += ‖g_i‖` with `g` the screen-space mean gradients (pixels) scaled to NDC units (× W/2,
/// H/2, as `accumulate_screen_stats` does).
fn add_ndc_norms(norms: &mut [f32], g: &[[f32; 2]], camera: &rasterize_cpu::Camera) {
    let (hw, hh) = (camera.width as f32 * 0.5, camera.height as f32 * 0.5);
    for (n, &[gx, gy]) in norms.iter_mut().zip(g) {
        *n += ((gx * hw).powi(2) + (gy * hh).powi(2)).sqrt();
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
