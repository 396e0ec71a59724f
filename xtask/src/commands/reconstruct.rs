//! `cargo xtask reconstruct`: train E-Sem3DGS on a scene-format-v1 directory (by default the synthetic
//! benchmark, generated on first use under `target/benchmark/default`), then evaluate the test split and
//! write the model, metrics, comparison strips and a loss/PSNR curve.
//!
//! Output directory layout: `config.json` (the resolved hyper-parameters), `log.jsonl` (one JSON object
//! per step), `checkpoint.safetensors` (atomic, every `checkpoint_every` steps and at the end),
//! `eval_curve.jsonl` (with `--eval-every N`: the held-out frames' mean figures every N steps),
//! `model/` (see `train::export`), `model/posed_frame_NNNNNN.ply` (a standard 3DGS PLY of the first
//! training frame in INRIA's degree-3 layout), `eval/strip_NNNNNN.png`, `metrics.json`, `curve.png`.

use crate::common::{default_benchmark, target_dir};
use crate::outputs::evaluation::{write_evaluation, EvalSummary};
use crate::training::{mean_times, prepare_training_data, scene_body};
use anyhow::{bail, Context, Result};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;
use train::config::{BlurModel, ExposureMotion, FlowSource, Preset, TrainConfig, TrainOptions};
use train::data::TrainingData;
use train::trainer::{StepReport, Trainer};
use train::TrainError;

/// How a run is configured — a preset, a config file over it and options over both — shared by
/// `reconstruct` and `ablate` (where it applies to every run).
#[derive(clap::Args, Clone, Debug)]
pub struct TrainingArgs {
    /// Hyper-parameter preset: quick (minutes on 2 cores) or full.
    #[arg(long, default_value = "quick")]
    pub preset: Preset,
    /// TOML or JSON file overriding preset values (any training option below, in snake_case).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Training options: each overrides the preset and the --config file.
    #[command(
        flatten,
        next_help_heading = "Training options (override the preset and --config)"
    )]
    pub options: TrainOptions,
}

impl TrainingArgs {
    /// The preset's name as typed on the command line.
    pub fn preset_name(&self) -> &'static str {
        self.preset.name()
    }

    /// Whether the user chose the training option `key` (snake_case): given on the command line or
    /// named by the config file.
    pub fn sets(&self, key: &str) -> Result<bool> {
        let given = serde_json::to_value(&self.options)?
            .get(key)
            .is_some_and(|v| !v.is_null());
        let in_file = match &self.config {
            Some(path) => TrainConfig::keys_in_file(path)?.iter().any(|k| k == key),
            None => false,
        };
        Ok(given || in_file)
    }

    /// The resolved configuration: preset, then the file, then the options.
    pub fn resolve(&self) -> Result<TrainConfig> {
        Ok(TrainConfig::resolve(
            self.preset,
            self.config.as_deref(),
            &self.options,
        )?)
    }
}

/// Arguments of `reconstruct`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Scene directory (scene format v1). Default: the synthetic benchmark's `default` preset, generated
    /// under target/benchmark/default if it is not there yet.
    #[arg(long)]
    pub data: Option<PathBuf>,
    /// Output directory (default: target/reconstruct/<data name>-<preset>).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// How to train: preset, config file, options.
    #[command(flatten)]
    pub training: TrainingArgs,
    /// Continue from OUT/checkpoint.safetensors (same bits as an uninterrupted run).
    #[arg(long)]
    pub resume: bool,
    /// Score the held-out frames every N steps (and at the end) while training: mean PSNR and
    /// SSIM, full frame and human box, and mask IoU, one JSON line per point in
    /// OUT/eval_curve.jsonl (no LPIPS). 0 = off. The model is only read: same bits either way.
    /// A point on a step with a density-control pass or an opacity reset is scored right after
    /// it, and reads low (freshly split or faded Gaussians).
    #[arg(long, default_value_t = 0, value_name = "N")]
    pub eval_every: usize,
    /// In the final evaluation, align each held-out frame's camera to its observed (blurred)
    /// frame in N Adam steps, the model frozen, before scoring it (`cargo xtask eval
    /// --align-test-cameras`): for estimated cameras. 0 = off. Training is unchanged.
    #[arg(long, default_value_t = 0, value_name = "N")]
    pub align_test_cameras: usize,
    /// Stop after this many steps of this invocation (the run can be resumed later).
    #[arg(long, hide = true)]
    pub stop_after: Option<usize>,
    /// A synthetic benchmark's diagnostic: train with the generator's own sub-exposure poses
    /// instead of the ones interpolated from the frames' (an upper bound on a better in-exposure
    /// motion; the test frames keep their given poses).
    #[arg(long, hide = true)]
    pub oracle_sub_frame_poses: bool,
}

