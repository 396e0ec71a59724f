//! The parts of a training run that `reconstruct` and `bench step` share: the body a scene
//! names, the supervision a configuration asks for (`TrainingData::prepare` with the frozen
//! networks loaded from their weights, and what was prepared printed), and the step-time breakdown.

use crate::common::{shipped_flow_network, shipped_lpips_weights};
use anyhow::{Context, Result};
use std::path::Path;
use train::config::{EventPairs, ExposurePairs, FlowMeasure, FlowSource, TrainConfig, TrainOn};
use train::data::{LossNetworks, Preparation, TrainingData};
use train::pose::body::Body;
use train::trainer::StepReport;

/// Loads the body model named by a scene (relative SMPL paths are taken relative to the scene).
pub fn scene_body(data: &train::data::Dataset) -> Result<Body> {
    data.body().with_context(|| {
        format!(
            "{}: loading the body model `{}` (scene.json body.model)",
            data.dir.display(),
            data.scene.body.model
        )
    })
}

/// Prepares on `ctx` the supervision `config` asks for (`TrainingData::prepare`, with the frozen
/// networks loaded from their weights) and reports what was prepared.
pub fn prepare_training_data(
    ctx: &mut TrainingData,
    data: &train::data::Dataset,
    config: &TrainConfig,
) -> Result<()> {
    let flow_path = config
        .flow_network
        .clone()
        .unwrap_or_else(shipped_flow_network);
    let networks = LossNetworks {
        flow: if config.flow_loss {
            Some(flow::load_safetensors(&flow_path).with_context(|| {
                format!(
                    "loading the flow network {} (train one with `cargo xtask train-flow`, or \
                     pass --flow-network)",
                    flow_path.display()
                )
            })?)
        } else {
            None
        },
        lpips: if config.lpips_weight > 0.0 {
            let weights = shipped_lpips_weights();
            Some(
                lpips::load_safetensors(&weights)
                    .with_context(|| format!("loading the LPIPS weights {}", weights.display()))?,
            )
        } else {
            None
        },
    };
    let done = ctx.prepare(data, config, networks)?;
    report_preparation(&done, config, &flow_path, ctx.frames.len());
    report_cameras(data, config);
    Ok(())
}

/// Says how a moving camera's poses are used: corrected (`--camera-correction on`) or taken as
/// given, which only exact cameras deserve.
fn report_cameras(data: &train::data::Dataset, config: &TrainConfig) {
    if config.camera_correction {
        println!(
            "camera correction: each training frame's camera and its motion over the exposure are \
             learned from step {} (rotation rate {}, shift rate {})",
            config.camera_correction_from, config.lr_camera_rotation, config.lr_camera_translation
        );
        if config.camera_correction_basis == train::config::CameraCorrectionBasis::Image {
            println!(
                "camera correction basis: the mid-exposure twists step in coordinates of the \
                 scene's image motion, {} px RMS per step (the shift and rotation rates above \
                 apply to the motion over the exposure)",
                config.lr_camera_pixels
            );
        }
        if config.camera_gauge == train::config::CameraGauge::Person {
            println!(
                "camera gauge: the offset common to every camera is learned from the person alone \
                 (the frames' own corrections keep a zero clip mean)"
            );
        }
    } else if data.camera_moves {
        eprintln!(
            "note: the camera moves and its poses are taken as given; with poses from a tracker \
             (SLAM, SfM, COLMAP) add --camera-correction on (docs/BENCHMARKS.md, \"A moving camera\")"
        );
    }
}

