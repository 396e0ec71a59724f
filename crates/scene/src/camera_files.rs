//! Camera files outside a scene directory, read into the workspace's one [`Camera`]: the project's
//! camera JSON (also a whole `scene.json`, whose `camera` is taken) and the INRIA 3DGS
//! `cameras.json` list. `docs/FORMATS.md`, "Cameras for `cargo xtask render`", specifies them.
//!
//! Reading checks the file's shape only (JSON syntax, field types, 3 or 4 matrix rows, a 4th row of
//! `[0, 0, 0, 1]`, the list index). Whether a camera can be rendered from (positive focal lengths, a
//! non-singular rotation, the image size) is [`Camera::validate`]'s, called by its users before
//! rendering (`train::data`, `xtask render`). This module must never know the renderer, and reads
//! no images.

use std::path::{Path, PathBuf};

use serde::Deserialize;

use crate::error::{Result, SceneError};
use crate::types::Camera;

/// The fields of a camera in the project's camera JSON (those of `scene.json`'s camera).
const CAMERA_FIELDS: [&str; 7] = ["width", "height", "fx", "fy", "cx", "cy", "world_to_camera"];

/// The project's camera JSON is `scene.json`'s camera read leniently: fields other than
/// [`CAMERA_FIELDS`] are ignored and `world_to_camera` may have a 4th row, which must be
/// `[0, 0, 0, 1]`. Normalises `camera` to the strict form that [`crate::camera_json`] reads.
fn normalise_camera_json(
    camera: &mut serde_json::Value,
) -> std::result::Result<(), serde_json::Error> {
    use serde::de::Error;
    let Some(fields) = camera.as_object_mut() else {
        return Ok(());
    };
    fields.retain(|k, _| CAMERA_FIELDS.contains(&k.as_str()));
    if let Some(serde_json::Value::Array(rows)) = fields.get_mut("world_to_camera") {
        if !(3..=4).contains(&rows.len()) {
            return Err(serde_json::Error::custom(format!(
                "camera world_to_camera: expected 3 or 4 rows of 4 numbers (row-major \
                 world-to-camera), found {}",
                rows.len()
            )));
        }
        if rows.len() == 4 {
            let last: [f64; 4] = serde_json::from_value(rows[3].clone())?;
            if last != [0.0, 0.0, 0.0, 1.0] {
                return Err(serde_json::Error::custom(format!(
                    "camera world_to_camera last row must be [0, 0, 0, 1], got {last:?}"
                )));
            }
            rows.truncate(3);
        }
    }
    Ok(())
}

/// One entry of the INRIA 3DGS `cameras.json` list. `rotation` is camera-to-world (3×3, rows),
/// `position` the camera centre in world coordinates; the principal point is the image centre.
#[derive(Deserialize)]
struct InriaCamera {
    width: u32,
    height: u32,
    position: [f64; 3],
    rotation: [[f64; 3]; 3],
    fx: f64,
    fy: f64,
}

impl InriaCamera {
    /// The same camera in the scene format's conventions: `world_to_camera = [Rᵀ | −Rᵀ c]` with
    /// R = camera-to-world rotation and c = camera centre; principal point at the image centre.
    fn to_camera(&self) -> Camera {
        let r = &self.rotation;
        let mut m = [[0.0; 4]; 4];
        m[3][3] = 1.0;
        for i in 0..3 {
            for k in 0..3 {
                m[i][k] = r[k][i];
            }
            m[i][3] = -(0..3).map(|k| r[k][i] * self.position[k]).sum::<f64>();
        }
        Camera {
            width: self.width,
            height: self.height,
            fx: self.fx,
            fy: self.fy,
            cx: f64::from(self.width) * 0.5,
            cy: f64::from(self.height) * 0.5,
            world_to_camera: m,
        }
    }
}

fn json_error(source: &Path) -> impl Fn(serde_json::Error) -> SceneError + '_ {
    move |e| SceneError::CameraJson {
        path: source.to_path_buf(),
        source: e,
    }
}

/// Parses the project's camera JSON from a string (`source` names it in errors). A scene format v1
/// `scene.json` (an object whose `camera` field holds the camera, and which has no `fx`) is accepted
/// too; its other fields are not read. Syntax errors carry their line and column; field errors name
/// the field.
pub fn from_json_str(text: &str, source: &Path) -> Result<Camera> {
    let mut value: serde_json::Value = serde_json::from_str(text).map_err(json_error(source))?;
    let is_scene = value
        .as_object()
        .is_some_and(|o| o.contains_key("camera") && !o.contains_key("fx"));
    if is_scene {
        value = value["camera"].take();
    }
    normalise_camera_json(&mut value).map_err(json_error(source))?;
    crate::camera_json::deserialize(value).map_err(json_error(source))
}

/// Reads the project's camera JSON file (or a `scene.json`, see [`from_json_str`]).
pub fn read_json(path: &Path) -> Result<Camera> {
    from_json_str(&read(path)?, path)
}

/// Parses an INRIA `cameras.json` list from a string (`source` names it in errors).
pub fn inria_list_from_str(text: &str, source: &Path) -> Result<Vec<Camera>> {
    let list: Vec<InriaCamera> = serde_json::from_str(text).map_err(json_error(source))?;
    Ok(list.iter().map(InriaCamera::to_camera).collect())
}