/// Appends `value` as one JSON line to the file at `path` (created if missing).
fn append_line(path: &Path, value: &serde_json::Value) -> Result<()> {
    let mut file = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(path)
        .with_context(|| format!("opening {}", path.display()))?;
    writeln!(file, "{value}").with_context(|| format!("writing {}", path.display()))
}

/// Keeps the log lines of steps before `step` and returns their summed wall time.
///
/// An unterminated last line that does not parse is the torn write of an interrupted run
/// and is dropped; a malformed line anywhere else is an error naming its line number.
fn truncate_log(path: &Path, step: usize) -> Result<f64> {
    let text = match std::fs::read_to_string(path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(0.0),
        Err(e) => return Err(e).with_context(|| format!("reading {}", path.display())),
    };
    let (kept, seconds) = kept_log_lines(&text, step)
        .with_context(|| format!("{}: cannot resume its log", path.display()))?;
    std::fs::write(path, kept).with_context(|| format!("rewriting {}", path.display()))?;
    Ok(seconds)
}

/// The lines of a JSON-lines training log whose `step` is below `step`, and their summed
/// `seconds`; see [`truncate_log`] for the handling of a torn last line.
fn kept_log_lines(text: &str, step: usize) -> Result<(String, f64)> {
    let mut kept = String::new();
    let mut seconds = 0.0;
    for (index, piece) in text.split_inclusive('\n').enumerate() {
        let terminated = piece.ends_with('\n');
        let line = piece.trim_end_matches(['\n', '\r']);
        if line.trim().is_empty() {
            continue;
        }
        let v: serde_json::Value = match serde_json::from_str(line) {
            Ok(v) => v,
            Err(_) if !terminated => {
                eprintln!(
                    "note: dropping the unfinished last log line {} (interrupted run)",
                    index + 1
                );
                continue;
            }
            Err(e) => return Err(e).with_context(|| format!("bad line {}", index + 1)),
        };
        if v["step"].as_u64().is_some_and(|s| (s as usize) < step) {
            seconds += v["seconds"].as_f64().unwrap_or(0.0);
            kept.push_str(line);
            kept.push('\n');
        }
    }
    Ok((kept, seconds))
}

/// How many of the sensor's thresholds one event is read as (`--event-threshold-scale`) when the
/// sensor has a refractory period: the best of 1 / 1.125 / 1.25 / 1.375 / 1.5 on the default
/// benchmark (`docs/notes/2026-12-05-event-threshold-scale.md`).
const REFRACTORY_THRESHOLD_SCALE: f32 = 1.25;