/// Prints what [`prepare_training_data`] set up.
fn report_preparation(done: &Preparation, config: &TrainConfig, flow_path: &Path, frames: usize) {
    if let Some(pairs) = done.flow_pairs {
        println!(
            "flow loss: {pairs} pairs of consecutive training frames, source {:?}, λ {}, τ {} px, \
             gradient to {:?}, measure {:?}, network {}",
            config.flow_source,
            config.flow_weight,
            config.flow_tau,
            config.flow_gradient,
            config.flow_measure,
            flow_path.display()
        );
        if config.flow_network.is_none()
            && config.flow_source != FlowSource::SharpNetwork
            && config.flow_measure == FlowMeasure::Network
        {
            eprintln!(
                "note: the shipped flow weights are weak, and with targets from the generator or \
                 the events the flow loss lowers PSNR; see docs/BENCHMARKS.md, \"Flow loss\"."
            );
        }
    }
    if done.lpips {
        println!(
            "perceptual loss: LPIPS (AlexNet, v0.1) of each frame's prediction, weight {}",
            config.lpips_weight
        );
    }
    if config.train_on == TrainOn::Sharp {
        println!("training on the sharp references (the benchmark's ceiling, not a method)");
    }
    if let Some(deblurred) = done.edi_deblurred {
        println!(
            "training on EDI-deblurred frames (the 2-D cascade baseline): {deblurred} of {frames} \
             training frames deblurred, the others' exposures are not covered by events"
        );
    }
    if let Some(deblurred) = done.edi_warmup {
        println!(
            "EDI warm-up: the first {} steps train on EDI-deblurred frames with one render and no \
             event term ({deblurred} of {frames} training frames deblurred)",
            config.edi_warmup
        );
    }
    if let Some((shortest, longest)) = done.exposure_s {
        let span = if longest - shortest > 1e-9 {
            format!("{:.1}–{:.1} ms", 1e3 * shortest, 1e3 * longest)
        } else {
            format!("{:.1} ms", 1e3 * longest)
        };
        println!(
            "exposure model: each training frame is the mean of {} renders over its {span} exposure",
            config.subframes
        );
    }
    if let Some(pairs) = done.event_pairs {
        let between = match config.event_pairs {
            EventPairs::Frames => "consecutive training frames",
            EventPairs::Exposure => "consecutive sub-exposure renders",
        };
        let compared = match (config.event_pairs, config.exposure_pairs) {
            (EventPairs::Exposure, ExposurePairs::All) => {
                " (every pair of an exposure's renders compared, the counts between them summed)"
            }
            (EventPairs::Exposure, ExposurePairs::SilentSpans) => {
                " (and every longer pair of an exposure's renders on the pixels silent between them)"
            }
            _ => "",
        };
        println!(
            "event loss: {pairs} pairs of {between}{compared}, weight {}, C {} per event",
            config.event_weight,
            config.event_thresholds().0
        );
    }
    if let Some(slices) = done.modulated_slices {
        println!(
            "event modulation: {slices} slices of exposures, each render modulated by the events \
             of its slice (EDI inside the slice)"
        );
    }
}

/// The renders the exposure's event loss compares, as the run's messages name them.
pub fn compared_renders(pairs: ExposurePairs) -> &'static str {
    match pairs {
        ExposurePairs::Consecutive => "consecutive sub-exposure renders",
        ExposurePairs::All => "every pair of sub-exposure renders",
        ExposurePairs::SilentSpans => {
            "consecutive sub-exposure renders (and longer pairs on silent pixels)"
        }
    }
}

/// Mean seconds per step stage over `recent`, in the step's order, with their total.
pub fn mean_times(recent: &[StepReport]) -> Vec<(&'static str, f64)> {
    let n = recent.len().max(1) as f64;
    let sum = |f: fn(&StepReport) -> f64| recent.iter().map(f).sum::<f64>() / n;
    vec![
        ("pose", sum(|r| r.times.pose)),
        ("render", sum(|r| r.times.render)),
        ("loss", sum(|r| r.times.loss)),
        ("lpips", sum(|r| r.times.lpips)),
        ("render_backward", sum(|r| r.times.render_backward)),
        ("model_backward", sum(|r| r.times.model_backward)),
        ("adam", sum(|r| r.times.adam)),
        ("density", sum(|r| r.times.density)),
        ("flow", sum(|r| r.times.flow)),
        ("flow_network", sum(|r| r.times.flow_network)),
        ("total", sum(|r| r.times.total())),
    ]
}

/// Replaces every training frame's sub-exposure poses by the generator's own poses at those times
/// (`reconstruct --oracle-sub-frame-poses`): a synthetic benchmark's diagnostic upper bound on what
/// a better in-exposure motion would give. One person only; refused, naming the field, when the
/// scene records no generator config or the exposure's poses were not prepared.
pub fn use_oracle_sub_frame_poses(
    ctx: &mut TrainingData,
    data: &train::data::Dataset,
    subframes: usize,
) -> Result<()> {
    anyhow::ensure!(
        ctx.exposure_poses.len() == ctx.frames.len(),
        "--oracle-sub-frame-poses takes the exposure model (blur_model = exposure)"
    );
    let motion = synth::generate::recorded_motion(
        &data.dir.join("scene.json"),
        data.scene.generator.as_ref(),
    )
    .context("--oracle-sub-frame-poses needs a one-person synthetic benchmark")?;
    let training = data
        .frames
        .iter()
        .filter(|f| f.split == scene::Split::Train);
    for (slot, frame) in training.enumerate() {
        let times =
            train::pose::exposure::subframe_times(frame.time_s, frame.exposure_s, subframes);
        ctx.exposure_poses[slot] = times
            .iter()
            .map(|&t| {
                let (pose, transl) = motion.at(t);
                let params = smpl_deform::SmplParams {
                    pose,
                    betas: vec![],
                    transl,
                };
                ctx.body.given(&params)
            })
            .collect::<Result<_, _>>()?;
    }
    println!("sub-exposure poses: the generator's own (a diagnostic oracle)");
    Ok(())
}
