//! `cargo xtask train-flow`: trains SPyNet-style weights on procedural FlyingChairs-style pairs and
//! writes them; deterministic from the seed. Two phases:
//!
//! 1. **Pre-training** of a single level on small pairs of pure background translation (no
//!    brightness jitter, textures resolved at that size) with a squared-error loss, from the
//!    motion-aware initialisation ([`flow::SpyNet::random_init`]). This is the phase that leaves the
//!    zero-flow plateau every earlier recipe stayed on (`docs/notes/benchmarks-history.md`, flow, "Leaving the plateau").
//! 2. The pre-trained level copied into every level ([`flow::train::replicate_level`]) and each level
//!    fine-tuned coarse to fine on the full generator at `--size` (lower levels frozen).
//! 3. `--joint-steps`: all levels trained together on a multi-scale loss
//!    ([`flow::train::Trainer::step_joint`]), gradients flowing through the whole pyramid; the
//!    weights are validated every `--report-every` steps and the best ones kept.
//!
//! With `--scene-pairs`, frame pairs rendered by the synthetic benchmark's generator (other seeds
//! than the benchmark's; `data-fixtures/flow/make-scene-pairs.sh`) are mixed into the procedural
//! pairs, their static pixels down-weighted (`--scene-static-weight`), and `--scene-validation`
//! scenes replace the procedural validation pairs with the EPE over moving pixels — the flow loss's
//! mask.
//!
//! Reports the held-out EPE against the zero-flow baseline; the weights are written after every
//! phase and level, so a stopped run leaves its latest weights behind.

use anyhow::{Context, Result};
use flow::synthetic::PairConfig;
use flow::train::{
    evaluate, evaluate_pairs, replicate_level, ExtraPairs, Optimizer, TrainConfig, Trainer,
};
use std::path::{Path, PathBuf};

/// Optimiser choice on the command line.
#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum OptimizerArg {
    /// Adam (PyTorch defaults apart from the learning rate).
    Adam,
    /// SGD with momentum `--momentum`.
    Sgd,
}

