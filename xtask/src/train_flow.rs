//! `cargo xtask train-flow`: trains SPyNet-style weights on procedural FlyingChairs-style pairs, coarse
//! to fine (level by level, lower levels frozen), with an end-point-error loss; deterministic from the
//! seed. Reports the held-out EPE against the zero-flow baseline and writes the weights.

use anyhow::{Context, Result};
use flow::synthetic::PairConfig;
use flow::train::{evaluate, TrainConfig, Trainer};
use indicatif::{ProgressBar, ProgressStyle};
use std::path::PathBuf;

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
    /// Training image side (pixels; a multiple of 2^(levels-1)).
    #[arg(long, default_value_t = 64)]
    pub size: usize,
    /// Optimiser steps per level, coarsest first (comma separated; one value = same for all).
    #[arg(long, value_delimiter = ',', default_value = "600,400,250,120")]
    pub steps: Vec<usize>,
    /// Pairs per step.
    #[arg(long, default_value_t = 4)]
    pub batch: usize,
    /// Adam learning rate.
    #[arg(long, default_value_t = 1e-3)]
    pub lr: f64,
    /// Seed of the initial weights and training pairs.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Seed of the held-out evaluation pairs.
    #[arg(long, default_value_t = 1_000_003)]
    pub eval_seed: u64,
    /// Number of held-out evaluation pairs.
    #[arg(long, default_value_t = 40)]
    pub eval_pairs: u64,
    /// Continue from existing weights instead of a fresh initialisation.
    #[arg(long)]
    pub init: Option<PathBuf>,
}

/// Runs the command.
pub fn run(args: Args) -> Result<()> {
    let pairs = PairConfig {
        size: args.size,
        ..PairConfig::default()
    };
    let cfg = TrainConfig {
        levels: args.levels,
        pairs,
        batch: args.batch,
        lr: args.lr,
        seed: args.seed,
        distinct_pairs: None,
    };
    let mut trainer = match &args.init {
        Some(p) => Trainer::from_net(
            flow::load_safetensors(p).with_context(|| format!("loading {}", p.display()))?,
            cfg,
        ),
        None => Trainer::new(cfg),
    };
    let steps: Vec<usize> = (0..args.levels)
        .map(|l| *args.steps.get(l).or(args.steps.last()).unwrap_or(&0))
        .collect();
    let total: usize = steps.iter().sum();
    let bar = ProgressBar::new(total as u64);
    bar.set_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} {elapsed_precise} eta {eta} {msg}")
            .context("progress style")?,
    );
    let start = std::time::Instant::now();
    for (level, &n) in steps.iter().enumerate() {
        let mut recent = Vec::new();
        for _ in 0..n {
            let epe = trainer.step(level)?;
            recent.push(epe);
            if recent.len() > 20 {
                recent.remove(0);
            }
            let mean = recent.iter().sum::<f64>() / recent.len() as f64;
            bar.set_message(format!("level {level} epe {mean:.3}"));
            bar.inc(1);
        }
        let line = format!(
            "level {level}: {n} steps, last-20 mean EPE {:.3} (level pixels), {:.0} s",
            recent.iter().sum::<f64>() / recent.len().max(1) as f64,
            start.elapsed().as_secs_f64()
        );
        // `suspend` prints whether or not the bar is drawn (it is hidden when stderr is not a terminal).
        bar.suspend(|| eprintln!("{line}"));
    }
    bar.finish();
    let train_s = start.elapsed().as_secs_f64();
    if let Some(dir) = args.out.parent() {
        if !dir.as_os_str().is_empty() {
            std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        }
    }
    flow::save_safetensors(&trainer.net, &args.out)
        .with_context(|| format!("writing {}", args.out.display()))?;
    let (epe, zero) = evaluate(&trainer.net, args.eval_seed, args.eval_pairs, &pairs)?;
    println!(
        "{}",
        serde_json::json!({
            "weights": args.out.display().to_string(), "levels": args.levels, "size": args.size,
            "steps": steps, "batch": args.batch, "lr": args.lr, "seed": args.seed,
            "train_seconds": train_s, "eval_seed": args.eval_seed, "eval_pairs": args.eval_pairs,
            "epe": epe, "zero_flow_epe": zero, "ratio": epe / zero,
        })
    );
    Ok(())
}
