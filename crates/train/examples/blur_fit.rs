//! Does the blurred input prefer the blur-trained model's sharp renders to the ceiling's? Every
//! model is scored through one common forward model of the exposure — the mean of S renders at the
//! generator's own poses at the midpoint-rule sub-exposure times, without the events' modulation —
//! against the observed (blurred) training frames, and its mid-exposure render against the sharp
//! references, full frame and in the person's box (the mask's tight box). A model that is sharper
//! *and* predicts the blurred frames better than another shows that the blurred frames do not hold
//! the second where it is (an optimisation gap); one that is sharper but predicts them worse shows
//! that the blur-trained model's own prediction (its learned in-exposure motion, its modulation)
//! fits the frames with a softer person (an identifiability gap). With `S` = the benchmark's own
//! sub-frame count the forward model is the generator's, up to its supersampling. With `POSES` =
//! `given` the sub-exposure poses are instead interpolated between the frames' given poses (the
//! model's `body_interpolation`): the operator a run with `--exposure-motion given` trains through,
//! without its modulation. `SUBFRAMES` with an `s` (`9s`) smears each render over its time slice
//! (`train::pose::smear`, the renders of `--exposure-smear on`). With `--against-own N` the
//! prediction is scored against the model's own mean of N renders at the same poses instead of
//! the observed frames: the time quadrature's own error, whatever the model (N = 64 stands for a
//! continuous exposure).
//!
//! ```text
//! cargo run --release -p train --example blur_fit -- DATA SUBFRAMES[s] truth|given \
//!     [--against-own N] MODEL_DIR...
//! ```
//!
//! `DATA` a one-person synthetic benchmark (its generator config in `scene.json`, sharp references
//! and masks); each `MODEL_DIR` a run's `model/`.

use std::path::PathBuf;

use scene::Split;
use train::eval::{box_psnr, mask_bbox, psnr};
use train::model::{PassCamera, PassPlan};
use train::pose::exposure::{subframe_times, PoseTrack};

/// Per-frame PSNR (dB) summed, full frame and box, and the number of frames.
#[derive(Default)]
struct Scores {
    full: f64,
    in_box: f64,
    frames: usize,
}

impl Scores {
    fn add(
        &mut self,
        a: &[f32],
        b: &[f32],
        w: usize,
        h: usize,
        bbox: (usize, usize, usize, usize),
    ) {
        self.full += psnr(a, b);
        self.in_box += box_psnr(a, b, w, h, bbox);
        self.frames += 1;
    }

    fn mean(&self) -> (f64, f64) {
        let n = self.frames.max(1) as f64;
        (self.full / n, self.in_box / n)
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [dir, subframes, poses, models @ ..] = &args[..] else {
        return Err(
            "usage: blur_fit DATA SUBFRAMES[s] truth|given [--against-own N] MODEL_DIR...".into(),
        );
    };
    let given = match poses.as_str() {
        "truth" => false,
        "given" => true,
        other => return Err(format!("POSES: `{other}`, expected truth or given").into()),
    };
    let (against_own, models) = match models {
        [flag, n, rest @ ..] if flag == "--against-own" => (Some(n.parse::<usize>()?), rest),
        _ => (None, models),
    };
    let smear = subframes.ends_with('s');
    let subframes: usize = subframes.trim_end_matches('s').parse()?;
    let data = train::data::load_dataset(&PathBuf::from(dir))?;
    let motion = synth::generate::recorded_motion(
        &data.dir.join("scene.json"),
        data.scene.generator.as_ref(),
    )?;
    let (w, h) = (data.camera.width as usize, data.camera.height as usize);
    let truth_at = |t: f64| {
        let (pose, transl) = motion.at(t);
        smpl_deform::SmplParams {
            pose,
            betas: vec![],
            transl,
        }
    };
    for model_dir in models {
        let loaded = train::export::load_model(&PathBuf::from(model_dir))?;
        let (model, cast) = (&loaded.model, loaded.cast());
        let keys: Vec<(f64, &smpl_deform::SmplParams)> =
            data.frames.iter().map(|f| (f.time_s, &f.smpl)).collect();
        let track = PoseTrack::new(&keys, loaded.manifest.config.body_interpolation);
        let pose_at = |t: f64| if given { track.at(t) } else { truth_at(t) };
        let (mut blurred, mut sharp) = (Scores::default(), Scores::default());
        for f in data.frames.iter().filter(|f| f.split == Split::Train) {
            let (Some(reference), Some(mask)) = (f.sharp.as_deref(), f.mask.as_deref()) else {
                return Err(format!("frame {}: no sharp reference or mask", f.index).into());
            };
            let Some(bbox) = mask_bbox(mask, w, h) else {
                continue;
            };
            let latent = model.latent_for(f.index);
            let mut mean = vec![0.0f32; 3 * w * h];
            let poses = subframe_times(f.time_s, f.exposure_s, subframes)
                .into_iter()
                .map(|t| cast.prepare(&pose_at(t), &f.others))
                .collect::<Result<Vec<_>, _>>()?;
            let mut add = |rgb: &[f32]| {
                for (m, &v) in mean.iter_mut().zip(rgb) {
                    *m += v / subframes as f32;
                }
            };
            if smear {
                let plan = PassPlan {
                    reposed: false,
                    share_static_tiles: false,
                    joint_backward_only: false,
                    static_layer: false,
                    smear: true,
                };
                let cameras = vec![PassCamera::of(&f.camera); subframes];
                let pose_refs: Vec<_> = poses.iter().collect();
                let passes =
                    model.forward_passes(&cameras, &pose_refs, subframes / 2, latent, plan)?;
                passes.passes.iter().for_each(|p| add(p.rgb()));
            } else {
                for pose in &poses {
                    add(&model.render_frame(f.index, &f.camera, pose, latent)?.rgb);
                }
            }
            match against_own {
                Some(n) => {
                    let mut own = vec![0.0f32; 3 * w * h];
                    for t in subframe_times(f.time_s, f.exposure_s, n) {
                        let pose = cast.prepare(&pose_at(t), &f.others)?;
                        let r = model.render_frame(f.index, &f.camera, &pose, latent)?;
                        for (m, &v) in own.iter_mut().zip(&r.rgb) {
                            *m += v / n as f32;
                        }
                    }
                    blurred.add(&mean, &own, w, h, bbox);
                }
                None => blurred.add(&mean, &f.image, w, h, bbox),
            }
            let pose = cast.prepare(&truth_at(f.time_s), &f.others)?;
            let mid = model.render_frame(f.index, &f.camera, &pose, latent)?;
            sharp.add(&mid.rgb, reference, w, h, bbox);
        }
        let ((bf, bb), (sf, sb)) = (blurred.mean(), sharp.mean());
        println!(
            "{model_dir}: {} training frames; blurred frames from {subframes} renders{} at {poses} \
             {bf:.2} / {bb:.2} dB; mid render against the sharp frames {sf:.2} / {sb:.2} dB \
             (full / box)",
            blurred.frames,
            if smear { " (smeared)" } else { "" }
        );
        if let Some(n) = against_own {
            println!(
                "  (scored against the model's own mean of {n} renders, not the observed frames)"
            );
        }
    }
    Ok(())
}
