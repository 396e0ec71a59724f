//! `cargo xtask bench step`: the training step's stage breakdown, measured the same way for every
//! change — from a saved checkpoint (a `reconstruct` run's `checkpoint.safetensors`, e.g. at its
//! Gaussian peak), with the run's own configuration and data preparation, for a few steps that
//! are not saved. One JSON line: the checkpoint's step and Gaussians, the threads, and the mean
//! milliseconds of each stage (`StepReport::times`).

use std::path::PathBuf;

use anyhow::{Context, Result};
use train::data::TrainingData;
use train::trainer::Trainer;

/// Arguments of `cargo xtask bench step`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The run directory whose `checkpoint.safetensors` is stepped from (default: the
    /// `--preset` run of the default benchmark, `target/reconstruct/default-<preset>`, as
    /// `cargo xtask reconstruct [--preset full]` writes it).
    #[arg(long, conflicts_with = "preset")]
    pub run: Option<PathBuf>,
    /// Which preset's default run to step from when `--run` is not given.
    #[arg(long, value_enum, default_value = "quick")]
    pub preset: train::config::Preset,
    /// The scene the run trained on (default: the synthetic benchmark's `default` preset).
    #[arg(long)]
    pub data: Option<PathBuf>,
    /// Timed steps (after one warm-up step).
    #[arg(long, default_value_t = 10)]
    pub steps: usize,
    /// Overrides the run's `share_static_tiles` (the renders of one exposure blend the tiles only
    /// static Gaussians reach once), to time the step with and without it.
    #[arg(long, value_parser = train::config::parse_on_off, value_name = "on|off")]
    pub share_static_tiles: Option<bool>,
    /// Overrides the run's `static_layer` (the static Gaussians behind every moving one are
    /// blended once per exposure, as a layer behind each render), to time the step with and
    /// without it.
    #[arg(long, value_parser = train::config::parse_on_off, value_name = "on|off")]
    pub static_layer: Option<bool>,
    /// Overrides the run's `view_rotation` (whose skinning weights canonicalise the human colour
    /// network's view directions), to time the step both ways.
    #[arg(long, value_enum)]
    pub view_rotation: Option<train::config::ViewRotation>,
}

/// Runs the benchmark.
pub fn run(args: Args) -> Result<()> {
    let run = args.run.unwrap_or_else(|| {
        crate::common::target_dir()
            .join("reconstruct")
            .join(format!("default-{}", args.preset.name()))
    });
    let data_dir = match args.data {
        Some(d) => d,
        None => crate::common::default_benchmark()?,
    };
    let data = train::data::load_dataset(&data_dir)
        .with_context(|| format!("loading the scene {}", data_dir.display()))?;
    let body = crate::training::scene_body(&data)?;
    let checkpoint = run.join("checkpoint.safetensors");
    // The run's seed (its `config.json`) samples the data's random parts as the run did.
    let seed = std::fs::read_to_string(run.join("config.json"))
        .ok()
        .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
        .and_then(|c| c["seed"].as_u64())
        .unwrap_or(0);
    let mut ctx = TrainingData::new(&data, body, seed)?;
    let mut trainer = Trainer::load_checkpoint(&checkpoint, &ctx).with_context(|| {
        format!(
            "loading {} (a `cargo xtask reconstruct` run's checkpoint: run one first, or name \
                 another run with --run)",
            checkpoint.display()
        )
    })?;
    if let Some(share) = args.share_static_tiles {
        trainer.set_share_static_tiles(share);
    }
    if let Some(layer) = args.static_layer {
        trainer.set_static_layer(layer);
    }
    if let Some(rotation) = args.view_rotation {
        trainer.set_view_rotation(rotation);
    }
    let config = trainer.config().clone();
    crate::training::prepare_training_data(&mut ctx, &data, &config)?;
    let (from, gaussians) = (trainer.step, trainer.model.set.len());
    trainer.step(&ctx)?; // warm-up: first touches of the buffers
    let steal = crate::steal::Meter::start();
    let mut reports = Vec::with_capacity(args.steps);
    for _ in 0..args.steps {
        reports.push(trainer.step(&ctx)?);
    }
    let mut line = serde_json::json!({
        "checkpoint": checkpoint.display().to_string(),
        "checkpoint_step": from,
        "gaussians": gaussians,
        "steps": args.steps,
        "threads": rayon::current_num_threads(),
        "steal_pct": steal.percent(),
        "share_static_tiles": config.share_static_tiles,
        "shared_tiles": reports.iter().map(|r| r.shared_tiles).sum::<f64>() / args.steps.max(1) as f64,
        "static_layer": config.static_layer,
        "view_rotation": config.view_rotation,
        "layered_tiles": reports.iter().map(|r| r.layered_tiles).sum::<f64>() / args.steps.max(1) as f64,
    });
    if let Some(obj) = line.as_object_mut() {
        for (stage, seconds) in crate::training::mean_times(&reports) {
            obj.insert(format!("{stage}_ms"), serde_json::json!(seconds * 1e3));
        }
    }
    println!("{line}");
    Ok(())
}
