//! The evaluation every run ends with (`reconstruct`, `eval`): the test split scored against the
//! sharp references (or the observed frames), `metrics.json`, one comparison strip per test frame,
//! the report, and the summary table on the terminal.

use anyhow::{Context, Result};
use serde_json::json;
use std::path::{Path, PathBuf};
use train::camera_alignment::{AlignmentSettings, ExposureSampling};
use train::eval::{
    evaluate_split, mean_metrics, mean_person_metrics, EvaluatedFrame, FrameMetrics, PersonMetrics,
};

use crate::outputs::camera_report::CameraError;
use train::model::Model;
use train::pose::body::Cast;

/// Training facts recorded next to the figures.
pub struct EvalSummary {
    /// Wall-clock training time (s); NaN when unknown (`eval` of a saved model), and then the
    /// entries of an existing `metrics.json` in the output folder that the evaluation does not
    /// write (the run's configuration and training time) are kept.
    pub train_seconds: f64,
    /// Optimisation steps.
    pub steps: usize,
    /// Gaussians with human probability ≥ 0.5.
    pub gaussians_human: usize,
    /// Other Gaussians.
    pub gaussians_scene: usize,
    /// Anything else to record (merged into metrics.json).
    pub extra: serde_json::Value,
    /// The frames scored: the held-out ones (`Test`, what every figure of the project is), or the
    /// training frames, against their sharp references (how much of the held-out gap is
    /// generalisation to unseen poses rather than what the blur hides).
    pub split: scene::Split,
    /// Each scored frame's camera aligned to its observed frame first, in this many Adam steps
    /// (`train::camera_alignment`; 0: the cameras as the model has them).
    pub camera_alignment_steps: usize,
    /// The trained model's exposure model, which alignment predicts each frame with
    /// (`train::camera_alignment::ExposureSampling::of` the run's configuration).
    pub camera_alignment_exposure: Option<ExposureSampling>,
}

/// One point of the held-out curve (`reconstruct --eval-every N`): the test split's mean PSNR
/// (dB) and SSIM, full frame and human box, and the mask IoU of the model after `step` steps, as
/// one JSON object. No LPIPS (it would cost more than the renders) and nothing written: the
/// model is only read, so the training's bits do not change.
pub fn held_out_point(
    model: &Model,
    cast: &Cast<'_>,
    data: &train::data::Dataset,
    step: usize,
) -> Result<serde_json::Value, train::TrainError> {
    let frames = evaluate_split(model, cast, data, (scene::Split::Test, None), None)?;
    let per_frame: Vec<_> = frames.iter().map(|f| f.metrics).collect();
    let m = mean_metrics(&per_frame);
    Ok(json!({
        "step": step,
        "test_frames": frames.len(),
        "test_psnr_full": m.psnr_full,
        "test_psnr_human_box": m.psnr_human_box,
        "test_ssim_full": m.ssim_full,
        "test_ssim_human_box": m.ssim_human_box,
        "test_mask_iou": m.mask_iou,
    }))
}

/// Prints the test split's image metrics against the sharp references (`sharp`), else against the
/// observed frames (real data); a figure that cannot be measured (no mask for a human box) is a
/// dash.
fn print_metrics_table(
    m: &train::eval::FrameMetrics,
    split: scene::Split,
    frames: usize,
    sharp: bool,
) {
    let reference = if sharp { "sharp" } else { "observed" };
    let cell = |v: f64, digits: usize, width: usize| {
        if v.is_finite() {
            format!("{v:>width$.digits$}")
        } else {
            format!("{:>width$}", "—")
        }
    };
    println!();
    let heading = format!("{} split ({frames} frames)", split.as_str());
    println!("| {heading:<28} | full frame | human box |");
    println!("|------------------------------|-----------:|----------:|");
    let rows = [
        ("PSNR render", " (dB)", m.psnr_full, m.psnr_human_box, 2),
        (
            "PSNR blurred",
            " (dB)",
            m.blurred_psnr_full,
            m.blurred_psnr_human_box,
            2,
        ),
        ("SSIM render", "", m.ssim_full, m.ssim_human_box, 4),
        (
            "SSIM blurred",
            "",
            m.blurred_ssim_full,
            m.blurred_ssim_human_box,
            4,
        ),
        ("LPIPS render", "", m.lpips_full, m.lpips_human_box, 4),
        (
            "LPIPS blurred",
            "",
            m.blurred_lpips_full,
            m.blurred_lpips_human_box,
            4,
        ),
    ];
    // Against the observed frames, the blurred rows would score a frame against itself.
    let rows = rows
        .into_iter()
        .filter(|r| sharp || !r.0.contains("blurred"));
    for (what, unit, full, human, digits) in rows {
        let label = format!("{what} vs {reference}{unit}");
        println!(
            "| {label:<28} | {} | {} |",
            cell(full, digits, 10),
            cell(human, digits, 9)
        );
    }
    println!(
        "| human mask IoU (p > 0.5)     | {} |           |",
        cell(m.mask_iou, 3, 10)
    );
}

