//! Everything about the person's pose, from the body model to the posed Gaussians:
//!
//! - [`body`]: the body model at fixed shape; SMPL parameters → pose feature, bone transforms, root.
//! - [`exposure`]: the sub-exposure times of a frame and the pose track between the scene's frames.
//! - [`correction`]: learned per-frame (per-knot) corrections of the given SMPL parameters.
//! - [`camera_correction`]: learned per-frame corrections of a moving camera's given poses.
//! - [`camera_scale`]: a prior keeping those corrections from rescaling the given camera path.
//! - [`posing`]: one frame's Gaussians posed (deformed, coloured, blended) and the exact backward.
//! - [`reposing`]: a posed frame re-posed at other bones, sharing its network evaluations.
//!
//! Imports run one way: `reposing` → `posing`, `camera_correction` → `correction`, `camera_scale` → `camera_correction`; `body`,
//! `exposure` and `correction` import none of the others.

pub mod body;
pub mod camera_basis;
pub mod camera_correction;
pub mod camera_scale;
pub mod correction;
pub mod exposure;
pub mod posing;
pub mod reposing;
pub mod smear;
