//! `cargo xtask ablate`: the paper's ablation set on one scene — semantic none / scalar / one-hot
//! without events, one-hot + the event-generation loss, one-hot + the flow loss with ground-truth flow
//! and with event-only flow, and beyond the paper the exposure model alone, the exposure model with
//! events between its sub-exposure renders and the sharp-trained ceiling — each a full `reconstruct` run in `OUT/<run>/`, then `OUT/ablation.md`
//! (a Markdown table), `OUT/ablation.json` and `OUT/ablation_grid.png` (the strip of the first test
//! frame of every run, one row per run, numbered as in the table). A run that fails (e.g. no flow
//! network weights, or a scene without event-only flow) is recorded with its error and the others go
//! on. With `--blur-levels` it runs the paper's Figure 5 study instead: one-hot without events, with
//! the event-generation loss, with the flow loss (ground-truth and event-only flow), and the exposure
//! rows on the `slow`, `medium` and `fast` variants of the default benchmark (each generated once
//! under `target/benchmark/default-<speed>`); `--only` picks among them. With `--seeds` every row
//! runs once per seed (in `OUT/<run>/seed-<s>/`) and the table gains a section with each measure's
//! mean and range over the seeds ([`seeds`]): a difference smaller than that range is not one.

mod seeds;

use anyhow::{Context, Result};
use image::{Rgb, RgbImage};
use std::path::Path;
use std::path::PathBuf;
use train::blend::SemanticMode;
use train::config::{
    BlurModel, EventPairs, EventPenaltyKind, ExposureMotion, FlowSource, TrackTangents, TrainOn,
    TrainOptions,
};

/// Arguments of `ablate`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Scene directory (default: the synthetic benchmark's `default` preset, generated once).
    #[arg(long)]
    pub data: Option<PathBuf>,
    /// Output directory (default: target/ablate/<data name>-<preset>).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// How every run is configured (each run then sets its own options, e.g. --semantic,
    /// --event-loss, over these).
    #[command(flatten)]
    pub training: crate::commands::reconstruct::TrainingArgs,
    /// Run only these (comma separated names from the table: semantic-none, semantic-scalar,
    /// one-hot, event-loss, flow-gt, flow-events, flow-sharp-net, exposure,
    /// exposure-events-squared, exposure-events-unmodulated, exposure-events-given-motion,
    /// exposure-events, edi-cascade, sharp-ceiling).
    #[arg(long, value_delimiter = ',')]
    pub only: Option<Vec<String>>,
    /// Run the blur-level study (paper Figure 5) instead of the ablation set: one-hot, event-loss,
    /// flow-gt, flow-events, flow-sharp-net, exposure, exposure-events and sharp-ceiling on the
    /// slow, medium and fast variants of the default
    /// benchmark (ignores --data).
    #[arg(long)]
    pub blur_levels: bool,
    /// The benchmark preset whose slow, medium and fast variants the blur-level study runs on
    /// (`tiny` for a smoke run of the study).
    #[arg(long, value_enum, default_value = "default", requires = "blur_levels")]
    pub blur_levels_preset: crate::commands::synth::PresetArg,
    /// Run every row once per seed (comma separated, e.g. `0,1,2`; overrides --seed), each in
    /// `OUT/<run>/seed-<s>/`, and report each measure's mean and range over the seeds beside the
    /// per-run table (`ablation.md`, `ablation_over_seeds.json`). On the default benchmark at
    /// `quick`, seeds 0, 1 and 2 of the default span 0.30 dB in the human box (0.49 dB with
    /// ideal events, 0.40 dB on the noisy sensor): a smaller difference between two rows of one
    /// seed is not a finding.
    #[arg(long, value_delimiter = ',')]
    pub seeds: Option<Vec<u64>>,
}

/// One configuration of the ablation set: its name, a description and the training options it sets
/// over the preset, the --config file and the options given to every run.
pub(crate) struct Run {
    name: &'static str,
    what: &'static str,
    options: fn() -> TrainOptions,
}

