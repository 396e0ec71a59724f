//! The body a model is posed with: a body model in its canonical pose with fixed shape parameters,
//! turning SMPL parameters into what the model consumes (pose feature, bone transforms, root).

use crate::TrainError;
use smpl_deform::deform_net::pose_code;
use smpl_deform::frame_pose::{frame_pose, frame_pose_backward, FramePose};
use smpl_deform::math::Affine;
use smpl_deform::{BodyModel, BodyRef, CanonicalBody, SmplDeformError, SmplParams, NUM_JOINTS};
use std::path::Path;

/// A body pose prepared for the model: the pose feature and the canonical-to-frame bone
/// transforms — of every person of the model, one after the other ([`Cast::prepare`]).
#[derive(Clone, Debug, PartialEq)]
pub struct PreparedPose {
    /// The 207-value pose feature (R[1:] − I), per person.
    pub pose_code: Vec<f32>,
    /// `frame_from_canonical` per bone (24 per person, row-major 3×4).
    pub bones: Vec<Affine<f32>>,
    /// World position of the first person's root joint (m).
    pub root: [f32; 3],
}

/// A body pose as the scene gives it (SMPL parameters, what pose correction corrects) and as the
/// model consumes it.
#[derive(Clone, Debug, PartialEq)]
pub struct GivenPose {
    /// The first person's SMPL parameters.
    pub params: SmplParams,
    /// The other people's SMPL parameters, the model's person order (empty with one person).
    pub others: Vec<SmplParams>,
    /// Every person's pose prepared by [`Cast::prepare`].
    pub prepared: PreparedPose,
}

/// The people a model is posed with: the first person's body and the others' (the scene's person
/// order). With no others it prepares exactly what [`Body::prepare`] does.
#[derive(Clone, Copy, Debug)]
pub struct Cast<'a> {
    /// The first person.
    pub first: &'a Body,
    /// Everyone else.
    pub others: &'a [Body],
}

impl Cast<'_> {
    /// The number of people.
    pub fn len(&self) -> usize {
        1 + self.others.len()
    }

    /// Always false: a cast has its first person.
    pub fn is_empty(&self) -> bool {
        false
    }

    /// Every person's pose prepared in one: `first` for the first person, `others[j]` for the
    /// others' (the pose codes and bones concatenated, the root the first person's). A missing
    /// or extra pose is an error.
    pub fn prepare(
        &self,
        first: &SmplParams,
        others: &[SmplParams],
    ) -> Result<PreparedPose, TrainError> {
        if others.len() != self.others.len() {
            return Err(TrainError::Config(format!(
                "a pose of {} people for a model of {}",
                1 + others.len(),
                self.len()
            )));
        }
        let mut prepared = self.first.prepare(first)?;
        for (body, params) in self.others.iter().zip(others) {
            let own = body.prepare(params)?;
            prepared.pose_code.extend_from_slice(&own.pose_code);
            prepared.bones.extend_from_slice(&own.bones);
        }
        Ok(prepared)
    }

    /// The poses with their prepared form ([`Cast::prepare`]).
    pub fn given(
        &self,
        first: &SmplParams,
        others: &[SmplParams],
    ) -> Result<GivenPose, TrainError> {
        Ok(GivenPose {
            prepared: self.prepare(first, others)?,
            params: first.clone(),
            others: others.to_vec(),
        })
    }
}

/// What [`Body::pose_backward`] needs of a pose prepared by [`Body::prepare_differentiable`]: the
/// pose in f64 and its forward kinematics.
#[derive(Clone, Debug)]
pub struct PoseTape {
    pose: Vec<f64>,
    frame: FramePose<f64>,
}

/// The body in canonical space, able to prepare any SMPL pose for the model.
#[derive(Clone, Debug)]
pub struct Body {
    /// The body model.
    pub model: BodyModel,
    /// Its canonical (Da-) pose.
    pub canonical: CanonicalBody,
    /// Shape parameters used for every pose.
    pub betas: Vec<f32>,
}

impl Body {
    /// Loads the canonical body of `model` with `betas`.
    pub fn new(model: BodyModel, betas: Vec<f32>) -> Result<Self, TrainError> {
        let canonical = CanonicalBody::new(&model, &betas)?;
        Ok(Self {
            model,
            canonical,
            betas,
        })
    }

    /// Loads the body a reference names (`builtin:makehuman` or an SMPL `.npz` path); a relative
    /// SMPL path is taken relative to `base` (the scene directory that named it).
    pub fn load(reference: &str, betas: Vec<f32>, base: &Path) -> Result<Self, TrainError> {
        let model = resolve_reference(reference, base)?.load()?;
        Self::new(model, betas)
    }

