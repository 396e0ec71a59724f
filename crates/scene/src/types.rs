//! The typed contents of `scene.json` (format version 1) and the writer.
//!
//! Conventions (DESIGN.md §3): metres, seconds, radians; OpenCV pinhole camera (x right, y down,
//! z forward, pixel (i, j) centred at (i + 0.5, j + 0.5)); SMPL pose as 24 axis-angle triples with
//! joint 0 the global orientation. Paths are relative to the scene directory, with `/` separators.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::error::{Result, SceneError};

/// The format version this crate reads and writes.
pub const FORMAT_VERSION: u32 = 1;
/// Name of the description file inside a scene directory.
pub const SCENE_FILE: &str = "scene.json";
/// Number of SMPL joints (pose entries per frame).
pub const NUM_JOINTS: usize = 24;

/// A whole scene description (`scene.json`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scene {
    /// Always [`FORMAT_VERSION`].
    pub format_version: u32,
    /// The fixed camera.
    pub camera: Camera,
    /// The body model and its shape.
    pub body: BodySpec,
    /// Nominal frame rate (frames per second).
    pub fps: f64,
    /// Exposure time of every frame (seconds), `0 < exposure_s <= 1 / fps`; frame `k` integrates
    /// light over `[time_s - exposure_s / 2, time_s + exposure_s / 2]`.
    pub exposure_s: f64,
    /// How the RGB images (inputs and sharp references) are encoded on disk.
    pub images: ImageEncoding,
    /// The frames, in time order.
    pub frames: Vec<Frame>,
    /// Free-form information from the tool that made the scene (generator name, knobs). Readers
    /// must not depend on it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub generator: Option<serde_json::Value>,
}

/// OpenCV pinhole camera, fixed for the whole scene.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Camera {
    /// Image width (pixels).
    pub width: u32,
    /// Image height (pixels).
    pub height: u32,
    /// Focal length along x (pixels).
    pub fx: f64,
    /// Focal length along y (pixels).
    pub fy: f64,
    /// Principal point x (pixels; the image's left edge is 0, the first pixel centre 0.5).
    pub cx: f64,
    /// Principal point y (pixels; the top edge is 0).
    pub cy: f64,
    /// `[R | t]` rows: `p_cam = R · p_world + t` (metres), R a rotation.
    pub world_to_camera: [[f64; 4]; 3],
}

/// Body model reference and shape.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BodySpec {
    /// `builtin:makehuman` or a path to an SMPL `.npz` (relative to the scene directory or absolute);
    /// interpreted by `smpl-deform`, not here.
    pub model: String,
    /// Shape coefficients (may be empty; models without shape blend shapes ignore them).
    pub betas: Vec<f32>,
}

/// On-disk encoding of the RGB images.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ImageEncoding {
    /// Bits per channel of the PNG files: 8 or 16.
    pub bit_depth: u8,
    /// Transfer function from linear intensity to the stored code values.
    pub transfer: Transfer,
}

/// Transfer function of stored code values.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Transfer {
    /// Code value = linear intensity × (2^bits − 1).
    Linear,
    /// Code value = sRGB OETF (IEC 61966-2-1) of linear intensity × (2^bits − 1).
    Srgb,
}

/// Train/test membership of a frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Split {
    /// Used for optimisation.
    Train,
    /// Held out for evaluation.
    Test,
}

impl Split {
    /// The JSON spelling.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Train => "train",
            Self::Test => "test",
        }
    }
}

/// Where a flow field to the next frame came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FlowKind {
    /// Exact flow from the generator's geometry (synthetic data only).
    GroundTruth,
    /// Estimated from the events alone by contrast maximisation.
    EventsCm,
    /// Made by another tool (a flow network on events, RAFT on frames ...).
    External,
}

impl FlowKind {
    /// The JSON spelling.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::GroundTruth => "ground_truth",
            Self::EventsCm => "events_cm",
            Self::External => "external",
        }
    }

    /// Every kind, in JSON spelling order of the docs.
    pub const ALL: [FlowKind; 3] = [Self::GroundTruth, Self::EventsCm, Self::External];
}

/// A forward flow field from a frame to the next entry of `frames`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FlowRef {
    /// Provenance.
    pub kind: FlowKind,
    /// Middlebury `.flo` file, `(2, H, W)` pixels, `x_next = x + F(x)`, camera size.
    pub path: String,
    /// Optional single-channel PNG of the camera size: non-zero where the flow is valid (visible in
    /// both frames). Absent = valid everywhere.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub valid_mask: Option<String>,
}

