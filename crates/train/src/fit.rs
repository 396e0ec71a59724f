//! The optimisation loop for statically coloured Gaussians: views visited in a seeded order, the
//! photometric step of [`crate::step`], Adam on every Gaussian group and on the colour network, the
//! 3DGS exponential decay of the position rate, and density control on its schedule.
//!
//! This is the scene branch of the E-Sem3DGS loop; the full method adds the human branch (deformation,
//! semantic blend, skinning and AIAP losses) around the same skeleton. Deterministic for a seed: the
//! view order and every split come from explicit seeds, and every kernel is thread-count invariant.

use crate::checkpoint::{rng_from_strings, rng_to_strings, CheckpointReader, CheckpointWriter};
use crate::colour::ColourNet;
use crate::step::{photometric_step, StaticGaussians};
use crate::TrainError;
use gaussians::adam::{AdamConfig, GaussianAdam, GaussianLearningRates};
use gaussians::density::{densify_and_prune, reset_opacity, DensifyConfig, DensityStats};
use gaussians::GaussianSet;
use rand::seq::SliceRandom;
use rand::SeedableRng;
use rasterize_cpu::{Camera, RenderSettings};
use std::path::Path;

/// One training view: a camera and its target image, (3, H, W) linear RGB.
#[derive(Clone, Debug)]
pub struct View {
    /// The camera.
    pub camera: Camera,
    /// Target image, planar (3, H, W).
    pub image: Vec<f32>,
}

/// Hyper-parameters of [`fit_static`] (defaults: the INRIA 3DGS schedule scaled to `steps`).
#[derive(Clone, Debug, PartialEq)]
pub struct FitConfig {
    /// Optimisation steps (one view each).
    pub steps: usize,
    /// Weight λ of D-SSIM in (1 − λ)·L1 + λ·(1 − SSIM) (3DGS: 0.2).
    pub ssim_weight: f32,
    /// Per-group Gaussian learning rates; `means` is multiplied by the scene extent.
    pub rates: GaussianLearningRates,
    /// Final position rate as a fraction of the initial one (3DGS: 1.6e-6 / 1.6e-4 = 0.01).
    pub means_rate_final_fraction: f32,
    /// Colour-network learning rate.
    pub colour_rate: f32,
    /// Scene extent in metres (scales the position rate and the density thresholds).
    pub scene_extent: f32,
    /// Density control: first step, last step, interval (3DGS: 500, 15000, 100).
    pub densify_from: usize,
    /// Last step at which density control runs.
    pub densify_until: usize,
    /// Steps between density-control passes.
    pub densify_every: usize,
    /// Steps between opacity resets (3DGS: 3000); 0 disables.
    pub opacity_reset_every: usize,
    /// Density-control thresholds (its `scene_extent` is overwritten by the field above).
    pub densify: DensifyConfig,
    /// Background colour.
    pub background: [f32; 3],
    /// Seed of the view order and of split sampling.
    pub seed: u64,
}

impl Default for FitConfig {
    fn default() -> Self {
        Self {
            steps: 3000,
            ssim_weight: 0.2,
            rates: GaussianLearningRates::default(),
            means_rate_final_fraction: 0.01,
            colour_rate: 1e-3,
            scene_extent: 1.0,
            densify_from: 500,
            densify_until: 1500,
            densify_every: 100,
            opacity_reset_every: 3000,
            densify: DensifyConfig::default(),
            background: [0.0; 3],
            seed: 0,
        }
    }
}

/// What one step did, reported to the progress callback.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepReport {
    /// 0-based step index.
    pub step: usize,
    /// Total loss.
    pub loss: f32,
    /// PSNR (dB) of the render against the target.
    pub psnr: f64,
    /// Number of Gaussians after the step.
    pub gaussians: usize,
}

/// The 3DGS position-rate schedule: log-linear from `lr0` to `lr0 · final_fraction` over `steps`.
pub fn exponential_rate(lr0: f32, final_fraction: f32, step: usize, steps: usize) -> f32 {
    let t = (step as f32 / steps.max(1) as f32).clamp(0.0, 1.0);
    (lr0.ln() * (1.0 - t) + (lr0 * final_fraction).ln() * t).exp()
}

/// Adds one view's screen-space statistics to `stats` in INRIA's NDC convention: pixel-space mean
/// gradients × (W/2, H/2), and the screen radii (pixels, 0 = culled).
pub fn accumulate_screen_stats(
    stats: &mut DensityStats,
    camera: &Camera,
    means_2d: &[[f32; 2]],
    radii: &[u32],
) {
    let (hw, hh) = (camera.width as f32 * 0.5, camera.height as f32 * 0.5);
    let grad_ndc: Vec<[f32; 2]> = means_2d.iter().map(|m| [m[0] * hw, m[1] * hh]).collect();
    let radius: Vec<f32> = radii.iter().map(|&r| r as f32).collect();
    stats.accumulate(&grad_ndc, &radius);
}

