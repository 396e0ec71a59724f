//! OpenCV pinhole camera (DESIGN.md §3): world-to-camera `[R|t]` with x right, y down, z forward;
//! intrinsics fx, fy, cx, cy in pixels; pixel (i, j) has its centre at (i + 0.5, j + 0.5).
//!
//! Also reads the project's camera JSON and the INRIA 3DGS `cameras.json` list. Construction always
//! validates (finite values, positive focal lengths, non-singular affine matrix, image size within
//! [`MAX_IMAGE_SIDE`]), so a [`Camera`] that exists can be rendered from. This module must never
//! touch Gaussians.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::RasterError;

/// Largest accepted image side (pixels); larger requests are rejected, not attempted.
pub const MAX_IMAGE_SIDE: u32 = 16384;

/// A validated OpenCV pinhole camera. All lengths in metres, intrinsics in pixels.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Camera {
    /// Image width (pixels).
    pub width: u32,
    /// Image height (pixels).
    pub height: u32,
    /// Horizontal focal length (pixels).
    pub fx: f64,
    /// Vertical focal length (pixels).
    pub fy: f64,
    /// Principal point x (pixels, pixel centres at i + 0.5).
    pub cx: f64,
    /// Principal point y (pixels).
    pub cy: f64,
    /// World-to-camera rigid transform, row-major 4×4 (`p_cam = M · [p_world, 1]`).
    pub world_to_camera: [[f64; 4]; 4],
}

/// The project's camera JSON: `{"width","height","fx","fy","cx","cy","world_to_camera":[[4×4 row-major]]}`.
/// When read, `world_to_camera` may also be its top 3×4 rows (as in scene format v1's `camera`);
/// the bottom row is then `[0, 0, 0, 1]`.
#[derive(Clone, Debug, Deserialize, Serialize)]
pub struct CameraJson {
    /// Image width (pixels).
    pub width: u64,
    /// Image height (pixels).
    pub height: u64,
    /// Horizontal focal length (pixels).
    pub fx: f64,
    /// Vertical focal length (pixels).
    pub fy: f64,
    /// Principal point x (pixels).
    pub cx: f64,
    /// Principal point y (pixels).
    pub cy: f64,
    /// World-to-camera, row-major 4×4 (3×4 accepted on input).
    #[serde(deserialize_with = "affine_rows")]
    pub world_to_camera: [[f64; 4]; 4],
}

/// Deserialises a row-major 4×4 matrix given as 4 rows, or as its top 3 rows of an affine map.
fn affine_rows<'de, D: serde::Deserializer<'de>>(d: D) -> Result<[[f64; 4]; 4], D::Error> {
    use serde::de::Error;
    let rows: Vec<[f64; 4]> = Vec::deserialize(d)?;
    match rows[..] {
        [a, b, c] => Ok([a, b, c, [0.0, 0.0, 0.0, 1.0]]),
        [a, b, c, e] => Ok([a, b, c, e]),
        _ => Err(D::Error::invalid_length(
            rows.len(),
            &"3 or 4 rows of 4 numbers (row-major world-to-camera)",
        )),
    }
}

/// One entry of the INRIA 3DGS `cameras.json` list. `rotation` is camera-to-world (3×3, rows),
/// `position` the camera centre in world coordinates; the principal point is the image centre.
#[derive(Clone, Debug, Deserialize, Serialize)]
pub struct InriaCameraJson {
    /// Image width (pixels).
    pub width: u64,
    /// Image height (pixels).
    pub height: u64,
    /// Camera centre (world, metres).
    pub position: [f64; 3],
    /// Camera-to-world rotation, rows.
    pub rotation: [[f64; 3]; 3],
    /// Horizontal focal length (pixels).
    pub fx: f64,
    /// Vertical focal length (pixels).
    pub fy: f64,
}

fn finite(field: impl FnOnce() -> String, value: f64) -> Result<(), RasterError> {
    if value.is_finite() {
        Ok(())
    } else {
        Err(RasterError::NonFiniteCamera {
            field: field(),
            value,
        })
    }
}

fn det3(m: &[[f64; 4]; 4]) -> f64 {
    m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
        - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
}

