//! [`TrainConfig::validate`]: settings that cannot be trained with are refused, naming the field.
//! The checks run in groups — sizes, loss weights, events, initialisation, rates, schedules — and
//! the first problem found is reported.

use super::{BlurModel, EventPairs, ExposureMotion, TrainConfig};
use crate::TrainError;

/// A refusal naming the field.
fn bad(field: &str, why: &str) -> Result<(), TrainError> {
    Err(TrainError::Config(format!("config `{field}`: {why}")))
}

/// Refuses `v` unless it is finite and ≥ 0.
fn non_negative(field: &str, v: f32) -> Result<(), TrainError> {
    if v >= 0.0 && v.is_finite() {
        Ok(())
    } else {
        bad(field, "must be a finite number ≥ 0")
    }
}

/// Refuses `v` unless it is finite and in `[lo, hi]`.
fn within(field: &str, v: f32, lo: f32, hi: f32) -> Result<(), TrainError> {
    if v.is_finite() && (lo..=hi).contains(&v) {
        Ok(())
    } else {
        bad(field, &format!("must be in [{lo}, {hi}]"))
    }
}

impl TrainConfig {
    /// Rejects settings that cannot be trained with, naming the field.
    pub fn validate(&self) -> Result<(), TrainError> {
        self.validate_sizes()?;
        self.validate_loss_weights()?;
        self.validate_events()?;
        self.validate_initialisation()?;
        self.validate_rates()?;
        self.validate_schedules()
    }

    /// Steps, Gaussian counts, network sizes.
    fn validate_sizes(&self) -> Result<(), TrainError> {
        if self.steps == 0 {
            return bad("steps", "must be at least 1");
        }
        if self.human_gaussians + self.scene_gaussians == 0 {
            return bad("human_gaussians", "no Gaussians to initialise");
        }
        if self.max_gaussians >= 1 << 24 {
            return bad("max_gaussians", "must be below 2^24 (16,777,216)");
        }
        if self.max_gaussians < self.human_gaussians + self.scene_gaussians {
            return bad("max_gaussians", "smaller than the initial count");
        }
        if self.feature_dim == 0 || self.deform_hidden == 0 {
            return bad("feature_dim", "network sizes must be positive");
        }
        Ok(())
    }

    /// The semantic gate, the image and flow losses' weights.
    fn validate_loss_weights(&self) -> Result<(), TrainError> {
        if !(0.0..1.0).contains(&self.semantic_gate) {
            return bad("semantic_gate", "must be in [0, 1)");
        }
        if !(0.0..=1.0).contains(&self.ssim_weight) {
            return bad("ssim_weight", "must be in [0, 1]");
        }
        if !(self.ssim_weight_final_fraction > 0.0 && self.ssim_weight_final_fraction <= 1.0) {
            return bad("ssim_weight_final_fraction", "must be in (0, 1]");
        }
        non_negative("image_gradient_weight", self.image_gradient_weight)?;
        non_negative("lpips_weight", self.lpips_weight)?;
        non_negative("flow_weight", self.flow_weight)?;
        non_negative("flow_tau", self.flow_tau)?;
        if !(self.flow_scale > 0.0 && self.flow_scale <= 1.0) {
            return bad("flow_scale", "must be in (0, 1]");
        }
        Ok(())
    }

