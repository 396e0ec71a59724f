//! The cameras a model renders from: a pass's camera (the one it is rasterized from and the centre
//! its colours are viewed from) and the model's learned camera corrections
//! (`crate::pose::camera_correction`).

use super::{Model, Rendered};
use crate::pose::body::PreparedPose;
use crate::pose::camera_correction::{
    corrected_world_to_camera, fitted_camera_correction, smoothed_corrections, smoothed_row,
    twist_at, CAMERA_CORRECTION_VALUES, TWIST_VALUES,
};
use crate::TrainError;
use rasterize_cpu::Camera;

/// The camera of one pass: the one the Gaussians are rasterized from, and the camera centre the
/// colour networks' view directions start at (world, metres). They are one camera's except under
/// camera correction, where colours keep the given camera's view (the correction moves only the
/// projection; `crate::pose::camera_correction`).
#[derive(Clone, Copy, Debug)]
pub struct PassCamera<'a> {
    /// The camera the pass is rasterized from.
    pub raster: &'a Camera,
    /// The centre of the colours' view directions.
    pub view_centre: [f32; 3],
}

impl<'a> PassCamera<'a> {
    /// One camera for both.
    pub fn of(camera: &'a Camera) -> Self {
        Self {
            raster: camera,
            view_centre: super::view_centre(camera),
        }
    }
}

/// `camera` with its pose corrected by a frame's `correction` at exposure offset `offset`.
pub fn corrected_camera(camera: &Camera, correction: &[f32], offset: f32) -> Camera {
    Camera {
        world_to_camera: corrected_world_to_camera(
            &camera.world_to_camera,
            &twist_at(correction, offset),
        ),
        ..camera.clone()
    }
}

impl Model {
    /// Training slot `slot`'s camera correction ([`CAMERA_CORRECTION_VALUES`] values, the clip-wide
    /// twist of [`Model::camera_gauge`] added to its mid-exposure half; empty when camera
    /// correction is off).
    pub fn training_camera_correction(&self, slot: usize) -> Vec<f32> {
        let sigma = self.config.camera_correction_smoothing;
        let smoothed = self.config.camera_correction_smoothed_values;
        self.with_gauge(smoothed_row(
            &self.camera_corrections,
            slot,
            sigma,
            smoothed,
        ))
    }

    /// The camera correction of frame `index` at mid exposure — a training frame's own, another
    /// frame's fitted to the training frames nearest to it (`fitted_camera_correction`) —
    /// with the clip-wide twist (empty when camera correction is off).
    pub fn camera_correction_for(&self, index: u32) -> Vec<f32> {
        self.with_gauge(fitted_camera_correction(
            &self.frame_indices,
            &smoothed_corrections(
                &self.camera_corrections,
                self.config.camera_correction_smoothing,
                self.config.camera_correction_smoothed_values,
            ),
            index,
        ))
    }

    /// `correction` with the clip-wide twist added to its mid-exposure half.
    fn with_gauge(&self, mut correction: Vec<f32>) -> Vec<f32> {
        if correction.len() == CAMERA_CORRECTION_VALUES {
            for (c, &g) in correction.iter_mut().zip(&self.camera_gauge[..]) {
                *c += g;
            }
        }
        correction
    }

    /// With a clip-wide twist: removes the clip mean of the training frames' mid-exposure twists
    /// (summed in slot order; the twists their cameras take, smoothed, whose weights sum to one,
    /// so that subtracting it from every stored row centres them), so that only the person's
    /// twist moves every camera together.
    pub fn centre_camera_corrections(&mut self) {
        let (n, rows) = (CAMERA_CORRECTION_VALUES, self.frame_indices.len());
        if self.camera_gauge.is_empty() || rows == 0 || self.camera_corrections.len() != rows * n {
            return;
        }
        let mut mean = [0.0f64; TWIST_VALUES];
        let sigma = self.config.camera_correction_smoothing;
        let smoothed = self.config.camera_correction_smoothed_values;
        for row in smoothed_corrections(&self.camera_corrections, sigma, smoothed).chunks(n) {
            for (m, &v) in mean.iter_mut().zip(row) {
                *m += f64::from(v);
            }
        }
        for row in self.camera_corrections.chunks_mut(n) {
            for (v, &m) in row.iter_mut().zip(&mean) {
                *v -= (m / rows as f64) as f32;
            }
        }
    }

    /// Frame `index`'s `camera` with its learned correction at mid exposure (`camera` unchanged
    /// when camera correction is off): what evaluation renders a scene's frame from.
    pub fn corrected_camera(&self, index: u32, camera: &Camera) -> Camera {
        let correction = self.camera_correction_for(index);
        if correction.is_empty() {
            camera.clone()
        } else {
            corrected_camera(camera, &correction, 0.0)
        }
    }

    /// Renders scene frame `index` (its given `camera`) in `pose` with the frame latent `latent`,
    /// from the camera as its learned correction moves it (colours viewed from the given camera,
    /// as in training; [`PassCamera`]).
    pub fn render_frame(
        &self,
        index: u32,
        camera: &Camera,
        pose: &PreparedPose,
        latent: &[f32],
    ) -> Result<Rendered, TrainError> {
        self.render_frame_from(&self.corrected_camera(index, camera), camera, pose, latent)
    }

    /// [`Model::render_frame`] rasterized from `raster` (e.g. a camera aligned at test time,
    /// `crate::camera_alignment`), colours viewed from the given `camera`.
    pub fn render_frame_from(
        &self,
        raster: &Camera,
        camera: &Camera,
        pose: &PreparedPose,
        latent: &[f32],
    ) -> Result<Rendered, TrainError> {
        let pass = self.forward_from(
            PassCamera {
                raster,
                view_centre: super::view_centre(camera),
            },
            pose,
            latent,
        )?;
        Ok(Rendered {
            rgb: pass.rgb().to_vec(),
            human: pass.human().to_vec(),
            people: pass.people_planes(),
            posed: pass.posed,
        })
    }
}
