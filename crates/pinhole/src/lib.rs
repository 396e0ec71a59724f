//! The workspace's one camera: an OpenCV pinhole camera (DESIGN.md §3), world-to-camera `[R|t]`
//! with x right, y down, z forward; intrinsics fx, fy, cx, cy in pixels; pixel (i, j) has its centre
//! at (i + 0.5, j + 0.5).
//!
//! [`Camera::new`] validates (finite values, positive focal lengths, an affine matrix with a
//! non-singular rotation part, image size within [`MAX_IMAGE_SIDE`]); [`Camera::validate`] applies
//! the same checks to a camera built field by field (as `scene` reads it from a file). The rasterizer
//! (`rasterize_cpu::Camera`) and the scene format (`scene::Camera`, `scene.json`'s `camera`) both use
//! this type. This crate is a foundation: it knows nothing of Gaussians or images, reads no files
//! and has no serialisation (the file formats are `scene`'s, `scene::camera_files`). Lens
//! distortion, for importing data from distorting cameras, is [`distortion`].

pub mod distortion;

pub use distortion::Distortion;

/// Largest accepted image side (pixels); larger requests are rejected, not attempted.
pub const MAX_IMAGE_SIDE: u32 = 16384;

/// Why a camera cannot be rendered from. Every variant names the field or value at fault.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CameraError {
    /// Image width or height is zero or larger than [`MAX_IMAGE_SIDE`].
    #[error("image size {width}x{height} is invalid: each side must be in 1..={max}")]
    InvalidImageSize {
        /// Requested width (pixels).
        width: u64,
        /// Requested height (pixels).
        height: u64,
        /// Largest allowed side (pixels).
        max: u32,
    },
    /// A camera field is NaN or infinite.
    #[error("camera field {field} is not finite ({value})")]
    NonFinite {
        /// Field name, e.g. `fx` or `world_to_camera[1][2]`.
        field: String,
        /// Offending value.
        value: f64,
    },
    /// A focal length is zero or negative.
    #[error("camera focal length {field} = {value} must be positive")]
    NonPositiveFocal {
        /// `fx` or `fy`.
        field: &'static str,
        /// Offending value (pixels).
        value: f64,
    },
    /// The rotation part of the world-to-camera matrix is singular (|det| below 1e-9).
    #[error("camera world_to_camera is singular: det of its 3x3 part is {det}")]
    SingularMatrix {
        /// Determinant of the upper-left 3×3 block.
        det: f64,
    },
    /// The last row of the world-to-camera matrix is not (0, 0, 0, 1).
    #[error("camera world_to_camera last row must be [0, 0, 0, 1], got {row:?}")]
    NotAffine {
        /// The last row as given.
        row: [f64; 4],
    },
}

/// An OpenCV pinhole camera. All lengths in metres, intrinsics in pixels. Built by [`Camera::new`]
/// it is valid; built field by field, [`Camera::validate`] says whether it can be rendered from.
#[derive(Clone, Debug, PartialEq)]
pub struct Camera {
    /// Image width (pixels).
    pub width: u32,
    /// Image height (pixels).
    pub height: u32,
    /// Horizontal focal length (pixels).
    pub fx: f64,
    /// Vertical focal length (pixels).
    pub fy: f64,
    /// Principal point x (pixels; the image's left edge is 0, the first pixel centre 0.5).
    pub cx: f64,
    /// Principal point y (pixels; the top edge is 0).
    pub cy: f64,
    /// World-to-camera rigid transform, row-major 4×4 (`p_cam = M · [p_world, 1]`, metres): the
    /// rows of `[R | t]`, then `[0, 0, 0, 1]`.
    pub world_to_camera: [[f64; 4]; 4],
}

fn finite(field: impl FnOnce() -> String, value: f64) -> Result<(), CameraError> {
    if value.is_finite() {
        Ok(())
    } else {
        Err(CameraError::NonFinite {
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
    /// Builds a camera, validating every field (see [`Camera::validate`]).
    pub fn new(
        width: u64,
        height: u64,
        fx: f64,
        fy: f64,
        cx: f64,
        cy: f64,
        world_to_camera: [[f64; 4]; 4],
    ) -> Result<Self, CameraError> {
        check_image_size(width, height)?;
        // Both sides were checked against MAX_IMAGE_SIDE, so they fit in u32.
        let camera = Self {
            width: width as u32,
            height: height as u32,
            fx,
            fy,
            cx,
            cy,
            world_to_camera,
        };
        camera.validate()?;
        Ok(camera)
    }

    /// Checks, in this order, that the image size is within `1..=`[`MAX_IMAGE_SIDE`], that fx, fy,
    /// cx, cy and every matrix entry are finite, that fx and fy are positive, that the last matrix
    /// row is `[0, 0, 0, 1]` and that the rotation part is non-singular (|det| > 1e-9).
    pub fn validate(&self) -> Result<(), CameraError> {
        let Self {
            width,
            height,
            fx,
            fy,
            cx,
            cy,
            ref world_to_camera,
        } = *self;
        check_image_size(width.into(), height.into())?;
        finite(|| "fx".into(), fx)?;
        finite(|| "fy".into(), fy)?;
        finite(|| "cx".into(), cx)?;
        finite(|| "cy".into(), cy)?;
        if fx <= 0.0 {
            return Err(CameraError::NonPositiveFocal {
                field: "fx",
                value: fx,
            });
        }
        if fy <= 0.0 {
            return Err(CameraError::NonPositiveFocal {
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
            return Err(CameraError::NotAffine {
                row: world_to_camera[3],
            });
        }
        let det = det3(world_to_camera);
        if !(det.abs() > 1e-9) {
            return Err(CameraError::SingularMatrix { det });
        }
        Ok(())
    }

    /// A camera looking down +z from the origin (identity extrinsics), principal point at the centre.
    pub fn looking_down_z(width: u32, height: u32, fx: f64, fy: f64) -> Result<Self, CameraError> {
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
pub fn check_image_size(width: u64, height: u64) -> Result<(), CameraError> {
    let max = u64::from(MAX_IMAGE_SIDE);
    if width == 0 || height == 0 || width > max || height > max {
        return Err(CameraError::InvalidImageSize {
            width,
            height,
            max: MAX_IMAGE_SIDE,
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn center_world_inverts_the_extrinsics() {
        // world_to_camera = [Rᵀ | −Rᵀ c] for the camera-to-world rotation R and the centre c.
        let r = [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]];
        let centre = [1.0, 2.0, 3.0];
        let mut m = [[0.0; 4]; 4];
        for i in 0..3 {
            for k in 0..3 {
                m[i][k] = r[k][i];
            }
            m[i][3] = -(0..3).map(|k| r[k][i] * centre[k]).sum::<f64>();
        }
        m[3][3] = 1.0;
        let cam = Camera::new(64, 48, 50.0, 50.0, 32.0, 24.0, m).expect("valid camera");
        let c = cam.center_world();
        for i in 0..3 {
            assert!((c[i] - centre[i]).abs() < 1e-12, "{c:?}");
        }
    }
}
