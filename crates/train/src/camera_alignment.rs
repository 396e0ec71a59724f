//! Test-time camera alignment of unseen frames. With estimated cameras every frame's camera carries
//! its own error; training corrects the training frames' cameras, and a held-out frame gets the
//! correction interpolated from its neighbours (`Model::camera_correction_for`), which cannot know
//! that frame's own error. As evaluations of pose-refining radiance fields do (BARF,
//! BAD-Gaussians), the held-out frame's camera is then refined with the model frozen — here
//! against the frame's *observed* image, the blurred input the method is given (never the sharp
//! reference the frame is scored against).
//!
//! The refinement is Adam on a left twist ξ = (ω, v) (radians, metres) of the frame's corrected
//! camera, minimising the mean squared difference between the model's mid-exposure render from
//! the twisted camera and the observed frame. A blurred frame is the mean of the exposure's sharp
//! images, whose centroid is the mid-exposure image, so the difference is smallest near the right
//! camera. The gradient is the rasterizer's camera gradient (`rasterize_cpu::camera_pose_gradient`)
//! chained through the twist (`crate::pose::camera_correction::twist_backward`), both checked
//! against finite differences in `gradient-checks`. The camera of lowest loss seen, the start
//! included, is the one returned: alignment never raises the loss it minimises.

use crate::loss::image::{luminance3, luminance3_backward};
use crate::model::{Model, PassCamera};
use crate::pose::body::PreparedPose;
use crate::pose::camera_correction::{corrected_world_to_camera, twist_backward, TWIST_VALUES};
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
}

impl AlignmentSettings {
    /// `steps` Adam steps from 1 mrad and 1 mm per step (a 0.5° / 1 cm camera error is 9–10
    /// steps away), falling to a tenth.
    pub fn with_steps(steps: usize) -> Self {
        Self {
            steps,
            rotation_rate: 1e-3,
            translation_rate: 1e-3,
            final_fraction: 0.1,
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

/// Aligns the camera `start` (the frame's given camera with its learned correction) of a frame
/// the model renders in `pose` with latent `latent` (colours viewed from the given camera `given`,
/// as in training) to the frame's observed image `observed` ((3, H, W) linear RGB; with `grey`
/// its three planes hold the luminance and the render's luminance is compared).
pub fn align_camera(
    model: &Model,
    (start, given): (&Camera, &Camera),
    pose: &PreparedPose,
    latent: &[f32],
    (observed, grey): (&[f32], bool),
    settings: &AlignmentSettings,
) -> Result<AlignedCamera, TrainError> {
    let hw = start.width as usize * start.height as usize;
    if observed.len() != 3 * hw {
        return Err(TrainError::Config(format!(
            "camera alignment: the observed frame has {} values, the camera's image {}",
            observed.len(),
            3 * hw
        )));
    }
    let pass = model.forward_from(
        PassCamera {
            raster: start,
            view_centre: PassCamera::of(given).view_centre,
        },
        pose,
        latent,
    )?;
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
    let mut twist = [0.0f64; TWIST_VALUES];
    let mut best: Option<AlignedCamera> = None;
    let mut loss_before = f64::NAN;
    for k in 0..=settings.steps {
        let camera = Camera {
            world_to_camera: corrected_world_to_camera(&start.world_to_camera, &twist),
            ..start.clone()
        };
        let out = pass.render_from(&camera)?;
        let (loss, d_rgb) = squared_error(&out.image[..3 * hw], observed, hw, grey);
        if !loss.is_finite() {
            break;
        }
        if k == 0 {
            loss_before = loss;
        }
        if best.as_ref().is_none_or(|b| loss < b.loss_after) {
            best = Some(AlignedCamera {
                camera: camera.clone(),
                twist,
                loss_before,
                loss_after: loss,
            });
        }
        if k == settings.steps {
            break;
        }
        let mut d_image = vec![0.0f32; out.image.len()];
        d_image[..3 * hw].copy_from_slice(&d_rgb);
        let d_left = pass.camera_twist_gradient(&camera, &out, &d_image)?;
        let g = twist_backward(&d_left, &twist);
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
