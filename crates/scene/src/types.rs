//! The typed contents of `scene.json` (format versions 1, 2 and 3) and the writer.
//!
//! Conventions (DESIGN.md §3): metres, seconds, radians; OpenCV pinhole camera (x right, y down,
//! z forward, pixel (i, j) centred at (i + 0.5, j + 0.5)); SMPL pose as 24 axis-angle triples with
//! joint 0 the global orientation. Paths are relative to the scene directory, with `/` separators.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Deserializer, Serialize, Serializer};

use crate::error::{Result, SceneError};

/// The format version of a scene filmed by one fixed camera: what this crate writes unless a frame
/// has a camera pose of its own.
pub const FORMAT_VERSION: u32 = 1;
/// The format version of a scene whose frames may carry their own camera pose (a moving camera,
/// [`Frame::world_to_camera`]); it reads every version-1 scene unchanged.
pub const FORMAT_VERSION_MOVING_CAMERA: u32 = 2;
/// The format version of a scene with several people ([`Scene::people`], [`Frame::people`]); its
/// frames may carry their own camera pose as in version 2, and it reads every version-1 and -2 scene
/// unchanged.
pub const FORMAT_VERSION_PEOPLE: u32 = 3;
/// Name of the description file inside a scene directory.
pub const SCENE_FILE: &str = "scene.json";
/// Number of SMPL joints (pose entries per frame).
pub const NUM_JOINTS: usize = 24;

/// A whole scene description (`scene.json`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scene {
    /// [`FORMAT_VERSION`], [`FORMAT_VERSION_MOVING_CAMERA`] when a frame has its own camera pose, or
    /// [`FORMAT_VERSION_PEOPLE`] when the scene has several people
    /// ([`Scene::format_version_needed`]).
    pub format_version: u32,
    /// The camera: its intrinsics, and its pose for every frame without one of its own.
    #[serde(with = "camera_json")]
    pub camera: Camera,
    /// The body model and the shape of the first person (the one of [`Frame::pose`]).
    pub body: BodySpec,
    /// The other people of a scene with several (version 3): each with a stable id and its own
    /// shape, posed by the same body model; every frame lists their poses in this order
    /// ([`Frame::people`]). Empty: the scene has one person. Use [`Scene::person_count`].
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub people: Vec<PersonSpec>,
    /// Nominal frame rate (frames per second).
    pub fps: f64,
    /// Exposure time of every frame (seconds), `0 < exposure_s <= 1 / fps`; frame `k` integrates
    /// light over `[time_s - exposure_s / 2, time_s + exposure_s / 2]`.
    pub exposure_s: f64,
    /// How the RGB images (inputs and sharp references) are encoded on disk.
    pub images: ImageEncoding,
    /// The frames, in time order.
    pub frames: Vec<Frame>,
    /// Encoding of the frames' Prophesee `.raw` event files whose header does not state it (a
    /// recording's header can lack the `% evt` / `% format` line; the encoding is never guessed).
    /// Absent: such a file is refused, naming it. A file whose header states its encoding is read
    /// as stated (and refused if this disagrees).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub events_raw_format: Option<RawEventsFormat>,
    /// `[first, last]`: the times (seconds, the frames' clock) of a recording's first and last
    /// event, which the frames' event files hold only between (a DAVIS camera's first frames can
    /// precede its first event). Outside it, a pixel without events is no evidence of a still
    /// pixel, and no loss reads those times ([`Scene::event_evidence_span`]). Absent: the files are
    /// a complete record of every frame's span (the generator, simulated events).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub events_recorded_s: Option<[f64; 2]>,
    /// Free-form information from the tool that made the scene (generator name, knobs). Readers
    /// must not depend on it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub generator: Option<serde_json::Value>,
}

/// Encoding of a Prophesee `.raw` event file (see [`Scene::events_raw_format`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RawEventsFormat {
    /// EVT 2.0 (32-bit words).
    Evt2,
    /// EVT 3.0 (16-bit words).
    Evt3,
}

/// OpenCV pinhole camera, fixed for the whole scene: the workspace's one camera type
/// (`pinhole::Camera`, also `rasterize_cpu::Camera`). In `scene.json` its `world_to_camera` is the 3
/// rows of `[R | t]` (`p_cam = R · p_world + t`, metres, R a rotation); in memory it is 4×4, the
/// last row `[0, 0, 0, 1]`.
pub use pinhole::{Camera, Distortion};

