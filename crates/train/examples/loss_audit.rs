//! Which solution does the training loss prefer? For each checkpoint, the exposure model's loss on
//! every training frame of a scene — the photometric term (L1, SSIM) of the mean of the S
//! sub-exposure renders (each modulated by its slice's events) against the blurred frame, and the
//! bound event term between consecutive renders, split by what the events of each pixel say —
//! beside how sharp the checkpoint's mid-exposure render is against the scene's sharp references.
//! Holding a sharp-trained checkpoint against a blur-trained one shows which term keeps a model
//! blurry (`docs/notes/2026-11-28-what-holds-the-blur.md`).
//!
//! ```text
//! cargo run --release -p train --example loss_audit -- [--true-poses] [--pairs P]
//!     [--refractory-us R] DATA S \
//!     [dead_zone margin] CHECKPOINT...
//! ```
//!
//! `DATA` a synthetic scene (it needs sharp references and events), `S` renders per exposure,
//! `dead_zone` and `margin` the bound penalty's z and m (default: the `quick` preset's). "Moving"
//! pixels are those where the blurred frame and its sharp reference differ by more than 0.02 in
//! some channel.

use std::path::{Path, PathBuf};
use train::config::{Preset, TrainConfig};
use train::data::edi::span_events;
use train::data::{load_dataset, Dataset, TrainingData};
use train::loss::event::{event_residual, LUMA};
use train::loss::image::ImageShape;
use train::loss::photometric::{exposure_loss, ExposureEvents, PhotometricWeights, RenderPairs};
use train::model::{PassCamera, PassPlan, RENDER_CHANNELS};
use train::pose::exposure::{subframe_times, TrackRules};
use train::trainer::Trainer;

/// PSNR (dB) of `a` against `b` over the pixels `mask` keeps (all without one); values clamped
/// to a difference of 1.
fn psnr(a: &[f32], b: &[f32], mask: Option<&[bool]>) -> f64 {
    let (mut se, mut n) = (0.0f64, 0usize);
    for (i, (x, y)) in a.iter().zip(b).enumerate() {
        if mask.is_some_and(|m| !m[i % m.len()]) {
            continue;
        }
        let d = (f64::from(*x) - f64::from(*y)).clamp(-1.0, 1.0);
        se += d * d;
        n += 1;
    }
    -10.0 * (se / n.max(1) as f64).log10()
}

/// The caps τ (log-intensity units) of the capped event term: the threshold C = 0.2 and fractions.
const CAPS: [f64; 4] = [0.4, 0.2, 0.1, 0.05];

/// Sums over the training frames, divided by their number when printed.
#[derive(Default)]
struct Audit {
    reblur_moving: f64,
    mid_vs_sharp_moving: f64,
    l1: f64,
    ssim: f64,
    photometric: f64,
    events: f64,
    /// The event term by pixel: [no events, events of one polarity and a change of their sign,
    /// of one polarity and a change of the other sign (or none), events of both polarities].
    by_pixel: [f64; 4],
    /// The share of pixel pairs in each `by_pixel` class.
    pixel_share: [f64; 4],
    /// The event term with each pixel's residual r capped: min(r², τ²) for τ in [`CAPS`].
    capped: [f64; 4],
    /// The event term on [static, moving] pixels.
    by_motion: [f64; 2],
    /// The bound event term on k×k blocks for k in [`POOLS`]: each block's mean change held to
    /// the mean of its pixels' bounds, [uncapped, capped at τ = C].
    pooled: [[f64; 2]; 3],
    /// The squared event term (mean change − mean C·E)² on 1×1 and the [`POOLS`] blocks
    /// (NaN-expected pixels left out), uncapped.
    pooled_squared: [f64; 4],
}

/// Block sides of the pooled event term.
const POOLS: [usize; 3] = [2, 4, 8];