/// True when the 1-based step count `done` falls on a density-control pass of the schedule
/// `from..=until` every `every` steps (`every = 0` disables it).
pub fn on_schedule(done: usize, from: usize, until: usize, every: usize) -> bool {
    every > 0 && done >= from && done <= until && done.is_multiple_of(every)
}

/// Optimises `set` (whose `features` feed `net`) and `net` against `views` for `config.steps` steps.
/// Calls `on_step` after every step. Stops with an error if a loss or gradient becomes non-finite; the
/// parameters are then those of the last finite step.
pub fn fit_static(
    set: &mut GaussianSet,
    net: &mut ColourNet<f32>,
    views: &[View],
    config: &FitConfig,
    on_step: impl FnMut(&StepReport),
) -> Result<(), TrainError> {
    let mut trainer = StaticTrainer::new(set.clone(), net.clone(), config.clone())?;
    let result = trainer.run(views, config.steps, on_step);
    *set = trainer.set;
    *net = trainer.net;
    result
}

/// All state of a scene-branch optimisation: parameters, optimiser moments, density statistics, the
/// view-order RNG and the step count. Saving and loading it resumes a run bit for bit.
#[derive(Clone, Debug)]
pub struct StaticTrainer {
    /// The Gaussians being optimised.
    pub set: GaussianSet,
    /// The scene-colour network.
    pub net: ColourNet<f32>,
    /// Hyper-parameters.
    pub config: FitConfig,
    /// Steps taken so far.
    pub step: usize,
    adam: GaussianAdam,
    net_adam: nn::Adam<f32>,
    stats: DensityStats,
    rng: rand_chacha::ChaCha8Rng,
    order: Vec<usize>,
}

impl StaticTrainer {
    /// Fresh optimiser state for `set` and `net`.
    pub fn new(
        set: GaussianSet,
        net: ColourNet<f32>,
        config: FitConfig,
    ) -> Result<Self, TrainError> {
        if set.feature_dim != net.config.feature_dim {
            return Err(TrainError::Shape {
                what: "Gaussian feature length vs colour network input".into(),
                expected: net.config.feature_dim,
                found: set.feature_dim,
            });
        }
        let adam = GaussianAdam::new(&set, AdamConfig::default());
        let net_adam = nn::Adam::<f32>::new(net.mlp.num_params(), net_adam_config(&config));
        let stats = DensityStats::new(set.len());
        let rng = rand_chacha::ChaCha8Rng::seed_from_u64(config.seed);
        Ok(Self {
            set,
            net,
            config,
            step: 0,
            adam,
            net_adam,
            stats,
            rng,
            order: Vec::new(),
        })
    }

    /// Runs steps until `self.step == until` (no-op if already there).
    pub fn run(
        &mut self,
        views: &[View],
        until: usize,
        mut on_step: impl FnMut(&StepReport),
    ) -> Result<(), TrainError> {
        while self.step < until {
            let report = self.step(views)?;
            on_step(&report);
        }
        Ok(())
    }

    /// One optimisation step on the next view of the seeded order.
    pub fn step(&mut self, views: &[View]) -> Result<StepReport, TrainError> {
        if views.is_empty() {
            return Err(TrainError::Config("no training views".into()));
        }
        let config = &self.config;
        let step = self.step;
        if self.order.is_empty() {
            self.order = (0..views.len()).collect();
            self.order.shuffle(&mut self.rng);
        }
        let view = &views[self.order.pop().unwrap_or(0) % views.len()];
        let settings = RenderSettings {
            near_plane: 0.2,
            background: config.background.iter().map(|&v| f64::from(v)).collect(),
        };
        let set = &mut self.set;
        let gaussians = StaticGaussians {
            means: &set.means,
            log_scales: &set.log_scales,
            quats: &set.quats,
            opacity_logits: &set.opacity_logits,
            features: &set.features,
        };
        let out = photometric_step(
            &view.camera,
            &gaussians,
            &self.net,
            &view.image,
            config.ssim_weight,
            &settings,
            true,
        )?;
        let Some(g) = out.grads else {
            return Err(TrainError::Config("the step returned no gradients".into()));
        };
        let finite = out.loss.is_finite()
            && g.means.iter().flatten().all(|v| v.is_finite())
            && g.log_scales.iter().flatten().all(|v| v.is_finite())
            && g.quats.iter().flatten().all(|v| v.is_finite())
            && g.opacity_logits.iter().all(|v| v.is_finite())
            && g.features.iter().all(|v| v.is_finite())
            && g.colour_params.iter().all(|v| v.is_finite());
        if !finite {
            return Err(TrainError::NonFinite { step });
        }
        let mut grads = set.zeros_like();
        grads.means = g.means;
        grads.log_scales = g.log_scales;
        grads.quats = g.quats;
        grads.opacity_logits = g.opacity_logits;
        grads.features = g.features;
        let mut rates = config.rates;
        rates.means = exponential_rate(
            config.rates.means * config.scene_extent,
            config.means_rate_final_fraction,
            step,
            config.steps,
        );
        self.adam
            .step(set, &grads, &rates)
            .map_err(|e| TrainError::Config(e.to_string()))?;
        self.net_adam
            .step(&mut self.net.mlp.params, &g.colour_params)?;
        accumulate_screen_stats(&mut self.stats, &view.camera, &g.means_2d, &out.radii);
        let done = step + 1;
        if on_schedule(
            done,
            config.densify_from,
            config.densify_until,
            config.densify_every,
        ) {
            let mut densify = config.densify;
            densify.scene_extent = config.scene_extent;
            densify_and_prune(
                set,
                &mut self.adam,
                &mut self.stats,
                &densify,
                config.seed ^ done as u64,
            );
        }
        if config.opacity_reset_every > 0
            && done.is_multiple_of(config.opacity_reset_every)
            && done < config.steps
        {
            reset_opacity(set, &mut self.adam, 0.01);
        }
        self.step = done;
        Ok(StepReport {
            step,
            loss: out.loss,
            psnr: crate::image_loss::psnr(&out.image, &view.image),
            gaussians: set.len(),
        })
    }

