//! The E-Sem3DGS method: model assembly (semantic Gaussians for human and scene, deformation and colour
//! networks), losses, the optimisation loop, checkpoints and evaluation. This is the only crate that
//! knows the method; everything it builds on is generic.

pub mod aiap;
pub mod blend;
pub mod colour;
pub mod flow_loss;
pub mod image_loss;
