//! Density control as one strategy, as gsplat's `DefaultStrategy` keeps it: which screen-space
//! statistic each step contributes, when the set is densified and pruned and with which
//! thresholds, and when opacities are reset. [`DensityStrategy`] holds the settings (built from the
//! configuration); the accumulated statistics are the trainer's state ([`DensityStats`],
//! checkpointed with it). The clone / split / prune / reset operations themselves are
//! `gaussians::density`'s.

use gaussians::adam::GaussianAdam;
use gaussians::density::{densify_and_prune, reset_opacity, DensifyConfig, DensityStats};
use gaussians::GaussianSet;
use rasterize_cpu::Camera;

use crate::config::TrainConfig;

/// Opacity every Gaussian is reset to (at most) on the reset schedule (3DGS: 0.01).
const RESET_OPACITY: f32 = 0.01;

/// What density control reads of one step: the screen-space data of its mid (or only) pass.
#[derive(Clone, Debug)]
pub struct StepStatistics {
    /// ∂L/∂ screen-space means (pixels), summed over the step's passes.
    pub means_2d: Vec<[f32; 2]>,
    /// Screen radii of the mid pass (pixels, 0 = culled).
    pub radii: Vec<u32>,
    /// With `density_gradient = per-pass`: Σ_s ‖g_s‖ per Gaussian, in NDC units
    /// ([`add_ndc_norms`]); else `None` and the norm of `means_2d` is used.
    pub pass_norms: Option<Vec<f32>>,
}

/// The density-control settings of a run.
#[derive(Clone, Debug, PartialEq)]
pub struct DensityStrategy {
    /// Densify and prune at the 1-based step counts `from..=until` that are multiples of
    /// `every` (`every = 0`: never).
    pub from: usize,
    /// Last step count that densifies.
    pub until: usize,
    /// Steps between densify-and-prune passes.
    pub every: usize,
    /// Thresholds of one pass.
    pub thresholds: DensifyConfig,
    /// Reset opacities every this many steps (0: never), except at the last step.
    pub reset_every: usize,
    /// Steps of the run.
    pub steps: usize,
    /// Seed of the split children's positions (mixed with the step count).
    pub seed: u64,
}

impl DensityStrategy {
    /// The strategy `config` describes for a scene of extent `scene_extent` (m).
    pub fn of(config: &TrainConfig, scene_extent: f32) -> Self {
        Self {
            from: config.densify_from,
            until: config.densify_until,
            every: config.densify_every,
            thresholds: DensifyConfig {
                grad_threshold: config.densify_grad_threshold,
                scene_extent,
                min_opacity: config.prune_min_opacity,
                max_gaussians: config.max_gaussians,
                ..DensifyConfig::default()
            },
            reset_every: config.opacity_reset_every,
            steps: config.steps,
            seed: config.seed,
        }
    }

    /// Adds one step's statistics to `stats`.
    pub fn observe(&self, stats: &mut DensityStats, camera: &Camera, step: &StepStatistics) {
        match &step.pass_norms {
            Some(norms) => {
                let radius: Vec<f32> = step.radii.iter().map(|&r| r as f32).collect();
                stats.accumulate_norms(norms, &radius);
            }
            None => accumulate_screen_stats(stats, camera, &step.means_2d, &step.radii),
        }
    }

    /// After the update of step count `done` (1-based): densify and prune on the schedule, then
    /// reset opacities on theirs. Returns whether the set's Gaussians changed (the caller
    /// refreshes what indexes them).
    pub fn refine(
        &self,
        done: usize,
        stats: &mut DensityStats,
        set: &mut GaussianSet,
        adam: &mut GaussianAdam,
    ) -> bool {
        let densify = on_schedule(done, self.from, self.until, self.every);
        if densify {
            let seed = self.seed ^ (done as u64).wrapping_mul(0x9e37_79b9);
            densify_and_prune(set, adam, stats, &self.thresholds, seed);
        }
        if self.reset_every > 0 && done.is_multiple_of(self.reset_every) && done < self.steps {
            reset_opacity(set, adam, RESET_OPACITY);
        }
        densify
    }
}

/// True when the 1-based step count `done` falls on a density-control pass of the schedule
/// `from..=until` every `every` steps (`every = 0` disables it).
pub fn on_schedule(done: usize, from: usize, until: usize, every: usize) -> bool {
    every > 0 && done >= from && done <= until && done.is_multiple_of(every)
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

/// `norms[i] += ‖g_i‖` with `g` the screen-space mean gradients (pixels) scaled to NDC units (× W/2,
/// H/2, as [`accumulate_screen_stats`] does).
pub fn add_ndc_norms(norms: &mut [f32], g: &[[f32; 2]], camera: &Camera) {
    let (hw, hh) = (camera.width as f32 * 0.5, camera.height as f32 * 0.5);
    for (n, &[gx, gy]) in norms.iter_mut().zip(g) {
        *n += ((gx * hw).powi(2) + (gy * hh).powi(2)).sqrt();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn density_control_runs_on_its_schedule_only() {
        let runs: Vec<usize> = (1..=20).filter(|&d| on_schedule(d, 5, 15, 5)).collect();
        assert_eq!(runs, vec![5, 10, 15]);
        assert!(!on_schedule(10, 5, 15, 0));
    }
}
