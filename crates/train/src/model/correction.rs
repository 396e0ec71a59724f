//! The model's learned pose corrections as the rest of the crate reads them: the knots' frames, a
//! frame's interpolated correction and its corrected SMPL parameters
//! (`crate::pose::correction`).

use super::Model;
use crate::pose::correction::{
    corrected_params, interpolated_correction, knot_slots, KnotSpan, CORRECTION_VALUES,
};
use smpl_deform::SmplParams;

impl Model {
    /// The frame numbers of the pose corrections' knots (`pose_correction_knot_every`; one row of
    /// [`Model::pose_corrections`] each).
    pub fn correction_knot_frames(&self) -> Vec<u32> {
        knot_slots(
            self.frame_indices.len(),
            self.config.pose_correction_knot_every,
        )
        .into_iter()
        .map(|slot| self.frame_indices[slot])
        .collect()
    }

    /// The pose correction of frame `index` at mid exposure ([`CORRECTION_VALUES`] values, the
    /// change over the exposure zero; empty when pose correction is off), interpolated between the
    /// knots around it (`train::pose::correction::interpolated_correction`).
    pub fn pose_correction_for(&self, index: u32) -> Vec<f32> {
        interpolated_correction(
            &self.correction_knot_frames(),
            &self.pose_corrections,
            index,
        )
    }

    /// Training slot `slot`'s whole correction (mid exposure and change; [`CORRECTION_VALUES`]
    /// values) and where it sits among the knots (for the backward). Pose correction must be on.
    pub fn training_correction(&self, slot: usize) -> (Vec<f32>, KnotSpan) {
        let span = KnotSpan::of(&self.correction_knot_frames(), self.frame_indices[slot]);
        let values = span.blend(&self.pose_corrections, CORRECTION_VALUES, CORRECTION_VALUES);
        (values, span)
    }

    /// SMPL parameters of frame `index` with its pose correction applied at mid exposure (`params`
    /// unchanged when pose correction is off): what evaluation renders a scene's frame with.
    pub fn corrected_params(&self, index: u32, params: &SmplParams) -> SmplParams {
        let correction = self.pose_correction_for(index);
        if correction.is_empty() {
            params.clone()
        } else {
            corrected_params(params, &correction, 0.0)
        }
    }
}
