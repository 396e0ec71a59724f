//! Loading with validation: every problem of a scene directory, each with its JSON path.
//!
//! The checker walks the raw JSON value (not the typed structs) so one run reports every problem:
//! a wrong type, a `null` where a number must be (JSON writers turn NaN and ±Inf into `null`), an
//! unknown key (a typo such as `shapr`), a non-increasing time, an unknown split or flow kind, a
//! missing file, an image of the wrong size or pixel format, a `.flo` with a bad header. Only when
//! nothing is wrong is the value converted to [`Scene`]. It never modifies the directory.

use std::collections::HashSet;
use std::io::Read;
use std::path::Path;

use image::ImageDecoder;
use serde_json::{Map, Value};

mod files;
mod people;

use crate::error::{Problem, Result, SceneError};
use crate::types::{
    Scene, FORMAT_VERSION, FORMAT_VERSION_MOVING_CAMERA, FORMAT_VERSION_PEOPLE, NUM_JOINTS,
    SCENE_FILE,
};
use people::PeopleSpec;

/// Largest accepted image side (pixels).
pub const MAX_SIDE: u64 = 65_536;
/// `.flo` magic number (the float 202021.25, "PIEH" in little-endian bytes).
const FLO_MAGIC: f32 = 202_021.25;

/// Reads and validates `dir/scene.json` and every file it names.
///
/// Returns the scene, or [`SceneError::Invalid`] listing every problem found (or
/// [`SceneError::Io`]/[`SceneError::Json`] when `scene.json` cannot be read or parsed at all).
pub fn load(dir: &Path) -> Result<Scene> {
    let value = read_value(dir)?;
    let problems = check_value(&value, Some(dir));
    if !problems.is_empty() {
        return Err(SceneError::Invalid {
            dir: dir.to_path_buf(),
            problems,
        });
    }
    serde_json::from_value(value).map_err(|e| SceneError::Invalid {
        dir: dir.to_path_buf(),
        problems: vec![Problem {
            path: SCENE_FILE.into(),
            message: format!("does not match the scene schema: {e}"),
        }],
    })
}

/// Every problem of the scene in `dir` (empty when it is valid). Errors only when `scene.json`
/// cannot be read or is not JSON.
pub fn validate_dir(dir: &Path) -> Result<Vec<Problem>> {
    let value = read_value(dir)?;
    Ok(check_value(&value, Some(dir)))
}

fn read_value(dir: &Path) -> Result<Value> {
    let path = dir.join(SCENE_FILE);
    let text = std::fs::read_to_string(&path).map_err(|source| SceneError::Io {
        path: path.clone(),
        source,
    })?;
    serde_json::from_str(&text).map_err(|source| SceneError::Json { path, source })
}

/// Checks a parsed `scene.json`; with `dir`, also every referenced file.
pub(crate) fn check_value(v: &Value, dir: Option<&Path>) -> Vec<Problem> {
    let mut c = Checker {
        problems: Vec::new(),
        dir,
    };
    c.scene(v);
    c.problems
}

struct Checker<'a> {
    problems: Vec<Problem>,
    dir: Option<&'a Path>,
}

/// What every frame's checks need of the scene's camera, images and version.
#[derive(Clone, Copy)]
struct Sensor {
    /// The camera's (width, height), when valid.
    size: Option<(u32, u32)>,
    /// Bits per channel of the RGB images, when valid.
    bits: Option<u8>,
    /// Grey frames (`images.channels = 1`).
    grey: bool,
    /// The frame interval 1/fps (seconds), when valid.
    max_exposure: Option<f64>,
    /// Whether frames may carry their own camera pose (version 2 or 3).
    moving_camera: bool,
}

#[derive(Clone, Copy)]
enum PngKind {
    Rgb(u8),
    Grey(u8),
    Mask,
}

fn describe(v: &Value) -> String {
    let s = v.to_string();
    if s.len() > 40 {
        format!("{}...", &s[..40])
    } else {
        s
    }
}