    /// Writes the whole state to one safetensors file, atomically (temporary sibling + rename).
    pub fn save_checkpoint(&self, path: &Path) -> Result<(), TrainError> {
        let mut w = CheckpointWriter::default();
        w.push_set("set", &self.set);
        let adam_steps = w.push_gaussian_adam("adam", &self.adam);
        w.push("net.params", self.net.mlp.params.clone());
        let net_adam_steps = w.push_adam("net_adam", &self.net_adam);
        w.push_stats("stats", &self.stats);
        let (rng_seed, rng_word_pos) = rng_to_strings(&self.rng);
        let meta = CheckpointMeta {
            format: CHECKPOINT_FORMAT.into(),
            step: self.step,
            sh_degree: self.set.sh_degree,
            feature_dim: self.set.feature_dim,
            semantic_classes: self.set.semantic_classes,
            adam_steps,
            net_adam_steps,
            rng_seed,
            rng_word_pos,
            order: self.order.clone(),
        };
        let meta_json = serde_json::to_string(&meta).map_err(|e| TrainError::Checkpoint {
            path: path.to_path_buf(),
            message: e.to_string(),
        })?;
        w.write(path, &meta_json)
    }

    /// Restores a trainer saved by [`StaticTrainer::save_checkpoint`]; `net` supplies the colour
    /// network's architecture (its parameters are replaced) and `config` the hyper-parameters.
    pub fn load_checkpoint(
        path: &Path,
        net: ColourNet<f32>,
        config: FitConfig,
    ) -> Result<Self, TrainError> {
        let r = CheckpointReader::open(path)?;
        let meta: CheckpointMeta =
            serde_json::from_str(&r.metadata).map_err(|e| r.error(format!("metadata: {e}")))?;
        if meta.format != CHECKPOINT_FORMAT {
            return Err(r.error(format!("unknown checkpoint format `{}`", meta.format)));
        }
        let set = r.set(
            "set",
            meta.sh_degree,
            meta.feature_dim,
            meta.semantic_classes,
        )?;
        let mut trainer = Self::new(set, net, config)?;
        r.gaussian_adam("adam", &mut trainer.adam, &meta.adam_steps)?;
        let n_params = trainer.net.mlp.num_params();
        trainer.net.mlp.params = r.get_len("net.params", n_params)?;
        trainer.net_adam = r.adam(
            "net_adam",
            net_adam_config(&trainer.config),
            n_params,
            meta.net_adam_steps,
        )?;
        trainer.stats = r.stats("stats", trainer.set.len())?;
        trainer.rng =
            rng_from_strings(&meta.rng_seed, &meta.rng_word_pos).map_err(|e| r.error(e))?;
        trainer.order = meta.order;
        trainer.step = meta.step;
        Ok(trainer)
    }
}

/// Identifier stored in every checkpoint's metadata.
pub const CHECKPOINT_FORMAT: &str = "e-sem3dgs-static-trainer-v1";

fn net_adam_config(config: &FitConfig) -> nn::AdamConfig {
    nn::AdamConfig {
        lr: f64::from(config.colour_rate),
        ..nn::AdamConfig::default()
    }
}

/// Non-tensor state of a checkpoint (stored as JSON in the safetensors metadata).
#[derive(serde::Serialize, serde::Deserialize)]
struct CheckpointMeta {
    format: String,
    step: usize,
    sh_degree: usize,
    feature_dim: usize,
    semantic_classes: usize,
    adam_steps: Vec<u64>,
    net_adam_steps: u64,
    rng_seed: String,
    rng_word_pos: String,
    order: Vec<usize>,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exponential_rate_interpolates_log_linearly() {
        assert!((exponential_rate(1e-2, 0.01, 0, 100) - 1e-2).abs() < 1e-9);
        assert!((exponential_rate(1e-2, 0.01, 100, 100) - 1e-4).abs() < 1e-9);
        assert!((exponential_rate(1e-2, 0.01, 50, 100) - 1e-3).abs() < 1e-8);
    }
}
