//! The step's share of learned camera correction (`crate::pose::camera_correction`): a frame's
//! pass cameras corrected by its twists, and the corrections' gradient from each pass's
//! rasterizer-input gradients.

use crate::config::TrainConfig;
use crate::data::TrainingData;
use crate::model::{corrected_camera, FramePass, Model, PassCamera, PosedGradients};
use crate::pose::camera_basis::{image_motion_metric, whitening_basis, BASIS_VALUES};
use crate::pose::camera_correction::{
    correction_backward, smoothing_weights, tracker_prior_terms, twist_at, twist_backward,
    CAMERA_CORRECTION_VALUES, TWIST_VALUES,
};
use crate::pose::camera_scale::{centre_deviations, scale_prior_terms};
use crate::pose::correction::{exposure_offset, knot_prior_terms, CorrectionPrior};
use crate::TrainError;
use rasterize_cpu::{camera_pose_gradient, Camera};

/// One training frame's corrected pass cameras and what their backward needs.
pub(super) struct CorrectedCameras {
    /// The frame's training slot.
    pub slot: usize,
    /// The corrected cameras, one per pass.
    cameras: Vec<Camera>,
    /// The given cameras' centres (the colours' view; [`PassCamera`]).
    view_centres: Vec<[f32; 3]>,
    /// Each pass's twist and exposure offset.
    twists: Vec<([f64; 6], f32)>,
    /// The model has a clip-wide twist (`Model::camera_gauge`), learned from the person alone.
    gauge: bool,
}

impl CorrectedCameras {
    /// The cameras `given` (one per pass, in exposure order) of training slot `slot` corrected by
    /// its current camera correction.
    pub fn of(model: &Model, given: &[&Camera], slot: usize) -> Self {
        let correction = model.training_camera_correction(slot);
        let count = given.len();
        let offsets: Vec<f32> = (0..count).map(|s| exposure_offset(s, count)).collect();
        Self {
            slot,
            cameras: given
                .iter()
                .zip(&offsets)
                .map(|(c, &o)| corrected_camera(c, &correction, o))
                .collect(),
            view_centres: given
                .iter()
                .map(|c| PassCamera::of(c).view_centre)
                .collect(),
            twists: offsets
                .iter()
                .map(|&o| (twist_at(&correction, o), o))
                .collect(),
            gauge: !model.camera_gauge.is_empty(),
        }
    }

    /// The passes' cameras: rasterized from the corrected camera, viewed from the given one.
    pub fn pass_cameras(&self) -> Vec<PassCamera<'_>> {
        self.cameras
            .iter()
            .zip(&self.view_centres)
            .map(|(raster, &view_centre)| PassCamera {
                raster,
                view_centre,
            })
            .collect()
    }

    /// Values of a frame's gradient ([`CorrectedCameras::add_gradient`]): its correction's, then
    /// with a clip-wide twist that twist's (the same layout).
    pub fn gradient_len(&self) -> usize {
        CAMERA_CORRECTION_VALUES * if self.gauge { 2 } else { 1 }
    }

    /// Adds ∂L/∂(this frame's correction) ([`CAMERA_CORRECTION_VALUES`] values) to `grad` from pass
    /// `s` (`pass`, its rasterizer-input gradients `posed`); with a clip-wide twist, then adds
    /// that twist's gradient from the person's Gaussians alone (the pass's active ones) to the
    /// next [`CAMERA_CORRECTION_VALUES`] values.
    pub fn add_gradient(
        &self,
        s: usize,
        pass: &FramePass<'_>,
        posed: &PosedGradients,
        grad: &mut [f64],
    ) -> Result<(), TrainError> {
        let (means, covariances) = (&pass.posed.means, &pass.posed.covariances);
        let camera = &self.cameras[s];
        let d_left =
            camera_pose_gradient(camera, means, covariances, &posed.means, &posed.covariances)?;
        let (twist, offset) = self.twists[s];
        let n = CAMERA_CORRECTION_VALUES;
        correction_backward(&twist_backward(&d_left, &twist), offset, &mut grad[..n]);
        if self.gauge {
            let person = pass.active();
            let pick = |v: &[[f32; 3]]| person.iter().map(|&i| v[i]).collect::<Vec<_>>();
            let pick_cov = |v: &[[[f32; 3]; 3]]| person.iter().map(|&i| v[i]).collect::<Vec<_>>();
            let d_person = camera_pose_gradient(
                camera,
                &pick(means),
                &pick_cov(covariances),
                &pick(&posed.means),
                &pick_cov(&posed.covariances),
            )?;
            // The clip-wide twist adds to the mid-exposure twist: its gradient is the mid half's.
            let g = twist_backward(&d_person, &twist);
            for (o, v) in grad[n..n + TWIST_VALUES].iter_mut().zip(g) {
                *o += v;
            }
        }
        Ok(())
    }
}

/// The camera corrections' gradient of one step: every training frame's row (zero but for the
/// step's frames) and the rows to step.
pub(super) struct CameraGradient {
    /// ∂L/∂ every camera correction (the model's `camera_corrections` layout).
    pub values: Vec<f32>,
    /// The training slots whose corrections the step moves.
    pub slots: Vec<usize>,
    /// ∂L/∂ the clip-wide twist (`Model::camera_gauge`; empty without one): the person's share.
    pub gauge: Vec<f32>,
    /// The prior's value on the step's frames.
    pub prior: f32,
}

