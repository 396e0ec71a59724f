//! `cargo xtask deblur-edi`: every frame of a scene deblurred on its own by the event double
//! integral (EDI, `events::edi`) from the events of its exposure, written as PNG so a user can look
//! at what the events alone recover; with sharp references and masks, the PSNR / SSIM / LPIPS of
//! the EDI frames and of the blurred frames against them (full frame and the mask's tight box),
//! also written to `edi.json`. The same frames are what `reconstruct --train-on edi` trains on.

use anyhow::{Context, Result};
use serde_json::json;
use std::path::PathBuf;
use train::eval::{evaluate_frame, mean_metrics, EvalFrame};

/// Arguments of `deblur-edi`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Scene directory (scene format v1) whose frames have `events` files; default: the default
    /// benchmark.
    #[arg(long)]
    pub data: Option<PathBuf>,
    /// Output directory for `edi_NNNNNN.png` (sRGB, 8 bit) and `edi.json`.
    #[arg(long)]
    pub out: PathBuf,
    /// Contrast threshold C+ (log intensity); default: the one the scene's generator recorded,
    /// else 0.2.
    #[arg(long)]
    pub threshold: Option<f64>,
    /// Negative contrast threshold C−; default: the generator's, else C+.
    #[arg(long)]
    pub threshold_neg: Option<f64>,
    /// ε of log(I + ε) (the benchmark simulator's 1e-3).
    #[arg(long, default_value_t = 1e-3)]
    pub log_eps: f64,
    /// Use the events of hot pixels too (by default pixels whose event count or net count towers
    /// over their neighbours', `events::hot_pixels`, keep their blurred value).
    #[arg(long)]
    pub keep_hot_pixels: bool,
}

/// Runs `deblur-edi`.
pub fn run(args: Args) -> Result<()> {
    let dir = match &args.data {
        Some(d) => d.clone(),
        None => crate::common::default_benchmark()?,
    };
    let data = train::data::load_dataset(&dir)
        .with_context(|| format!("loading the scene {}", dir.display()))?;
    let c_pos = args
        .threshold
        .or_else(|| data.recorded_positive("event_threshold"))
        .unwrap_or(0.2);
    let c_neg = args
        .threshold_neg
        .or_else(|| data.recorded_positive("event_threshold_neg"))
        .unwrap_or(c_pos);
    let config = events::EdiConfig { c_pos, c_neg };
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let weights = crate::common::shipped_lpips_weights();
    let lpips = lpips::load_safetensors(&weights)
        .with_context(|| format!("loading the LPIPS weights {}", weights.display()))?;
    let (w, h) = (data.camera.width as usize, data.camera.height as usize);
    let hot = train::data::edi::hot_pixels(&data, !args.keep_hot_pixels, "EDI deblurring")?;
    let bar = crate::common::progress_bar(data.frames.len() as u64, "EDI frames")?;
    let mut scored = Vec::new();
    let mut uncovered = Vec::new();
    for (p, frame) in data.frames.iter().enumerate() {
        bar.set_position(p as u64);
        let Some(image) = train::data::edi::edi_image(&data, p, frame, config, args.log_eps, &hot)?
        else {
            uncovered.push(frame.index);
            continue;
        };
        let path = args.out.join(format!("edi_{:06}.png", frame.index));
        let rgb = scene::Rgb {
            width: w as u32,
            height: h as u32,
            data: image.iter().map(|v| v.clamp(0.0, 1.0)).collect(),
        };
        scene::write_rgb(
            &path,
            &rgb,
            scene::ImageEncoding::rgb(8, scene::Transfer::Srgb),
        )
        .with_context(|| format!("writing {}", path.display()))?;
        if let (Some(sharp), Some(mask)) = (&frame.sharp, &frame.mask) {
            let probability: Vec<f32> = mask.iter().map(|&m| f32::from(u8::from(m))).collect();
            let eval = EvalFrame {
                width: w,
                height: h,
                render: &rgb.data,
                reference: sharp,
                blurred: &frame.image,
                mask: Some(mask),
                human_probability: &probability,
            };
            scored.push(evaluate_frame(&eval, Some(&lpips))?);
        }
    }
    bar.finish_and_clear();
    let written = data.frames.len() - uncovered.len();
    println!(
        "wrote {written} EDI frames to {} (C+ {c_pos:.4}, C- {c_neg:.4})",
        args.out.display()
    );
    if !uncovered.is_empty() {
        println!(
            "{} frames not deblurred: the event files do not cover their exposures (frames {uncovered:?})",
            uncovered.len()
        );
    }
    let mut summary = json!({
        "scene": dir.display().to_string(),
        "c_pos": c_pos,
        "c_neg": c_neg,
        "log_eps": args.log_eps,
        "frames_deblurred": written,
        "frames_uncovered": uncovered,
    });
    if !scored.is_empty() {
        let m = mean_metrics(&scored);
        println!(
            "against the sharp references ({} frames), full frame / human box:\n  \
             EDI     PSNR {:.2} / {:.2} dB  SSIM {:.4} / {:.4}  LPIPS {:.4} / {:.4}\n  \
             blurred PSNR {:.2} / {:.2} dB  SSIM {:.4} / {:.4}  LPIPS {:.4} / {:.4}",
            scored.len(),
            m.psnr_full,
            m.psnr_human_box,
            m.ssim_full,
            m.ssim_human_box,
            m.lpips_full,
            m.lpips_human_box,
            m.blurred_psnr_full,
            m.blurred_psnr_human_box,
            m.blurred_ssim_full,
            m.blurred_ssim_human_box,
            m.blurred_lpips_full,
            m.blurred_lpips_human_box,
        );
        summary["scored_frames"] = json!(scored.len());
        summary["mean"] = serde_json::to_value(m)?;
    }
    let path = args.out.join("edi.json");
    std::fs::write(&path, serde_json::to_string_pretty(&summary)? + "\n")
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}
