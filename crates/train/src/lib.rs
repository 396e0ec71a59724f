//! The E-Sem3DGS method: model assembly (semantic Gaussians for human and scene, deformation and colour
//! networks), losses, the optimisation loop, checkpoints and evaluation. This is the only crate that
//! knows the method; everything it builds on is generic.

pub mod blend;
pub mod camera_alignment;
pub mod checkpoint;
pub mod colour;
pub mod config;
pub mod data;
pub mod density;
pub mod eval;
pub mod export;
pub mod init;
pub mod loss;
pub mod model;
pub mod optimisers;
pub mod pose;
pub mod schedule;
pub mod trainer;

/// Errors of the training crate.
#[derive(Debug, thiserror::Error)]
pub enum TrainError {
    /// A network op rejected its inputs.
    #[error(transparent)]
    Nn(#[from] nn::NnError),
    /// The dataset is invalid (every problem is listed with its path).
    #[error(transparent)]
    Scene(#[from] scene::SceneError),
    /// The body model or deformation failed.
    #[error(transparent)]
    SmplDeform(#[from] smpl_deform::SmplDeformError),
    /// The rasterizer rejected its inputs.
    #[error(transparent)]
    Raster(#[from] rasterize_cpu::RasterError),
    /// A camera (the scene's, the model's) cannot be rendered from.
    #[error(transparent)]
    Camera(#[from] rasterize_cpu::CameraError),
    /// The flow network rejected its inputs or weights.
    #[error("flow network: {0}")]
    Flow(#[from] flow::FlowError),
    /// The LPIPS network rejected its inputs (e.g. an image below its minimum size).
    #[error("lpips: {0}")]
    Lpips(#[from] lpips::LpipsError),
    /// A configuration or input that cannot be trained on.
    #[error("{0}")]
    Config(String),
    /// Preparing one kind of supervision failed (`TrainingData::prepare`).
    #[error("preparing {what}: {source}")]
    Prepare {
        /// What was being prepared (e.g. "the flow loss").
        what: &'static str,
        /// Why it failed.
        source: Box<TrainError>,
    },
    /// A loss or gradient became NaN or infinite; the parameters of the previous step are kept.
    #[error(
        "non-finite loss or gradient at step {step}; stopping with the last finite parameters"
    )]
    NonFinite {
        /// The step at which it happened.
        step: usize,
    },
    /// A checkpoint could not be written or read.
    #[error("checkpoint {path}: {message}")]
    Checkpoint {
        /// The checkpoint file.
        path: std::path::PathBuf,
        /// What went wrong.
        message: String,
    },
    /// An array does not have the expected length.
    #[error("{what}: expected {expected} values, found {found}")]
    Shape {
        /// What was checked.
        what: String,
        /// Expected length.
        expected: usize,
        /// Actual length.
        found: usize,
    },
}
