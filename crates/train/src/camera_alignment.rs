//! Test-time camera alignment of unseen frames. With estimated cameras every frame's camera carries
//! its own error; training corrects the training frames' cameras, and a held-out frame gets the
//! correction interpolated from its neighbours (`Model::camera_correction_for`), which cannot know
//! that frame's own error. As evaluations of pose-refining radiance fields do (BARF,
//! BAD-Gaussians), the held-out frame's camera is then refined with the model frozen — here
//! against the frame's *observed* image, the blurred input the method is given (never the sharp
//! reference the frame is scored against).
//!
//! The refinement is Adam on a left twist ξ = (ω, v) (radians, metres) of the frame's corrected
//! camera, minimising the mean squared difference between the observed frame and the model's
//! prediction of it: the mean of the exposure's renders (the trained model's own exposure model,
//! every render's camera moved by the same twist), or the mid-exposure render alone for a model
//! trained without one. The mid render alone is biased by a camera that moves unevenly inside
//! the exposure (a hand's tremor): the blurred frame's centroid is then not the mid image. The gradient is the rasterizer's camera gradient (`rasterize_cpu::camera_pose_gradient`)
//! chained through the twist (`crate::pose::camera_correction::twist_backward`), both checked
//! against finite differences in `gradient-checks`. The camera of lowest loss seen, the start
//! included, is the one returned: alignment never raises the loss it minimises.

use crate::data::{Dataset, ScenePaths, TrainFrame};
use crate::loss::image::{luminance3, luminance3_backward};
use crate::model::{corrected_camera, Model, PassCamera};
use crate::pose::body::Cast;
use crate::pose::body::PreparedPose;
use crate::pose::camera_correction::{corrected_world_to_camera, twist_backward, TWIST_VALUES};
use crate::pose::correction::exposure_offset;
use crate::pose::exposure::subframe_times;
use crate::TrainError;
use nn::{Adam, AdamConfig};
use rasterize_cpu::Camera;

/// How a held-out frame's camera is aligned.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AlignmentSettings {
    /// Adam steps per frame (0: no alignment).
    pub steps: usize,
    /// Adam's step size for the rotation (radians per step).
    pub rotation_rate: f64,
    /// Adam's step size for the translation (metres per step).
    pub translation_rate: f64,
    /// The step sizes fall exponentially to this fraction of themselves over the steps.
    pub final_fraction: f64,
    /// The renders a frame's exposure is modelled with ([`crate::pose::exposure::subframe_times`]),
    /// the body and the camera at each render's time; `None` (or 1): the mid-exposure render
    /// alone, which a camera moving unevenly inside the exposure biases.
    pub exposure: Option<ExposureSampling>,
}

/// How the exposure of a frame is sampled for alignment: the trained model's own rule.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ExposureSampling {
    /// Renders per exposure.
    pub subframes: usize,
    /// How the body's and the camera's paths are interpolated between frames.
    pub rules: crate::pose::exposure::TrackRules,
}

impl ExposureSampling {
    /// The exposure model of `config`, `None` when it renders one image per frame.
    pub fn of(config: &crate::config::TrainConfig) -> Option<Self> {
        (config.blur_model == crate::config::BlurModel::Exposure && config.subframes > 1).then(
            || Self {
                subframes: config.subframes,
                rules: crate::pose::exposure::TrackRules::of(config),
            },
        )
    }
}

impl AlignmentSettings {
    /// `steps` Adam steps from 1 mrad and 1 mm per step (a 0.5° / 1 cm camera error is 9–10
    /// steps away), falling to a tenth, on the exposure `exposure` samples.
    pub fn with_steps(steps: usize, exposure: Option<ExposureSampling>) -> Self {
        Self {
            steps,
            rotation_rate: 1e-3,
            translation_rate: 1e-3,
            final_fraction: 0.1,
            exposure,
        }
    }
}

/// One frame's aligned camera.
#[derive(Clone, Debug)]
pub struct AlignedCamera {
    /// The camera of lowest loss seen (the start when no step lowered it).
    pub camera: Camera,
    /// The left twist (ω, v) taking the start to it (radians, metres).
    pub twist: [f64; TWIST_VALUES],
    /// Mean squared difference against the observed frame from the start camera.
    pub loss_before: f64,
    /// The same from the returned camera.
    pub loss_after: f64,
}

