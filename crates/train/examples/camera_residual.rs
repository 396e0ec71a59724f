//! Where a camera-corrected reconstruction's cameras still err, and what the error costs. For a
//! synthetic scene with `cameras_true.json` (the generator's truth, which training never reads)
//! and a model trained on it, per split (training / held-out frames), for the cameras as given
//! and as corrected:
//!
//! - the residual rotation `R_true · R_cameraᵀ` as an axis-angle vector in the camera's
//!   coordinates (x right, y down, z forward; degrees), its RMS per axis and its clip mean (what a
//!   common offset explains), and the RMS centre error per camera axis (cm);
//! - how far the error moves the model's Gaussians on the image: the RMS pixel distance between
//!   each posed Gaussian's projection through the camera and through the true camera, separately
//!   for the person's Gaussians and the room's;
//! - the held-out frames' PSNR (full frame, against the sharp references) rendered from the
//!   corrected cameras (what `eval` scores) and from the true cameras (what the reconstruction
//!   scores once the held-out cameras are right).
//!
//! ```text
//! cargo run --release -p train --example camera_residual -- DATA MODEL_DIR
//! ```

use glam::{DMat3, DVec3};
use rasterize_cpu::Camera;
use scene::Split;
use synth::camera_error::TrueCameras;
use train::data::load_dataset;
use train::model::PassCamera;

/// Rotation (rows) and centre (world, m) of a world-to-camera transform.
fn rotation_and_centre(m: &[[f64; 4]; 4]) -> (DMat3, DVec3) {
    let r = DMat3::from_cols_array_2d(&[
        [m[0][0], m[1][0], m[2][0]],
        [m[0][1], m[1][1], m[2][1]],
        [m[0][2], m[1][2], m[2][2]],
    ]);
    let t = DVec3::new(m[0][3], m[1][3], m[2][3]);
    (r, -(r.transpose() * t))
}

/// Pixel of world point `p` through `camera` (`None` behind it).
fn pixel(camera: &Camera, p: DVec3) -> Option<[f64; 2]> {
    let (r, c) = rotation_and_centre(&camera.world_to_camera);
    let q = r * (p - c);
    (q.z > 1e-3).then(|| {
        [
            camera.fx * q.x / q.z + camera.cx,
            camera.fy * q.y / q.z + camera.cy,
        ]
    })
}

/// Sums over one split's frames for one set of cameras.
#[derive(Default)]
struct Residuals {
    frames: usize,
    rotation_sq: DVec3,
    rotation_sum: DVec3,
    centre_sq: DVec3,
    /// Sum of the centre errors in world coordinates (m).
    centre_world_sum: DVec3,
    /// (squared pixel distance sum, count) for the person's and the room's Gaussians.
    person_px: (f64, usize),
    room_px: (f64, usize),
}

impl Residuals {
    fn add(&mut self, camera: &Camera, truth: &Camera, means: &[[f32; 3]], human: &[f32]) {
        let (r, c) = rotation_and_centre(&camera.world_to_camera);
        let (rt, ct) = rotation_and_centre(&truth.world_to_camera);
        let (axis, angle) = glam::DQuat::from_mat3(&(rt * r.transpose())).to_axis_angle();
        let w = axis * angle.to_degrees();
        let dc = rt * (c - ct) * 100.0;
        self.frames += 1;
        self.rotation_sq += w * w;
        self.rotation_sum += w;
        self.centre_sq += dc * dc;
        self.centre_world_sum += c - ct;
        if std::env::var_os("CAMERA_RESIDUAL_FRAMES").is_some() {
            println!(
                "  frame rotation {:+.3} {:+.3} {:+.3}° centre {:+.3} {:+.3} {:+.3} cm",
                w.x, w.y, w.z, dc.x, dc.y, dc.z
            );
        }
        for (m, &h) in means.iter().zip(human) {
            let p = DVec3::new(f64::from(m[0]), f64::from(m[1]), f64::from(m[2]));
            if let (Some(a), Some(b)) = (pixel(camera, p), pixel(truth, p)) {
                let d2 = (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2);
                let slot = if h >= 0.5 {
                    &mut self.person_px
                } else {
                    &mut self.room_px
                };
                slot.0 += d2;
                slot.1 += 1;
            }
        }
    }