    /// The event loss: weight, thresholds, the bound penalty's shape, ε, and its pairs.
    fn validate_events(&self) -> Result<(), TrainError> {
        non_negative("event_weight", self.event_weight)?;
        if !(self.event_weight_final_fraction > 0.0 && self.event_weight_final_fraction <= 1.0) {
            return bad("event_weight_final_fraction", "must be in (0, 1]");
        }
        if !(self.event_threshold > 0.0 && self.event_threshold.is_finite()) {
            return bad("event_threshold", "must be a finite number > 0");
        }
        if let Some(c) = self.event_threshold_neg {
            if !(c > 0.0 && c.is_finite()) {
                return bad("event_threshold_neg", "must be a finite number > 0");
            }
        }
        within(
            "event_threshold_scale",
            self.event_threshold_scale,
            0.25,
            4.0,
        )?;
        within("event_bound_margin", self.event_bound_margin, 0.0, 2.0)?;
        within("event_dead_zone", self.event_dead_zone, 0.0, 4.0)?;
        within(
            "event_overshoot_weight",
            self.event_overshoot_weight,
            0.0,
            1.0,
        )?;
        non_negative("event_residual_cap", self.event_residual_cap)?;
        if !(1..=16).contains(&self.event_pool) {
            return bad("event_pool", "must be a block side of 1 to 16 pixels");
        }
        if self.event_pool > 1
            && (self.event_penalty != super::EventPenaltyKind::Squared
                || self.event_pairs != super::EventPairs::Exposure)
        {
            return bad(
                "event_pool",
                "pools the squared penalty between sub-exposure renders: needs \
                 `event_penalty = squared` and `event_pairs = exposure`",
            );
        }
        if !(self.event_refractory_us.is_finite()
            && (0.0..=1e5).contains(&self.event_refractory_us))
        {
            return bad("event_refractory_us", "must be 0 to 100000 µs");
        }
        if self.event_refractory_us > 0.0 && self.event_pairs != super::EventPairs::Exposure {
            return bad(
                "event_refractory_us",
                "reads the intervals between sub-exposure renders: needs `event_pairs = exposure`",
            );
        }
        if self.event_reach > 3 {
            return bad("event_reach", "must be 0 to 3 pixels");
        }
        if self.event_reach > 0 && self.event_pool > 1 {
            return bad(
                "event_reach",
                "holds each pixel through its neighbourhood; `event_pool` averages blocks: \
                 one of them at a time",
            );
        }
        if !(self.event_log_eps > 0.0 && self.event_log_eps.is_finite()) {
            return bad("event_log_eps", "must be a finite number > 0");
        }
        if self.edi_warmup > 0 && self.train_on != super::TrainOn::Blurred {
            return bad(
                "edi_warmup",
                "warms up before training on the observed (blurred) frames: \
                 needs `train_on = blurred`",
            );
        }
        if self.edi_warmup > 0 && self.edi_warmup >= self.steps {
            return bad("edi_warmup", "must be fewer than `steps`");
        }
        Ok(())
    }

    /// The initial Gaussians.
    fn validate_initialisation(&self) -> Result<(), TrainError> {
        if !(self.max_initial_scale > 0.0) {
            return bad("max_initial_scale", "must be positive");
        }
        if !(self.initial_opacity > 0.0 && self.initial_opacity < 1.0) {
            return bad("initial_opacity", "must be in (0, 1)");
        }
        Ok(())
    }