/// The camera as `scene.json` stores it, for `#[serde(with = "scene::camera_json")]` (also used by
/// the trained model's `model.json`): the fields of [`Camera`] with `world_to_camera` as its top 3
/// rows (the 4th is `[0, 0, 0, 1]` when read, and not written); unknown fields are an error.
pub mod camera_json {
    use super::{Camera, Deserialize, Deserializer, Serialize, Serializer};

    /// Serde's view of [`Camera`] in `scene.json` (a serde remote definition: the compiler keeps its
    /// fields identical to [`Camera`]'s).
    #[derive(Serialize, Deserialize)]
    #[serde(remote = "Camera", deny_unknown_fields)]
    struct SceneCamera {
        width: u32,
        height: u32,
        fx: f64,
        fy: f64,
        cx: f64,
        cy: f64,
        #[serde(with = "rigid_rows")]
        world_to_camera: [[f64; 4]; 4],
    }

    /// Writes `camera` in the `scene.json` layout.
    pub fn serialize<S: Serializer>(camera: &Camera, s: S) -> Result<S::Ok, S::Error> {
        SceneCamera::serialize(camera, s)
    }

    /// Reads a camera in the `scene.json` layout.
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Camera, D::Error> {
        SceneCamera::deserialize(d)
    }

    /// A 4×4 affine world-to-camera matrix as its top 3 rows.
    mod rigid_rows {
        use super::{Deserialize, Deserializer, Serialize, Serializer};

        pub(super) fn serialize<S: Serializer>(m: &[[f64; 4]; 4], s: S) -> Result<S::Ok, S::Error> {
            [m[0], m[1], m[2]].serialize(s)
        }

        pub(super) fn deserialize<'de, D: Deserializer<'de>>(
            d: D,
        ) -> Result<[[f64; 4]; 4], D::Error> {
            let [r0, r1, r2] = <[[f64; 4]; 3]>::deserialize(d)?;
            Ok([r0, r1, r2, [0.0, 0.0, 0.0, 1.0]])
        }
    }

    /// An optional world-to-camera matrix as its top 3 rows ([`super::Frame::world_to_camera`]).
    pub(crate) mod optional_rigid_rows {
        use super::{Deserialize, Deserializer, Serialize, Serializer};

        pub(crate) fn serialize<S: Serializer>(
            m: &Option<[[f64; 4]; 4]>,
            s: S,
        ) -> Result<S::Ok, S::Error> {
            m.map(|m| [m[0], m[1], m[2]]).serialize(s)
        }

        pub(crate) fn deserialize<'de, D: Deserializer<'de>>(
            d: D,
        ) -> Result<Option<[[f64; 4]; 4]>, D::Error> {
            let rows = Option::<[[f64; 4]; 3]>::deserialize(d)?;
            Ok(rows.map(|[r0, r1, r2]| [r0, r1, r2, [0.0, 0.0, 0.0, 1.0]]))
        }
    }
}

/// Body model reference and the first person's shape.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BodySpec {
    /// `builtin:makehuman` or a path to an SMPL `.npz` (relative to the scene directory or absolute);
    /// interpreted by `smpl-deform`, not here.
    pub model: String,
    /// Shape coefficients (may be empty; models without shape blend shapes ignore them).
    pub betas: Vec<f32>,
    /// The first person's stable id in a scene with several people (version 3; 0 when absent, and
    /// not written when 0).
    #[serde(default, skip_serializing_if = "is_zero_u32")]
    pub id: u32,
}

fn is_zero_u32(v: &u32) -> bool {
    *v == 0
}

/// One of the other people of a scene with several ([`Scene::people`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PersonSpec {
    /// Stable id (unique in the scene, the first person's [`BodySpec::id`] included): what a
    /// tracker or EasyMocap calls this person.
    pub id: u32,
    /// Shape coefficients of this person (same meaning as [`BodySpec::betas`]).
    pub betas: Vec<f32>,
}

/// One of the other people's pose in a frame ([`Frame::people`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PersonPose {
    /// The person's id ([`PersonSpec::id`]).
    pub id: u32,
    /// SMPL pose at mid exposure, as [`Frame::pose`].
    pub pose: Vec<[f32; 3]>,
    /// SMPL global translation (metres, world frame), as [`Frame::transl`].
    pub transl: [f32; 3],
}