/// Arguments of `train-flow`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Output weights (safetensors).
    #[arg(
        long,
        default_value = "data-fixtures/flow/spynet-synthetic.safetensors"
    )]
    pub out: PathBuf,
    /// Pyramid levels.
    #[arg(long, default_value_t = 4)]
    pub levels: usize,
    /// Training and evaluation image side of the fine-tuning phase (pixels; a multiple of
    /// 2^(levels-1)).
    #[arg(long, default_value_t = 64)]
    pub size: usize,
    /// Pre-training steps of the single level (0 = no pre-training: a fresh network is trained
    /// level by level, the original recipe).
    #[arg(long, default_value_t = 3000)]
    pub pretrain_steps: usize,
    /// Image side of the pre-training pairs (pixels).
    #[arg(long, default_value_t = 16)]
    pub pretrain_size: usize,
    /// Largest background translation of the pre-training pairs, as a fraction of their size.
    #[arg(long, default_value_t = 0.06)]
    pub pretrain_max_translation: f32,
    /// Pairs per pre-training step.
    #[arg(long, default_value_t = 8)]
    pub pretrain_batch: usize,
    /// Peak learning rate of the pre-training.
    #[arg(long, default_value_t = 2e-4)]
    pub pretrain_lr: f64,
    /// Fine-tuning steps per level, coarsest first (comma separated; one value = same for all).
    #[arg(long, value_delimiter = ',', default_value = "300,200,80,20")]
    pub steps: Vec<usize>,
    /// Pairs per fine-tuning step.
    #[arg(long, default_value_t = 4)]
    pub batch: usize,
    /// Peak learning rate of the fine-tuning.
    #[arg(long, default_value_t = 1e-4)]
    pub lr: f64,
    /// Optimiser of both phases.
    #[arg(long, value_enum, default_value_t = OptimizerArg::Adam)]
    pub optimizer: OptimizerArg,
    /// Momentum of `--optimizer sgd`.
    #[arg(long, default_value_t = 0.9)]
    pub momentum: f64,
    /// Linear learning-rate warm-up steps at the start of every phase and level.
    #[arg(long, default_value_t = 20)]
    pub warmup_steps: usize,
    /// Steps trained on the squared end-point error before switching to the end-point error, per
    /// phase and level (default: squared error throughout).
    #[arg(long, default_value_t = usize::MAX)]
    pub mse_steps: usize,
    /// Scale of the output convolution's initial weights relative to He-uniform (0 = zero).
    #[arg(long, default_value_t = 0.0)]
    pub output_init_gain: f64,
    /// Use independent random first-layer weights instead of the motion-aware initialisation.
    #[arg(long)]
    pub plain_init: bool,
    /// Seed of the initial weights and training pairs.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Seed of the held-out evaluation pairs.
    #[arg(long, default_value_t = 1_000_003)]
    pub eval_seed: u64,
    /// Number of held-out evaluation pairs.
    #[arg(long, default_value_t = 40)]
    pub eval_pairs: u64,
    /// Print the pre-training's held-out ratio every this many steps (0 = never).
    #[arg(long, default_value_t = 250)]
    pub report_every: usize,
    /// Validation pairs (seed `--eval-seed + 1`, disjoint from the held-out set) on which each
    /// fine-tuned level must beat its pre-fine-tuning weights to be kept, and each joint-phase report
    /// the best weights so far (0 = always keep the latest).
    #[arg(long, default_value_t = 10)]
    pub validation_pairs: u64,
    /// Continue from existing weights instead of a fresh initialisation (skips the pre-training).
    #[arg(long)]
    pub init: Option<PathBuf>,
    /// Steps of joint multi-scale training of all levels after the per-level fine-tuning.
    #[arg(long, default_value_t = 0)]
    pub joint_steps: usize,
    /// Pairs per joint step (run in parallel over the threads).
    #[arg(long, default_value_t = 8)]
    pub joint_batch: usize,
    /// Peak learning rate of the joint phase.
    #[arg(long, default_value_t = 5e-5)]
    pub joint_lr: f64,
    /// Decay the joint phase's learning rate from the peak to zero along a cosine over
    /// `--joint-steps` (default: constant after the warm-up).
    #[arg(long)]
    pub joint_cosine: bool,
    /// Probability that a fine-tuning or joint training pair has a static background (only the
    /// foreground layers move, as with the synthetic benchmark's fixed camera). The held-out
    /// figures are reported on the default generator (moving background) and with this setting.
    #[arg(long, default_value_t = 0.0)]
    pub static_background: f32,
    /// Scene directories (the synthetic benchmark's format, with ground-truth flow) whose
    /// consecutive frame pairs, sharp and blurred, resized to `--size` exactly as the flow loss
    /// resizes renders, are mixed into the training pairs (comma separated or repeated). Make them
    /// with `cargo xtask synth` and seeds other than the benchmark's, so it stays held out.
    #[arg(long, value_delimiter = ',')]
    pub scene_pairs: Vec<PathBuf>,
    /// Probability that a training pair is one of the `--scene-pairs` (mirrored left-right half of
    /// the time) rather than a procedural pair.
    #[arg(long, default_value_t = 0.5)]
    pub scene_fraction: f32,
    /// Scene directories whose pairs replace the procedural validation pairs (joint phase and
    /// per-level fine-tuning), and on which the final EPE is also reported.
    #[arg(long, value_delimiter = ',')]
    pub scene_validation: Vec<PathBuf>,
    /// Loss weight of a scene pair's static pixels (flow at most `--scene-tau`) relative to its
    /// moving pixels. The benchmark's person covers about a tenth of the frame, so with a weight
    /// of 1 the static room dominates the loss and pulls the prediction towards zero motion; the
    /// flow loss only supervises moving pixels.
    #[arg(long, default_value_t = 0.1)]
    pub scene_static_weight: f32,
    /// Motion threshold (pixels at `--size`) that separates a scene pair's moving pixels from its
    /// static ones; the flow loss's default τ.
    #[arg(long, default_value_t = 0.25)]
    pub scene_tau: f32,
}

