//! Event-camera streams (read/write), voxel grids, an ESIM-style simulator, flow files, event-only
//! flow and event deblurring of a frame (EDI).
//!
//! Conventions (DESIGN.md §3): events are `(t: i64 microseconds, x: u16, y: u16, p: ±1)` with pixel
//! (x, y) = (column, row), row 0 at the top; flow is `(2, H, W)` f32 planar in pixels, forward from
//! frame k to k+1 (`x_{k+1} = x_k + F(x_k)`). This crate knows nothing of the flow network, of
//! training or of the synthetic benchmark (it sits below them, DESIGN.md §2).

pub mod cmax;
pub mod edi;
pub mod error;
pub mod flowio;
pub mod hot_pixels;
pub mod io;
pub mod repr;
pub mod simulate;
pub mod stream;

pub use cmax::{flow_from_events, CmaxConfig, CmaxProblem};
pub use edi::{apply_gain, edi_gain, EdiConfig, Exposure};
pub use error::{EventsError, Result};
pub use flowio::{flow_to_rgb, read_flow, write_flo, write_flow, write_flow_colour_png, Flow};
pub use hot_pixels::{hot_pixel_mask, without_pixels, HotPixelRule};
pub use io::{
    open_events, open_events_with, read_events, read_events_with, write_events, EventReader,
    ReadOptions,
};
pub use repr::{count_frame, time_slice_frames, voxel_grid, CountMode};
pub use simulate::{grey_from_rgb, simulate_sequence, EsimConfig, EventSimulator};
pub use stream::{Event, EventSlice, EventStream, SensorSize};