/// The body's, the other people's and (when it moves) the camera's paths through a scene's frames,
/// to sample any frame's exposure as training samples a training frame's
/// (`TrainingData::enable_exposure`).
pub struct ExposurePaths {
    paths: ScenePaths,
    subframes: usize,
}

impl ExposurePaths {
    /// The paths through every frame of `data`, interpolated by `sampling`'s rules.
    pub fn new(data: &Dataset, sampling: &ExposureSampling) -> Self {
        let people = data.frames.first().map_or(0, |f| f.others.len());
        Self {
            paths: data.paths(sampling.rules, people),
            subframes: sampling.subframes,
        }
    }

    /// Frame `f`'s exposure renders: at each sub-exposure time the camera (the path's, else the
    /// frame's) with the model's correction of the frame at that offset, and the body's pose
    /// with the model's pose correction of the frame, prepared with `cast`.
    pub fn renders(
        &self,
        model: &Model,
        cast: &Cast<'_>,
        f: &TrainFrame,
    ) -> Result<Vec<(Camera, PreparedPose)>, TrainError> {
        let correction = model.camera_correction_for(f.index);
        let count = self.subframes;
        subframe_times(f.time_s, f.exposure_s, count)
            .iter()
            .enumerate()
            .map(|(s, &t)| {
                let camera = Camera {
                    world_to_camera: self
                        .paths
                        .camera
                        .as_ref()
                        .map_or(f.camera.world_to_camera, |c| c.at(t)),
                    ..f.camera.clone()
                };
                let camera = if correction.is_empty() {
                    camera
                } else {
                    corrected_camera(&camera, &correction, exposure_offset(s, count))
                };
                let others: Vec<_> = self.paths.others.iter().map(|o| o.at(t)).collect();
                let pose = cast.prepare(
                    &model.corrected_params(f.index, &self.paths.body.at(t)),
                    &others,
                )?;
                Ok((camera, pose))
            })
            .collect()
    }
}

/// One render of a frame's modelled exposure: the frame's corrected camera and the body's pose
/// at the render's time.
pub type ExposureRender<'a> = (Camera, &'a PreparedPose);