const RUNS: [Run; 14] = [
    Run {
        name: "semantic-none",
        what: "no semantics (every Gaussian deformed), no events",
        options: || TrainOptions {
            blur_model: Some(BlurModel::None),
            semantic: Some(SemanticMode::None),
            event_loss: Some(false),
            flow_loss: Some(false),
            ..TrainOptions::default()
        },
    },
    Run {
        name: "semantic-scalar",
        what: "one sigmoid logit (p = 0.5 at start), no events",
        options: || TrainOptions {
            blur_model: Some(BlurModel::None),
            semantic: Some(SemanticMode::Scalar),
            event_loss: Some(false),
            flow_loss: Some(false),
            ..TrainOptions::default()
        },
    },
    Run {
        name: "one-hot",
        what: "one-hot semantics (paper), no events",
        options: || TrainOptions {
            blur_model: Some(BlurModel::None),
            semantic: Some(SemanticMode::OneHot),
            event_loss: Some(false),
            flow_loss: Some(false),
            ..TrainOptions::default()
        },
    },
    Run {
        name: "event-loss",
        what: "one-hot + event-generation loss (EventNeRF/E-NeRF)",
        options: || TrainOptions {
            blur_model: Some(BlurModel::None),
            semantic: Some(SemanticMode::OneHot),
            event_loss: Some(true),
            event_pairs: Some(EventPairs::Frames),
            event_weight: Some(3.0),
            event_penalty: Some(EventPenaltyKind::Squared),
            flow_loss: Some(false),
            event_threshold_scale: Some(1.0),
            event_weight_final_fraction: Some(1.0),
            ..TrainOptions::default()
        },
    },
    Run {
        name: "flow-gt",
        what: "one-hot + flow loss, ground-truth flow",
        options: || TrainOptions {
            blur_model: Some(BlurModel::None),
            semantic: Some(SemanticMode::OneHot),
            event_loss: Some(false),
            flow_loss: Some(true),
            flow_source: Some(FlowSource::GroundTruth),
            ..TrainOptions::default()
        },
    },
    Run {
        name: "flow-events",
        what: "one-hot + flow loss, event-only flow (contrast maximisation)",
        options: || TrainOptions {
            blur_model: Some(BlurModel::None),
            semantic: Some(SemanticMode::OneHot),
            event_loss: Some(false),
            flow_loss: Some(true),
            flow_source: Some(FlowSource::Events),
            ..TrainOptions::default()
        },
    },
    Run {
        name: "flow-sharp-net",
        what:
            "one-hot + flow loss, targets from the flow network on the sharp frames (the paper's \
               ZJU-MoCap-Blur protocol)",
        options: || TrainOptions {
            blur_model: Some(BlurModel::None),
            semantic: Some(SemanticMode::OneHot),
            event_loss: Some(false),
            flow_loss: Some(true),
            flow_source: Some(FlowSource::SharpNetwork),
            ..TrainOptions::default()
        },
    },
    Run {
        name: "exposure",
        what: "one-hot + exposure model (mean of sub-exposure renders at interpolated poses)",
        options: || TrainOptions {
            semantic: Some(SemanticMode::OneHot),
            blur_model: Some(BlurModel::Exposure),
            event_loss: Some(false),
            flow_loss: Some(false),
            ..TrainOptions::default()
        },
    },
    Run {
        name: "exposure-events-squared",
        what: "one-hot + exposure model + event-generation loss between sub-exposure renders, \
               squared penalty (the previous default)",
        options: || TrainOptions {
            semantic: Some(SemanticMode::OneHot),
            blur_model: Some(BlurModel::Exposure),
            event_loss: Some(true),
            event_pairs: Some(EventPairs::Exposure),
            event_penalty: Some(EventPenaltyKind::Squared),
            event_weight: Some(0.3),
            flow_loss: Some(false),
            event_threshold_scale: Some(1.0),
            event_weight_final_fraction: Some(1.0),
            ..TrainOptions::default()
        },
    },
    Run {
        name: "exposure-events-unmodulated",
        what: "one-hot + exposure model + events between sub-exposure renders, counts as lower \
               bounds, renders not modulated by their slice's events (the previous default)",
        options: || TrainOptions {
            semantic: Some(SemanticMode::OneHot),
            blur_model: Some(BlurModel::Exposure),
            event_loss: Some(true),
            event_pairs: Some(EventPairs::Exposure),
            event_penalty: Some(EventPenaltyKind::Bound),
            event_modulation: Some(false),
            flow_loss: Some(false),
            event_threshold_scale: Some(1.0),
            event_weight_final_fraction: Some(1.0),
            ..TrainOptions::default()
        },
    },
    Run {
        name: "exposure-events-given-motion",
        what: "one-hot + exposure model + events between sub-exposure renders, counts as lower \
               bounds, each render modulated by its slice's events, the in-exposure motion \
               interpolated with local tangents and not learned, 3DGS's position rate (the \
               previous default)",
        options: || TrainOptions {
            semantic: Some(SemanticMode::OneHot),
            blur_model: Some(BlurModel::Exposure),
            event_loss: Some(true),
            event_pairs: Some(EventPairs::Exposure),
            event_penalty: Some(EventPenaltyKind::Bound),
            event_modulation: Some(true),
            exposure_motion: Some(ExposureMotion::Given),
            body_interpolation: Some(TrackTangents::Local),
            lr_means: Some(1.6e-4),
            flow_loss: Some(false),
            event_threshold_scale: Some(1.0),
            event_weight_final_fraction: Some(1.0),
            ..TrainOptions::default()
        },
    },
    Run {
        name: "exposure-events",
        what: "one-hot + exposure model + events between sub-exposure renders, counts as lower \
               bounds, each render modulated by its slice's events, the change over each \
               exposure learned (the default)",
        options: || TrainOptions {
            semantic: Some(SemanticMode::OneHot),
            blur_model: Some(BlurModel::Exposure),
            event_loss: Some(true),
            event_pairs: Some(EventPairs::Exposure),
            event_penalty: Some(EventPenaltyKind::Bound),
            event_modulation: Some(true),
            flow_loss: Some(false),
            ..TrainOptions::default()
        },
    },
    Run {
        name: "edi-cascade",
        what: "one-hot trained on every frame deblurred by EDI from its events, one render per \
               frame (deblur first, then reconstruct)",
        options: || TrainOptions {
            semantic: Some(SemanticMode::OneHot),
            train_on: Some(TrainOn::Edi),
            blur_model: Some(BlurModel::None),
            event_loss: Some(false),
            flow_loss: Some(false),
            ..TrainOptions::default()
        },
    },
    Run {
        name: "sharp-ceiling",
        what: "one-hot trained on the sharp references: the ceiling a blur model chases",
        options: || TrainOptions {
            semantic: Some(SemanticMode::OneHot),
            train_on: Some(TrainOn::Sharp),
            blur_model: Some(BlurModel::None),
            event_loss: Some(false),
            flow_loss: Some(false),
            ..TrainOptions::default()
        },
    },
];