    /// Learning rates and regulariser weights.
    fn validate_rates(&self) -> Result<(), TrainError> {
        let rates = [
            ("lr_means", self.lr_means),
            ("lr_log_scales", self.lr_log_scales),
            ("lr_quats", self.lr_quats),
            ("lr_opacity", self.lr_opacity),
            ("lr_features", self.lr_features),
            ("lr_semantic", self.lr_semantic),
            ("lr_nonrigid", self.lr_nonrigid),
            ("lr_skinning", self.lr_skinning),
            ("lr_colour", self.lr_colour),
            ("lr_latent", self.lr_latent),
            ("lr_pose_correction", self.lr_pose_correction),
            ("lr_pose_correction_root", self.lr_pose_correction_root),
            ("lr_exposure_motion", self.lr_exposure_motion),
            ("lr_exposure_motion_root", self.lr_exposure_motion_root),
            (
                "pose_correction_zero_weight",
                self.pose_correction_zero_weight,
            ),
            (
                "pose_correction_smooth_weight",
                self.pose_correction_smooth_weight,
            ),
            ("lr_camera_rotation", self.lr_camera_rotation),
            ("lr_camera_translation", self.lr_camera_translation),
            ("lr_camera_pixels", self.lr_camera_pixels),
            (
                "camera_correction_zero_weight",
                self.camera_correction_zero_weight,
            ),
            (
                "camera_correction_smooth_weight",
                self.camera_correction_smooth_weight,
            ),
            (
                "camera_tracker_prior_weight",
                self.camera_tracker_prior_weight,
            ),
            ("camera_scale_prior_weight", self.camera_scale_prior_weight),
            ("skinning_weight", self.skinning_weight),
            ("aiap_position_weight", self.aiap_position_weight),
            ("aiap_covariance_weight", self.aiap_covariance_weight),
            ("size_prior_weight", self.size_prior_weight),
            ("opacity_entropy_weight", self.opacity_entropy_weight),
        ];
        for (name, v) in rates {
            if !(v.is_finite() && v >= 0.0) {
                return bad(name, "must be a finite non-negative number");
            }
        }
        for (name, v) in [
            ("camera_tracker_error_deg", self.camera_tracker_error_deg),
            ("camera_tracker_error_cm", self.camera_tracker_error_cm),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return bad(name, "must be a finite positive number");
            }
        }
        Ok(())
    }

    /// Options that depend on each other, sub-exposures, rate schedules, the camera's near plane
    /// and the background.
    fn validate_schedules(&self) -> Result<(), TrainError> {
        if self.event_loss
            && self.event_pairs == EventPairs::Exposure
            && self.blur_model != BlurModel::Exposure
        {
            return bad(
                "event_pairs",
                "`exposure` compares sub-exposure renders: it needs blur_model = exposure \
                 (for the pairs of consecutive frames: event_pairs = frames)",
            );
        }
        if self.subframes == 0 || self.subframes > 64 {
            return bad("subframes", "must be in 1..=64");
        }
        let sigma = self.camera_correction_smoothing;
        if !(sigma.is_finite() && (0.0..=100.0).contains(&sigma)) {
            return bad(
                "camera_correction_smoothing",
                "must be a width in training frames in 0..=100",
            );
        }
        for (name, v) in [
            ("lr_means_final_fraction", self.lr_means_final_fraction),
            (
                "lr_pose_correction_final_fraction",
                self.lr_pose_correction_final_fraction,
            ),
            (
                "lr_exposure_motion_final_fraction",
                self.lr_exposure_motion_final_fraction,
            ),
            ("lr_camera_final_fraction", self.lr_camera_final_fraction),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return bad(
                    name,
                    "must be a finite number > 0 (a fraction of the first rate)",
                );
            }
        }
        let learned_motion = self.exposure_motion == ExposureMotion::Learned;
        if learned_motion && self.blur_model != BlurModel::Exposure {
            return bad(
                "exposure_motion",
                "`learned` reshapes the motion inside each exposure: it needs blur_model = exposure",
            );
        }
        if self.pose_correction
            && !self.pose_correction_mid
            && !self.pose_correction_change
            && !learned_motion
        {
            return bad(
                "pose_correction_mid",
                "off with pose_correction_change off and exposure_motion given leaves pose correction \
                 nothing to learn",
            );
        }
        if self.camera_correction && !self.camera_correction_mid && !self.camera_correction_change {
            return bad(
                "camera_correction_mid",
                "off with camera_correction_change off leaves camera correction nothing to learn",
            );
        }
        if self.pose_correction_knot_every == 0 {
            return bad(
                "pose_correction_knot_every",
                "must be at least 1 (training frames)",
            );
        }
        if !(self.near_plane > 0.0 && self.near_plane.is_finite()) {
            return bad("near_plane", "must be a finite number > 0 (metres)");
        }
        if self.background.iter().any(|v| !v.is_finite()) {
            return bad("background", "must be finite");
        }
        Ok(())
    }
}