/// The defaults that depend on the scene, for the settings the user left alone: the contrast
/// thresholds its generator recorded, each event read as 1.25 of them unless the sensor was
/// recorded without a refractory period or the camera moves, mixed-polarity pixels held to their
/// counts and a bound margin of one threshold when it recorded a sensor without a refractory period, and the event loss between sub-exposure renders and the
/// events' modulation of each render's slice when the blur model is `exposure` and every frame
/// has events (a scene without events trains with the exposure
/// model alone, and says so), the learned in-exposure motion with the exposure model when the
/// scene has one person, and learned camera correction and scene Gaussians started on swept
/// surfaces (`--scene-init stereo`) when the camera moves.
fn scene_defaults(
    mut config: TrainConfig,
    training: &TrainingArgs,
    data: &train::data::Dataset,
) -> Result<TrainConfig> {
    if let Some(c) = data.recorded_positive("event_threshold") {
        if !training.sets("event_threshold")? {
            config.event_threshold = c as f32;
        }
    }
    if let Some(c) = data.recorded_positive("event_threshold_neg") {
        if !training.sets("event_threshold_neg")? {
            config.event_threshold_neg = Some(c as f32);
        }
    }
    // A sensor without a refractory period reports every crossing, so a pixel that fired both
    // polarities within an interval has an exact net count: evidence, not noise.
    if data.recorded("refractory_us") == Some(0.0) && !training.sets("event_ignore_mixed")? {
        config.event_ignore_mixed = false;
        println!(
            "events: the scene's sensor has no refractory period, so a pixel that fired both \
             polarities is held to its net count (--event-ignore-mixed on to leave it free)"
        );
    }
    // Every crossing is reported there, and the pixel's reference level can sit anywhere in its
    // threshold bin when an interval starts, so n events bound the change by n − 1 thresholds.
    if data.recorded("refractory_us") == Some(0.0) && !training.sets("event_bound_margin")? {
        config.event_bound_margin = 1.0;
        println!(
            "events: every crossing is reported, so n events bound a pixel's change by n - 1 \
             thresholds (--event-bound-margin 1; give it to choose)"
        );
    }
    // A sensor with a refractory period (every real one) drops crossings, so each of a moving
    // person's events stands for more than one threshold of change; one recorded without reports
    // them all, and a moving camera's events are mostly the room's slower edges, which it drops
    // fewer of (there 1.25 costs the room 0.5 dB on two seeds of `handheld`).
    if !training.sets("event_threshold_scale")? {
        let every_crossing = data.recorded("refractory_us") == Some(0.0);
        config.event_threshold_scale = if every_crossing || data.camera_moves {
            1.0
        } else {
            REFRACTORY_THRESHOLD_SCALE
        };
        if config.event_threshold_scale != 1.0 {
            println!(
                "events: a sensor's refractory period drops crossings, so each event is read as \
                 {} thresholds (--event-threshold-scale 1 to read the sensor's own)",
                config.event_threshold_scale
            );
        }
    }
    let with_events = data.scene.frames.iter().all(|f| f.events.is_some());
    if config.blur_model == BlurModel::Exposure && !training.sets("event_modulation")? {
        config.event_modulation = with_events;
        if with_events {
            println!(
                "events: each sub-exposure render is modulated by the events of its slice of the \
                 exposure (--event-modulation off to train without)"
            );
        }
    }
    if config.blur_model == BlurModel::Exposure && !training.sets("exposure_motion")? {
        if data.people() == 1 {
            config.exposure_motion = ExposureMotion::Learned;
            println!(
                "exposure model: the body's change over each exposure is learned per frame \
                 (--exposure-motion given to keep the interpolated poses' motion)"
            );
        } else {
            println!(
                "exposure model: the scene has {} people, so their motion inside each exposure \
                 is the given poses' (the learned in-exposure motion moves one person)",
                data.people()
            );
        }
    }
    // A moving camera's poses come from a tracker, whose errors the images can correct (worth
    // 7 dB on `handheld-err`; exact cameras lose 0.45 dB full frame to it): learn the corrections
    // unless the user chose.
    if data.camera_moves && !training.sets("camera_correction")? {
        config.camera_correction = true;
        println!(
            "cameras: the camera moves, so each training frame's camera is corrected from the \
             images (--camera-correction off to keep the given cameras)"
        );
    }
    // A moving camera sees the room with parallax: scene Gaussians must start near its surfaces.
    if data.camera_moves && !training.sets("scene_init")? {
        config.scene_init = train::init::SceneInit::Stereo;
        println!(
            "scene: the camera moves, so half the initial scene Gaussians start on the surfaces a \
             plane sweep over the training frames finds (--scene-init volume to draw them all in \
             the scene cube)"
        );
    }
    if config.blur_model == BlurModel::Exposure && !training.sets("event_loss")? {
        config.event_loss = with_events;
        if with_events {
            let (c_pos, c_neg) = config.event_thresholds();
            println!(
                "events: the event loss compares {} (weight {}, C+ {c_pos}, C- {c_neg} per event, \
                 {:?} penalty; --event-loss off to train without)",
                crate::training::compared_renders(config.exposure_pairs),
                config.event_weight,
                config.event_penalty
            );
        } else {
            println!(
                "the scene has no events (or not for every frame): training with the exposure \
                 model alone"
            );
        }
    }
    config.validate()?;
    Ok(config)
}

