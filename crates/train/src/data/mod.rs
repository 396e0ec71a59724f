//! Loading a scene-format-v1 directory into what training needs: the rasterizer camera, every frame's
//! decoded images (linear, planar), masks and SMPL parameters, with the split.
//!
//! All validation is `scene::load`'s (every problem reported with its path, nothing skipped); this
//! module only converts, and reports which file failed to decode if one does. [`TrainingData`] is the
//! training split prepared for the loop (poses, skinning samples, pair supervision).

mod dataset;
pub mod edi;
mod event_counts;
mod event_files;
mod prepare;
mod training;

pub use dataset::{load_dataset, Dataset, ScenePaths, TrainFrame};
pub use event_files::event_read_options;
pub use prepare::{LossNetworks, Preparation};
pub use training::{
    consecutive_training_pairs, read_pair_flow, sharp_flow_pairs, EventPair, FlowPair, PairFlow,
    SharpFlowPair, TrainingData, TrainingFrame,
};
