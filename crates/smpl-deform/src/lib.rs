//! Body models (SMPL `.npz`, the built-in CC0 MakeHuman body), forward kinematics, linear blend
//! skinning, canonical-space sampling and the inside/outside test.
//!
//! This crate knows bodies and skinning, never cameras, images, rasterization or training losses.
//! Math kernels are generic over f32/f64 ([`num_traits::Float`]) so the f64 versions are checked by
//! finite differences in the `gradient-checks` package.

mod batch_mlp;
pub mod body;
pub mod canonical;
pub mod deform_net;
pub mod error;
pub mod fk;
pub mod frame_pose;
pub mod inside;
pub mod io;
pub mod lbs;
pub mod makehuman;
pub mod math;
pub mod motion;
pub mod npz;
pub mod pose_blend;
pub mod sample;
pub mod skeleton;
pub mod zju;

pub use body::{builtin_makehuman_path, BodyModel, BodyRef, PosedBody, SmplParams, UvMap};
pub use canonical::{da_pose_params, CanonicalBody};
pub use error::{Result, SmplDeformError};
pub use inside::{inside, winding_number};
pub use sample::{sample_surface, SurfaceSamples};
pub use skeleton::{NUM_JOINTS, NUM_POSE_FEATURES, SMPL_JOINT_NAMES, SMPL_PARENTS};
