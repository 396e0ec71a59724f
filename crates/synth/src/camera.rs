//! The benchmark's pinhole camera (OpenCV conventions, DESIGN.md §3).
//!
//! x right, y down, z forward; `p_cam = R · p_world + t`; pixel (i, j) has its centre at
//! (i + 0.5, j + 0.5), so a camera-space point projects to `(fx·x/z + cx, fy·y/z + cy)` in
//! continuous pixel coordinates whose integer grid lines are pixel edges.

use glam::{Mat3, Vec3};

/// An OpenCV pinhole camera with its pose.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PinholeCamera {
    /// Image width (pixels).
    pub width: u32,
    /// Image height (pixels).
    pub height: u32,
    /// Focal length along x (pixels).
    pub fx: f32,
    /// Focal length along y (pixels).
    pub fy: f32,
    /// Principal point x (pixels).
    pub cx: f32,
    /// Principal point y (pixels).
    pub cy: f32,
    /// Rotation of `world_to_camera`.
    pub rot_cam_from_world: Mat3,
    /// Translation of `world_to_camera` (metres).
    pub t_cam_from_world: Vec3,
}

impl PinholeCamera {
    /// A camera at `eye` looking at `target` (world metres, world y up), with the horizontal field
    /// of view `hfov` (radians) and the principal point at the image centre.
    pub fn look_at(width: u32, height: u32, hfov: f32, eye: Vec3, target: Vec3) -> Self {
        let z = (target - eye).normalize();
        let x = z.cross(Vec3::Y).normalize();
        let y = z.cross(x);
        // Rows of R are the camera axes in world coordinates.
        let rot = Mat3::from_cols(x, y, z).transpose();
        let fx = 0.5 * width as f32 / (0.5 * hfov).tan();
        Self {
            width,
            height,
            fx,
            fy: fx,
            cx: 0.5 * width as f32,
            cy: 0.5 * height as f32,
            rot_cam_from_world: rot,
            t_cam_from_world: -(rot * eye),
        }
    }

    /// World point (metres) to camera space (metres).
    pub fn cam_from_world(&self, p_world: Vec3) -> Vec3 {
        self.rot_cam_from_world * p_world + self.t_cam_from_world
    }

    /// The camera centre in world coordinates (metres): `−Rᵀ t`.
    pub fn centre_world(&self) -> Vec3 {
        -(self.rot_cam_from_world.transpose() * self.t_cam_from_world)
    }

    /// World direction to camera space.
    pub fn cam_dir_from_world(&self, d_world: Vec3) -> Vec3 {
        self.rot_cam_from_world * d_world
    }

    /// Camera-space point to continuous pixel coordinates (only meaningful for z > 0).
    pub fn pixel_from_cam(&self, p_cam: Vec3) -> [f32; 2] {
        [
            self.fx * p_cam.x / p_cam.z + self.cx,
            self.fy * p_cam.y / p_cam.z + self.cy,
        ]
    }

    /// The camera in scene-format terms.
    pub fn to_scene(&self) -> scene::Camera {
        let r = self.rot_cam_from_world;
        let t = self.t_cam_from_world;
        let row = |i: usize| {
            let c = r.row(i);
            [
                f64::from(c.x),
                f64::from(c.y),
                f64::from(c.z),
                f64::from(t[i]),
            ]
        };
        scene::Camera {
            width: self.width,
            height: self.height,
            fx: f64::from(self.fx),
            fy: f64::from(self.fy),
            cx: f64::from(self.cx),
            cy: f64::from(self.cy),
            world_to_camera: [row(0), row(1), row(2), [0.0, 0.0, 0.0, 1.0]],
        }
    }
}