    fn print(&self, label: &str) {
        let n = self.frames.max(1) as f64;
        let rms = |v: DVec3| (v / n).to_array().map(f64::sqrt);
        let mean = (self.rotation_sum / n).to_array();
        let px = |(s, k): (f64, usize)| (s / k.max(1) as f64).sqrt();
        println!(
            "{label:<28} rotation RMS x/y/z {:.3} / {:.3} / {:.3}° (clip mean {:+.3} / {:+.3} / \
             {:+.3}°); centre RMS x/y/z {:.3} / {:.3} / {:.3} cm; on the image: person {:.2} px, \
             room {:.2} px",
            rms(self.rotation_sq)[0],
            rms(self.rotation_sq)[1],
            rms(self.rotation_sq)[2],
            mean[0],
            mean[1],
            mean[2],
            rms(self.centre_sq)[0],
            rms(self.centre_sq)[1],
            rms(self.centre_sq)[2],
            px(self.person_px),
            px(self.room_px),
        );
    }
}

/// `truth` moved by the clip-wide offset of `r`'s cameras: rotated by the mean residual rotation
/// (camera coordinates) and shifted by the mean centre error (world), i.e. the true cameras in the
/// reconstruction's own gauge.
fn in_gauge(truth: &Camera, r: &Residuals) -> Camera {
    let n = r.frames.max(1) as f64;
    let w = (r.rotation_sum / n).to_array().map(f64::to_radians);
    let offset = DMat3::from_quat(glam::DQuat::from_scaled_axis(DVec3::from(w)));
    let (rt, ct) = rotation_and_centre(&truth.world_to_camera);
    let (rot, centre) = (offset.transpose() * rt, ct + r.centre_world_sum / n);
    let t = -(rot * centre);
    let mut out = truth.clone();
    for i in 0..3 {
        let row = rot.row(i);
        out.world_to_camera[i] = [row.x, row.y, row.z, t[i]];
    }
    out
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [data_dir, model_dir] = args.as_slice() else {
        return Err("usage: camera_residual DATA MODEL_DIR".into());
    };
    let data = load_dataset(std::path::Path::new(data_dir))?;
    let truth = TrueCameras::read(std::path::Path::new(data_dir))?;
    let loaded = train::export::load_model(std::path::Path::new(model_dir))?;
    let (model, cast) = (&loaded.model, loaded.cast());
    let (w, h) = (data.camera.width as usize, data.camera.height as usize);
    let mut gauge = Residuals::default();
    for split in [Split::Train, Split::Test] {
        let (mut given, mut corrected) = (Residuals::default(), Residuals::default());
        let (mut psnr_corrected, mut psnr_true, mut psnr_gauge, mut scored) = (0.0, 0.0, 0.0, 0);
        for f in data.frames.iter().filter(|f| f.split == split) {
            let t = truth
                .frames
                .iter()
                .find(|t| t.index == f.index)
                .ok_or_else(|| format!("no true camera for frame {}", f.index))?;
            let mut true_camera = f.camera.clone();
            true_camera.world_to_camera[..3].copy_from_slice(&t.world_to_camera);
            let pose = cast.prepare(&model.corrected_params(f.index, &f.smpl), &f.others)?;
            let latent = model.latent_for(f.index);
            let r = model.render_frame(f.index, &f.camera, &pose, latent)?;
            let camera = model.corrected_camera(f.index, &f.camera);
            let (means, human) = (&r.posed.means, &r.posed.human_probability);
            given.add(&f.camera, &true_camera, means, human);
            corrected.add(&camera, &true_camera, means, human);
            if split == Split::Test {
                let reference = f.sharp.as_deref().unwrap_or(&f.image);
                let view_centre = f.camera.center_world().map(|v| v as f32);
                let pass = model.forward_from(
                    PassCamera {
                        raster: &true_camera,
                        view_centre,
                    },
                    &pose,
                    latent,
                )?;
                psnr_corrected += train::eval::psnr(&r.rgb, reference);
                psnr_true += train::eval::psnr(&pass.rgb()[..3 * w * h], reference);
                let aligned = in_gauge(&true_camera, &gauge);
                let pass = model.forward_from(
                    PassCamera {
                        raster: &aligned,
                        view_centre,
                    },
                    &pose,
                    latent,
                )?;
                psnr_gauge += train::eval::psnr(&pass.rgb()[..3 * w * h], reference);
                scored += 1;
            }
        }
        let name = if split == Split::Train {
            "training"
        } else {
            "held-out"
        };
        given.print(&format!("{name} frames, given"));
        corrected.print(&format!("{name} frames, corrected"));
        if scored > 0 {
            let n = scored as f64;
            println!(
                "held-out PSNR full: corrected cameras {:.2} dB, true cameras {:.2} dB, true \
                 cameras in the reconstruction's gauge (the training frames' mean offset) {:.2} dB",
                psnr_corrected / n,
                psnr_true / n,
                psnr_gauge / n
            );
        }
        if split == Split::Train {
            gauge = corrected;
        }
    }
    Ok(())
}
