//! How the training options read the sensor's events: the change one event stands for, and the
//! event loss's penalty built from it.

use super::{EventPenaltyKind, TrainConfig};

impl TrainConfig {
    /// The log-intensity changes (C+, C−) one positive and one negative event stand for: the
    /// sensor's thresholds (`event_threshold`, `event_threshold_neg`, C− = C+ when unset) times
    /// `event_threshold_scale`, the product in f64 rounded to f32 (exact, so with scale 1 the
    /// thresholds themselves).
    pub fn event_thresholds(&self) -> (f32, f32) {
        let scale = f64::from(self.event_threshold_scale);
        let scaled = |c: f32| (scale * f64::from(c)) as f32;
        let c_pos = self.event_threshold;
        (
            scaled(c_pos),
            scaled(self.event_threshold_neg.unwrap_or(c_pos)),
        )
    }

    /// The event loss's penalty as `train::loss::event` takes it (thresholds C± from
    /// [`TrainConfig::event_thresholds`]).
    pub fn event_penalty(&self) -> crate::loss::event::EventPenalty {
        let (c_pos, c_neg) = self.event_thresholds();
        let (c_pos, c_neg) = (f64::from(c_pos), f64::from(c_neg));
        match self.event_penalty {
            EventPenaltyKind::Squared => crate::loss::event::EventPenalty::Squared,
            EventPenaltyKind::Bound => crate::loss::event::EventPenalty::Bound {
                c_pos,
                c_neg,
                margin: f64::from(self.event_bound_margin),
                dead_zone: f64::from(self.event_dead_zone),
                overshoot: f64::from(self.event_overshoot_weight),
                cap: if self.event_residual_cap > 0.0 {
                    f64::from(self.event_residual_cap) * 0.5 * (c_pos + c_neg)
                } else {
                    f64::INFINITY
                },
                huber: self.event_residual_cap_huber,
            },
        }
    }
}
