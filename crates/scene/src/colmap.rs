//! Cameras of a COLMAP sparse model in its text form (`cameras.txt` + `images.txt`, what
//! `colmap model_converter --output_type TXT` writes), read into the workspace's [`Camera`]: one
//! per registered image, named by its image file name.
//!
//! COLMAP's conventions are the project's (OpenCV axes; `images.txt` holds the world-to-camera
//! rotation as a quaternion `QW QX QY QZ` and the translation `TX TY TZ`; the centre of the top-left
//! pixel is at (0.5, 0.5)), so poses are taken as they are. Intrinsics: `SIMPLE_PINHOLE`,
//! `PINHOLE`, and the distorted models `SIMPLE_RADIAL`, `RADIAL`, `OPENCV` only when every
//! distortion coefficient is zero; other models and real distortion are refused (undistort the
//! images first, e.g. `colmap image_undistorter`, which writes a `PINHOLE` model).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use crate::error::{Result, SceneError};
use crate::types::Camera;

/// One registered image of a COLMAP model.
#[derive(Clone, Debug, PartialEq)]
pub struct ColmapImage {
    /// The image's file name as COLMAP stores it (relative to its image folder).
    pub name: String,
    /// Its camera: the model's intrinsics and the image's pose.
    pub camera: Camera,
}

/// Intrinsics of one COLMAP camera.
#[derive(Clone, Copy, Debug)]
struct Intrinsics {
    width: u32,
    height: u32,
    fx: f64,
    fy: f64,
    cx: f64,
    cy: f64,
}

/// Reads `dir/cameras.txt` and `dir/images.txt`: every registered image with its camera, in the
/// order of `images.txt`.
pub fn read_text_model(dir: &Path) -> Result<Vec<ColmapImage>> {
    let cameras_path = dir.join("cameras.txt");
    let images_path = dir.join("images.txt");
    let read = |p: &PathBuf| {
        std::fs::read_to_string(p).map_err(|source| SceneError::Io {
            path: p.clone(),
            source,
        })
    };
    let cameras = parse_cameras(&read(&cameras_path)?, &cameras_path)?;
    parse_images(&read(&images_path)?, &images_path, &cameras)
}

fn error(path: &Path, line: usize, message: impl Into<String>) -> SceneError {
    SceneError::Colmap {
        path: path.to_path_buf(),
        line,
        message: message.into(),
    }
}

fn number<T: std::str::FromStr>(token: &str, what: &str, path: &Path, line: usize) -> Result<T> {
    token
        .parse()
        .map_err(|_| error(path, line, format!("{what} `{token}` is not a number")))
}

/// `cameras.txt`: `CAMERA_ID MODEL WIDTH HEIGHT PARAMS…` per line, `#` comments.
fn parse_cameras(text: &str, path: &Path) -> Result<BTreeMap<u32, Intrinsics>> {
    let mut out = BTreeMap::new();
    for (i, raw) in text.lines().enumerate() {
        let line = i + 1;
        let raw = raw.trim();
        if raw.is_empty() || raw.starts_with('#') {
            continue;
        }
        let t: Vec<&str> = raw.split_whitespace().collect();
        if t.len() < 4 {
            return Err(error(
                path,
                line,
                "expected CAMERA_ID MODEL WIDTH HEIGHT PARAMS…",
            ));
        }
        let id: u32 = number(t[0], "CAMERA_ID", path, line)?;
        let width: u32 = number(t[2], "WIDTH", path, line)?;
        let height: u32 = number(t[3], "HEIGHT", path, line)?;
        let params = t[4..]
            .iter()
            .map(|p| number::<f64>(p, "parameter", path, line))
            .collect::<Result<Vec<f64>>>()?;
        let model = t[1];
        let (focal, centre, distortion, count) = match model {
            "SIMPLE_PINHOLE" => ((0, 0), (1, 2), 3..3, 3),
            "PINHOLE" => ((0, 1), (2, 3), 4..4, 4),
            "SIMPLE_RADIAL" => ((0, 0), (1, 2), 3..4, 4),
            "RADIAL" => ((0, 0), (1, 2), 3..5, 5),
            "OPENCV" => ((0, 1), (2, 3), 4..8, 8),
            other => {
                return Err(error(
                    path,
                    line,
                    format!(
                        "camera model {other} is not read (SIMPLE_PINHOLE, PINHOLE, or SIMPLE_RADIAL, RADIAL, OPENCV without distortion); undistort the images first (colmap image_undistorter)"
                    ),
                ))
            }
        };
        if params.len() != count {
            return Err(error(
                path,
                line,
                format!("{model} has {count} parameters, found {}", params.len()),
            ));
        }
        if params[distortion.clone()].iter().any(|&k| k != 0.0) {
            return Err(error(
                path,
                line,
                format!(
                    "camera {id} ({model}) has distortion {:?}; undistort the images first (colmap image_undistorter)",
                    &params[distortion]
                ),
            ));
        }
        let intrinsics = Intrinsics {
            width,
            height,
            fx: params[focal.0],
            fy: params[focal.1],
            cx: params[centre.0],
            cy: params[centre.1],
        };
        if out.insert(id, intrinsics).is_some() {
            return Err(error(path, line, format!("camera {id} is listed twice")));
        }
    }
    Ok(out)
}

