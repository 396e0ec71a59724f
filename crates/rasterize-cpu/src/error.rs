//! The crate's one error type. Every variant names the field or value at fault so that a caller
//! can report it without adding context of its own.

/// Errors of render requests (a camera that cannot be rendered from is [`RasterError::Camera`]).
#[derive(Debug, thiserror::Error)]
pub enum RasterError {
    /// The camera cannot be rendered from (its image size, focal lengths or matrix).
    #[error(transparent)]
    Camera(#[from] pinhole::CameraError),
    /// A per-Gaussian input slice has the wrong length.
    #[error("input {field} has {got} entries, expected {expected}")]
    LengthMismatch {
        /// Field name (`log_scales`, `channels`, `d_image`, ...).
        field: &'static str,
        /// Entries found.
        got: usize,
        /// Entries expected.
        expected: usize,
    },
    /// A Gaussian's quaternion is zero (it has no orientation).
    #[error("Gaussian {index}: quaternion is zero")]
    ZeroQuaternion {
        /// Index of the Gaussian.
        index: usize,
    },
    /// A Gaussian parameter is NaN or infinite.
    #[error("Gaussian {index}: {field} is not finite")]
    NonFiniteParameter {
        /// Index of the Gaussian.
        index: usize,
        /// Field name.
        field: &'static str,
    },
    /// A Gaussian's 3D covariance (or smear) is not symmetric: |Σ_row,col − Σ_col,row| exceeds
    /// [`crate::raster::COVARIANCE_SYMMETRY_TOLERANCE`] times its largest |diagonal| entry.
    #[error(
        "Gaussian {index}: {field} is not symmetric: |S[{row}][{col}] - S[{col}][{row}]| = {asymmetry:e} \
         exceeds 1e-4 x max|diag| = {scale:e}"
    )]
    NonSymmetricCovariance {
        /// Index of the Gaussian.
        index: usize,
        /// The input field (`covariances` or `smears`).
        field: &'static str,
        /// Row of the offending upper-triangle entry.
        row: usize,
        /// Column of the offending upper-triangle entry.
        col: usize,
        /// |Σ_row,col − Σ_col,row| (m²).
        asymmetry: f64,
        /// Largest |diagonal| entry (m²).
        scale: f64,
    },
    /// Render settings are invalid.
    #[error("render settings: {0}")]
    InvalidSettings(String),
    /// The SH degree is above 3 or does not match the coefficient count.
    #[error("SH degree {degree} is unsupported (0..=3)")]
    InvalidShDegree {
        /// Requested degree.
        degree: usize,
    },
    /// `render_backward` was given a forward output of another scene or camera.
    #[error("forward output does not match this request: {0}")]
    ForwardMismatch(String),
}
