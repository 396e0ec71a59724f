//! The step's share of learned pose correction (`crate::pose::correction`): a frame's poses prepared
//! from its corrected SMPL parameters, and the correction's gradient from the passes' bone and
//! pose-code gradients.

use crate::config::TrainConfig;
use crate::data::TrainingData;
use crate::model::Model;
use crate::pose::body::{Body, PoseTape, PreparedPose};
use crate::pose::correction::{
    correct_pose_backward, corrected_params, exposure_offset, prior_terms, root_indices,
    CorrectionPrior, KnotSpan, CORRECTION_VALUES,
};
use crate::TrainError;
use smpl_deform::math::Affine;

/// One frame's corrected poses (one per pass) and what their backward needs.
pub(super) struct CorrectedPoses {
    /// Where the frame's correction comes from among the knots.
    span: KnotSpan,
    /// The prepared poses, one per pass.
    pub prepared: Vec<PreparedPose>,
    tapes: Vec<PoseTape>,
    offsets: Vec<f32>,
}

impl CorrectedPoses {
    /// The poses of training slot `slot` corrected by its current correction: the sub-exposure
    /// poses when `exposure` (and the data has them), else the mid-exposure pose.
    pub fn of(
        model: &Model,
        data: &TrainingData,
        slot: usize,
        exposure: bool,
    ) -> Result<Self, TrainError> {
        let (correction, span) = model.training_correction(slot);
        let params: Vec<_> = data
            .poses(slot, exposure)?
            .iter()
            .map(|p| &p.params)
            .collect();
        let count = params.len();
        let offsets: Vec<f32> = (0..count).map(|s| exposure_offset(s, count)).collect();
        let mut prepared = Vec::with_capacity(count);
        let mut tapes = Vec::with_capacity(count);
        for (p, &offset) in params.iter().zip(&offsets) {
            let (pose, tape) =
                data.body
                    .prepare_differentiable(&corrected_params(p, &correction, offset))?;
            prepared.push(pose);
            tapes.push(tape);
        }
        Ok(Self {
            span,
            prepared,
            tapes,
            offsets,
        })
    }

    /// The knots this frame's correction is interpolated from (one or two).
    pub fn knots(&self) -> Vec<usize> {
        self.span.weights().into_iter().map(|(k, _)| k).collect()
    }

    /// Adds ∂L/∂knots of these poses' correction to `grad` (every knot's, [`CORRECTION_VALUES`]
    /// per knot) from each pass's ∂L/∂bones and ∂L/∂pose code (same order as the poses; an empty
    /// code gradient for a pass that re-posed another's networks); the root's values get none
    /// unless `correct_root`.
    pub fn add_gradient(
        &self,
        body: &Body,
        correct_root: bool,
        d_bones: &[&[Affine<f32>]],
        d_pose_codes: &[&[f32]],
        grad: &mut [f32],
    ) {
        let mut slot_grad = vec![0.0f64; CORRECTION_VALUES];
        for (((tape, &offset), bones), code) in self
            .tapes
            .iter()
            .zip(&self.offsets)
            .zip(d_bones)
            .zip(d_pose_codes)
        {
            let (d_pose, d_transl) = body.pose_backward(tape, bones, code);
            correct_pose_backward(&d_pose, d_transl, f64::from(offset), &mut slot_grad);
        }
        if !correct_root {
            for k in root_indices() {
                slot_grad[k] = 0.0;
            }
        }
        let slot_grad: Vec<f32> = slot_grad.into_iter().map(|g| g as f32).collect();
        self.span.blend_backward(&slot_grad, grad);
    }
}

/// The prior's terms for the knots `knots` ([`prior_terms`] with the weights of `config`), their
/// gradient added to `grad`.
pub(super) fn add_prior(
    model: &Model,
    config: &TrainConfig,
    knots: &[usize],
    grad: &mut [f32],
) -> f32 {
    let prior = CorrectionPrior {
        zero: config.pose_correction_zero_weight,
        smooth: config.pose_correction_smooth_weight,
    };
    let n = CORRECTION_VALUES;
    knots
        .iter()
        .map(|&k| {
            prior_terms(
                &model.pose_corrections,
                k,
                prior,
                &mut grad[k * n..(k + 1) * n],
            )
        })
        .sum()
}
