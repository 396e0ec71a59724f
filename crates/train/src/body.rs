//! The body a model is posed with: a body model in its canonical pose with fixed shape parameters,
//! turning SMPL parameters into what the model consumes (pose feature, bone transforms, root).

use crate::TrainError;
use smpl_deform::deform_net::pose_code;
use smpl_deform::math::Affine;
use smpl_deform::{BodyModel, BodyRef, CanonicalBody, SmplParams};
use std::path::Path;

/// A body pose prepared for the model: the pose feature and the canonical-to-frame bone transforms.
#[derive(Clone, Debug, PartialEq)]
pub struct PreparedPose {
    /// The 207-value pose feature (R[1:] − I).
    pub pose_code: Vec<f32>,
    /// `frame_from_canonical` per bone (24, row-major 3×4).
    pub bones: Vec<Affine<f32>>,
    /// World position of the root joint (m).
    pub root: [f32; 3],
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

    /// The body a scene names (`scene.json`'s `body`), a relative SMPL path taken relative to the
    /// scene directory.
    pub fn of_scene(data: &crate::data::Dataset) -> Result<Self, TrainError> {
        let spec = &data.scene.body;
        Self::load(&spec.model, spec.betas.clone(), &data.dir)
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
}

/// The body reference `reference` with a relative SMPL path joined to `base`.
pub fn resolve_reference(reference: &str, base: &Path) -> Result<BodyRef, TrainError> {
    Ok(match BodyRef::parse(reference)? {
        BodyRef::SmplFile(p) if p.is_relative() => BodyRef::SmplFile(base.join(p)),
        r => r,
    })
}