/// Runs `reconstruct`.
pub fn run(args: Args) -> Result<()> {
    let data_dir = match &args.data {
        Some(d) => d.clone(),
        None => default_benchmark()?,
    };
    let config = args.training.resolve()?;
    let preset_name = args.training.preset_name();
    let out = args.out.clone().unwrap_or_else(|| {
        let name = data_dir
            .file_name()
            .map_or_else(|| "data".into(), |n| n.to_string_lossy().into_owned());
        target_dir()
            .join("reconstruct")
            .join(format!("{name}-{preset_name}"))
    });
    std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
    let data = train::data::load_dataset(&data_dir)
        .with_context(|| format!("loading the scene {}", data_dir.display()))?;
    let config = scene_defaults(config, &args.training, &data)?;
    let body = scene_body(&data)?;
    let mut ctx = TrainingData::new(&data, body.clone(), config.seed)?;
    let checkpoint = out.join("checkpoint.safetensors");
    let log_path = out.join("log.jsonl");
    let curve_path = out.join("eval_curve.jsonl");
    let (mut trainer, mut train_seconds) = if args.resume {
        let t = Trainer::load_checkpoint(&checkpoint, &ctx)
            .with_context(|| format!("resuming from {}", checkpoint.display()))?;
        if *t.config() != config {
            eprintln!("note: --resume continues with the configuration stored in the checkpoint");
        }
        let secs = truncate_log(&log_path, t.step)?;
        truncate_log(&curve_path, t.step)?;
        (t, secs)
    } else {
        let _ = std::fs::remove_file(&log_path);
        let _ = std::fs::remove_file(&curve_path);
        (Trainer::new(&ctx, config)?, 0.0)
    };
    let config = trainer.config().clone();
    prepare_training_data(&mut ctx, &data, &config)?;
    if args.oracle_sub_frame_poses {
        crate::training::use_oracle_sub_frame_poses(&mut ctx, &data, config.subframes)?;
    }
    let config_path = out.join("config.json");
    std::fs::write(&config_path, serde_json::to_string_pretty(&config)?)
        .with_context(|| format!("writing {}", config_path.display()))?;
    println!(
        "training on {} ({} training frames, {}x{}), {} steps from step {}, {} Gaussians ({} human), {} threads",
        data_dir.display(),
        ctx.frames.len(),
        ctx.camera.width,
        ctx.camera.height,
        config.steps,
        trainer.step,
        trainer.model.set.len(),
        trainer.model.human_count(),
        rayon::current_num_threads()
    );
    let mut log = std::io::BufWriter::new(
        std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&log_path)
            .with_context(|| format!("opening {}", log_path.display()))?,
    );
    let bar = crate::common::progress_bar(config.steps as u64, "train")?;
    bar.set_position(trainer.step as u64);
    let until = match args.stop_after {
        Some(n) => (trainer.step + n).min(config.steps),
        None => config.steps,
    };
    let mut running_psnr: Option<f64> = None;
    let mut last_step_start = Instant::now();
    let mut recent: Vec<StepReport> = Vec::new();
    let result = trainer.run(&ctx, until, |t, r| {
        let secs = last_step_start.elapsed().as_secs_f64();
        last_step_start = Instant::now();
        train_seconds += secs;
        let ema = running_psnr.map_or(r.psnr, |p| 0.9 * p + 0.1 * r.psnr);
        running_psnr = Some(ema);
        bar.set_position(t.step as u64);
        bar.set_message(format!(
            "loss {:.4}  PSNR {:.2} dB  {} human + {} scene Gaussians",
            r.loss, ema, r.gaussians_human, r.gaussians_scene
        ));
        let mut line = serde_json::to_value(r).map_err(|e| TrainError::Config(e.to_string()))?;
        line["seconds"] = serde_json::json!(secs);
        writeln!(log, "{line}").map_err(|e| TrainError::Config(format!("log: {e}")))?;
        recent.push(r.clone());
        if recent.len() > 50 {
            recent.remove(0);
        }
        if args.eval_every > 0 && (t.step.is_multiple_of(args.eval_every) || t.step == config.steps)
        {
            let point =
                crate::outputs::evaluation::held_out_point(&t.model, &ctx.cast(), &data, t.step)?;
            bar.println(format!(
                "step {}: held-out PSNR {:.2} / {:.2} dB (full / box)",
                t.step,
                point["test_psnr_full"].as_f64().unwrap_or(f64::NAN),
                point["test_psnr_human_box"].as_f64().unwrap_or(f64::NAN)
            ));
            append_line(&curve_path, &point).map_err(|e| TrainError::Config(format!("{e:#}")))?;
        }
        if config.checkpoint_every > 0
            && t.step.is_multiple_of(config.checkpoint_every)
            && t.step < config.steps
        {
            log.flush()
                .map_err(|e| TrainError::Config(format!("log: {e}")))?;
            t.save_checkpoint(&checkpoint)?;
        }
        Ok(())
    });
    log.flush().context("flushing the log")?;
    if let Err(e) = result {
        bar.abandon();
        if matches!(e, TrainError::NonFinite { .. }) {
            bail!(
                "{e}. The last good checkpoint is {} (written every {} steps); nothing newer was saved",
                checkpoint.display(),
                config.checkpoint_every
            );
        }
        return Err(e.into());
    }
    trainer
        .save_checkpoint(&checkpoint)
        .context("writing the checkpoint")?;
    bar.finish_and_clear();
    if trainer.step < config.steps {
        println!(
            "stopped at step {} of {}; continue with --resume (checkpoint {})",
            trainer.step,
            config.steps,
            checkpoint.display()
        );
        return Ok(());
    }
    let model_dir = out.join("model");
    let model = &trainer.model;
    train::export::save_model(&model_dir, model, &config, trainer.step, &data)
        .with_context(|| format!("writing the model to {}", model_dir.display()))?;
    if config.pose_correction {
        train::export::write_corrected_poses(&model_dir, model, &data)
            .with_context(|| format!("writing the corrected poses to {}", model_dir.display()))?;
    }
    if let Some(first) = ctx.frames.first() {
        let pose = ctx.cast().prepare(
            &model.corrected_params(first.index, &first.pose.params),
            &first.pose.others,
        )?;
        let r = model.render_frame(
            first.index,
            &first.camera,
            &pose,
            model.latent_for(first.index),
        )?;
        let posed = train::export::posed_set(model, &r.posed);
        let path = model_dir.join(format!("posed_frame_{:06}.ply", first.index));
        gaussians::ply::write_ply(&path, &posed)
            .with_context(|| format!("writing {}", path.display()))?;
        if model.people() > 1 {
            // Each person alone: its Gaussians (human probability ≥ 0.5, most probably its).
            for (j, id) in data.scene.person_ids().into_iter().enumerate() {
                let own: Vec<usize> = (0..model.set.len())
                    .filter(|&i| model.probability(i) >= 0.5 && model.person_of(i) == j)
                    .collect();
                let path =
                    model_dir.join(format!("posed_frame_{:06}_person_{id}.ply", first.index));
                gaussians::ply::write_ply(&path, &posed.select(&own))
                    .with_context(|| format!("writing {}", path.display()))?;
            }
        }
    }
    let breakdown = mean_times(&recent);
    let pose_error = crate::outputs::pose_report::pose_report(&data, model, &ctx.body)?;
    let camera_error = crate::outputs::camera_report::camera_report(&data, model)?;
    let summary = EvalSummary {
        split: scene::Split::Test,
        camera_alignment_steps: args.align_test_cameras,
        camera_alignment_exposure: train::camera_alignment::ExposureSampling::of(&config),
        train_seconds,
        steps: trainer.step,
        gaussians_human: model.human_count(),
        gaussians_scene: model.set.len() - model.human_count(),
        extra: serde_json::json!({
            "data": data_dir.display().to_string(),
            "preset": preset_name,
            "semantic": config.semantic,
            "init": config.init,
            "semantic_init": config.semantic_init,
            "flow_loss": config.flow_loss,
            "flow_source": config.flow_source,
            "flow_weight": config.flow_weight,
            "flow_tau": config.flow_tau,
            "flow_gradient": config.flow_gradient,
            "flow_measure": config.flow_measure,
            "train_on": config.train_on,
            "blur_model": config.blur_model,
            "subframes": config.subframes,
            "event_loss": config.event_loss,
            "event_pairs": config.event_pairs,
            "event_weight": config.event_weight,
            "event_threshold": config.event_threshold,
            "event_threshold_neg": config.event_threshold_neg,
            "event_threshold_scale": config.event_threshold_scale,
            "event_penalty": config.event_penalty,
            "event_modulation": config.event_modulation,
            "exposure_motion": config.exposure_motion,
            "body_interpolation": config.body_interpolation,
            "lpips_weight": config.lpips_weight,
            "pose_correction": config.pose_correction,
            "pose_error": pose_error,
            "camera_correction": config.camera_correction,
            "camera_gauge": config.camera_gauge,
            "camera_error": camera_error,
            "seed": config.seed,
            "threads": rayon::current_num_threads(),
            "step_seconds_breakdown": breakdown
                .iter()
                .map(|&(name, seconds)| (name.to_string(), serde_json::json!(seconds)))
                .collect::<serde_json::Map<_, _>>(),
        }),
    };
    let mut summary = summary;
    if model.people() > 1 {
        summary.extra["people_count"] = serde_json::json!(model.people());
        summary.extra["person_class_changes"] = serde_json::json!(trainer.person_changes);
    }
    if config.event_loss {
        crate::outputs::pictures::write_event_picture(&data, &out)?;
    }
    if config.flow_loss {
        let kind = match config.flow_source {
            FlowSource::GroundTruth => Some(scene::FlowKind::GroundTruth),
            FlowSource::Events => Some(scene::FlowKind::EventsCm),
            FlowSource::File => Some(scene::FlowKind::External),
            FlowSource::SharpNetwork => None,
        };
        if let Some(kind) = kind {
            crate::outputs::pictures::write_flow_picture(&data, kind, &out)?;
        }
    }
    write_evaluation(model, &ctx.cast(), &data, &out, &summary)?;
    if let Some(report) = &pose_error {
        println!("{}", crate::outputs::pose_report::summary_line(report));
    }
    if let Some(report) = &camera_error {
        println!("{}", crate::outputs::camera_report::summary_line(report));
    }
    println!("model: {}", model_dir.display());
    println!(
        "step time, mean of the last {} steps (ms):\n{}",
        recent.len(),
        step_time_table(&breakdown)
    );
    Ok(())
}