/// On-disk encoding of the frames (inputs and sharp references).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ImageEncoding {
    /// Bits per channel of the PNG files: 8 or 16.
    pub bit_depth: u8,
    /// Transfer function from linear intensity to the stored code values.
    pub transfer: Transfer,
    /// Channels of the PNG files: 3 (RGB, the default, not written) or 1 (grey: a DAVIS APS or
    /// CeleX-V intensity frame). Grey frames are read into memory as three equal planes
    /// ([`crate::read_rgb`]); a trainer compares them with the luminance of its renders.
    #[serde(default = "three", skip_serializing_if = "is_three")]
    pub channels: u8,
}

fn three() -> u8 {
    3
}

fn is_three(c: &u8) -> bool {
    *c == 3
}

impl ImageEncoding {
    /// RGB frames of `bit_depth` bits with `transfer`.
    pub fn rgb(bit_depth: u8, transfer: Transfer) -> Self {
        Self {
            bit_depth,
            transfer,
            channels: 3,
        }
    }

    /// True for single-channel (grey) frames.
    pub fn is_grey(&self) -> bool {
        self.channels == 1
    }
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
    /// Human mask at mid exposure: single-channel PNG, non-zero = human (any person).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mask: Option<String>,
    /// Which person each pixel shows at mid exposure (version 3): single-channel PNG, 0 = scene,
    /// `p + 1` = person `p` in [`Scene::person_ids`] order (1 = the first person).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub person_ids: Option<String>,
    /// SMPL pose of the first person at mid exposure: 24 axis-angle rotations (radians), joint 0 =
    /// global orientation.
    pub pose: Vec<[f32; 3]>,
    /// SMPL global translation of the first person (metres, world frame).
    pub transl: [f32; 3],
    /// The other people's poses at mid exposure (version 3): one entry per [`Scene::people`], in
    /// that order. Use [`Frame::pose_of`].
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub people: Vec<PersonPose>,
    /// Flow fields to the next frame (at most one per kind; none on the last frame).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub flow_to_next: Vec<FlowRef>,
    /// Raw events with timestamps in `[time_s, next time_s)` (`.npz`, `events` crate layout).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub events: Option<String>,
    /// This frame's own exposure (seconds, `0 < e ≤ 1/fps`) when it differs from the scene's
    /// (auto-exposure); absent = [`Scene::exposure_s`]. Use [`Scene::exposure_of`].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub exposure_s: Option<f64>,
    /// The camera's pose at this frame's mid exposure when the camera moves (format version 2):
    /// `p_cam = R · p_world + t`, stored as the 3 rows of `[R | t]` like the scene camera's (4×4 in
    /// memory, last row `[0, 0, 0, 1]`); absent = the scene camera's pose. Use [`Scene::camera_of`].
    #[serde(
        default,
        skip_serializing_if = "Option::is_none",
        with = "camera_json::optional_rigid_rows"
    )]
    pub world_to_camera: Option<[[f64; 4]; 4]>,
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

    /// Person `p`'s pose (24 axis-angle triples) and translation in this frame, `p` in
    /// [`Scene::person_ids`] order (0 = the first person); `None` past the frame's people.
    pub fn pose_of(&self, p: usize) -> Option<(&[[f32; 3]], [f32; 3])> {
        match p {
            0 => Some((&self.pose, self.transl)),
            _ => self
                .people
                .get(p - 1)
                .map(|o| (o.pose.as_slice(), o.transl)),
        }
    }
}

impl Scene {
    /// Indices (into `frames`) of the frames of a split.
    pub fn split_indices(&self, split: Split) -> Vec<usize> {
        (0..self.frames.len())
            .filter(|&i| self.frames[i].split == split)
            .collect()
    }

    /// The camera of frame `k` at mid exposure: the scene camera's intrinsics with the frame's own
    /// pose when it has one.
    pub fn camera_of(&self, k: usize) -> Camera {
        let mut camera = self.camera.clone();
        if let Some(pose) = self.frames.get(k).and_then(|f| f.world_to_camera) {
            camera.world_to_camera = pose;
        }
        camera
    }

    /// True when some frame has a camera pose of its own that differs from the scene camera's.
    pub fn camera_moves(&self) -> bool {
        self.frames.iter().any(|f| {
            f.world_to_camera
                .is_some_and(|pose| pose != self.camera.world_to_camera)
        })
    }

    /// How many people the scene has: 1 plus [`Scene::people`].
    pub fn person_count(&self) -> usize {
        1 + self.people.len()
    }