impl CameraGradient {
    /// The gradient of the frames `frames` (slot, ∂L/∂ its correction, then the clip-wide twist's
    /// share as [`CorrectedCameras::gradient_len`] lays it out), with the prior's terms of each
    /// (weights of `config`).
    pub fn of(
        model: &Model,
        config: &TrainConfig,
        data: &TrainingData,
        frames: &[(usize, Vec<f64>)],
    ) -> Self {
        let n = CAMERA_CORRECTION_VALUES;
        let mut values = vec![0.0f32; model.camera_corrections.len()];
        let mut slots = Vec::new();
        let prior = CorrectionPrior {
            zero: config.camera_correction_zero_weight,
            smooth: config.camera_correction_smooth_weight,
        };
        let mut prior_value = 0.0;
        let mut gauge = vec![0.0f32; model.camera_gauge.len()];
        let sigma = model.config.camera_correction_smoothing;
        let rows = model.camera_corrections.len() / n;
        for (slot, g) in frames {
            for (r, &v) in gauge.iter_mut().zip(g.get(n..).unwrap_or(&[])) {
                *r += v as f32;
            }
            // Each stored row the frame's twist weighs gets its share of the smoothed values
            // (the frame's own alone without smoothing), the frame's own row the rest.
            let smoothed = model.config.camera_correction_smoothed_values;
            for (j, w) in smoothing_weights(*slot, rows, sigma) {
                let row = &mut values[j * n..(j + 1) * n];
                for (r, &v) in row.iter_mut().zip(&g[..smoothed]) {
                    *r += (w * v) as f32;
                }
                if !slots.contains(&j) {
                    slots.push(j);
                }
            }
            let own = &mut values[slot * n..(slot + 1) * n];
            for (r, &v) in own.iter_mut().zip(&g[..n]).skip(smoothed) {
                *r += v as f32;
            }
        }
        let tracker = (
            config.camera_tracker_prior_weight,
            config.camera_tracker_error_deg.to_radians(),
            config.camera_tracker_error_cm / 100.0,
        );
        for &slot in &slots {
            let row = &mut values[slot * n..(slot + 1) * n];
            prior_value += knot_prior_terms(&model.camera_corrections, n, slot, prior, row);
            if tracker.0 > 0.0 {
                let own = &model.camera_corrections[slot * n..(slot + 1) * n];
                prior_value += tracker_prior_terms(own, tracker, row);
            }
        }
        if config.camera_scale_prior_weight > 0.0 {
            prior_value += scale_prior(model, config, data, &slots, &mut values);
        }
        for row in values.chunks_mut(n) {
            if !config.camera_correction_change {
                row[n / 2..].fill(0.0);
            }
            if !config.camera_correction_mid {
                row[..n / 2].fill(0.0);
            }
        }
        Self {
            values,
            slots,
            gauge,
            prior: prior_value,
        }
    }

    /// True when every value is finite.
    pub fn all_finite(&self) -> bool {
        self.values.iter().chain(&self.gauge).all(|v| v.is_finite()) && self.prior.is_finite()
    }
}

/// The scale prior's value (`crate::pose::camera_scale`) on every training frame's stored
/// correction, its gradient added to the rows of `slots` (the step's) in `values`.
fn scale_prior(
    model: &Model,
    config: &TrainConfig,
    data: &TrainingData,
    slots: &[usize],
    values: &mut [f32],
) -> f32 {
    let n = CAMERA_CORRECTION_VALUES;
    let given: Vec<[[f64; 4]; 4]> = data
        .frames
        .iter()
        .map(|f| f.camera.world_to_camera)
        .collect();
    let deviations = centre_deviations(&given);
    let stored: Vec<f64> = model
        .camera_corrections
        .iter()
        .map(|&v| f64::from(v))
        .collect();
    let mut grad = vec![0.0f64; stored.len()];
    let weights = (
        f64::from(config.camera_scale_prior_weight),
        f64::from(config.camera_tracker_error_cm) / 100.0,
    );
    let value = scale_prior_terms(&stored, &deviations, weights, &mut grad);
    for &slot in slots {
        for (r, g) in values[slot * n..(slot + 1) * n]
            .iter_mut()
            .zip(&grad[slot * n..(slot + 1) * n])
        {
            *r += *g as f32;
        }
    }
    value as f32
}

/// The image-motion basis of the camera corrections' steps (`crate::pose::camera_basis`), from the
/// initial `model` seen by the first training frame's camera: its scene Gaussians' means weighted
/// by their opacity, and the person as its root in that frame weighted by its Gaussians' summed
/// opacity (their canonical means are not in the world yet).
pub(super) fn image_motion_basis(
    model: &Model,
    data: &TrainingData,
) -> Result<[f32; BASIS_VALUES], TrainError> {
    let refuse = |why: &str| {
        TrainError::Config(format!(
            "camera_correction_basis = image: {why} (use camera_correction_basis = twist)"
        ))
    };
    let first = data
        .frames
        .first()
        .ok_or_else(|| refuse("no training frame"))?;
    let set = &model.set;
    let (mut points, mut weights) = (Vec::with_capacity(set.len() + 1), Vec::new());
    let mut person = 0.0f32;
    for i in 0..set.len() {
        if model.probability(i) >= 0.5 {
            person += set.opacity(i);
        } else {
            points.push(set.means[i]);
            weights.push(set.opacity(i));
        }
    }
    points.push(first.pose.prepared.root);
    weights.push(person);
    let metric = image_motion_metric(&first.camera, &points, &weights)
        .ok_or_else(|| refuse("nothing of the initial scene is in front of the first camera"))?;
    whitening_basis(&metric).ok_or_else(|| refuse("the scene's image does not move"))
}
