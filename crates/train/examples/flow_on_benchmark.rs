//! Diagnostic: how well does the frozen flow network of the flow loss predict the benchmark's
//! motion? `flow_on_benchmark DIR [WEIGHTS] [TAU]` (defaults: the shipped weights, τ = 0.25 px):
//! for every frame with ground-truth flow to the next frame, the sharp and the blurred frames k and
//! k+1 are resized to 1/4 exactly as in the training step, the network predicts the flow, and the
//! end-point error against the resized ground truth is compared with the zero-flow baseline — over
//! the loss's mask M (|F| > τ, valid) and over every valid pixel. A ratio near 1 means the loss's
//! gradient carries little information about the true motion. For the sharp frames it also reports
//! the ratio over M with one pyramid level's output replaced by the resized truth pooled to that
//! level (`SpyNet::forward_with_level_flow`): how much a perfect coarse estimate would help.
//!
//! `flow_on_benchmark DIR WEIGHTS TAU RUN...` also asks which images the flow loss prefers: for each
//! reconstruction directory RUN (with its `checkpoint.safetensors`), the model renders every pair of
//! consecutive training frames the loss trains on, and the mean flow loss (the training step's masked
//! L1, without λ) of those renders is printed next to the same loss on the sharp references and on
//! the blurred input frames. A loss that scores a run's renders below the sharp truth pulls the
//! reconstruction away from it. Next to the network's loss it prints the ideal-estimator loss
//! (`train::loss::optical_flow::pair_warp_loss`: render k against render k+1 warped back by the exact flow)
//! at the loss's 1/4 resolution (τ as given) and at full resolution (τ × 4 px): whether even a
//! perfect flow estimator would prefer the sharp frames.

use nn::resize_bilinear_forward;
use std::path::{Path, PathBuf};
use train::data::{read_pair_flow, sharp_flow_pairs};
use train::loss::optical_flow::prepare_target;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let dir = PathBuf::from(
        args.first()
            .ok_or("usage: flow_on_benchmark DIR [WEIGHTS] [TAU]")?,
    );
    let weights = args.get(1).map_or_else(
        || {
            Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("../../data-fixtures/flow/spynet-synthetic.safetensors")
        },
        PathBuf::from,
    );
    let tau: f32 = args.get(2).map_or(Ok(0.25), |s| s.parse())?;
    let net = flow::load_safetensors(&weights)?;
    let data = train::data::load_dataset(&dir)?;
    let (w, h) = (data.camera.width as usize, data.camera.height as usize);
    let (wo, ho) = (w / 4, h / 4);
    // [masked net, masked zero, all net, all zero] EPE sums and counts, for sharp and blurred input.
    let mut sums = [[0.0f64; 4]; 2];
    let mut counts = [0usize; 2];
    let mut pairs = 0;
    // Sharp frames, over M: the network's EPE with level l's output replaced by the pooled truth.
    let levels = net.levels_run(ho, wo);
    let mut substituted = vec![0.0f64; levels.saturating_sub(1)];
    for pair in sharp_flow_pairs(&data, (ho, wo), tau)? {
        let (a, b) = pair.frames;
        let (sharp_a, sharp_b) = pair.sharp;
        let (target, all) = (&pair.target, &pair.all);
        for (which, (ia, ib)) in [(sharp_a, sharp_b), (&a.image, &b.image)]
            .into_iter()
            .enumerate()
        {
            let mut small = [vec![0.0f32; 3 * ho * wo], vec![0.0f32; 3 * ho * wo]];
            for (img, out) in [ia, ib].into_iter().zip(small.iter_mut()) {
                resize_bilinear_forward(3, h, w, img, ho, wo, true, out)?;
            }
            let pred = net.forward(&small[0], &small[1], ho, wo)?.flow;
            let plane = ho * wo;
            if which == 0 && ho % net.size_multiple() == 0 && wo % net.size_multiple() == 0 {
                for (level, sum) in substituted.iter_mut().enumerate() {
                    let truth = flow::train::flow_at_level(&target.flow, ho, wo, levels, level);
                    let (_, out) =
                        net.forward_with_level_flow(&small[0], &small[1], ho, wo, level, &truth)?;
                    for p in (0..plane).filter(|&p| target.mask[p]) {
                        let (gx, gy) = (target.flow[p], target.flow[plane + p]);
                        *sum += f64::from((out[p] - gx).hypot(out[plane + p] - gy));
                    }
                }
            }
            for p in 0..plane {
                let (gx, gy) = (target.flow[p] as f64, target.flow[plane + p] as f64);
                let (px, py) = (pred[p] as f64, pred[plane + p] as f64);
                let e_net = ((px - gx).powi(2) + (py - gy).powi(2)).sqrt();
                let e_zero = (gx * gx + gy * gy).sqrt();
                if target.mask[p] {
                    sums[which][0] += e_net;
                    sums[which][1] += e_zero;
                    if which == 0 {
                        counts[0] += 1;
                    }
                }
                if all.mask[p] {
                    sums[which][2] += e_net;
                    sums[which][3] += e_zero;
                    if which == 0 {
                        counts[1] += 1;
                    }
                }
            }
        }
        pairs += 1;
    }
    println!(
        "{pairs} pairs at {wo}x{ho}, tau {tau} px: {} masked pixels, {} valid pixels",
        counts[0], counts[1]
    );
    for (which, name) in ["sharp", "blurred"].iter().enumerate() {
        let s = sums[which];
        let (m, v) = (counts[0].max(1) as f64, counts[1].max(1) as f64);
        println!(
            "{name:>7} frames: EPE over M net {:.3} px vs zero {:.3} (ratio {:.3}); over all valid net {:.3} vs zero {:.3} (ratio {:.3})",
            s[0] / m,
            s[1] / m,
            s[0] / s[1].max(1e-12),
            s[2] / v,
            s[3] / v,
            s[2] / s[3].max(1e-12)
        );
    }
    for (level, sum) in substituted.iter().enumerate() {
        println!(
            "  sharp frames with level {level}'s output replaced by the pooled truth: ratio over M {:.3}",
            sum / sums[0][1].max(1e-12)
        );
    }
    if args.len() > 3 {
        compare_renders(&data, net, tau, &args[3..])?;
    }
    Ok(())
}