/// The step-time breakdown of [`mean_times`] as a two-row text table in milliseconds.
fn step_time_table(breakdown: &[(&str, f64)]) -> String {
    let (mut names, mut values) = (String::new(), String::new());
    for (name, seconds) in breakdown {
        let ms = format!("{:.1}", seconds * 1e3);
        let width = name.len().max(ms.len());
        names.push_str(&format!("  {name:>width$}"));
        values.push_str(&format!("  {ms:>width$}"));
    }
    format!("{names}\n{values}")
}

#[cfg(test)]
mod tests {
    use super::kept_log_lines;

    const LOG: &str = "{\"step\":0,\"seconds\":1.5}\n{\"step\":1,\"seconds\":2.0}\n{\"step\":2,\"seconds\":4.0}\n";

    #[test]
    fn keeps_the_steps_before_the_checkpoint_and_sums_their_time() {
        let (kept, seconds) = kept_log_lines(LOG, 2).unwrap();
        assert_eq!(
            kept,
            "{\"step\":0,\"seconds\":1.5}\n{\"step\":1,\"seconds\":2.0}\n"
        );
        assert_eq!(seconds, 3.5);
    }

    #[test]
    fn a_torn_last_line_is_dropped_but_a_torn_middle_line_is_an_error() {
        let torn = format!("{LOG}{{\"step\":3,\"sec");
        let (kept, seconds) = kept_log_lines(&torn, 10).unwrap();
        assert_eq!(kept, LOG);
        assert_eq!(seconds, 7.5);
        let broken = format!("{{\"step\":0,\"sec\n{LOG}");
        let err = kept_log_lines(&broken, 10).unwrap_err();
        assert!(format!("{err:#}").contains("bad line 1"), "{err:#}");
    }
}