/// One frame.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Frame {
    /// Frame number; strictly increasing along `frames` (gaps allowed).
    pub index: u32,
    /// Mid-exposure time (seconds); strictly increasing along `frames`.
    pub time_s: f64,
    /// The observed (possibly blurred) RGB image.
    pub image: String,
    /// Sharp reference RGB image at mid exposure (evaluation only; real data has none).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sharp: Option<String>,
    /// Human mask at mid exposure: single-channel PNG, non-zero = human.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mask: Option<String>,
    /// SMPL pose at mid exposure: 24 axis-angle rotations (radians), joint 0 = global orientation.
    pub pose: Vec<[f32; 3]>,
    /// SMPL global translation (metres, world frame).
    pub transl: [f32; 3],
    /// Flow fields to the next frame (at most one per kind; none on the last frame).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub flow_to_next: Vec<FlowRef>,
    /// Raw events with timestamps in `[time_s, next time_s)` (`.npz`, `events` crate layout).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub events: Option<String>,
    /// Train or test.
    pub split: Split,
}

impl Frame {
    /// The flow of the given kind, if the frame has one.
    pub fn flow(&self, kind: FlowKind) -> Option<&FlowRef> {
        self.flow_to_next.iter().find(|f| f.kind == kind)
    }

    /// The 72 pose values, joint-major (the `SmplParams::pose` layout).
    pub fn pose_flat(&self) -> Vec<f32> {
        self.pose.iter().flatten().copied().collect()
    }
}

impl Camera {
    /// Projects a world point (metres) to pixel coordinates `(u, v)` and camera depth `z` (metres).
    pub fn project(&self, p_world: [f64; 3]) -> [f64; 3] {
        let m = &self.world_to_camera;
        let p_cam: [f64; 3] = std::array::from_fn(|r| {
            m[r][0] * p_world[0] + m[r][1] * p_world[1] + m[r][2] * p_world[2] + m[r][3]
        });
        [
            self.fx * p_cam[0] / p_cam[2] + self.cx,
            self.fy * p_cam[1] / p_cam[2] + self.cy,
            p_cam[2],
        ]
    }

    /// Camera centre in world coordinates (metres): `−Rᵀ t`.
    pub fn centre_world(&self) -> [f64; 3] {
        let m = &self.world_to_camera;
        std::array::from_fn(|c| -(m[0][c] * m[0][3] + m[1][c] * m[1][3] + m[2][c] * m[2][3]))
    }
}

impl Scene {
    /// Indices (into `frames`) of the frames of a split.
    pub fn split_indices(&self, split: Split) -> Vec<usize> {
        (0..self.frames.len())
            .filter(|&i| self.frames[i].split == split)
            .collect()
    }

    /// Absolute path of a file named in the scene.
    pub fn resolve(dir: &Path, rel: &str) -> PathBuf {
        dir.join(rel)
    }

    /// Writes `dir/scene.json` (pretty JSON, trailing newline, via a temporary file and a rename).
    ///
    /// The description is checked first (the JSON-level checks of [`crate::load`], not the files,
    /// which may be written afterwards); any problem is an error listing all of them.
    pub fn write(&self, dir: &Path) -> Result<()> {
        let value = serde_json::to_value(self).map_err(|e| SceneError::Arg {
            name: "scene".into(),
            message: format!("not serialisable (non-finite number?): {e}"),
        })?;
        let problems = crate::validate::check_value(&value, None);
        if !problems.is_empty() {
            return Err(SceneError::Invalid {
                dir: dir.to_path_buf(),
                problems,
            });
        }
        let mut text = serde_json::to_string_pretty(self).map_err(|e| SceneError::Arg {
            name: "scene".into(),
            message: e.to_string(),
        })?;
        text.push('\n');
        let path = dir.join(SCENE_FILE);
        let tmp = dir.join(format!("{SCENE_FILE}.tmp"));
        let io = |p: &Path| {
            let p = p.to_path_buf();
            move |source| SceneError::Io { path: p, source }
        };
        std::fs::write(&tmp, text).map_err(io(&tmp))?;
        std::fs::rename(&tmp, &path).map_err(io(&path))?;
        Ok(())
    }
}