/// Reads camera `index` of an INRIA `cameras.json` file.
pub fn read_inria(path: &Path, index: usize) -> Result<Camera> {
    nth_camera(inria_list_from_str(&read(path)?, path)?, path, index)
}

/// Reads a camera file in either format: a JSON object is the project's format (or a `scene.json`),
/// a JSON list is INRIA's `cameras.json`, from which camera `index` is taken (`index` is ignored
/// for an object).
pub fn read_any(path: &Path, index: usize) -> Result<Camera> {
    let text = read(path)?;
    if text.trim_start().starts_with('[') {
        nth_camera(inria_list_from_str(&text, path)?, path, index)
    } else {
        from_json_str(&text, path)
    }
}

fn nth_camera(cameras: Vec<Camera>, path: &Path, index: usize) -> Result<Camera> {
    let count = cameras.len();
    cameras
        .into_iter()
        .nth(index)
        .ok_or(SceneError::CameraIndex {
            path: path.to_path_buf(),
            index,
            count,
        })
}

fn read(path: &Path) -> Result<String> {
    std::fs::read_to_string(path).map_err(|e| SceneError::Io {
        path: PathBuf::from(path),
        source: e,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inria_camera_round_trips_centre() {
        let text = r#"[{"id": 0, "img_name": "a", "width": 64, "height": 48,
            "position": [1.0, 2.0, 3.0],
            "rotation": [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]],
            "fx": 50.0, "fy": 50.0}]"#;
        let cams = inria_list_from_str(text, Path::new("<test>")).expect("valid list");
        let cam = &cams[0];
        let c = cam.center_world();
        for (i, want) in [1.0, 2.0, 3.0].into_iter().enumerate() {
            assert!((c[i] - want).abs() < 1e-12, "{c:?}");
        }
        assert_eq!(cam.cx, 32.0);
        assert_eq!(cam.cy, 24.0);
    }

    #[test]
    fn camera_json_takes_3x4_or_4x4_and_a_scene_file() {
        let cam4 = r#"{"width": 8, "height": 6, "fx": 10, "fy": 11, "cx": 4, "cy": 3,
            "world_to_camera": [[1,0,0,0.5],[0,1,0,0],[0,0,1,2],[0,0,0,1]]}"#;
        let cam3 = r#"{"width": 8, "height": 6, "fx": 10, "fy": 11, "cx": 4, "cy": 3,
            "world_to_camera": [[1,0,0,0.5],[0,1,0,0],[0,0,1,2]]}"#;
        let scene = format!(r#"{{"format_version": 1, "camera": {cam3}, "frames": []}}"#);
        let p = Path::new("<test>");
        let a = from_json_str(cam4, p).expect("4x4");
        assert_eq!(a.world_to_camera[2], [0.0, 0.0, 1.0, 2.0]);
        assert_eq!(from_json_str(cam3, p).expect("3x4"), a);
        assert_eq!(from_json_str(&scene, p).expect("scene.json"), a);
        let two_rows = r#"{"width": 8, "height": 6, "fx": 10, "fy": 11, "cx": 4, "cy": 3,
            "world_to_camera": [[1,0,0,0.5],[0,1,0,0]]}"#;
        let err = from_json_str(two_rows, p).expect_err("2 rows").to_string();
        assert!(err.contains("3 or 4 rows"), "{err}");
        assert!(err.contains("<test>"), "{err}");
        let projective = r#"{"width": 8, "height": 6, "fx": 10, "fy": 11, "cx": 4, "cy": 3,
            "world_to_camera": [[1,0,0,0.5],[0,1,0,0],[0,0,1,2],[0,0,1,1]]}"#;
        let err = from_json_str(projective, p)
            .expect_err("last row")
            .to_string();
        assert!(err.contains("last row must be [0, 0, 0, 1]"), "{err}");
    }

    #[test]
    fn bad_camera_files_give_typed_errors_naming_the_file() {
        let p = Path::new("<test>");
        // JSON has no NaN: the parser rejects it, naming the file.
        let nan = r#"{"width":64,"height":48,"fx":NaN,"fy":50,"cx":32,"cy":24,
            "world_to_camera":[[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]}"#;
        assert!(matches!(
            from_json_str(nan, p),
            Err(SceneError::CameraJson { .. })
        ));
        let dir = tempfile::tempdir().expect("temp dir");
        let list = dir.path().join("cameras.json");
        std::fs::write(
            &list,
            r#"[{"width": 4, "height": 4, "position": [0, 0, 0],
                "rotation": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "fx": 5, "fy": 5}]"#,
        )
        .expect("writing the list");
        assert_eq!(read_any(&list, 0).expect("entry 0").width, 4);
        assert_eq!(read_inria(&list, 0).expect("entry 0").width, 4);
        let err = read_any(&list, 1).expect_err("index 1 of 1");
        assert!(
            matches!(
                err,
                SceneError::CameraIndex {
                    index: 1,
                    count: 1,
                    ..
                }
            ),
            "{err}"
        );
        assert!(err.to_string().contains("cameras.json"), "{err}");
        let missing = dir.path().join("missing.json");
        assert!(matches!(read_json(&missing), Err(SceneError::Io { .. })));
    }
}
