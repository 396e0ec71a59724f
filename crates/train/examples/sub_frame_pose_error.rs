//! How far the exposure model's sub-exposure poses are from the motion that made a synthetic
//! benchmark, before and after a run's learned pose correction. For every training frame and each
//! of S sub-exposure times (the midpoint rule of `train::pose::exposure`), three poses: the truth
//! (the generator's motion at that time, rebuilt from `scene.json`'s `generator.config`), the
//! poses interpolated between the frames' given poses (what training renders without correction,
//! with the run's `body_interpolation`), and those corrected by the run's pose correction at the
//! render's exposure offset. Reports, over the 23 body joints (root excluded) and over the
//! sub-exposure times other than mid exposure: the mean and RMS geodesic angle between each
//! joint's local rotation and the truth's (degrees), the share of the interpolation's squared
//! error the correction removes, and the worst joint; and the root translation's RMS error (mm).
//! Also the same figures for the corrections that fit the truth best per frame (least squares):
//! a change linear in the exposure offset (the form `--pose-correction-change` learns) and a
//! linear plus quadratic one — the ceilings of what such a correction can remove. With
//! `SUB_FRAME_POSE_ERROR_JOINTS` set, every sub-exposure time's worst joint and the knees' errors.
//!
//! ```text
//! cargo run --release -p train --example sub_frame_pose_error -- DATA MODEL_DIR [SUBFRAMES]
//! ```

use scene::Split;
use synth::pose_metrics::{angle_of, quat_of};
use train::data::load_dataset;
use train::pose::correction::{corrected_params, exposure_offset};
use train::pose::exposure::{subframe_times, PoseTrack};

/// Joints per SMPL pose (the root is joint 0).
const JOINTS: usize = 24;

/// Geodesic angle (degrees) between the rotations of axis-angles `a` and `b` (three values each).
fn angle_deg(a: &[f32], b: &[f32]) -> f64 {
    let q = |v: &[f32]| quat_of([v[0], v[1], v[2]]);
    angle_of(q(a).inverse() * q(b)).to_degrees()
}

/// Whether sub-exposure time `s` of `count` is mid exposure (where the given pose is the truth's
/// key, so it is left out).
fn is_mid(s: usize, count: usize) -> bool {
    2 * s + 1 == count
}

/// Joint-angle and translation errors of one set of poses against the truth.
#[derive(Default)]
struct Errors {
    sum: f64,
    sum_sq: f64,
    count: usize,
    worst: (f64, usize, u32),
    transl_sq: f64,
    transl_count: usize,
}

impl Errors {
    fn add(
        &mut self,
        pose: &[f32],
        transl: [f32; 3],
        truth: &[f32],
        truth_transl: [f32; 3],
        frame: u32,
    ) {
        for j in 1..JOINTS {
            let e = angle_deg(&pose[3 * j..3 * j + 3], &truth[3 * j..3 * j + 3]);
            self.sum += e;
            self.sum_sq += e * e;
            self.count += 1;
            if e > self.worst.0 {
                self.worst = (e, j, frame);
            }
        }
        let d: f64 = (0..3)
            .map(|k| (f64::from(transl[k]) - f64::from(truth_transl[k])).powi(2))
            .sum();
        self.transl_sq += d;
        self.transl_count += 1;
    }

    fn report(&self, name: &str) {
        let n = self.count.max(1) as f64;
        println!(
            "{name:<28} joints mean {:.4}° RMS {:.4}° (worst {:.2}°, joint {} of frame {}); root translation RMS {:.3} mm",
            self.sum / n,
            (self.sum_sq / n).sqrt(),
            self.worst.0,
            self.worst.1,
            self.worst.2,
            1e3 * (self.transl_sq / self.transl_count.max(1) as f64).sqrt()
        );
    }
}

/// One sub-exposure time of a frame: its exposure offset, the interpolated pose and the truth's
/// pose and translation.
type Sample = (f64, smpl_deform::SmplParams, (Vec<f32>, [f32; 3]));