/// The metrics of `metrics.json` shown in the table, in order.
const COLUMNS: [(&str, &str); 10] = [
    ("test_psnr_full", "PSNR full (dB)"),
    ("test_psnr_human_box", "PSNR human box (dB)"),
    ("blurred_psnr_full", "blurred full (dB)"),
    ("blurred_psnr_human_box", "blurred human box (dB)"),
    ("test_ssim_full", "SSIM full"),
    ("test_ssim_human_box", "SSIM human box"),
    ("test_lpips_full", "LPIPS full"),
    ("test_lpips_human_box", "LPIPS human box"),
    ("mask_iou", "mask IoU"),
    ("train_seconds", "train s"),
];

/// Runs `ablate`.
pub fn run(args: Args) -> Result<()> {
    if let Some(only) = &args.only {
        for name in only {
            anyhow::ensure!(
                RUNS.iter().any(|r| r.name == name),
                "--only: unknown run `{name}` (expected one of: {})",
                RUNS.iter().map(|r| r.name).collect::<Vec<_>>().join(", ")
            );
        }
    }
    let preset_name = args.training.preset_name();
    // (row label, scene directory, run) in table order.
    let mut jobs: Vec<(String, PathBuf, &Run)> = Vec::new();
    let selected = |names: &[&str]| -> Vec<&'static Run> {
        RUNS.iter()
            .filter(|r| names.contains(&r.name))
            .filter(|r| {
                args.only
                    .as_ref()
                    .is_none_or(|o| o.iter().any(|n| n == r.name))
            })
            .collect()
    };
    let scene_name;
    if args.blur_levels {
        scene_name = "blur-levels".to_string();
        for (speed, label) in [
            (::synth::Speed::Slow, "slow"),
            (::synth::Speed::Medium, "medium"),
            (::synth::Speed::Fast, "fast"),
        ] {
            let cfg = ::synth::SynthConfig {
                speed,
                ..::synth::SynthConfig::preset(args.blur_levels_preset.preset())
            };
            let base = format!("{:?}", args.blur_levels_preset).to_lowercase();
            let data = crate::common::benchmark(&cfg, &format!("{base}-{label}"))?;
            for r in selected(&[
                "one-hot",
                "event-loss",
                "flow-gt",
                "flow-events",
                "flow-sharp-net",
                "exposure",
                "exposure-events",
                "sharp-ceiling",
            ]) {
                jobs.push((format!("{label}/{}", r.name), data.clone(), r));
            }
        }
    } else {
        let data = match &args.data {
            Some(d) => d.clone(),
            None => crate::common::default_benchmark()?,
        };
        scene_name = data
            .file_name()
            .map_or_else(|| "data".into(), |n| n.to_string_lossy().into_owned());
        for r in selected(&RUNS.map(|r| r.name)) {
            jobs.push((r.name.to_string(), data.clone(), r));
        }
    }
    let jobs = seeds::per_seed(jobs, args.seeds.as_deref())?;
    let out = args.out.clone().unwrap_or_else(|| {
        crate::common::target_dir()
            .join("ablate")
            .join(format!("{scene_name}-{preset_name}"))
    });
    std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
    let mut results = Vec::new();
    for (k, (label, data, r, seed)) in jobs.iter().enumerate() {
        println!(
            "=== run {}/{}: {label} ({}) on {} ===",
            k + 1,
            jobs.len(),
            r.what,
            data.display()
        );
        let run_out = out.join(label);
        let run_args = crate::commands::reconstruct::Args {
            data: Some(data.clone()),
            out: Some(run_out.clone()),
            training: crate::commands::reconstruct::TrainingArgs {
                options: args
                    .training
                    .options
                    .overridden_by(&(r.options)())
                    .overridden_by(&TrainOptions {
                        seed: *seed,
                        ..TrainOptions::default()
                    }),
                ..args.training.clone()
            },
            resume: false,
            align_test_cameras: 0,
            eval_every: 0,
            stop_after: None,
            oracle_sub_frame_poses: false,
        };
        let outcome = crate::commands::reconstruct::run(run_args).and_then(|()| {
            let path = run_out.join("metrics.json");
            let text = std::fs::read_to_string(&path)
                .with_context(|| format!("reading {}", path.display()))?;
            serde_json::from_str::<serde_json::Value>(&text)
                .with_context(|| format!("parsing {}", path.display()))
        });
        match &outcome {
            Ok(_) => println!("{label}: done"),
            Err(e) => eprintln!("{label}: failed: {e:#}"),
        }
        results.push((label.clone(), *r, run_out, outcome));
    }
    write_table(&out, &scene_name, preset_name, &results)?;
    if args.seeds.as_ref().is_some_and(|s| s.len() > 1) {
        seeds::write_over_seeds(&out, &results)?;
    }
    write_grid(&out, &results)?;
    let md = std::fs::read_to_string(out.join("ablation.md"))
        .with_context(|| format!("reading {}", out.join("ablation.md").display()))?;
    let runs: Vec<String> = results.iter().map(|(label, ..)| label.clone()).collect();
    let report = crate::outputs::report::write_ablation_report(
        &out,
        &format!("E-Sem3DGS ablation: {scene_name}, {preset_name} preset"),
        &md,
        &runs,
    )?;
    println!(
        "ablation: {}, {} and {}",
        out.join("ablation.md").display(),
        out.join("ablation_grid.png").display(),
        report.display()
    );
    Ok(())
}