/// The mean flow loss over the training pairs of the sharp frames, the blurred frames and the renders
/// of each run in `runs`.
fn compare_renders(
    data: &train::data::Dataset,
    net: flow::SpyNet<f32>,
    tau: f32,
    runs: &[String],
) -> Result<(), Box<dyn std::error::Error>> {
    let body = data.body()?;
    let config = train::config::TrainConfig {
        flow_loss: true,
        flow_source: train::config::FlowSource::GroundTruth,
        flow_tau: tau,
        ..train::config::TrainConfig::default()
    };
    let mut ctx = train::data::TrainingData::new(data, body, config.seed)?;
    ctx.enable_flow(data, &config, net.clone())?;
    let (h, w) = (ctx.camera.height as usize, ctx.camera.width as usize);
    let pairs: Vec<_> = ctx
        .flow_pairs
        .iter()
        .enumerate()
        .filter_map(|(slot, p)| p.as_ref().map(|p| (slot, p)))
        .collect();
    let frame_of = |slot: usize| {
        let index = ctx.frames[slot].index;
        data.frames.iter().find(|f| f.index == index)
    };
    // Full-resolution targets for the ideal-estimator loss at scale 1 (the pairs' own are at 1/4).
    let mut full_targets = Vec::with_capacity(pairs.len());
    for &(slot, _) in &pairs {
        let k = data
            .frames
            .iter()
            .position(|f| f.index == ctx.frames[slot].index)
            .ok_or("a training frame is missing from the dataset")?;
        let pair = read_pair_flow(data, k, scene::FlowKind::GroundTruth)?
            .ok_or("a training pair has no ground-truth flow")?;
        full_targets.push(prepare_target(&pair.flow, None, h, w, h, w, 4.0 * tau)?);
    }
    // Mean over the pairs of [network loss, ideal-estimator loss at 1/4, at full resolution].
    let mean_loss = |images: &dyn Fn(usize) -> Result<Vec<f32>, Box<dyn std::error::Error>>| {
        let mut sum = [0.0f64; 3];
        for (&(slot, pair), full) in pairs.iter().zip(&full_targets) {
            let (a, b) = (images(slot)?, images(pair.next_slot)?);
            let fl = train::loss::optical_flow::pair_flow_loss(&net, &a, &b, h, w, &pair.target)?;
            let quarter = train::loss::optical_flow::pair_warp_loss(&a, &b, h, w, &pair.target)?;
            let whole = train::loss::optical_flow::pair_warp_loss(&a, &b, h, w, full)?;
            sum[0] += f64::from(fl.loss);
            sum[1] += f64::from(quarter.loss);
            sum[2] += f64::from(whole.loss);
        }
        let n = pairs.len().max(1) as f64;
        Ok::<[f64; 3], Box<dyn std::error::Error>>(sum.map(|s| s / n))
    };
    println!(
        "mean over the {} training pairs, lower = preferred: the flow loss (masked L1, tau {tau} px \
         at 1/4) and the ideal-estimator loss (render k vs render k+1 warped by the exact flow, \
         masked L1 over RGB) at 1/4 and at full resolution (tau {} px):",
        pairs.len(),
        4.0 * tau
    );
    let print = |name: &str, l: [f64; 3]| {
        println!(
            "{name:>40}: network {:.4}  warp 1/4 {:.4}  warp full {:.4}",
            l[0], l[1], l[2]
        )
    };
    let sharp = mean_loss(&|slot| {
        frame_of(slot)
            .and_then(|f| f.sharp.clone())
            .ok_or_else(|| "a training frame has no sharp reference".into())
    })?;
    print("sharp references", sharp);
    let blurred = mean_loss(&|slot| Ok(ctx.frames[slot].image.clone()))?;
    print("blurred input", blurred);
    for run in runs {
        let model = train::trainer::Trainer::load_checkpoint(
            &Path::new(run).join("checkpoint.safetensors"),
            &ctx,
        )?
        .model;
        let loss = mean_loss(&|slot| {
            let frame = &ctx.frames[slot];
            Ok(model
                .render(&ctx.camera, &frame.pose.prepared, model.latent(slot))?
                .rgb)
        })?;
        print(run, loss);
    }
    Ok(())
}