impl Checker<'_> {
    fn bad(&mut self, path: &str, message: impl Into<String>) {
        self.problems.push(Problem {
            path: path.into(),
            message: message.into(),
        });
    }

    fn obj<'v>(
        &mut self,
        v: &'v Value,
        path: &str,
        required: &[&str],
        optional: &[&str],
    ) -> Option<&'v Map<String, Value>> {
        let Some(m) = v.as_object() else {
            self.bad(path, format!("expected an object, found {}", describe(v)));
            return None;
        };
        for key in required {
            if !m.contains_key(*key) {
                self.bad(path, format!("missing required key \"{key}\""));
            }
        }
        for key in m.keys() {
            if !required.contains(&key.as_str()) && !optional.contains(&key.as_str()) {
                self.bad(
                    &format!("{path}.{key}"),
                    format!(
                        "unknown key (expected one of: {})",
                        required
                            .iter()
                            .chain(optional)
                            .copied()
                            .collect::<Vec<_>>()
                            .join(", ")
                    ),
                );
            }
        }
        Some(m)
    }

    fn num(&mut self, v: &Value, path: &str) -> Option<f64> {
        match v.as_f64() {
            Some(x) if x.is_finite() => Some(x),
            _ if v.is_null() => {
                self.bad(
                    path,
                    "is null: not a finite number (NaN/Inf are written as null)",
                );
                None
            }
            _ => {
                self.bad(
                    path,
                    format!("expected a finite number, found {}", describe(v)),
                );
                None
            }
        }
    }

    fn f32(&mut self, v: &Value, path: &str) -> Option<f32> {
        let x = self.num(v, path)?;
        if x.abs() > f64::from(f32::MAX) {
            self.bad(path, format!("{x} does not fit in f32"));
            return None;
        }
        Some(x as f32)
    }

    fn uint(&mut self, v: &Value, path: &str, max: u64) -> Option<u64> {
        match v.as_u64() {
            Some(x) if x <= max => Some(x),
            _ => {
                self.bad(
                    path,
                    format!("expected an integer in 0..={max}, found {}", describe(v)),
                );
                None
            }
        }
    }

    fn string<'v>(&mut self, v: &'v Value, path: &str) -> Option<&'v str> {
        match v.as_str() {
            Some(s) => Some(s),
            None => {
                self.bad(path, format!("expected a string, found {}", describe(v)));
                None
            }
        }
    }

    fn enumeration(&mut self, v: &Value, path: &str, allowed: &[&str]) -> Option<String> {
        let s = self.string(v, path)?;
        if allowed.contains(&s) {
            Some(s.to_string())
        } else {
            self.bad(
                path,
                format!(
                    "unknown value \"{s}\" (expected one of: {})",
                    allowed.join(", ")
                ),
            );
            None
        }
    }

    fn floats(&mut self, v: &Value, path: &str, len: Option<usize>) -> Option<Vec<f32>> {
        let Some(a) = v.as_array() else {
            self.bad(path, format!("expected an array, found {}", describe(v)));
            return None;
        };
        if let Some(n) = len {
            if a.len() != n {
                self.bad(path, format!("expected {n} values, found {}", a.len()));
                return None;
            }
        }
        let vals: Vec<Option<f32>> = a
            .iter()
            .enumerate()
            .map(|(i, x)| self.f32(x, &format!("{path}[{i}]")))
            .collect();
        vals.into_iter().collect()
    }

    /// `events_recorded_s`: two finite times, the first not after the second.
    fn recorded_span(&mut self, v: &Value) {
        let path = "events_recorded_s";
        match v.as_array().map(Vec::as_slice) {
            Some([a, b]) => {
                if let (Some(a), Some(b)) = (self.num(a, path), self.num(b, path)) {
                    if a > b {
                        self.bad(
                            path,
                            format!("first event at {a} s after the last at {b} s"),
                        );
                    }
                }
            }
            _ => self.bad(
                path,
                format!("expected [first, last], found {}", describe(v)),
            ),
        }
    }

    fn scene(&mut self, v: &Value) {
        let Some(m) = self.obj(
            v,
            "scene",
            &[
                "format_version",
                "camera",
                "body",
                "fps",
                "exposure_s",
                "images",
                "frames",
            ],
            &[
                "generator",
                "events_raw_format",
                "events_recorded_s",
                "people",
            ],
        ) else {
            return;
        };
        if let Some(span) = m.get("events_recorded_s") {
            self.recorded_span(span);
        }
        if let Some(f) = m.get("events_raw_format") {
            if let Some(name) = self.string(f, "events_raw_format") {
                if name != "evt2" && name != "evt3" {
                    self.bad(
                        "events_raw_format",
                        format!("`{name}` is not an event encoding (expected evt2 or evt3)"),
                    );
                }
            }
        }
        let version = m
            .get("format_version")
            .and_then(|fv| self.uint(fv, "format_version", u64::from(u32::MAX)));
        if let Some(x) = version {
            let known = [
                FORMAT_VERSION,
                FORMAT_VERSION_MOVING_CAMERA,
                FORMAT_VERSION_PEOPLE,
            ];
            if !known.iter().any(|&k| x == u64::from(k)) {
                self.bad(
                    "format_version",
                    format!(
                        "{x} is not supported (this reader knows {FORMAT_VERSION}, {FORMAT_VERSION_MOVING_CAMERA} and {FORMAT_VERSION_PEOPLE})"
                    ),
                );
            }
        }
        let size = m.get("camera").and_then(|c| self.camera(c));
        if let Some(b) = m.get("body") {
            if let Some(bm) = self.obj(b, "body", &["model", "betas"], &["id"]) {
                if let Some(s) = bm.get("model").and_then(|s| self.string(s, "body.model")) {
                    if s.is_empty() {
                        self.bad("body.model", "is empty");
                    }
                }
                if let Some(betas) = bm.get("betas") {
                    self.floats(betas, "body.betas", None);
                }
            }
        }
        let fps = m.get("fps").and_then(|x| self.num(x, "fps"));
        if let Some(f) = fps {
            if f <= 0.0 {
                self.bad("fps", format!("{f} must be > 0"));
            }
        }
        if let Some(e) = m.get("exposure_s").and_then(|x| self.num(x, "exposure_s")) {
            if e <= 0.0 {
                self.bad("exposure_s", format!("{e} must be > 0"));
            } else if let Some(f) = fps.filter(|f| *f > 0.0) {
                if e > (1.0 / f) * (1.0 + 1e-9) {
                    self.bad(
                        "exposure_s",
                        format!(
                            "{e} s is longer than the frame interval 1/fps = {} s",
                            1.0 / f
                        ),
                    );
                }
            }
        }
        let mut bits = None;
        let mut grey = false;
        if let Some(im) = m.get("images") {
            if let Some(imm) = self.obj(im, "images", &["bit_depth", "transfer"], &["channels"]) {
                if let Some(c) = imm.get("channels") {
                    match self.uint(c, "images.channels", 255) {
                        Some(1) => grey = true,
                        Some(3) | None => {}
                        Some(c) => {
                            self.bad("images.channels", format!("{c} is not 1 (grey) or 3 (RGB)"))
                        }
                    }
                }
                if let Some(b) = imm
                    .get("bit_depth")
                    .and_then(|b| self.uint(b, "images.bit_depth", 255))
                {
                    if b == 8 || b == 16 {
                        bits = Some(b as u8);
                    } else {
                        self.bad("images.bit_depth", format!("{b} is not 8 or 16"));
                    }
                }
                if let Some(t) = imm.get("transfer") {
                    self.enumeration(t, "images.transfer", &["linear", "srgb"]);
                }
            }
        }
        let several_people = version == Some(u64::from(FORMAT_VERSION_PEOPLE));
        let people = self.people(m, several_people);
        if let Some(frames) = m.get("frames") {
            let max_exposure = fps.filter(|f| *f > 0.0).map(|f| 1.0 / f);
            let moving_camera =
                several_people || version == Some(u64::from(FORMAT_VERSION_MOVING_CAMERA));
            let sensor = Sensor {
                size,
                bits,
                grey,
                max_exposure,
                moving_camera,
            };
            self.frames(frames, &sensor, &people);
        }
    }

    fn camera(&mut self, v: &Value) -> Option<(u32, u32)> {
        let m = self.obj(
            v,
            "camera",
            &["width", "height", "fx", "fy", "cx", "cy", "world_to_camera"],
            &[],
        )?;
        let w = m
            .get("width")
            .and_then(|x| self.uint(x, "camera.width", MAX_SIDE));
        let h = m
            .get("height")
            .and_then(|x| self.uint(x, "camera.height", MAX_SIDE));
        for key in ["fx", "fy"] {
            if let Some(f) = m
                .get(key)
                .and_then(|x| self.num(x, &format!("camera.{key}")))
            {
                if f <= 0.0 {
                    self.bad(&format!("camera.{key}"), format!("{f} must be > 0"));
                }
            }
        }
        for key in ["cx", "cy"] {
            if let Some(x) = m.get(key) {
                self.num(x, &format!("camera.{key}"));
            }
        }
        if let Some(rt) = m.get("world_to_camera") {
            self.rigid(rt, "camera.world_to_camera");
        }
        match (w, h) {
            (Some(0), _) | (_, Some(0)) => {
                self.bad("camera", "width and height must be > 0");
                None
            }
            (Some(w), Some(h)) => Some((w as u32, h as u32)),
            _ => None,
        }
    }

    fn rigid(&mut self, v: &Value, path: &str) {
        let rows: Option<Vec<Vec<f32>>> = match v.as_array() {
            Some(a) if a.len() == 3 => a
                .iter()
                .enumerate()
                .map(|(r, row)| self.floats(row, &format!("{path}[{r}]"), Some(4)))
                .collect(),
            _ => {
                self.bad(
                    path,
                    format!("expected 3 rows of 4 numbers, found {}", describe(v)),
                );
                None
            }
        };
        let Some(rows) = rows else { return };
        let r = |i: usize, j: usize| f64::from(rows[i][j]);
        let mut err = 0.0f64;
        for i in 0..3 {
            for j in 0..3 {
                let d: f64 = (0..3).map(|k| r(k, i) * r(k, j)).sum();
                err = err.max((d - if i == j { 1.0 } else { 0.0 }).abs());
            }
        }
        let det = r(0, 0) * (r(1, 1) * r(2, 2) - r(1, 2) * r(2, 1))
            - r(0, 1) * (r(1, 0) * r(2, 2) - r(1, 2) * r(2, 0))
            + r(0, 2) * (r(1, 0) * r(2, 1) - r(1, 1) * r(2, 0));
        if err > 1e-4 || det <= 0.0 {
            self.bad(
                path,
                format!("R is not a rotation (max |RᵀR − I| = {err:.2e}, det = {det:.4})"),
            );
        }
    }

    fn frames(&mut self, v: &Value, sensor: &Sensor, people: &PeopleSpec) {
        let Sensor {
            size,
            bits,
            grey,
            max_exposure,
            moving_camera,
        } = *sensor;
        let Some(a) = v.as_array() else {
            self.bad(
                "frames",
                format!("expected an array, found {}", describe(v)),
            );
            return;
        };
        if a.is_empty() {
            self.bad("frames", "no frames");
            return;
        }
        let mut last_index: Option<u64> = None;
        let mut last_time: Option<f64> = None;
        let mut train = 0usize;
        for (k, f) in a.iter().enumerate() {
            let p = format!("frames[{k}]");
            let Some(m) = self.obj(
                f,
                &p,
                &["index", "time_s", "image", "pose", "transl", "split"],
                &[
                    "sharp",
                    "mask",
                    "flow_to_next",
                    "events",
                    "exposure_s",
                    "world_to_camera",
                    "people",
                    "person_ids",
                ],
            ) else {
                continue;
            };
            if let Some(rt) = m.get("world_to_camera") {
                let path = format!("{p}.world_to_camera");
                if moving_camera {
                    self.rigid(rt, &path);
                } else {
                    self.bad(
                        &path,
                        format!("a camera pose per frame needs format_version {FORMAT_VERSION_MOVING_CAMERA} or {FORMAT_VERSION_PEOPLE}"),
                    );
                }
            }
            if let Some(e) = m
                .get("exposure_s")
                .and_then(|x| self.num(x, &format!("{p}.exposure_s")))
            {
                if e <= 0.0 {
                    self.bad(&format!("{p}.exposure_s"), format!("{e} must be > 0"));
                } else if let Some(max) = max_exposure.filter(|&max| e > max * (1.0 + 1e-9)) {
                    self.bad(
                        &format!("{p}.exposure_s"),
                        format!("{e} s is longer than the frame interval 1/fps = {max} s"),
                    );
                }
            }
            if let Some(i) = m
                .get("index")
                .and_then(|x| self.uint(x, &format!("{p}.index"), u64::from(u32::MAX)))
            {
                if let Some(prev) = last_index {
                    if i <= prev {
                        self.bad(
                            &format!("{p}.index"),
                            format!("{i} does not increase (previous frame has {prev})"),
                        );
                    }
                }
                last_index = Some(i);
            }
            if let Some(t) = m
                .get("time_s")
                .and_then(|x| self.num(x, &format!("{p}.time_s")))
            {
                if let Some(prev) = last_time {
                    if t <= prev {
                        self.bad(
                            &format!("{p}.time_s"),
                            format!("{t} s is not after the previous frame's {prev} s (time must increase)"),
                        );
                    }
                }
                last_time = Some(t);
            }
            let rgb = if grey {
                PngKind::Grey(bits.unwrap_or(16))
            } else {
                PngKind::Rgb(bits.unwrap_or(16))
            };
            let check_rgb = bits.is_some();
            for key in ["image", "sharp"] {
                if let Some(x) = m.get(key) {
                    let jp = format!("{p}.{key}");
                    if check_rgb {
                        self.png(x, &jp, rgb, size);
                    } else {
                        self.rel_file(x, &jp);
                    }
                }
            }
            if let Some(x) = m.get("mask") {
                self.png(x, &format!("{p}.mask"), PngKind::Mask, size);
            }
            if let Some(x) = m.get("events") {
                self.rel_file(x, &format!("{p}.events"));
            }
            if let Some(pose) = m.get("pose") {
                self.pose(pose, &format!("{p}.pose"));
            }
            self.frame_people(m, &p, people, size);
            if let Some(t) = m.get("transl") {
                self.floats(t, &format!("{p}.transl"), Some(3));
            }
            if let Some(s) = m.get("split") {
                if self
                    .enumeration(s, &format!("{p}.split"), &["train", "test"])
                    .as_deref()
                    == Some("train")
                {
                    train += 1;
                }
            }
            if let Some(fl) = m.get("flow_to_next") {
                self.flows(fl, &p, k + 1 == a.len(), size);
            }
        }
        if train == 0 {
            self.bad("frames", "no frame has split \"train\"");
        }
    }

    fn flows(&mut self, v: &Value, p: &str, last: bool, size: Option<(u32, u32)>) {
        let fp = format!("{p}.flow_to_next");
        let Some(a) = v.as_array() else {
            self.bad(&fp, format!("expected an array, found {}", describe(v)));
            return;
        };
        if last && !a.is_empty() {
            self.bad(&fp, "the last frame has no next frame to flow to");
        }
        let mut kinds = HashSet::new();
        for (i, f) in a.iter().enumerate() {
            let ip = format!("{fp}[{i}]");
            let Some(m) = self.obj(f, &ip, &["kind", "path"], &["valid_mask"]) else {
                continue;
            };
            if let Some(k) = m.get("kind").and_then(|k| {
                self.enumeration(
                    k,
                    &format!("{ip}.kind"),
                    &["ground_truth", "events_cm", "external"],
                )
            }) {
                if !kinds.insert(k.clone()) {
                    self.bad(&format!("{ip}.kind"), format!("a second \"{k}\" flow"));
                }
            }
            if let Some(x) = m.get("path") {
                self.flo(x, &format!("{ip}.path"), size);
            }
            if let Some(x) = m.get("valid_mask") {
                self.png(x, &format!("{ip}.valid_mask"), PngKind::Mask, size);
            }
        }
    }
}