/// A run's table label, its configuration, its directory and its metrics (or why it failed).
type Outcome<'a> = (String, &'a Run, PathBuf, Result<serde_json::Value>);

fn write_table(out: &Path, scene: &str, preset: &str, results: &[Outcome<'_>]) -> Result<()> {
    let mut md = format!(
        "# Ablation on {scene} (preset `{preset}`)\n\nRows are numbered as in `ablation_grid.png`; \
         `blurred` columns are the input frames against the same references; LPIPS (AlexNet v0.1, lower \
         is closer) as in `metrics.json`. Poses: `exact` (the \
         scene has no `poses_true.json`: its poses are the truth), `estimated` (a fitter's, used as \
         given) or `corrected` (learned pose correction).\n\n| # | run | what | poses |"
    );
    push_measure_header(&mut md, "| ---: | --- | --- | --- |");
    let mut json = Vec::new();
    for (k, (label, r, dir, outcome)) in results.iter().enumerate() {
        md.push_str(&format!("| {} | `{label}` | {} |", k + 1, r.what));
        match outcome {
            Ok(m) => {
                md.push_str(&format!(" {} |", pose_source(m)));
                for (key, _) in COLUMNS {
                    let cell = m[key]
                        .as_f64()
                        .map_or_else(|| "—".to_string(), |v| format_measure(key, v));
                    md.push_str(&format!(" {cell} |"));
                }
                json.push(serde_json::json!({
                    "run": label, "what": r.what, "options": (r.options)(), "dir": dir.display().to_string(), "metrics": m,
                }));
            }
            Err(e) => {
                let msg = format!("{e:#}").replace('|', "/").replace('\n', " ");
                md.push_str(&format!(" — | failed: {msg} |"));
                md.push_str(&" |".repeat(COLUMNS.len() - 1));
                json.push(serde_json::json!({
                    "run": label, "what": r.what, "options": (r.options)(), "dir": dir.display().to_string(),
                    "error": format!("{e:#}"),
                }));
            }
        }
        md.push('\n');
    }
    let md_path = out.join("ablation.md");
    std::fs::write(&md_path, &md).with_context(|| format!("writing {}", md_path.display()))?;
    let json_path = out.join("ablation.json");
    std::fs::write(&json_path, serde_json::to_string_pretty(&json)?)
        .with_context(|| format!("writing {}", json_path.display()))?;
    print!("{md}");
    Ok(())
}

/// Ends a table's header row in `md` with the [`COLUMNS`] titles and adds the alignment row:
/// `lead` for the leading columns, right-aligned measures.
fn push_measure_header(md: &mut String, lead: &str) {
    for (_, title) in COLUMNS {
        md.push_str(&format!(" {title} |"));
    }
    md.push('\n');
    md.push_str(lead);
    md.push_str(&" ---: |".repeat(COLUMNS.len()));
    md.push('\n');
}

/// `v`, the value of the [`COLUMNS`] measure `key`, to the digits the table shows it with.
fn format_measure(key: &str, v: f64) -> String {
    match key {
        "train_seconds" => format!("{v:.0}"),
        "mask_iou" | "test_ssim_full" | "test_ssim_human_box" => format!("{v:.3}"),
        "test_lpips_full" | "test_lpips_human_box" => format!("{v:.4}"),
        _ => format!("{v:.2}"),
    }
}

/// Where a run's poses came from, by its metrics: `exact` without a pose error report (no
/// `poses_true.json`), else `corrected` with pose correction and `estimated` without.
fn pose_source(metrics: &serde_json::Value) -> &'static str {
    if metrics["pose_error"].is_null() {
        "exact"
    } else if metrics["pose_correction"].as_bool() == Some(true) {
        "corrected"
    } else {
        "estimated"
    }
}

