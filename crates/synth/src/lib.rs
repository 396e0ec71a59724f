//! The synthetic motion-blur benchmark generator: a textured room, a dressed SMPL-topology body
//! moving fast, a fixed camera; S sub-frames per exposure rendered by a triangle-mesh renderer
//! independent of the Gaussian rasterizer; blurred frames, sharp references, masks, ground-truth
//! flow, events; written in scene format v1 (DESIGN.md §5, docs/FORMATS.md). Optionally the SMPL
//! parameters given to the trainer carry a monocular fitter's error (`pose_error`), the truth
//! then written beside them (`true_poses`).
//!
//! This crate must never depend on `rasterize-cpu` or `train`: the benchmark would otherwise share
//! the model's renderer or its assumptions. Every output byte is a function of [`SynthConfig`].

pub mod body;
pub mod camera;
pub mod camera_error;
pub mod camera_motion;
pub mod cast;
pub mod config;
pub mod error;
pub mod flow;
pub mod from_frames;
pub mod generate;
pub mod mesh;
pub mod motion;
pub mod pose_error;
pub mod pose_metrics;
mod preview;
pub mod raster;
pub mod room;
mod side_file;
pub mod texture;
pub mod true_poses;

/// Version of the generator's output: bump it whenever the bytes written for some [`SynthConfig`]
/// change (a new renderer detail, motion, simulator or contrast-maximisation setting), so cached
/// benchmarks made by an older generator are regenerated. History: 1 — first release; 2 — event-only
/// flow from the affine/curvature contrast maximisation of `events` (2026-11-22).
pub const GENERATOR_VERSION: u32 = 2;

pub use camera_motion::CameraMotion;
pub use config::{Preset, SynthConfig};
pub use error::{Result, SynthError};
pub use generate::{generate, generate_with_body, Stats};
pub use motion::Speed;
pub use pose_error::PoseError;
pub use pose_metrics::{PoseErrorStats, ViewErrorStats};
pub use true_poses::{FramePose, TruePoses, TRUE_POSES_FILE};