/// The interval `[low, high]` the bound penalty holds a pixel's change to (overshoot free, so a
/// count bounds one side only); NaN-expected pixels are free.
fn bound_interval(expected: f64, c_pos: f64, c_neg: f64, margin: f64, zone: f64) -> (f64, f64) {
    if expected.is_nan() {
        (f64::NEG_INFINITY, f64::INFINITY)
    } else if expected > 0.0 {
        (expected - margin * c_pos, f64::INFINITY)
    } else if expected < 0.0 {
        (f64::NEG_INFINITY, expected + margin * c_neg)
    } else {
        (-zone * 0.5 * (c_pos + c_neg), zone * 0.5 * (c_pos + c_neg))
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let usage =
        "usage: loss_audit [--true-poses] [--pairs P] [--refractory-us R] DATA S [dead_zone margin] \
         CHECKPOINT...";
    // The generator's own sub-frame poses instead of the ones interpolated from the frames' (a
    // synthetic benchmark only): how much of the event term is the in-exposure motion's error.
    let true_poses = args.iter().any(|a| a == "--true-poses");
    args.retain(|a| a != "--true-poses");
    // `--refractory-us R`: a pixel silent between two renders that fired less than R µs before
    // the interval is free there (`reconstruct --event-refractory-us R`).
    // `--pairs all|silent-spans`: which pairs of renders the event term compares
    // (`reconstruct --exposure-pairs`; default consecutive).
    let mut pairs = RenderPairs::Consecutive;
    if let Some(at) = args.iter().position(|a| a == "--pairs") {
        let name = args.get(at + 1).map_or("", String::as_str);
        pairs = <train::config::ExposurePairs as clap::ValueEnum>::from_str(name, false)
            .map_err(|_| "--pairs takes consecutive, all or silent-spans")?
            .render_pairs();
        args.drain(at..at + 2);
    }
    let mut refractory_us = 0.0f32;
    if let Some(at) = args.iter().position(|a| a == "--refractory-us") {
        let value = args.get(at + 1).ok_or("--refractory-us needs a value")?;
        refractory_us = value.parse()?;
        args.drain(at..at + 2);
    }
    let (Some(dir), Some(s)) = (args.first(), args.get(1)) else {
        return Err(usage.into());
    };
    let subframes: usize = s.parse()?;
    let mut config = TrainConfig::preset(Preset::Quick);
    config.subframes = subframes;
    config.event_modulation = true;
    config.event_refractory_us = refractory_us;
    let mut rest = &args[2..];
    if let (Some(z), Some(m)) = (rest.first(), rest.get(1)) {
        if let (Ok(z), Ok(m)) = (z.parse(), m.parse()) {
            (config.event_dead_zone, config.event_bound_margin) = (z, m);
            rest = &rest[2..];
        }
    }
    let data = load_dataset(&PathBuf::from(dir))?;
    // The scene's defaults, as `cargo xtask reconstruct` takes them: its thresholds, and a pixel
    // with both polarities held to its net count on a sensor without a refractory period.
    if let Some(c) = data.recorded_positive("event_threshold") {
        config.event_threshold = c as f32;
    }
    config.event_threshold_neg = data
        .recorded_positive("event_threshold_neg")
        .map(|c| c as f32);
    config.event_ignore_mixed = data.recorded("refractory_us") != Some(0.0);
    let body = data.body()?;
    let mut blurred = TrainingData::new(&data, body.clone(), 0)?;
    blurred.enable_exposure(&data, subframes, TrackRules::of(&config))?;
    blurred.enable_exposure_events(&data, &config)?;
    if true_poses {
        use_true_sub_frame_poses(&data, &mut blurred, subframes)?;
    }
    let mut sharp = TrainingData::new(&data, body, 0)?;
    sharp.use_sharp_images(&data)?;
    println!(
        "{} sub-frame poses",
        if true_poses {
            "the generator's"
        } else {
            "interpolated"
        }
    );
    println!(
        "S = {subframes}, dead zone {}, margin {}, C+ {}, mixed pixels {}, silence after an event \
         within {refractory_us} µs free, pairs {pairs:?}",
        config.event_dead_zone,
        config.event_bound_margin,
        config.event_threshold,
        if config.event_ignore_mixed {
            "free"
        } else {
            "held to their counts"
        }
    );
    for checkpoint in rest {
        let audit = audit(checkpoint, &data, &blurred, &sharp, &config, pairs)?;
        let k = blurred.frames.len() as f64;
        let p = audit.by_pixel.map(|v| v / k);
        let q = audit.pixel_share.map(|v| 100.0 * v / k);
        println!(
            "{checkpoint}: reblur moving {:.2} dB, mid vs sharp moving {:.2} dB | L1 {:.6} SSIM \
             {:.6} photometric {:.6} events {:.6} total {:.6}",
            audit.reblur_moving / k,
            audit.mid_vs_sharp_moving / k,
            audit.l1 / k,
            audit.ssim / k,
            audit.photometric / k,
            audit.events / k,
            (audit.photometric + audit.events) / k
        );
        println!(
            "  events by pixel (share of pixel pairs): none {:.6} ({:.1} %) | one polarity, a \
             change of its sign {:.6} ({:.1} %) | one polarity, the other sign {:.6} ({:.1} %) | \
             both polarities {:.6} ({:.1} %) | static {:.6}, moving {:.6}",
            p[0],
            q[0],
            p[1],
            q[1],
            p[2],
            q[2],
            p[3],
            q[3],
            audit.by_motion[0] / k,
            audit.by_motion[1] / k
        );
        let pooled = audit.pooled.map(|v| v.map(|x| x / k));
        println!("  events pooled on {POOLS:?} blocks [uncapped, capped at C]: {pooled:.6?}");
        let sq = audit.pooled_squared.map(|v| v / k);
        println!("  squared event term on 1, {POOLS:?} blocks: {sq:.6?}");
        let capped = audit.capped.map(|v| v / k);
        println!(
            "  events with r capped at {CAPS:?}: {capped:.6?}; without the pixels of both \
             polarities {:.6}",
            (audit.events - audit.by_pixel[3]) / k
        );
    }
    Ok(())
}

/// Replaces the sub-exposure poses of every training frame by the generator's own poses at those
/// times (the scene's `generator.config` read as the synthetic benchmark's settings).
fn use_true_sub_frame_poses(
    data: &Dataset,
    blurred: &mut TrainingData,
    subframes: usize,
) -> Result<(), Box<dyn std::error::Error>> {
    let motion = synth::generate::recorded_motion(
        &data.dir.join("scene.json"),
        data.scene.generator.as_ref(),
    )?;
    let training = data
        .frames
        .iter()
        .filter(|f| f.split == scene::Split::Train);
    for (slot, frame) in training.enumerate() {
        let times = subframe_times(frame.time_s, frame.exposure_s, subframes);
        blurred.exposure_poses[slot] = times
            .iter()
            .map(|&t| {
                let (pose, transl) = motion.at(t);
                let params = smpl_deform::SmplParams {
                    pose,
                    betas: vec![],
                    transl,
                };
                blurred.body.given(&params)
            })
            .collect::<Result<_, _>>()?;
    }
    Ok(())
}

/// The audit of one checkpoint over every training frame.
fn audit(
    checkpoint: &str,
    data: &Dataset,
    blurred: &TrainingData,
    sharp: &TrainingData,
    config: &TrainConfig,
    pairs: RenderPairs,
) -> Result<Audit, Box<dyn std::error::Error>> {
    let (h, w) = (data.camera.height as usize, data.camera.width as usize);
    let sensor = events::SensorSize::new(data.camera.width, data.camera.height);
    let training: Vec<usize> = (0..data.frames.len())
        .filter(|&p| data.frames[p].split == scene::Split::Train)
        .collect();
    let trainer = Trainer::load_checkpoint(Path::new(checkpoint), blurred)?;
    let model = &trainer.model;
    let hw = h * w;
    let mut a = Audit::default();
    let penalty = config.event_penalty();
    let eps = f64::from(config.event_log_eps);
    for slot in 0..blurred.frames.len() {
        let poses: Vec<_> = blurred
            .poses(slot, true)?
            .iter()
            .map(|p| &p.prepared)
            .collect();
        let cameras: Vec<_> = blurred
            .cameras(slot, true)?
            .into_iter()
            .map(PassCamera::of)
            .collect();
        let plan = PassPlan {
            reposed: true,
            share_static_tiles: false,
            joint_backward_only: false,
            static_layer: false,
            smear: config.exposure_smear,
        };
        let passes =
            model.forward_passes(&cameras, &poses, poses.len() / 2, model.latent(slot), plan)?;
        let renders: Vec<&[f32]> = passes.passes.iter().map(|p| p.rgb()).collect();
        let image = &blurred.frames[slot].image;
        let reference = &sharp.frames[slot].image;
        let counts = blurred.exposure_event_counts(slot)?;
        let events = ExposureEvents {
            expected: counts,
            weight: 1.0,
            penalty,
            log_eps: config.event_log_eps,
            pairs,
            pool: 1,
            reach: 0,
            modulation: blurred.exposure_modulation(slot)?,
        };
        let shape = ImageShape {
            channels: 3,
            height: h,
            width: w,
        };
        let out = exposure_loss(
            &renders,
            image,
            shape,
            PhotometricWeights {
                ssim: config.ssim_weight,
                image_gradient: config.image_gradient_weight,
            },
            Some(events),
            RENDER_CHANNELS,
            false,
        );
        let moving: Vec<bool> = (0..hw)
            .map(|i| (0..3).any(|c| (image[c * hw + i] - reference[c * hw + i]).abs() > 0.02))
            .collect();
        a.reblur_moving += psnr(&out.prediction, image, Some(&moving));
        let frame = &blurred.frames[slot];
        let mid = model.forward(&frame.camera, &frame.pose.prepared, model.latent(slot))?;
        a.mid_vs_sharp_moving += psnr(mid.rgb(), reference, Some(&moving));
        a.l1 += f64::from(out.l1);
        a.ssim += f64::from(out.ssim);
        a.photometric += f64::from(out.photometric);
        a.events += f64::from(out.events);
        // Each pixel's positive and negative events between consecutive sub-exposure times.
        let source = &data.frames[training[slot]];
        let times = subframe_times(source.time_s, source.exposure_s, config.subframes);
        let us = |t: f64| (t * 1e6).round() as i64;
        let stream = span_events(
            data,
            training[slot],
            times[0],
            times[times.len() - 1],
            "audit",
        )?;
        let luma = |im: &[f32], i: usize| {
            (0..3)
                .map(|c| LUMA[c] * f64::from(im[c * hw + i]))
                .sum::<f64>()
                .max(0.0)
        };
        for (pair, count) in counts.iter().enumerate() {
            let (Some(count), Some(stream)) = (count, &stream) else {
                continue;
            };
            let window = stream.window(us(times[pair]), us(times[pair + 1]));
            let two = events::count_frame(&window, sensor, events::CountMode::TwoChannel);
            let (first, second) = (renders[pair], renders[pair + 1]);
            let mut intervals = Vec::with_capacity(hw);
            for i in 0..hw {
                let (ya, yb) = (luma(first, i), luma(second, i));
                let change = (yb + eps).ln() - (ya + eps).ln();
                let (low, high) = bound_interval(
                    f64::from(count[i]),
                    f64::from(config.event_threshold),
                    f64::from(config.event_threshold_neg.unwrap_or(config.event_threshold)),
                    f64::from(config.event_bound_margin),
                    f64::from(config.event_dead_zone),
                );
                intervals.push((change, low, high));
            }
            for (sq, k) in a
                .pooled_squared
                .iter_mut()
                .zip([1].into_iter().chain(POOLS))
            {
                for by in (0..h).step_by(k) {
                    for bx in (0..w).step_by(k) {
                        let (mut d, mut m) = (0.0, 0.0);
                        for y in by..(by + k).min(h) {
                            for x in bx..(bx + k).min(w) {
                                let e = f64::from(count[y * w + x]);
                                if e.is_nan() {
                                    continue;
                                }
                                d += intervals[y * w + x].0 - e;
                                m += 1.0;
                            }
                        }
                        if m > 0.0 {
                            *sq += d * d / m / hw as f64;
                        }
                    }
                }
            }
            let tau = f64::from(config.event_threshold);
            for (pooled, k) in a.pooled.iter_mut().zip(POOLS) {
                for by in (0..h).step_by(k) {
                    for bx in (0..w).step_by(k) {
                        let (mut c, mut lo, mut hi, mut m) = (0.0, 0.0, 0.0, 0.0);
                        for y in by..(by + k).min(h) {
                            for x in bx..(bx + k).min(w) {
                                let (ci, li, hi_) = intervals[y * w + x];
                                c += ci;
                                lo += li;
                                hi += hi_;
                                m += 1.0;
                            }
                        }
                        let (c, lo, hi) = (c / m, lo / m, hi / m);
                        let r = if c < lo {
                            c - lo
                        } else if c > hi {
                            c - hi
                        } else {
                            0.0
                        };
                        pooled[0] += m * r * r / hw as f64;
                        pooled[1] += m * (r * r).min(tau * tau) / hw as f64;
                    }
                }
            }
            for i in 0..hw {
                let (ya, yb) = (luma(first, i), luma(second, i));
                let change = (yb + eps).ln() - (ya + eps).ln();
                let expected = f64::from(count[i]);
                let (r, weight) = event_residual(change, expected, penalty);
                let cost = weight * r * r / hw as f64;
                let (pos, neg) = (two[i], two[hw + i]);
                let kind = if pos > 0.0 && neg > 0.0 {
                    3
                } else if pos + neg == 0.0 {
                    0
                } else if (expected > 0.0) == (change > 0.0) {
                    1
                } else {
                    2
                };
                a.by_pixel[kind] += cost;
                for (c, tau) in a.capped.iter_mut().zip(CAPS) {
                    *c += weight * (r * r).min(tau * tau) / hw as f64;
                }
                a.pixel_share[kind] += 1.0 / ((renders.len() - 1) * hw) as f64;
                a.by_motion[usize::from(moving[i])] += cost;
            }
        }
    }
    Ok(a)
}
