//! `cargo xtask eval`: score a saved model on a scene's test split (PSNR/SSIM/LPIPS full frame and in
//! the human box against the sharp references, mask IoU, the blurred input's own figures), write
//! `metrics.json` and one comparison strip PNG per test frame, and print a summary table. LPIPS uses
//! the shipped weights (`data-fixtures/lpips/`). `--split train` scores the training frames
//! instead, into their own folder.

use crate::outputs::evaluation::{write_evaluation, EvalSummary};
use anyhow::{Context, Result};
use serde_json::json;
use std::path::{Path, PathBuf};
use train::camera_alignment::ExposureSampling;

/// Arguments of `eval`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Model directory (written by `cargo xtask reconstruct`, its `model/` folder).
    #[arg(long)]
    pub model: PathBuf,
    /// Scene directory (scene format v1) with the test split; default: the default benchmark.
    #[arg(long)]
    pub data: Option<PathBuf>,
    /// Output directory for metrics.json and eval/strip_*.png (default: the model's parent; with
    /// `--split train`, its `train-split/` folder).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Which frames to score against their sharp references: `test` (the held-out frames) or
    /// `train` (the frames the model was trained on: a small gap between the two says the
    /// held-out error is what the blur hid, not unseen poses).
    #[arg(long, value_enum, default_value_t = SplitArg::Test)]
    pub split: SplitArg,
    /// Before scoring, align each frame's camera to its observed (blurred) frame in this many
    /// Adam steps, the model frozen: for estimated cameras, whose held-out frames carry errors
    /// that the training frames' corrections cannot know (0: off)
    #[arg(long, default_value_t = 0)]
    pub align_test_cameras: usize,
}

/// The frames `eval` scores.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum SplitArg {
    /// The held-out frames.
    Test,
    /// The training frames.
    Train,
}

/// Runs `eval`.
pub fn run(args: Args) -> Result<()> {
    let loaded = train::export::load_model(&args.model)
        .with_context(|| format!("loading the model {}", args.model.display()))?;
    let data_dir = match &args.data {
        Some(d) => d.clone(),
        None => crate::common::default_benchmark()?,
    };
    let data = train::data::load_dataset(&data_dir)
        .with_context(|| format!("loading the scene {}", data_dir.display()))?;
    let split = match args.split {
        SplitArg::Test => scene::Split::Test,
        SplitArg::Train => scene::Split::Train,
    };
    let out = args.out.clone().unwrap_or_else(|| {
        let parent = args
            .model
            .parent()
            .map_or_else(|| PathBuf::from("."), Path::to_path_buf);
        match split {
            scene::Split::Test => parent,
            scene::Split::Train => parent.join("train-split"),
        }
    });
    let model = &loaded.model;
    let human = model.human_count();
    let camera_error = crate::outputs::camera_report::camera_report(&data, model)?;
    write_evaluation(
        model,
        &loaded.cast(),
        &data,
        &out,
        &EvalSummary {
            split,
            camera_alignment_steps: args.align_test_cameras,
            camera_alignment_exposure: ExposureSampling::of(&loaded.manifest.config),
            train_seconds: f64::NAN,
            steps: loaded.manifest.steps,
            gaussians_human: human,
            gaussians_scene: model.set.len() - human,
            extra: json!({
                "model": args.model.display().to_string(),
                "data": data_dir.display().to_string(),
                "camera_error": camera_error,
            }),
        },
    )?;
    if let Some(report) = &camera_error {
        println!("{}", crate::outputs::camera_report::summary_line(report));
    }
    Ok(())
}