/// How a scene pair's pixels are weighted in the loss.
#[derive(Clone, Copy, Debug)]
struct SceneWeights {
    /// Motion threshold (pixels at the resized scale).
    tau: f32,
    /// Weight of pixels moving by at most `tau` (moving pixels weigh 1).
    static_weight: f32,
    /// Give pixels whose flow is invalid (occluded at the next frame) weight 0.
    valid_only: bool,
}

/// Consecutive frame pairs of a scene with ground-truth flow, resized to `size × size` as the
/// flow loss resizes renders (bilinear, `align_corners = true`; flow vectors scaled alike): one
/// pair of sharp frames (when the scene has them) and one of blurred frames per flow file.
fn load_scene_pairs(
    dir: &Path,
    size: usize,
    weights: SceneWeights,
) -> Result<Vec<flow::synthetic::Pair>> {
    let data = train::data::load_dataset(dir)
        .with_context(|| format!("loading the scene {}", dir.display()))?;
    let (w, h) = (data.camera.width as usize, data.camera.height as usize);
    if w != h {
        anyhow::bail!(
            "{}: the camera is {w}x{h}; --scene-pairs needs square frames",
            dir.display()
        );
    }
    let resize = |img: &[f32]| -> Result<Vec<f32>> {
        let mut out = vec![0.0f32; 3 * size * size];
        nn::resize_bilinear_forward(3, h, w, img, size, size, true, &mut out)?;
        Ok(out)
    };
    let mut pairs = Vec::new();
    for k in 0..data.frames.len().saturating_sub(1) {
        let Some(pair) = train::data::read_pair_flow(&data, k, scene::FlowKind::GroundTruth)
            .with_context(|| format!("{}: frame {k}'s flow", dir.display()))?
        else {
            continue;
        };
        let (a, b) = (&data.frames[k], &data.frames[k + 1]);
        let valid = pair.valid.filter(|_| weights.valid_only);
        let target = train::loss::optical_flow::prepare_target(
            &pair.flow,
            valid.as_deref(),
            h,
            w,
            size,
            size,
            weights.tau,
        )?;
        // Training pairs: moving pixels 1 (occluded ones too: their geometric flow is still the
        // truth), static pixels `static_weight`. Validation pairs: the flow loss's mask M.
        let plane = size * size;
        let weight: Vec<f32> = (0..plane)
            .map(|p| {
                if target.mask[p] {
                    1.0
                } else if weights.valid_only {
                    0.0
                } else {
                    weights.static_weight
                }
            })
            .collect();
        if weight.iter().all(|&v| v == 0.0) {
            continue;
        }
        let flow = target.flow;
        let mut images = vec![(&a.image, &b.image)];
        if let (Some(sa), Some(sb)) = (&a.sharp, &b.sharp) {
            images.push((sa, sb));
        }
        for (ia, ib) in images {
            pairs.push(flow::synthetic::Pair {
                height: size,
                width: size,
                img1: resize(ia)?,
                img2: resize(ib)?,
                flow: flow.clone(),
                weight: Some(weight.clone()),
            });
        }
    }
    if pairs.is_empty() {
        anyhow::bail!(
            "{}: no frame has ground-truth flow to a next frame",
            dir.display()
        );
    }
    Ok(pairs)
}

/// The pairs of every scene in `dirs`, in order.
fn load_all_scene_pairs(
    dirs: &[PathBuf],
    size: usize,
    weights: SceneWeights,
) -> Result<Vec<flow::synthetic::Pair>> {
    let mut all = Vec::new();
    for d in dirs {
        all.extend(load_scene_pairs(d, size, weights)?);
    }
    Ok(all)
}

