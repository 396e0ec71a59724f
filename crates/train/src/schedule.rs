//! Learning-rate schedules of the optimisation: the 3DGS position-rate decay and the pose
//! corrections' rates and the event weight (density control's cadence is `crate::density`'s).

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

/// The event weight at `step`: `event_weight`, decaying log-linearly from
/// `event_weight_decay_from` to `event_weight_final_fraction` of it at the last step (exactly
/// `event_weight` at every step when the fraction is 1).
pub fn event_weight_at(config: &crate::config::TrainConfig, step: usize) -> f32 {
    config.event_weight * late_decay(config, config.event_weight_final_fraction, step)
}

/// The D-SSIM weight λ at `step`: `ssim_weight`, decaying log-linearly over the event weight's
/// window (from `event_weight_decay_from`) to `ssim_weight_final_fraction` of it at the last step
/// (exactly `ssim_weight` at every step when the fraction is 1).
pub fn ssim_weight_at(config: &crate::config::TrainConfig, step: usize) -> f32 {
    config.ssim_weight * late_decay(config, config.ssim_weight_final_fraction, step)
}

/// The factor of a loss weight at `step` in the window after densification: 1 until
/// `event_weight_decay_from`, then log-linear to `final_fraction` at the last step (exactly 1 at
/// every step when `final_fraction` is 1).
fn late_decay(config: &crate::config::TrainConfig, final_fraction: f32, step: usize) -> f32 {
    correction_rate_scale(
        final_fraction,
        config.event_weight_decay_from,
        step,
        config.steps,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::{Preset, TrainConfig};

    #[test]
    fn the_event_weight_decays_from_its_step_to_its_final_fraction() {
        let mut config = TrainConfig::preset(Preset::Quick);
        config.event_weight_final_fraction = 1.0;
        let w = config.event_weight;
        assert_eq!(event_weight_at(&config, config.steps), w);
        config.event_weight_final_fraction = 0.1;
        config.event_weight_decay_from = 600;
        assert_eq!(event_weight_at(&config, 300), w);
        let last = event_weight_at(&config, config.steps);
        assert!((last - 0.1 * w).abs() < 1e-5 * w, "{last}");
    }

    #[test]
    fn the_ssim_weight_is_constant_by_default_and_decays_over_the_event_window() {
        let mut config = TrainConfig::preset(Preset::Full);
        let l = config.ssim_weight;
        for step in [0, 3999, 4000, 5000, config.steps] {
            assert_eq!(ssim_weight_at(&config, step), l);
        }
        config.ssim_weight_final_fraction = 0.1;
        assert_eq!(ssim_weight_at(&config, config.event_weight_decay_from), l);
        let last = ssim_weight_at(&config, config.steps);
        assert!((last - 0.1 * l).abs() < 1e-6 * l, "{last}");
    }

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
}