/// `images.txt`: per image two lines, `IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME` and its 2-D
/// points (possibly empty); `#` comments before them.
fn parse_images(
    text: &str,
    path: &Path,
    cameras: &BTreeMap<u32, Intrinsics>,
) -> Result<Vec<ColmapImage>> {
    let lines: Vec<(usize, &str)> = text
        .lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l))
        .skip_while(|(_, l)| l.trim_start().starts_with('#'))
        .collect();
    let mut out: Vec<ColmapImage> = Vec::new();
    for &(line, raw) in lines.iter().step_by(2) {
        let t: Vec<&str> = raw.split_whitespace().collect();
        if t.is_empty() {
            continue;
        }
        if t.len() < 10 {
            return Err(error(
                path,
                line,
                "expected IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME",
            ));
        }
        let v = |k: usize, what: &str| number::<f64>(t[k], what, path, line);
        let q = [v(1, "QW")?, v(2, "QX")?, v(3, "QY")?, v(4, "QZ")?];
        let tr = [v(5, "TX")?, v(6, "TY")?, v(7, "TZ")?];
        let camera_id: u32 = number(t[8], "CAMERA_ID", path, line)?;
        let name = t[9..].join(" ");
        let Some(k) = cameras.get(&camera_id) else {
            return Err(error(
                path,
                line,
                format!("image {name}: camera {camera_id} is not in cameras.txt"),
            ));
        };
        let norm = q.iter().map(|c| c * c).sum::<f64>().sqrt();
        if !(norm.is_finite() && norm > 0.0) {
            return Err(error(path, line, format!("image {name}: quaternion {q:?}")));
        }
        let [w, x, y, z] = q.map(|c| c / norm);
        let rotation = [
            [
                1.0 - 2.0 * (y * y + z * z),
                2.0 * (x * y - w * z),
                2.0 * (x * z + w * y),
            ],
            [
                2.0 * (x * y + w * z),
                1.0 - 2.0 * (x * x + z * z),
                2.0 * (y * z - w * x),
            ],
            [
                2.0 * (x * z - w * y),
                2.0 * (y * z + w * x),
                1.0 - 2.0 * (x * x + y * y),
            ],
        ];
        let row = |r: usize| [rotation[r][0], rotation[r][1], rotation[r][2], tr[r]];
        if out.iter().any(|im| im.name == name) {
            return Err(error(path, line, format!("image {name} is listed twice")));
        }
        out.push(ColmapImage {
            name,
            camera: Camera {
                width: k.width,
                height: k.height,
                fx: k.fx,
                fy: k.fy,
                cx: k.cx,
                cy: k.cy,
                world_to_camera: [row(0), row(1), row(2), [0.0, 0.0, 0.0, 1.0]],
            },
        });
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    const CAMERAS: &str = "# Camera list with one line of data per camera:\n\
        #   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n\
        1 PINHOLE 640 480 500 510 320 240\n\
        2 OPENCV 64 48 50 50 32 24 0 0 0 0\n";
    // Image 1: identity rotation; image 2: 90° about y (qw = qy = √½), with 2-D points.
    const IMAGES: &str = "# Image list with two lines of data per image:\n\
        #   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n\
        #   POINTS2D[] as (X, Y, POINT3D_ID)\n\
        1 1 0 0 0 0.1 0.2 0.3 1 frame_000.png\n\
        \n\
        2 0.7071067811865476 0 0.7071067811865476 0 0 0 2 2 frame 001.png\n\
        10.0 20.0 -1 30.0 40.0 7\n";

    fn parse(cameras: &str, images: &str) -> Result<Vec<ColmapImage>> {
        let p = Path::new("m");
        parse_images(images, p, &parse_cameras(cameras, p)?)
    }

    #[test]
    fn a_text_model_gives_each_image_its_camera() {
        let images = parse(CAMERAS, IMAGES).unwrap();
        assert_eq!(images.len(), 2);
        let a = &images[0];
        assert_eq!(a.name, "frame_000.png");
        assert_eq!(
            (a.camera.width, a.camera.fx, a.camera.fy, a.camera.cx),
            (640, 500.0, 510.0, 320.0)
        );
        assert_eq!(a.camera.world_to_camera[0], [1.0, 0.0, 0.0, 0.1]);
        assert_eq!(a.camera.world_to_camera[2], [0.0, 0.0, 1.0, 0.3]);
        let b = &images[1];
        assert_eq!(b.name, "frame 001.png");
        let r = b.camera.world_to_camera;
        // R_y(90°): x → −z, z → x.
        let close = |a: f64, b: f64| (a - b).abs() < 1e-12;
        assert!(
            close(r[0][2], 1.0) && close(r[2][0], -1.0) && close(r[1][1], 1.0),
            "{r:?}"
        );
        assert_eq!((b.camera.width, b.camera.cx), (64, 32.0));
    }

    #[test]
    fn distortion_unknown_models_and_missing_cameras_are_refused_with_their_line() {
        let distorted = CAMERAS.replace("0 0 0 0\n", "0.1 0 0 0\n");
        let err = parse(&distorted, IMAGES).unwrap_err().to_string();
        assert!(
            err.starts_with("m:4:") && err.contains("undistort"),
            "{err}"
        );
        let fisheye = CAMERAS.replace("PINHOLE 640", "OPENCV_FISHEYE 640");
        let err = parse(&fisheye, IMAGES).unwrap_err().to_string();
        assert!(err.contains("OPENCV_FISHEYE is not read"), "{err}");
        let err = parse(CAMERAS, &IMAGES.replace("0 0 2 2 frame", "0 0 2 9 frame"))
            .unwrap_err()
            .to_string();
        assert!(err.starts_with("m:6:") && err.contains("camera 9"), "{err}");
        let err = parse(CAMERAS, &IMAGES.replace("0.1 0.2", "0.1 x"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("TY `x` is not a number"), "{err}");
    }
}