    /// The people's stable ids, the first person's ([`BodySpec::id`]) first.
    pub fn person_ids(&self) -> Vec<u32> {
        std::iter::once(self.body.id)
            .chain(self.people.iter().map(|p| p.id))
            .collect()
    }

    /// Person `p`'s shape coefficients, `p` in [`Scene::person_ids`] order.
    pub fn betas_of(&self, p: usize) -> Option<&[f32]> {
        match p {
            0 => Some(&self.body.betas),
            _ => self.people.get(p - 1).map(|o| o.betas.as_slice()),
        }
    }

    /// The lowest format version that can describe this scene: [`FORMAT_VERSION_PEOPLE`] when it
    /// has several people (or a first person's id other than 0), [`FORMAT_VERSION_MOVING_CAMERA`]
    /// when a frame has its own camera pose, else [`FORMAT_VERSION`].
    pub fn format_version_needed(&self) -> u32 {
        let people = !self.people.is_empty()
            || self.body.id != 0
            || self
                .frames
                .iter()
                .any(|f| !f.people.is_empty() || f.person_ids.is_some());
        if people {
            FORMAT_VERSION_PEOPLE
        } else if self.frames.iter().any(|f| f.world_to_camera.is_some()) {
            FORMAT_VERSION_MOVING_CAMERA
        } else {
            FORMAT_VERSION
        }
    }

    /// The exposure of frame `k` (seconds): its own `exposure_s`, else the scene's.
    pub fn exposure_of(&self, k: usize) -> f64 {
        self.frames
            .get(k)
            .and_then(|f| f.exposure_s)
            .unwrap_or(self.exposure_s)
    }

    /// The time span `[from, to)` (seconds) of the events that frame `k`'s `events` file holds —
    /// the scene format's one rule for it (docs/FORMATS.md): from its `time_s` to the next frame's;
    /// the last frame's file holds every later event of the recording (`to` = +∞), of which the
    /// losses read only what lies inside its exposure. Every writer of event files (the
    /// generator, the importers) splits a recording by this rule, and every reader checks it.
    pub fn event_file_span(&self, k: usize) -> (f64, f64) {
        let from = self.frames[k].time_s;
        let to = self.frames.get(k + 1).map_or(f64::INFINITY, |f| f.time_s);
        (from, to)
    }

    /// The part of [`Scene::event_file_span`] over which frame `k`'s events are a complete record:
    /// the span cut to [`Scene::events_recorded_s`] when it is set. `None` when nothing is left
    /// (the frame's file holds no evidence).
    pub fn event_evidence_span(&self, k: usize) -> Option<(f64, f64)> {
        let (mut from, mut to) = self.event_file_span(k);
        if let Some([first, last]) = self.events_recorded_s {
            from = from.max(first);
            to = to.min(last);
        }
        (from < to).then_some((from, to))
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

#[cfg(test)]
mod tests {
    use super::*;

    /// `scene.json`'s camera: 3 rows in, 3 rows out, the 4th `[0, 0, 0, 1]` in memory; 4 rows or
    /// an unknown field are errors.
    #[test]
    fn scene_camera_is_three_rows_of_r_t() {
        #[derive(Debug, PartialEq, Serialize, Deserialize)]
        struct Holder {
            #[serde(with = "camera_json")]
            camera: Camera,
        }
        let text = r#"{"camera":{"width":8,"height":6,"fx":10.0,"fy":11.0,"cx":4.0,"cy":3.0,"world_to_camera":[[1.0,0.0,0.0,0.5],[0.0,1.0,0.0,0.0],[0.0,0.0,1.0,2.0]]}}"#;
        let held: Holder = serde_json::from_str(text).expect("a scene camera");
        assert_eq!(held.camera.world_to_camera[3], [0.0, 0.0, 0.0, 1.0]);
        assert_eq!(held.camera.world_to_camera[2], [0.0, 0.0, 1.0, 2.0]);
        assert_eq!(serde_json::to_string(&held).expect("serialisable"), text);
        let four_rows = text.replace("2.0]]", "2.0],[0.0,0.0,0.0,1.0]]");
        assert!(serde_json::from_str::<Holder>(&four_rows).is_err());
        let unknown = text.replace("\"cy\"", "\"skew\":0.0,\"cy\"");
        let err = serde_json::from_str::<Holder>(&unknown).expect_err("unknown field");
        assert!(err.to_string().contains("unknown field `skew`"), "{err}");
    }
}