/// Stacks the first test strip of every successful run, each row headed by its table number.
fn write_grid(out: &Path, results: &[Outcome<'_>]) -> Result<()> {
    const LABEL_W: u32 = 28;
    let mut rows: Vec<(usize, RgbImage)> = Vec::new();
    for (k, (_, _, dir, outcome)) in results.iter().enumerate() {
        if outcome.is_err() {
            continue;
        }
        let strips = dir.join("eval");
        let mut names: Vec<PathBuf> = std::fs::read_dir(&strips)
            .with_context(|| format!("listing {}", strips.display()))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| {
                p.file_name()
                    .is_some_and(|n| n.to_string_lossy().starts_with("strip_"))
            })
            .collect();
        names.sort();
        if let Some(first) = names.first() {
            let img = image::open(first)
                .with_context(|| format!("reading {}", first.display()))?
                .to_rgb8();
            rows.push((k + 1, img));
        }
    }
    if rows.is_empty() {
        return Ok(());
    }
    let width = LABEL_W + rows.iter().map(|(_, i)| i.width()).max().unwrap_or(0);
    let height: u32 = rows.iter().map(|(_, i)| i.height()).sum();
    let mut grid = RgbImage::from_pixel(width, height, Rgb([255, 255, 255]));
    let mut y = 0;
    for (number, img) in &rows {
        image::imageops::replace(&mut grid, img, i64::from(LABEL_W), i64::from(y));
        crate::outputs::pixel_font::text(
            &mut grid,
            4,
            y + img.height() / 2 - 5,
            &number.to_string(),
            Rgb([0, 0, 0]),
        );
        y += img.height();
    }
    let path = out.join("ablation_grid.png");
    grid.save(&path)
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}