/// Aligns the camera `mid` (the frame's given camera `given` with its learned correction, at mid
/// exposure) of a frame the model renders with latent `latent` to the frame's observed image
/// `observed` ((3, H, W) linear RGB; with `grey` its three planes hold the luminance and the
/// render's luminance is compared). The prediction is the mean of the renders `exposure` (each
/// camera moved by the same left twist; colours viewed from `given`, as in training): the
/// frame's exposure, or its mid-exposure render alone.
pub fn align_camera(
    model: &Model,
    (mid, given): (&Camera, &Camera),
    exposure: &[ExposureRender<'_>],
    latent: &[f32],
    (observed, grey): (&[f32], bool),
    settings: &AlignmentSettings,
) -> Result<AlignedCamera, TrainError> {
    let hw = mid.width as usize * mid.height as usize;
    if observed.len() != 3 * hw || exposure.is_empty() {
        return Err(TrainError::Config(format!(
            "camera alignment: the observed frame has {} values, the camera's image {}, over {} renders",
            observed.len(),
            3 * hw,
            exposure.len()
        )));
    }
    let view_centre = PassCamera::of(given).view_centre;
    let passes = exposure
        .iter()
        .map(|(raster, pose)| {
            model.forward_from(
                PassCamera {
                    raster,
                    view_centre,
                },
                pose,
                latent,
            )
        })
        .collect::<Result<Vec<_>, _>>()?;
    let rate = |base: f64, k: usize| {
        base * settings
            .final_fraction
            .powf(k as f64 / settings.steps.max(1) as f64)
    };
    let adam = |lr| {
        Adam::<f64>::new(
            3,
            AdamConfig {
                lr,
                ..AdamConfig::default()
            },
        )
    };
    let (mut rotation, mut translation) = (adam(0.0), adam(0.0));
    let twisted = |camera: &Camera, twist: &[f64; TWIST_VALUES]| Camera {
        world_to_camera: corrected_world_to_camera(&camera.world_to_camera, twist),
        ..camera.clone()
    };
    let mut twist = [0.0f64; TWIST_VALUES];
    let mut best: Option<AlignedCamera> = None;
    let mut loss_before = f64::NAN;
    let scale = 1.0 / exposure.len() as f32;
    for k in 0..=settings.steps {
        let cameras: Vec<Camera> = exposure.iter().map(|(c, _)| twisted(c, &twist)).collect();
        let outs = passes
            .iter()
            .zip(&cameras)
            .map(|(pass, camera)| pass.render_from(camera))
            .collect::<Result<Vec<_>, _>>()?;
        let mut mean = vec![0.0f32; 3 * hw];
        for out in &outs {
            for (m, &v) in mean.iter_mut().zip(&out.image[..3 * hw]) {
                *m += scale * v;
            }
        }
        let (loss, d_mean) = squared_error(&mean, observed, hw, grey);
        if !loss.is_finite() {
            break;
        }
        if k == 0 {
            loss_before = loss;
        }
        if best.as_ref().is_none_or(|b| loss < b.loss_after) {
            best = Some(AlignedCamera {
                camera: twisted(mid, &twist),
                twist,
                loss_before,
                loss_after: loss,
            });
        }
        if k == settings.steps {
            break;
        }
        // Every render gets 1/S of the mean's cotangent; the twist's gradient sums theirs.
        let mut d_image = vec![0.0f32; outs[0].image.len()];
        for (d, &g) in d_image.iter_mut().zip(&d_mean) {
            *d = scale * g;
        }
        let mut g = [0.0f64; TWIST_VALUES];
        for ((pass, camera), out) in passes.iter().zip(&cameras).zip(&outs) {
            let d_left = pass.camera_twist_gradient(camera, out, &d_image)?;
            for (a, b) in g.iter_mut().zip(twist_backward(&d_left, &twist)) {
                *a += b;
            }
        }
        if !g.iter().all(|v| v.is_finite()) {
            break;
        }
        rotation.config.lr = rate(settings.rotation_rate, k);
        translation.config.lr = rate(settings.translation_rate, k);
        let (w, v) = twist.split_at_mut(3);
        rotation.step(w, &g[..3])?;
        translation.step(v, &g[3..])?;
    }
    best.ok_or_else(|| {
        TrainError::Config("camera alignment: the start camera's render is not finite".into())
    })
}

/// The mean squared difference of `render` ((3, H, W)) from `observed` (the render's luminance
/// with `grey`) and its gradient w.r.t. `render`.
fn squared_error(render: &[f32], observed: &[f32], hw: usize, grey: bool) -> (f64, Vec<f32>) {
    let compared = grey.then(|| luminance3(render, hw));
    let prediction = compared.as_deref().unwrap_or(render);
    let n = prediction.len().max(1) as f64;
    let mut loss = 0.0f64;
    let mut grad = Vec::with_capacity(prediction.len());
    for (&p, &o) in prediction.iter().zip(observed) {
        let d = f64::from(p) - f64::from(o);
        loss += d * d;
        grad.push((2.0 * d / n) as f32);
    }
    let grad = if grey {
        luminance3_backward(&grad, hw)
    } else {
        grad
    };
    (loss / n, grad)
}

#[cfg(test)]
mod tests {
    use super::squared_error;

    #[test]
    fn squared_error_and_its_gradient() {
        // Two pixels; the second channel differs by 0.5 at pixel 0: loss 0.25 / 6.
        let render = [0.0, 0.0, 0.5, 0.0, 0.0, 0.0];
        let observed = [0.0; 6];
        let (loss, grad) = squared_error(&render, &observed, 2, false);
        assert!((loss - 0.25 / 6.0).abs() < 1e-12);
        assert!((f64::from(grad[2]) - 1.0 / 6.0).abs() < 1e-7);
        assert_eq!(grad.iter().filter(|&&g| g != 0.0).count(), 1);
        // Grey: the luminance is compared, and the gradient is the luminance's adjoint.
        let (grey_loss, grey_grad) = squared_error(&render, &observed, 2, true);
        let y = f64::from(scene::image_io::REC601_LUMA[1]) * 0.5;
        assert!((grey_loss - 3.0 * y * y / 6.0).abs() < 1e-7);
        assert!(grey_grad[0] > 0.0 && grey_grad[2] > 0.0 && grey_grad[4] > 0.0);
    }
}
