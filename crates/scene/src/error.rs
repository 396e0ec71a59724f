//! The crate's one error type, and [`Problem`], one finding of the validator.

use std::fmt;
use std::path::PathBuf;

/// One thing wrong with a scene: where (a JSON path such as `frames[3].pose[5][1]`, or a file path
/// relative to the scene directory) and what.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Problem {
    /// JSON path inside `scene.json` (`frames[3].split`) or `path/of/file (frames[3].image)`.
    pub path: String,
    /// What is wrong, naming the value found and what was expected.
    pub message: String,
}

impl fmt::Display for Problem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}", self.path, self.message)
    }
}

/// Errors of the `scene` crate.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// An I/O error on `path`.
    #[error("{path}: I/O error: {source}")]
    Io {
        /// File being read or written.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// `scene.json` is not JSON at all.
    #[error("{path}: not valid JSON: {source}")]
    Json {
        /// The `scene.json` path.
        path: PathBuf,
        /// The parser's error (with line and column).
        #[source]
        source: serde_json::Error,
    },
    /// The scene has problems; all of them are listed.
    #[error("{}: {} problem(s):\n  {}", dir.join("scene.json").display(), problems.len(), join(problems))]
    Invalid {
        /// The scene directory.
        dir: PathBuf,
        /// Every problem found.
        problems: Vec<Problem>,
    },
    /// An image could not be encoded or decoded.
    #[error("{path}: image error: {message}")]
    Image {
        /// The image file.
        path: PathBuf,
        /// What went wrong (decoder message, or the size/format mismatch).
        message: String,
    },
    /// A camera file (`camera_files`) is not JSON of an accepted camera shape.
    #[error("parsing camera JSON {path}: {source}")]
    CameraJson {
        /// File being parsed (`<string>` or similar for in-memory JSON).
        path: PathBuf,
        /// The parser's error (with line and column).
        #[source]
        source: serde_json::Error,
    },
    /// A camera index into an INRIA `cameras.json` list is out of range.
    #[error("camera index {index} out of range: {path} holds {count} cameras")]
    CameraIndex {
        /// File holding the list.
        path: PathBuf,
        /// Requested index.
        index: usize,
        /// Number of cameras in the file.
        count: usize,
    },
    /// A COLMAP text model cannot be read (`scene::colmap`).
    #[error("{path}:{line}: {message}")]
    Colmap {
        /// `cameras.txt` or `images.txt`.
        path: PathBuf,
        /// 1-based line number (0: the file as a whole).
        line: usize,
        /// What is wrong.
        message: String,
    },
    /// A caller-supplied argument is out of its domain.
    #[error("invalid argument {name}: {message}")]
    Arg {
        /// The argument.
        name: String,
        /// What is wrong with it.
        message: String,
    },
}

fn join(problems: &[Problem]) -> String {
    problems
        .iter()
        .map(ToString::to_string)
        .collect::<Vec<_>>()
        .join("\n  ")
}

/// Result alias of the crate.
pub type Result<T, E = SceneError> = std::result::Result<T, E>;
