//! Gaussian parameter sets for 3D Gaussian splatting, stored as structure-of-arrays, with the math every
//! other crate shares: activations, 3D covariance from (log-scale, quaternion), real spherical harmonics,
//! the INRIA 3DGS PLY format, Adam and the 3DGS density control.
//!
//! This crate is the bottom layer of the workspace: it knows nothing of cameras, rasterization, humans
//! or training schedules.

pub mod adam;
pub mod covariance;
pub mod density;
pub mod init;
pub mod ply;
mod ply_ascii;
mod ply_compressed;
pub mod set;
pub mod sh;

pub use adam::{AdamConfig, AdamState, GaussianAdam, GaussianLearningRates};
pub use ply::{read_ply, read_ply_bytes, write_ply, write_ply_bytes, PlyError};
pub use set::{inverse_sigmoid, sigmoid, softmax, GaussianSet};

/// Errors of in-memory Gaussian sets and their optimiser state (file errors are [`PlyError`]).
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum GaussianError {
    /// An attribute does not have the length the set's shape implies.
    #[error("field `{field}`: expected {expected} values, found {found}")]
    Shape {
        /// Attribute name.
        field: String,
        /// Expected number of values.
        expected: usize,
        /// Number found.
        found: usize,
    },
    /// A NaN or infinite parameter.
    #[error("field `{field}`: non-finite value at Gaussian {index}")]
    NonFinite {
        /// Attribute name.
        field: String,
        /// Index of the first offending Gaussian.
        index: usize,
    },
    /// A quaternion with all four components zero has no rotation.
    #[error("field `quats`: Gaussian {index} has a zero quaternion")]
    ZeroQuaternion {
        /// Index of the offending Gaussian.
        index: usize,
    },
    /// SH degree outside 0..=3.
    #[error("unsupported SH degree {0} (supported: 0 to 3)")]
    ShDegree(usize),
    /// Two sets or a set and its optimiser state do not have matching shapes.
    #[error("{0}")]
    Incompatible(String),
}