/// Evaluates the split `summary.split` (the test split unless told), writes `out/metrics.json` and `out/eval/strip_NNNNNN.png`, prints a table.
pub fn write_evaluation(
    model: &Model,
    cast: &Cast<'_>,
    data: &train::data::Dataset,
    out: &Path,
    summary: &EvalSummary,
) -> Result<()> {
    let weights = crate::common::shipped_lpips_weights();
    let lpips = lpips::load_safetensors(&weights)
        .with_context(|| format!("loading the LPIPS weights {}", weights.display()))?;
    let alignment = AlignmentSettings::with_steps(
        summary.camera_alignment_steps,
        summary.camera_alignment_exposure,
    );
    let frames = evaluate_split(
        model,
        cast,
        data,
        (summary.split, Some(&alignment)),
        Some(&lpips),
    )?;
    let strips = write_strips(&frames, out)?;
    let per_frame: Vec<_> = frames.iter().map(|f| f.metrics).collect();
    let m = mean_metrics(&per_frame);
    let people = people_means(model, &frames);
    let ids = data.scene.person_ids();
    let mut metrics = metrics_json(&m, &frames, &people, &ids, summary);
    let aligned: Vec<_> = frames
        .iter()
        .filter_map(|f| {
            f.alignment
                .as_ref()
                .map(|a| (f.index, a.camera.world_to_camera))
        })
        .collect();
    let aligned_error = crate::outputs::camera_report::aligned_error(data, &aligned)?;
    if let Some(e) = &aligned_error {
        metrics["camera_error_aligned"] = json!(e);
    }
    let path = out.join("metrics.json");
    if summary.train_seconds.is_nan() {
        keep_what_the_run_recorded(&path, &mut metrics);
    }
    std::fs::write(&path, serde_json::to_string_pretty(&metrics)?)
        .with_context(|| format!("writing {}", path.display()))?;
    let sharp = data.scene.frames.iter().any(|f| f.sharp.is_some());
    print_metrics_table(&m, summary.split, frames.len(), sharp);
    print_run_rows(&people, &ids, summary);
    print_alignment(
        &frames,
        aligned_error.as_ref(),
        summary.camera_alignment_steps,
    );
    let title = out
        .canonicalize()
        .ok()
        .and_then(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
        .unwrap_or_else(|| "run".into());
    let report = crate::outputs::report::write_run_report(out, &format!("E-Sem3DGS run: {title}"))?;
    println!(
        "metrics: {}; strips: {}; report: {}",
        path.display(),
        strips.display(),
        report.display()
    );
    Ok(())
}

/// Writes each evaluated frame's strip (reference | render | …) as `out/eval/strip_NNNNNN.png`
/// (8-bit sRGB) and returns the folder.
fn write_strips(frames: &[EvaluatedFrame], out: &Path) -> Result<PathBuf> {
    let strips = out.join("eval");
    std::fs::create_dir_all(&strips).with_context(|| format!("creating {}", strips.display()))?;
    for f in frames {
        let (w, h, data) = &f.strip;
        let path = strips.join(format!("strip_{:06}.png", f.index));
        scene::write_rgb(
            &path,
            &scene::Rgb {
                width: *w as u32,
                height: *h as u32,
                data: data.clone(),
            },
            scene::ImageEncoding::rgb(8, scene::Transfer::Srgb),
        )
        .with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(strips)
}

/// Each person's figures averaged over the frames, when the model has several people (else none).
fn people_means(model: &Model, frames: &[EvaluatedFrame]) -> Vec<PersonMetrics> {
    (0..model.people())
        .filter(|_| model.people() > 1)
        .map(|j| {
            let own: Vec<_> = frames
                .iter()
                .filter_map(|f| f.people.get(j).copied())
                .collect();
            mean_person_metrics(&own)
        })
        .collect()
}

/// The contents of `metrics.json`: the split's means, the run's figures, each frame's and each
/// person's, and `summary.extra` (the run's configuration) merged in.
fn metrics_json(
    m: &FrameMetrics,
    frames: &[EvaluatedFrame],
    people: &[PersonMetrics],
    ids: &[u32],
    summary: &EvalSummary,
) -> serde_json::Value {
    let mut metrics = json!({
        "split": summary.split.as_str(),
        "test_frames": frames.len(),
        "test_psnr_full": m.psnr_full,
        "test_ssim_full": m.ssim_full,
        "test_psnr_human_box": m.psnr_human_box,
        "test_ssim_human_box": m.ssim_human_box,
        "mask_iou": m.mask_iou,
        "blurred_psnr_full": m.blurred_psnr_full,
        "blurred_psnr_human_box": m.blurred_psnr_human_box,
        "blurred_ssim_full": m.blurred_ssim_full,
        "blurred_ssim_human_box": m.blurred_ssim_human_box,
        "test_lpips_full": m.lpips_full,
        "test_lpips_human_box": m.lpips_human_box,
        "blurred_lpips_full": m.blurred_lpips_full,
        "blurred_lpips_human_box": m.blurred_lpips_human_box,
        "test_psnr_outside_box": m.psnr_outside_box,
        "blurred_psnr_outside_box": m.blurred_psnr_outside_box,
        "gap_to_blurred_full_db": m.psnr_full - m.blurred_psnr_full,
        "gap_to_blurred_human_box_db": m.psnr_human_box - m.blurred_psnr_human_box,
        "train_seconds": summary.train_seconds,
        "steps": summary.steps,
        "gaussians_human": summary.gaussians_human,
        "gaussians_scene": summary.gaussians_scene,
        "camera_alignment_steps": summary.camera_alignment_steps,
        "lpips": "AlexNet v0.1 on sRGB-encoded images (lower is closer); a human box below 31 px per side is grown to 31 for LPIPS",
        "per_frame": frames.iter().map(|f| per_frame_json(f, ids)).collect::<Vec<_>>(),
    });
    if !people.is_empty() {
        metrics["people"] = people
            .iter()
            .zip(ids)
            .map(|(p, id)| person_json(p, *id))
            .collect();
    }
    if let (Some(obj), Some(extra)) = (metrics.as_object_mut(), summary.extra.as_object()) {
        for (k, v) in extra {
            obj.insert(k.clone(), v.clone());
        }
    }
    metrics
}

/// Re-scoring a run in its own folder keeps what the run recorded in `path` and this evaluation
/// does not know (the training configuration, the step breakdown, the training time): the new
/// figures are written over the previous file's.
fn keep_what_the_run_recorded(path: &Path, metrics: &mut serde_json::Value) {
    let Some(serde_json::Value::Object(mut previous)) = std::fs::read_to_string(path)
        .ok()
        .and_then(|t| serde_json::from_str(&t).ok())
    else {
        return;
    };
    if let Some(obj) = metrics.as_object_mut() {
        obj.remove("train_seconds");
        for (k, v) in std::mem::take(obj) {
            previous.insert(k, v);
        }
        *obj = previous;
    }
}

/// The table's rows after the metrics: each person's box PSNR and IoU, training time and steps,
/// the Gaussians.
fn print_run_rows(people: &[PersonMetrics], ids: &[u32], summary: &EvalSummary) {
    for (p, id) in people.iter().zip(ids) {
        let label = format!("person {id}: box PSNR, IoU");
        println!(
            "| {label:<28} | {:>7.2} dB | {:>9.3} |",
            p.psnr_box, p.mask_iou
        );
    }
    if summary.train_seconds.is_finite() {
        println!(
            "| training                     | {:>8.0} s | {} steps |",
            summary.train_seconds, summary.steps
        );
    } else {
        println!(
            "| training                     |          — | {} steps |",
            summary.steps
        );
    }
    println!(
        "| Gaussians (human + scene)    | {:>10} | {:>9} |",
        summary.gaussians_human, summary.gaussians_scene
    );
}

/// One line on the test-time camera alignment, when it ran: the mean loss before and after, and
/// the aligned cameras' error against the truth when the scene has it.
fn print_alignment(frames: &[EvaluatedFrame], aligned_error: Option<&CameraError>, steps: usize) {
    let alignments: Vec<_> = frames.iter().filter_map(|f| f.alignment.as_ref()).collect();
    if alignments.is_empty() {
        return;
    }
    let n = alignments.len() as f64;
    let before = alignments.iter().map(|a| a.loss_before).sum::<f64>() / n;
    let after = alignments.iter().map(|a| a.loss_after).sum::<f64>() / n;
    let truth = aligned_error.map_or(String::new(), |e| {
        format!(
            "; RMS error against cameras_true.json {:.3}° / {:.2} cm",
            e.rotation_rms_deg, e.centre_rms_cm
        )
    });
    println!(
        "cameras aligned in {steps} steps: MSE against the observed frames {before:.3e} → {after:.3e}{truth}"
    );
}

/// One evaluated frame in `metrics.json`: its figures and, with several people, each person's.
fn per_frame_json(f: &train::eval::EvaluatedFrame, ids: &[u32]) -> serde_json::Value {
    let mut entry = json!({"index": f.index, "metrics": f.metrics});
    if let Some(a) = &f.alignment {
        let norm = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
        entry["camera_alignment"] = json!({
            "loss_before": a.loss_before,
            "loss_after": a.loss_after,
            "rotation_deg": norm(&a.twist[..3]).to_degrees(),
            "translation_cm": norm(&a.twist[3..]) * 100.0,
            "twist": a.twist,
        });
    }
    if !f.people.is_empty() {
        entry["people"] = f
            .people
            .iter()
            .zip(ids)
            .map(|(p, id)| person_json(p, *id))
            .collect();
    }
    entry
}

/// One person's figures under its stable id.
fn person_json(p: &PersonMetrics, id: u32) -> serde_json::Value {
    json!({
        "id": id,
        "mask_iou": p.mask_iou,
        "test_psnr_box": p.psnr_box,
        "test_ssim_box": p.ssim_box,
        "test_lpips_box": p.lpips_box,
        "blurred_psnr_box": p.blurred_psnr_box,
        "blurred_ssim_box": p.blurred_ssim_box,
        "blurred_lpips_box": p.blurred_lpips_box,
        "gap_to_blurred_box_db": p.psnr_box - p.blurred_psnr_box,
    })
}
