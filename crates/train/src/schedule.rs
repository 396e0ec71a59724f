//! Schedules of the optimisation: the 3DGS position-rate decay, the density-control cadence, and the
//! screen-space statistics density control reads.

use gaussians::density::DensityStats;
use rasterize_cpu::Camera;

/// The 3DGS position-rate schedule: log-linear from `lr0` to `lr0 · final_fraction` over `steps`.
pub fn exponential_rate(lr0: f32, final_fraction: f32, step: usize, steps: usize) -> f32 {
    let t = (step as f32 / steps.max(1) as f32).clamp(0.0, 1.0);
    (lr0.ln() * (1.0 - t) + (lr0 * final_fraction).ln() * t).exp()
}

/// The factor of the pose corrections' rates at `step`: 1 until the corrections start at `from`,
/// then log-linear to `final_fraction` at the run's last step `steps`.
pub fn correction_rate_scale(final_fraction: f32, from: usize, step: usize, steps: usize) -> f32 {
    exponential_rate(
        1.0,
        final_fraction,
        step.saturating_sub(from),
        steps.saturating_sub(from),
    )
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_position_rate_decays_log_linearly_to_its_final_fraction() {
        let (lr0, f) = (1.6e-4f32, 0.01f32);
        assert!((exponential_rate(lr0, f, 0, 100) - lr0).abs() < 1e-9);
        assert!((exponential_rate(lr0, f, 100, 100) - lr0 * f).abs() < 1e-10);
        // Halfway: the geometric mean.
        let mid = exponential_rate(lr0, f, 50, 100);
        assert!((mid - lr0 * f.sqrt()).abs() < 1e-9, "{mid}");
        // Past the end it stays at the final rate.
        assert_eq!(
            exponential_rate(lr0, f, 200, 100),
            exponential_rate(lr0, f, 100, 100)
        );
    }

    #[test]
    fn the_correction_rates_decay_from_their_first_step_and_stay_constant_at_one() {
        assert_eq!(correction_rate_scale(0.1, 100, 0, 1100), 1.0);
        assert_eq!(correction_rate_scale(0.1, 100, 100, 1100), 1.0);
        let mid = correction_rate_scale(0.1, 100, 600, 1100);
        assert!((mid - 0.1f32.sqrt()).abs() < 1e-6, "{mid}");
        assert!((correction_rate_scale(0.1, 100, 1100, 1100) - 0.1).abs() < 1e-7);
        // A fraction of 1 is exactly 1 at every step (the constant rates' bits).
        for step in [0, 100, 333, 1100, 5000] {
            assert_eq!(correction_rate_scale(1.0, 100, step, 1100), 1.0);
        }
    }

    #[test]
    fn density_control_runs_on_its_schedule_only() {
        let runs: Vec<usize> = (1..=20).filter(|&d| on_schedule(d, 5, 15, 5)).collect();
        assert_eq!(runs, vec![5, 10, 15]);
        assert!(!on_schedule(10, 5, 15, 0));
    }
}
