//! The crate's one error type. Messages name the knob, file or field and the offending value.

use std::path::PathBuf;

/// Errors of the `synth` crate.
#[derive(Debug, thiserror::Error)]
pub enum SynthError {
    /// A generator knob is out of range.
    #[error("invalid setting {knob} = {value}: {reason}")]
    Knob {
        /// The knob's name (as on the command line).
        knob: &'static str,
        /// The value given.
        value: String,
        /// The accepted range.
        reason: String,
    },
    /// An I/O error on `path`.
    #[error("{path}: I/O error: {source}")]
    Io {
        /// File or directory.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// The body model could not be loaded or posed.
    #[error("body model: {0}")]
    Body(#[from] smpl_deform::SmplDeformError),
    /// The event simulator or an event/flow file writer failed.
    #[error("events: {0}")]
    Events(#[from] events::EventsError),
    /// Writing the scene (images, masks, scene.json) failed.
    #[error("scene: {0}")]
    Scene(#[from] scene::SceneError),
    /// Encoding an image failed.
    #[error("{path}: image error: {message}")]
    Image {
        /// File being written.
        path: PathBuf,
        /// The encoder's message.
        message: String,
    },
    /// `poses_true.json` is not what this crate writes.
    #[error("{path}: {reason}")]
    TruePoses {
        /// The file.
        path: PathBuf,
        /// What is wrong, naming the frame and field.
        reason: String,
    },
    /// A scene's `generator.config` is absent or not a benchmark this crate can rebuild.
    #[error("{path}: generator.config: {reason}")]
    GeneratorConfig {
        /// The scene file (`scene.json`).
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// Reading or writing JSON failed.
    #[error("{path}: JSON error: {source}")]
    Json {
        /// File being read or written.
        path: PathBuf,
        /// The parser's or serialiser's error.
        #[source]
        source: serde_json::Error,
    },
}

/// Result alias of the crate.
pub type Result<T, E = SynthError> = std::result::Result<T, E>;
