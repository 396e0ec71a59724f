//! The canonical body space of 3DGS-Avatar and the transforms from it to any posed frame.
//!
//! Canonical pose ("Da-pose"/"Vitruvian"): the body's rest pose (arms in T-pose) with the left hip
//! (SMPL joint 1) rotated by +45° and the right hip (joint 2) by −45° about the forward axis z, i.e.
//! axis-angle `pose[3·1 + 2] = +π/4`, `pose[3·2 + 2] = −π/4`, all else zero, no translation. With
//! SMPL's frame (x = body's left, y up) this spreads the legs outwards symmetrically.
//! Human Gaussians live in this space; a frame's bone transforms map canonical points to the frame:
//! `frame_from_canonical_b = posed_from_rest_b(frame) · posed_from_rest_b(canonical)⁻¹`.

use crate::body::{BodyModel, PosedBody, SmplParams};
use crate::error::Result;
use crate::math::{affine_inverse, affine_mul, Affine};
use crate::skeleton::NUM_JOINTS;

/// Hip abduction of the canonical pose (radians about z; + for the left hip, − for the right).
pub const DA_POSE_HIP_ANGLE: f32 = std::f32::consts::FRAC_PI_4;

/// The canonical (Da-) pose parameters with the given betas.
pub fn da_pose_params(betas: &[f32]) -> SmplParams {
    let mut pose = vec![0.0; 3 * NUM_JOINTS];
    pose[3 + 2] = DA_POSE_HIP_ANGLE;
    pose[6 + 2] = -DA_POSE_HIP_ANGLE;
    SmplParams {
        pose,
        betas: betas.to_vec(),
        transl: [0.0; 3],
    }
}

/// A body posed in canonical space, with the inverse skinning transforms cached.
#[derive(Clone, Debug)]
pub struct CanonicalBody {
    /// The canonical mesh, joints and `posed_from_rest` transforms.
    pub posed: PosedBody,
    /// `rest_from_canonical_b`, the inverse of each canonical skinning transform.
    pub rest_from_canonical: Vec<Affine<f32>>,
}

impl CanonicalBody {
    /// Poses `model` in the canonical pose with `betas`.
    pub fn new(model: &BodyModel, betas: &[f32]) -> Result<Self> {
        let posed = model.pose(&da_pose_params(betas))?;
        let rest_from_canonical = posed
            .posed_from_rest
            .iter()
            .map(|a| {
                let a64 = a.map(f64::from);
                affine_inverse(&a64).map(|x| x as f32)
            })
            .collect();
        Ok(Self {
            posed,
            rest_from_canonical,
        })
    }

    /// Per-bone transforms from canonical space to the frame posed by `frame`
    /// (`frame.posed_from_rest` must come from the same model and betas).
    pub fn frame_from_canonical(&self, frame: &PosedBody) -> Vec<Affine<f32>> {
        self.frame_from_canonical_of(&frame.posed_from_rest)
    }

    /// [`CanonicalBody::frame_from_canonical`] of a frame's skinning transforms `posed_from_rest`.
    pub fn frame_from_canonical_of(&self, posed_from_rest: &[Affine<f32>]) -> Vec<Affine<f32>> {
        posed_from_rest
            .iter()
            .zip(&self.rest_from_canonical)
            .map(|(f, inv)| affine_mul(&f.map(f64::from), &inv.map(f64::from)).map(|x| x as f32))
            .collect()
    }
}
