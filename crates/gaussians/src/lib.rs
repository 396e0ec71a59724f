//! Gaussian parameter sets for 3D Gaussian splatting, stored as structure-of-arrays, with the math every
//! other crate shares: activations, 3D covariance from (log-scale, quaternion), real spherical harmonics,
//! the INRIA 3DGS PLY format, Adam and the 3DGS density control.
//!
//! This crate is the bottom layer of the workspace: it knows nothing of cameras, rasterization, humans
//! or training schedules.

pub mod covariance;
pub mod sh;
