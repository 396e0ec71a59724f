//! What several commands write: the evaluation (`metrics.json`, strips), the run report (`report.html`), its pictures (strips, event and
//! flow panels, curves), the pose and camera reports against a synthetic scene's truth, and the bitmap font
//! the pictures are labelled with.

pub mod camera_report;
pub mod evaluation;
pub mod pictures;
pub mod pixel_font;
pub mod pose_report;
pub mod report;