impl Camera {
    /// Builds a camera, validating every field (see the module docs for the rules).
    pub fn new(
        width: u64,
        height: u64,
        fx: f64,
        fy: f64,
        cx: f64,
        cy: f64,
        world_to_camera: [[f64; 4]; 4],
    ) -> Result<Self, RasterError> {
        check_image_size(width, height)?;
        finite(|| "fx".into(), fx)?;
        finite(|| "fy".into(), fy)?;
        finite(|| "cx".into(), cx)?;
        finite(|| "cy".into(), cy)?;
        if fx <= 0.0 {
            return Err(RasterError::NonPositiveFocal {
                field: "fx",
                value: fx,
            });
        }
        if fy <= 0.0 {
            return Err(RasterError::NonPositiveFocal {
                field: "fy",
                value: fy,
            });
        }
        for (i, row) in world_to_camera.iter().enumerate() {
            for (j, &v) in row.iter().enumerate() {
                finite(|| format!("world_to_camera[{i}][{j}]"), v)?;
            }
        }
        if world_to_camera[3] != [0.0, 0.0, 0.0, 1.0] {
            return Err(RasterError::NotAffine {
                row: world_to_camera[3],
            });
        }
        let det = det3(&world_to_camera);
        if !(det.abs() > 1e-9) {
            return Err(RasterError::SingularMatrix { det });
        }
        // Both sides were checked against MAX_IMAGE_SIDE, so they fit in u32.
        Ok(Self {
            width: width as u32,
            height: height as u32,
            fx,
            fy,
            cx,
            cy,
            world_to_camera,
        })
    }

    /// A camera looking down +z from the origin (identity extrinsics), principal point at the centre.
    pub fn looking_down_z(width: u32, height: u32, fx: f64, fy: f64) -> Result<Self, RasterError> {
        let mut m = [[0.0; 4]; 4];
        for (i, row) in m.iter_mut().enumerate() {
            row[i] = 1.0;
        }
        Self::new(
            width.into(),
            height.into(),
            fx,
            fy,
            f64::from(width) * 0.5,
            f64::from(height) * 0.5,
            m,
        )
    }

    /// Builds a camera from the project's camera JSON value.
    pub fn from_json(j: &CameraJson) -> Result<Self, RasterError> {
        Self::new(j.width, j.height, j.fx, j.fy, j.cx, j.cy, j.world_to_camera)
    }

    /// Builds a camera from one INRIA `cameras.json` entry (principal point at the image centre).
    pub fn from_inria(j: &InriaCameraJson) -> Result<Self, RasterError> {
        for i in 0..3 {
            finite(|| format!("position[{i}]"), j.position[i])?;
            for k in 0..3 {
                finite(|| format!("rotation[{i}][{k}]"), j.rotation[i][k])?;
            }
        }
        // world_to_camera = [Rᵀ | −Rᵀ c] with R = camera-to-world rotation, c = camera centre.
        let r = &j.rotation;
        let mut m = [[0.0; 4]; 4];
        for i in 0..3 {
            for k in 0..3 {
                m[i][k] = r[k][i];
            }
            m[i][3] = -(0..3).map(|k| r[k][i] * j.position[k]).sum::<f64>();
        }
        m[3][3] = 1.0;
        Self::new(
            j.width,
            j.height,
            j.fx,
            j.fy,
            j.width as f64 * 0.5,
            j.height as f64 * 0.5,
            m,
        )
    }

    /// Parses the project's camera JSON from a string (`source` names it in errors). A scene
    /// format v1 `scene.json` (an object whose `camera` field holds the camera) is accepted too.
    pub fn from_json_str(text: &str, source: &Path) -> Result<Self, RasterError> {
        #[derive(Deserialize)]
        struct SceneCamera {
            camera: CameraJson,
        }
        let json_error = |e| RasterError::Json {
            path: source.to_path_buf(),
            source: e,
        };
        // Decide the shape first, then deserialise from the text so that errors keep their
        // line and column.
        let value: serde_json::Value = serde_json::from_str(text).map_err(json_error)?;
        let is_scene = value
            .as_object()
            .is_some_and(|o| o.contains_key("camera") && !o.contains_key("fx"));
        let j = if is_scene {
            serde_json::from_str::<SceneCamera>(text)
                .map_err(json_error)?
                .camera
        } else {
            serde_json::from_str::<CameraJson>(text).map_err(json_error)?
        };
        Self::from_json(&j)
    }

    /// Reads the project's camera JSON file.
    pub fn read_json(path: &Path) -> Result<Self, RasterError> {
        Self::from_json_str(&read(path)?, path)
    }

    /// Parses an INRIA `cameras.json` list from a string into validated cameras.
    pub fn inria_list_from_str(text: &str, source: &Path) -> Result<Vec<Self>, RasterError> {
        let list: Vec<InriaCameraJson> =
            serde_json::from_str(text).map_err(|e| RasterError::Json {
                path: source.to_path_buf(),
                source: e,
            })?;
        list.iter().map(Self::from_inria).collect()
    }

    /// Reads camera `index` of an INRIA `cameras.json` file.
    pub fn read_inria(path: &Path, index: usize) -> Result<Self, RasterError> {
        let cams = Self::inria_list_from_str(&read(path)?, path)?;
        let count = cams.len();
        cams.into_iter().nth(index).ok_or(RasterError::CameraIndex {
            path: path.to_path_buf(),
            index,
            count,
        })
    }

