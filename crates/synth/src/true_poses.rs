//! `poses_true.json`: the generator's true per-frame SMPL parameters, written beside `scene.json`
//! when the scene's own parameters carry an estimation error ([`crate::pose_error`]).
//!
//! The file is for evaluation and tests only (pose error of a method, oracle experiments). It is
//! not part of scene format v1: `scene::load` never reads it, and the trainer (`crates/train`, which
//! does not depend on this crate) must never read it — a method that saw it would be trained on
//! ground truth. The values are the ones `scene.json` would hold without the error, bit for bit
//! (the same `f32` numbers, written by the same JSON writer).

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::error::{Result, SynthError};

/// Name of the file inside a scene directory.
pub const TRUE_POSES_FILE: &str = "poses_true.json";
/// The only `format_version` written and read.
pub const TRUE_POSES_VERSION: u32 = 1;

/// SMPL parameters of one frame at its mid-exposure time.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FramePose {
    /// The frame's `index` in `scene.json`.
    pub index: u32,
    /// Mid-exposure time (seconds), as in `scene.json`.
    pub time_s: f64,
    /// 24 axis-angle rotations (radians), joint 0 the global orientation (world frame), each
    /// joint's rotation in its parent's frame (the `scene.json` layout).
    pub pose: Vec<[f32; 3]>,
    /// SMPL translation (metres, world frame).
    pub transl: [f32; 3],
}

/// The whole file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TruePoses {
    /// Always [`TRUE_POSES_VERSION`].
    pub format_version: u32,
    /// One entry per frame of `scene.json`, in the same order.
    pub frames: Vec<FramePose>,
}

impl TruePoses {
    /// Path of the file in the scene directory `dir`.
    pub fn path(dir: &Path) -> PathBuf {
        dir.join(TRUE_POSES_FILE)
    }

    /// Writes `dir/poses_true.json` (pretty JSON, trailing newline).
    pub fn write(&self, dir: &Path) -> Result<()> {
        crate::side_file::write_json(&Self::path(dir), self)
    }

    /// Removes `dir/poses_true.json` if there is one.
    pub fn remove(dir: &Path) -> Result<()> {
        crate::side_file::remove(&Self::path(dir))
    }

    /// Reads `dir/poses_true.json`, refusing another version, a frame without 24 joints and
    /// non-finite numbers (the message names the frame and field).
    pub fn read(dir: &Path) -> Result<Self> {
        let path = Self::path(dir);
        let poses: Self = crate::side_file::read_json(&path)?;
        let bad = |reason: String| SynthError::TruePoses {
            path: path.clone(),
            reason,
        };
        if poses.format_version != TRUE_POSES_VERSION {
            return Err(bad(format!(
                "format_version {} (expected {TRUE_POSES_VERSION})",
                poses.format_version
            )));
        }
        for (i, f) in poses.frames.iter().enumerate() {
            if f.pose.len() != scene::NUM_JOINTS {
                return Err(bad(format!(
                    "frames[{i}].pose has {} joints (expected {})",
                    f.pose.len(),
                    scene::NUM_JOINTS
                )));
            }
            let finite = f
                .pose
                .iter()
                .flatten()
                .chain(&f.transl)
                .all(|v| v.is_finite());
            if !finite || !f.time_s.is_finite() {
                return Err(bad(format!("frames[{i}]: a number is not finite")));
            }
        }
        Ok(poses)
    }
}
