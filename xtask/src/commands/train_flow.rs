//! `cargo xtask train-flow`: trains SPyNet-style weights on procedural FlyingChairs-style pairs by
//! the recipe of `flow::train::recipe` (pre-training of one level, fine-tuning level by level,
//! joint training), deterministic from the seed, and writes them. The history of the recipe is in
//! `docs/notes/benchmarks-history.md` (flow, "Leaving the plateau").
//!
//! With `--scene-pairs`, frame pairs rendered by the synthetic benchmark's generator (other seeds
//! than the benchmark's; `data-fixtures/flow/make-scene-pairs.sh`) are mixed into the procedural
//! pairs, their static pixels down-weighted (`--scene-static-weight`), and `--scene-validation`
//! scenes replace the procedural validation pairs with the EPE over moving pixels — the flow loss's
//! mask. Loading them needs the scene format, which is why that part lives here.
//!
//! Reports the held-out EPE against the zero-flow baseline; the best weights are written as they
//! come, so a stopped run leaves its latest weights behind.

use anyhow::{Context, Result};
use flow::synthetic::PairConfig;
use flow::train::recipe::{JointPhase, Pretraining, Recipe, RecipeObserver};
use flow::train::{evaluate, evaluate_pairs, ExtraPairs, Optimizer};
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

/// Shows a run of the recipe: a progress bar per phase, report lines above it, the best weights
/// written to `out` as they come.
struct Console<'a> {
    out: &'a Path,
    bar: Option<indicatif::ProgressBar>,
    started: std::time::Instant,
    /// Seconds from the start to the end of the pre-training (the first fine-tuning step).
    pretrain_seconds: f64,
}

impl RecipeObserver for Console<'_> {
    type Error = anyhow::Error;

    fn phase_started(&mut self, phase: &'static str, steps: u64) -> Result<()> {
        if phase == "train" {
            self.pretrain_seconds = self.started.elapsed().as_secs_f64();
        }
        self.bar = Some(crate::common::progress_bar(steps, phase)?);
        Ok(())
    }

    fn stepped(&mut self, status: String) {
        if let Some(bar) = &self.bar {
            bar.set_message(status);
            bar.inc(1);
        }
    }

    fn phase_finished(&mut self, phase: &'static str) {
        match self.bar.take() {
            Some(bar) if phase == "pretrain" => bar.finish_and_clear(),
            Some(bar) => bar.finish(),
            None => {}
        }
    }

    fn report(&mut self, line: String) {
        match &self.bar {
            Some(bar) => bar.suspend(|| eprintln!("{line}")),
            None => eprintln!("{line}"),
        }
    }

    fn weights(&mut self, net: &flow::SpyNet<f32>) -> Result<()> {
        save(net, self.out)
    }
}

/// The recipe the arguments describe, with its scene pairs loaded.
fn recipe_of(args: &Args) -> Result<Recipe> {
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
    Ok(Recipe {
        levels: args.levels,
        size: args.size,
        pretraining: Pretraining {
            steps: args.pretrain_steps,
            size: args.pretrain_size,
            max_translation: args.pretrain_max_translation,
            batch: args.pretrain_batch,
            lr: args.pretrain_lr,
        },
        level_steps: (0..args.levels)
            .map(|l| *args.steps.get(l).or(args.steps.last()).unwrap_or(&0))
            .collect(),
        batch: args.batch,
        lr: args.lr,
        joint: JointPhase {
            steps: args.joint_steps,
            batch: args.joint_batch,
            lr: args.joint_lr,
            cosine: args.joint_cosine,
        },
        optimizer: match args.optimizer {
            OptimizerArg::Adam => Optimizer::Adam,
            OptimizerArg::Sgd => Optimizer::Sgd {
                momentum: args.momentum,
            },
        },
        warmup_steps: args.warmup_steps,
        mse_steps: args.mse_steps,
        output_init_gain: args.output_init_gain,
        paired_input_init: !args.plain_init,
        seed: args.seed,
        static_background: args.static_background,
        extra_pairs,
        report_every: args.report_every,
        eval_seed: args.eval_seed,
        validation_pairs: args.validation_pairs,
        validation_set: load_all_scene_pairs(
            &args.scene_validation,
            args.size,
            validation_weights,
        )?,
    })
}

/// The weights `--init` names, checked against `--levels`.
fn initial_weights(args: &Args) -> Result<Option<flow::SpyNet<f32>>> {
    let Some(p) = &args.init else {
        return Ok(None);
    };
    let net = flow::load_safetensors(p).with_context(|| format!("loading {}", p.display()))?;
    if net.num_levels() != args.levels {
        anyhow::bail!(
            "--init {} has {} pyramid levels but --levels is {}",
            p.display(),
            net.num_levels(),
            args.levels
        );
    }
    Ok(Some(net))
}

/// Runs the command.
pub fn run(args: Args) -> Result<()> {
    let recipe = recipe_of(&args)?;
    let init = initial_weights(&args)?;
    let mut console = Console {
        out: &args.out,
        bar: None,
        started: std::time::Instant::now(),
        pretrain_seconds: 0.0,
    };
    let net = recipe.run(init, &mut console)?;
    let (pretrain_s, train_s) = (
        console.pretrain_seconds,
        console.started.elapsed().as_secs_f64(),
    );
    save(&net, &args.out)?;
    report(&args, &recipe, &net, pretrain_s, train_s)
}

/// Prints the run's settings and its held-out figures as one JSON object.
fn report(
    args: &Args,
    recipe: &Recipe,
    net: &flow::SpyNet<f32>,
    pretrain_s: f64,
    train_s: f64,
) -> Result<()> {
    let held_out = PairConfig {
        size: args.size,
        ..PairConfig::default()
    };
    let pairs = recipe.pairs();
    let scene_validation = &recipe.validation_set;
    let (epe, zero) = evaluate(net, args.eval_seed, args.eval_pairs, &held_out)?;
    let (epe_st, zero_st) = evaluate(net, args.eval_seed, args.eval_pairs, &pairs)?;
    let still = PairConfig {
        brightness_jitter: 0.0,
        ..held_out
    };
    let (epe_nj, zero_nj) = evaluate(net, args.eval_seed, args.eval_pairs, &still)?;
    // `null` in the report without `--scene-validation` (rather than a meaningless 0).
    let (epe_sv, zero_sv) = if scene_validation.is_empty() {
        (None, None)
    } else {
        let (e, z) = evaluate_pairs(net, scene_validation)?;
        (Some(e), Some(z))
    };
    let ratio_sv = epe_sv.zip(zero_sv).map(|(e, z)| e / z.max(1e-12));
    let steps = &recipe.level_steps;
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
