//! The crate's one error type. Every variant names the file key or field it is about, so a user with
//! a broken body file learns which array to fix.

use std::path::PathBuf;

/// Errors from loading, converting and posing body models.
#[derive(Debug, thiserror::Error)]
pub enum SmplDeformError {
    /// Reading or writing a file failed.
    #[error("i/o error on {path}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// A required array is absent from the `.npz` file.
    #[error("missing key `{key}` in body file")]
    MissingKey {
        /// The array name.
        key: String,
    },
    /// An array has a shape other than the expected one.
    #[error("key `{key}`: wrong shape {found:?}, expected {expected}")]
    WrongShape {
        /// The array name.
        key: String,
        /// The shape found in the file.
        found: Vec<u64>,
        /// Human-readable expected shape.
        expected: String,
    },
    /// An array has a dtype this loader does not read.
    #[error("key `{key}`: unsupported dtype {dtype}")]
    UnsupportedDtype {
        /// The array name.
        key: String,
        /// The dtype string from the npy header.
        dtype: String,
    },
    /// An array holds a NaN or an infinity.
    #[error("key `{key}`: non-finite value at flat index {index}")]
    NonFinite {
        /// The array name.
        key: String,
        /// Flat (C-order) index of the first bad value.
        index: usize,
    },
    /// The kinematic tree is not a tree rooted at joint 0 with parents before children.
    #[error("key `{key}`: not a kinematic tree: {reason}")]
    NotATree {
        /// The array name (`kintree_table`).
        key: String,
        /// What is wrong.
        reason: String,
    },
    /// An index array refers outside its target (a face vertex, a UV index).
    #[error("key `{key}`: index {index} out of range (< {bound})")]
    IndexOutOfRange {
        /// The array name.
        key: String,
        /// The offending index.
        index: i64,
        /// The exclusive upper bound.
        bound: usize,
    },
    /// Reading an array from the archive failed (corrupt npy data, zip error).
    #[error("key `{key}`: {message}")]
    BadArray {
        /// The array name.
        key: String,
        /// What went wrong.
        message: String,
    },
    /// Pose parameters with the wrong length or non-finite values.
    #[error("invalid parameter `{field}`: {reason}")]
    InvalidParams {
        /// The field name (`pose`, `betas`, `transl`, ...).
        field: String,
        /// What is wrong.
        reason: String,
    },
    /// The MakeHuman conversion found inconsistent assets.
    #[error("makehuman conversion: {0}")]
    Conversion(String),
    /// An unknown body model reference (neither a path nor `builtin:makehuman`).
    #[error("unknown body model `{0}`")]
    UnknownModel(String),
}

/// Shorthand for results of this crate.
pub type Result<T> = std::result::Result<T, SmplDeformError>;