/// The corrections of one frame's sub-exposure poses that fit the truth best in least squares,
/// per axis-angle value (the additive form of `train::pose::correction`, zero at mid exposure):
/// a change linear in the exposure offset, and a linear plus a quadratic term. Adds their errors
/// to `fits[0]` and `fits[1]`.
fn best_fits(
    track: &PoseTrack,
    motion: &synth::motion::Motion,
    times: &[f64],
    frame: u32,
    fits: &mut [Errors; 2],
) {
    let count = times.len();
    let samples: Vec<Sample> = times
        .iter()
        .enumerate()
        .filter(|&(s, _)| !is_mid(s, count))
        .map(|(s, &t)| {
            let o = f64::from(exposure_offset(s, count));
            (o, track.at(t), motion.at(t))
        })
        .collect();
    let values = samples.first().map_or(0, |s| s.1.pose.len());
    // Normal equations of the bases (o) and (o, o²), the same for every value.
    let (s11, s12, s22) = samples
        .iter()
        .fold((0.0, 0.0, 0.0), |(a, b, c), (o, _, _)| {
            (a + o * o, b + o * o * o, c + o * o * o * o)
        });
    let det = s11 * s22 - s12 * s12;
    let mut linear = vec![0.0f64; values];
    let mut quadratic = vec![[0.0f64; 2]; values];
    for k in 0..values {
        let (r1, r2) = samples.iter().fold((0.0, 0.0), |(a, b), (o, p, (q, _))| {
            let r = f64::from(q[k]) - f64::from(p.pose[k]);
            (a + o * r, b + o * o * r)
        });
        linear[k] = r1 / s11;
        quadratic[k] = [(s22 * r1 - s12 * r2) / det, (s11 * r2 - s12 * r1) / det];
    }
    for (o, p, (q, qt)) in &samples {
        let fitted = |f: &dyn Fn(usize) -> f64| -> Vec<f32> {
            (0..values)
                .map(|k| (f64::from(p.pose[k]) + f(k)) as f32)
                .collect()
        };
        let a = fitted(&|k| linear[k] * o);
        let b = fitted(&|k| quadratic[k][0] * o + quadratic[k][1] * o * o);
        fits[0].add(&a, p.transl, q, *qt, frame);
        fits[1].add(&b, p.transl, q, *qt, frame);
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (data_dir, model_dir, subframes) = match args.as_slice() {
        [d, m] => (d, m, 9),
        [d, m, s] => (d, m, s.parse()?),
        _ => return Err("usage: sub_frame_pose_error DATA MODEL_DIR [SUBFRAMES]".into()),
    };
    let data = load_dataset(std::path::Path::new(data_dir))?;
    let loaded = train::export::load_model(std::path::Path::new(model_dir))?;
    let model = &loaded.model;
    let motion = synth::generate::recorded_motion(
        &data.dir.join("scene.json"),
        data.scene.generator.as_ref(),
    )?;
    let keys: Vec<(f64, &smpl_deform::SmplParams)> =
        data.frames.iter().map(|f| (f.time_s, &f.smpl)).collect();
    let track = PoseTrack::new(&keys, loaded.manifest.config.body_interpolation);
    let corrections = !model.pose_corrections.is_empty();
    let (mut given, mut corrected) = (Errors::default(), Errors::default());
    let mut fits = [Errors::default(), Errors::default()];
    let training: Vec<_> = data
        .frames
        .iter()
        .filter(|f| f.split == Split::Train)
        .collect();
    for (slot, frame) in training.iter().enumerate() {
        let correction = corrections.then(|| model.training_correction(slot).0);
        let times = subframe_times(frame.time_s, frame.exposure_s, subframes);
        best_fits(&track, &motion, &times, frame.index, &mut fits);
        for (s, &t) in times.iter().enumerate() {
            if is_mid(s, subframes) {
                continue;
            }
            let (truth, truth_transl) = motion.at(t);
            let interpolated = track.at(t);
            if std::env::var_os("SUB_FRAME_POSE_ERROR_JOINTS").is_some() {
                let worst = (1..JOINTS)
                    .map(|j| {
                        let e = angle_deg(
                            &interpolated.pose[3 * j..3 * j + 3],
                            &truth[3 * j..3 * j + 3],
                        );
                        (e, j)
                    })
                    .fold((0.0, 0), |a, b| if b.0 > a.0 { b } else { a });
                println!(
                    "  frame {} sub {s}: worst joint {} {:.3}°",
                    frame.index, worst.1, worst.0
                );
            }
            given.add(
                &interpolated.pose,
                interpolated.transl,
                &truth,
                truth_transl,
                frame.index,
            );
            if let Some(c) = &correction {
                let p = corrected_params(&interpolated, c, exposure_offset(s, subframes));
                corrected.add(&p.pose, p.transl, &truth, truth_transl, frame.index);
                if std::env::var_os("SUB_FRAME_POSE_ERROR_JOINTS").is_some() {
                    for j in [4, 5] {
                        let r = 3 * j..3 * j + 3;
                        println!(
                            "    knee {j}: interpolated {:.3}° corrected {:.3}°",
                            angle_deg(&interpolated.pose[r.clone()], &truth[r.clone()]),
                            angle_deg(&p.pose[r.clone()], &truth[r])
                        );
                    }
                }
            }
        }
    }
    println!(
        "{} training frames, {subframes} sub-exposure times each (mid exposure excluded)",
        training.len()
    );
    given.report("interpolated (given)");
    fits[0].report("best change (linear)");
    fits[1].report("best linear + quadratic");
    if corrections {
        corrected.report("with the run's correction");
        println!(
            "squared joint error removed by the correction: {:.1} %",
            100.0 * (1.0 - corrected.sum_sq / given.sum_sq.max(f64::MIN_POSITIVE))
        );
    } else {
        println!("the run learned no pose correction");
    }
    Ok(())
}