    /// Reads a camera file in either format: a JSON object is the project's format, a JSON list is
    /// INRIA's `cameras.json` (from which camera `index` is taken; `index` is ignored for an object).
    pub fn read_any(path: &Path, index: usize) -> Result<Self, RasterError> {
        let text = read(path)?;
        if text.trim_start().starts_with('[') {
            let cams = Self::inria_list_from_str(&text, path)?;
            let count = cams.len();
            cams.into_iter().nth(index).ok_or(RasterError::CameraIndex {
                path: path.to_path_buf(),
                index,
                count,
            })
        } else {
            Self::from_json_str(&text, path)
        }
    }

    /// The project's JSON form of this camera.
    pub fn to_json(&self) -> CameraJson {
        CameraJson {
            width: self.width.into(),
            height: self.height.into(),
            fx: self.fx,
            fy: self.fy,
            cx: self.cx,
            cy: self.cy,
            world_to_camera: self.world_to_camera,
        }
    }

    /// Camera centre in world coordinates (metres): `−R⁻¹ t`.
    pub fn center_world(&self) -> [f64; 3] {
        let m = &self.world_to_camera;
        let inv = inverse3(m);
        let t = [m[0][3], m[1][3], m[2][3]];
        let mut c = [0.0; 3];
        for i in 0..3 {
            c[i] = -(inv[i][0] * t[0] + inv[i][1] * t[1] + inv[i][2] * t[2]);
        }
        c
    }
}

fn inverse3(m: &[[f64; 4]; 4]) -> [[f64; 3]; 3] {
    let det = det3(m);
    let a = |i: usize, j: usize| m[i][j];
    let cof = [
        [
            a(1, 1) * a(2, 2) - a(1, 2) * a(2, 1),
            a(0, 2) * a(2, 1) - a(0, 1) * a(2, 2),
            a(0, 1) * a(1, 2) - a(0, 2) * a(1, 1),
        ],
        [
            a(1, 2) * a(2, 0) - a(1, 0) * a(2, 2),
            a(0, 0) * a(2, 2) - a(0, 2) * a(2, 0),
            a(0, 2) * a(1, 0) - a(0, 0) * a(1, 2),
        ],
        [
            a(1, 0) * a(2, 1) - a(1, 1) * a(2, 0),
            a(0, 1) * a(2, 0) - a(0, 0) * a(2, 1),
            a(0, 0) * a(1, 1) - a(0, 1) * a(1, 0),
        ],
    ];
    cof.map(|row| row.map(|v| v / det))
}

/// Checks an image size against `1..=MAX_IMAGE_SIDE` per side.
pub fn check_image_size(width: u64, height: u64) -> Result<(), RasterError> {
    let max = u64::from(MAX_IMAGE_SIDE);
    if width == 0 || height == 0 || width > max || height > max {
        return Err(RasterError::InvalidImageSize {
            width,
            height,
            max: MAX_IMAGE_SIDE,
        });
    }
    Ok(())
}

fn read(path: &Path) -> Result<String, RasterError> {
    std::fs::read_to_string(path).map_err(|e| RasterError::Io {
        path: PathBuf::from(path),
        source: e,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inria_camera_round_trips_centre() {
        let j = InriaCameraJson {
            width: 64,
            height: 48,
            position: [1.0, 2.0, 3.0],
            rotation: [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]],
            fx: 50.0,
            fy: 50.0,
        };
        let cam = Camera::from_inria(&j).expect("valid camera");
        let c = cam.center_world();
        for i in 0..3 {
            assert!((c[i] - j.position[i]).abs() < 1e-12, "{c:?}");
        }
        assert_eq!(cam.cx, 32.0);
    }

    #[test]
    fn camera_json_takes_3x4_or_4x4_and_a_scene_file() {
        let cam4 = r#"{"width": 8, "height": 6, "fx": 10, "fy": 11, "cx": 4, "cy": 3,
            "world_to_camera": [[1,0,0,0.5],[0,1,0,0],[0,0,1,2],[0,0,0,1]]}"#;
        let cam3 = r#"{"width": 8, "height": 6, "fx": 10, "fy": 11, "cx": 4, "cy": 3,
            "world_to_camera": [[1,0,0,0.5],[0,1,0,0],[0,0,1,2]]}"#;
        let scene = format!(r#"{{"format_version": 1, "camera": {cam3}, "frames": []}}"#);
        let p = Path::new("<test>");
        let a = Camera::from_json_str(cam4, p).expect("4x4");
        assert_eq!(Camera::from_json_str(cam3, p).expect("3x4"), a);
        assert_eq!(Camera::from_json_str(&scene, p).expect("scene.json"), a);
        let two_rows = r#"{"width": 8, "height": 6, "fx": 10, "fy": 11, "cx": 4, "cy": 3,
            "world_to_camera": [[1,0,0,0.5],[0,1,0,0]]}"#;
        let err = Camera::from_json_str(two_rows, p)
            .expect_err("2 rows")
            .to_string();
        assert!(err.contains("3 or 4 rows"), "{err}");
    }
}