    /// Pose feature and bone transforms of SMPL parameters (`params.betas` is replaced by the body's).
    pub fn prepare(&self, params: &SmplParams) -> Result<PreparedPose, TrainError> {
        let params = SmplParams {
            betas: self.betas.clone(),
            ..params.clone()
        };
        let posed = self.model.pose(&params)?;
        Ok(PreparedPose {
            pose_code: pose_code(&posed.local_rotations),
            bones: self.canonical.frame_from_canonical(&posed),
            root: posed.joints.first().copied().unwrap_or(params.transl),
        })
    }

    /// `params` with its prepared pose ([`Body::prepare`]), the body alone.
    pub fn given(&self, params: &SmplParams) -> Result<GivenPose, TrainError> {
        Ok(GivenPose {
            prepared: self.prepare(params)?,
            params: params.clone(),
            others: Vec::new(),
        })
    }

    /// [`Body::prepare`] (the same values, bit for bit, without posing the mesh) with what
    /// [`Body::pose_backward`] needs to differentiate the bones and the pose code w.r.t. the pose.
    pub fn prepare_differentiable(
        &self,
        params: &SmplParams,
    ) -> Result<(PreparedPose, PoseTape), TrainError> {
        let invalid = |field: &str, reason: &str| {
            TrainError::SmplDeform(SmplDeformError::InvalidParams {
                field: field.into(),
                reason: reason.into(),
            })
        };
        if params.pose.len() != 3 * NUM_JOINTS {
            return Err(invalid("pose", "expected 72 values"));
        }
        if params
            .pose
            .iter()
            .chain(&params.transl)
            .any(|v| !v.is_finite())
        {
            return Err(invalid("pose", "non-finite value"));
        }
        let pose: Vec<f64> = params.pose.iter().map(|&x| f64::from(x)).collect();
        let (joints, inverses) = self.constants_f64();
        let frame = frame_pose(
            &pose,
            params.transl.map(f64::from),
            &joints,
            &self.model.parents,
            &inverses,
        );
        // The same roundings as `BodyModel::pose` and `CanonicalBody::frame_from_canonical`.
        let to_f32 = |m: &[f64; 12]| m.map(|x| x as f32);
        let posed_from_rest: Vec<Affine<f32>> =
            frame.fk.posed_from_rest.iter().map(to_f32).collect();
        let local: Vec<[f32; 9]> = frame
            .fk
            .local_rotations
            .iter()
            .map(|m| m.map(|x| x as f32))
            .collect();
        let root = frame
            .fk
            .joints_posed
            .first()
            .map_or(params.transl, |j| j.map(|x| x as f32));
        let prepared = PreparedPose {
            pose_code: pose_code(&local),
            bones: self.canonical.frame_from_canonical_of(&posed_from_rest),
            root,
        };
        Ok((prepared, PoseTape { pose, frame }))
    }

    /// ∂L/∂pose (72) and ∂L/∂transl of a pose prepared by [`Body::prepare_differentiable`], from the
    /// gradients of its bones and pose code ([`crate::pose::posing::ModelGradients`]'s `bones` and
    /// `pose_code`; an empty `d_pose_code` when the code was not differentiated).
    pub fn pose_backward(
        &self,
        tape: &PoseTape,
        d_bones: &[Affine<f32>],
        d_pose_code: &[f32],
    ) -> (Vec<f64>, [f64; 3]) {
        let (joints, inverses) = self.constants_f64();
        let d_bones: Vec<Affine<f64>> = d_bones.iter().map(|b| b.map(f64::from)).collect();
        let d_code: Vec<f64> = d_pose_code.iter().map(|&x| f64::from(x)).collect();
        let g = frame_pose_backward(
            &tape.pose,
            &joints,
            &self.model.parents,
            &inverses,
            &tape.frame,
            &d_bones,
            &d_code,
        );
        (g.pose, g.transl)
    }

    /// The rest joints and canonical inverses in f64 (the constants of a frame's pose).
    fn constants_f64(&self) -> (Vec<[f64; 3]>, Vec<Affine<f64>>) {
        let joints = self
            .canonical
            .posed
            .joints_rest
            .iter()
            .map(|j| j.map(f64::from))
            .collect();
        let inverses = self
            .canonical
            .rest_from_canonical
            .iter()
            .map(|a| a.map(f64::from))
            .collect();
        (joints, inverses)
    }
}

/// The body reference `reference` with a relative SMPL path joined to `base`.
pub fn resolve_reference(reference: &str, base: &Path) -> Result<BodyRef, TrainError> {
    Ok(match BodyRef::parse(reference)? {
        BodyRef::SmplFile(p) if p.is_relative() => BodyRef::SmplFile(base.join(p)),
        r => r,
    })
}