fn save(net: &flow::SpyNet<f32>, out: &Path) -> Result<()> {
    if let Some(dir) = out.parent() {
        if !dir.as_os_str().is_empty() {
            std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        }
    }
    // Atomically (`save_safetensors` writes a temporary file and renames it): the joint phase
    // rewrites the file at every new best, and a run stopped mid-write must leave the previous
    // weights intact.
    flow::save_safetensors(net, out).with_context(|| format!("writing {}", out.display()))
}

/// Appends `value` to the window `recent`, keeps its last `len` values and returns their mean.
fn running_mean(recent: &mut Vec<f64>, value: f64, len: usize) -> f64 {
    recent.push(value);
    if recent.len() > len {
        recent.remove(0);
    }
    recent.iter().sum::<f64>() / recent.len() as f64
}

/// Runs the command.
pub fn run(args: Args) -> Result<()> {
    let optimizer = match args.optimizer {
        OptimizerArg::Adam => Optimizer::Adam,
        OptimizerArg::Sgd => Optimizer::Sgd {
            momentum: args.momentum,
        },
    };
    let held_out = PairConfig {
        size: args.size,
        ..PairConfig::default()
    };
    let pairs = PairConfig {
        static_background: args.static_background,
        ..held_out
    };
    if !(args.scene_static_weight >= 0.0 && args.scene_static_weight.is_finite()) {
        anyhow::bail!(
            "--scene-static-weight {} must be finite and non-negative",
            args.scene_static_weight
        );
    }
    if !(0.0..=1.0).contains(&args.scene_fraction) {
        anyhow::bail!("--scene-fraction {} is not in [0, 1]", args.scene_fraction);
    }
    let extra_pairs = if args.scene_pairs.is_empty() {
        None
    } else {
        let weights = SceneWeights {
            tau: args.scene_tau,
            static_weight: args.scene_static_weight,
            valid_only: false,
        };
        let pairs = load_all_scene_pairs(&args.scene_pairs, args.size, weights)?;
        eprintln!(
            "{} scene pairs from {} scenes, drawn with probability {}",
            pairs.len(),
            args.scene_pairs.len(),
            args.scene_fraction
        );
        Some(ExtraPairs {
            pairs: std::sync::Arc::new(pairs),
            fraction: args.scene_fraction,
        })
    };
    // Validation over the moving, valid pixels only: the flow loss's mask M.
    let validation_weights = SceneWeights {
        tau: args.scene_tau,
        static_weight: 0.0,
        valid_only: true,
    };
    let scene_validation =
        load_all_scene_pairs(&args.scene_validation, args.size, validation_weights)?;
    let config = |levels: usize, pairs: PairConfig, batch: usize, lr: f64| TrainConfig {
        levels,
        pairs,
        batch,
        lr,
        optimizer,
        warmup_steps: args.warmup_steps,
        mse_steps: args.mse_steps,
        output_init_gain: args.output_init_gain,
        paired_input_init: !args.plain_init,
        seed: args.seed,
        distinct_pairs: None,
        decay_steps: 0,
        extra_pairs: extra_pairs.clone(),
    };
    let start = std::time::Instant::now();
    let log = |bar: &indicatif::ProgressBar, line: String| bar.suspend(|| eprintln!("{line}"));
    let net = match &args.init {
        Some(p) => {
            let net =
                flow::load_safetensors(p).with_context(|| format!("loading {}", p.display()))?;
            if net.num_levels() != args.levels {
                anyhow::bail!(
                    "--init {} has {} pyramid levels but --levels is {}",
                    p.display(),
                    net.num_levels(),
                    args.levels
                );
            }
            net
        }
        None if args.pretrain_steps > 0 => {
            let pre = PairConfig {
                size: args.pretrain_size,
                max_translation: args.pretrain_max_translation,
                max_rotation: 0.0,
                max_scale: 0.0,
                max_foreground_layers: 0,
                brightness_jitter: 0.0,
                ..PairConfig::default()
            };
            let mut t = Trainer::new(config(1, pre, args.pretrain_batch, args.pretrain_lr));
            let bar = crate::common::progress_bar(args.pretrain_steps as u64, "pretrain")?;
            let mut recent = Vec::new();
            for s in 0..args.pretrain_steps {
                let r = t.step_report(0)?;
                let mean = running_mean(&mut recent, r.epe, 50);
                bar.set_message(format!("pre-training epe {mean:.3}"));
                bar.inc(1);
                if args.report_every > 0 && (s + 1) % args.report_every == 0 {
                    let (e, z) = evaluate(&t.net, args.eval_seed, 20, &pre)?;
                    let live: Vec<String> = r.live_relu.iter().map(|v| format!("{v:.2}")).collect();
                    log(
                        &bar,
                        format!(
                            "pre-training step {}: last-50 EPE {mean:.3}, held-out {e:.3} / zero {z:.3} = {:.3}, live ReLUs [{}], {:.0} s",
                            s + 1,
                            e / z,
                            live.join(" "),
                            start.elapsed().as_secs_f64()
                        ),
                    );
                    save(&replicate_level(&t.net, 0, args.levels), &args.out)?;
                }
            }
            bar.finish_and_clear();
            let net = replicate_level(&t.net, 0, args.levels);
            save(&net, &args.out)?;
            net
        }
        None => flow::SpyNet::random_init(
            args.levels,
            args.seed,
            args.output_init_gain,
            !args.plain_init,
        ),
    };
    let pretrain_s = start.elapsed().as_secs_f64();
    let mut trainer = Trainer::from_net(net, config(args.levels, pairs, args.batch, args.lr));
    let steps: Vec<usize> = (0..args.levels)
        .map(|l| *args.steps.get(l).or(args.steps.last()).unwrap_or(&0))
        .collect();
    let bar = crate::common::progress_bar(steps.iter().sum::<usize>() as u64, "train")?;
    let validation = |net: &flow::SpyNet<f32>| -> Result<f64> {
        if scene_validation.is_empty() {
            Ok(evaluate(net, args.eval_seed + 1, args.validation_pairs, &pairs)?.0)
        } else {
            Ok(evaluate_pairs(net, &scene_validation)?.0)
        }
    };
    for (level, &n) in steps.iter().enumerate() {
        let before = (n > 0 && args.validation_pairs > 0)
            .then(|| {
                Ok::<_, anyhow::Error>((
                    trainer.net.levels[level].clone(),
                    validation(&trainer.net)?,
                ))
            })
            .transpose()?;
        let mut recent = Vec::new();
        for _ in 0..n {
            let epe = trainer.step(level)?;
            let mean = running_mean(&mut recent, epe, 20);
            bar.set_message(format!("level {level} epe {mean:.3}"));
            bar.inc(1);
        }
        if n > 0 {
            let mut verdict = String::new();
            if let Some((old, old_epe)) = before {
                let new_epe = validation(&trainer.net)?;
                verdict = format!(", validation EPE {old_epe:.3} -> {new_epe:.3} px");
                if new_epe >= old_epe {
                    trainer.net.levels[level] = old;
                    verdict += " (fine-tuning discarded)";
                }
            }
            save(&trainer.net, &args.out)?;
            log(
                &bar,
                format!(
                    "level {level}: {n} steps, last-20 mean EPE {:.3} (level pixels){verdict}, {:.0} s",
                    recent.iter().sum::<f64>() / recent.len().max(1) as f64,
                    start.elapsed().as_secs_f64()
                ),
            );
        }
    }
    bar.finish();
    if args.joint_steps > 0 {
        let decay_steps = if args.joint_cosine {
            args.joint_steps
        } else {
            0
        };
        let mut joint = Trainer::from_net(
            trainer.net.clone(),
            TrainConfig {
                decay_steps,
                ..config(args.levels, pairs, args.joint_batch, args.joint_lr)
            },
        );
        let bar = crate::common::progress_bar(args.joint_steps as u64, "joint")?;
        let mut best = validation(&joint.net)?;
        log(
            &bar,
            format!("joint phase: validation EPE {best:.3} px at the start"),
        );
        let mut recent = Vec::new();
        for s in 0..args.joint_steps {
            let r = joint.step_joint()?;
            let mean = running_mean(&mut recent, r.epe, 50);
            bar.set_message(format!("joint epe {mean:.3}"));
            bar.inc(1);
            let last = s + 1 == args.joint_steps;
            if (args.report_every > 0 && (s + 1) % args.report_every == 0) || last {
                // Without validation pairs every report keeps the latest weights.
                let v = validation(&joint.net)?;
                let kept = args.validation_pairs == 0 || v < best;
                if kept {
                    best = v;
                    trainer.net = joint.net.clone();
                    save(&trainer.net, &args.out)?;
                }
                log(
                    &bar,
                    format!(
                        "joint step {}: last-50 EPE {mean:.3}, validation {v:.3} px{}, {:.0} s",
                        s + 1,
                        if kept { " (best, saved)" } else { "" },
                        start.elapsed().as_secs_f64()
                    ),
                );
            }
        }
        bar.finish();
    }
    let train_s = start.elapsed().as_secs_f64();
    save(&trainer.net, &args.out)?;
    let (epe, zero) = evaluate(&trainer.net, args.eval_seed, args.eval_pairs, &held_out)?;
    let (epe_st, zero_st) = evaluate(&trainer.net, args.eval_seed, args.eval_pairs, &pairs)?;
    let still = PairConfig {
        brightness_jitter: 0.0,
        ..held_out
    };
    let (epe_nj, zero_nj) = evaluate(&trainer.net, args.eval_seed, args.eval_pairs, &still)?;
    // `null` in the report without `--scene-validation` (rather than a meaningless 0).
    let (epe_sv, zero_sv) = if scene_validation.is_empty() {
        (None, None)
    } else {
        let (e, z) = evaluate_pairs(&trainer.net, &scene_validation)?;
        (Some(e), Some(z))
    };
    let ratio_sv = epe_sv.zip(zero_sv).map(|(e, z)| e / z.max(1e-12));
    println!(
        "{}",
        serde_json::json!({
            "weights": args.out.display().to_string(), "levels": args.levels, "size": args.size,
            "pretrain_steps": args.pretrain_steps, "pretrain_size": args.pretrain_size,
            "pretrain_batch": args.pretrain_batch, "pretrain_lr": args.pretrain_lr,
            "steps": steps, "batch": args.batch, "lr": args.lr, "seed": args.seed,
            "pretrain_seconds": pretrain_s, "train_seconds": train_s,
            "eval_seed": args.eval_seed, "eval_pairs": args.eval_pairs,
            "epe": epe, "zero_flow_epe": zero, "ratio": epe / zero,
            "no_jitter_epe": epe_nj, "no_jitter_zero_flow_epe": zero_nj,
            "no_jitter_ratio": epe_nj / zero_nj,
            "joint_steps": args.joint_steps, "joint_batch": args.joint_batch,
            "joint_lr": args.joint_lr, "joint_cosine": args.joint_cosine, "static_background": args.static_background,
            "training_distribution_epe": epe_st, "training_distribution_zero_flow_epe": zero_st,
            "training_distribution_ratio": epe_st / zero_st,
            "scene_pairs": args.scene_pairs, "scene_fraction": args.scene_fraction,
            "scene_validation": args.scene_validation,
            "scene_validation_pairs": scene_validation.len(),
            "scene_validation_epe": epe_sv, "scene_validation_zero_flow_epe": zero_sv,
            "scene_validation_ratio": ratio_sv,
            "scene_static_weight": args.scene_static_weight, "scene_tau": args.scene_tau,
        })
    );
    Ok(())
}
