//! Do the per-frame colour latents carry a frame's blur into the renders? Every held-out frame is
//! rendered with the latent the evaluation uses (the nearest training frame's) and again with
//! other latents: the mean over the training frames (the frames' own variations averaged out),
//! zero, and the latent of the training frame whose blurred image is closest to its sharp
//! reference in the person's box (the sharpest). A model whose latents learned to soften the
//! person where its frame was blurred scores higher with the mean or sharpest latent than with the
//! nearest; one whose latents hold only lighting or appearance does not.
//!
//! ```text
//! cargo run --release -p train --example latent_swap -- DATA MODEL_DIR...
//! ```
//!
//! `DATA` a synthetic scene with sharp references and masks; each `MODEL_DIR` a run's `model/`.

use std::path::PathBuf;
use train::eval::{box_psnr, mask_bbox};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some((dir, models)) = args.split_first() else {
        return Err("usage: latent_swap DATA MODEL_DIR...".into());
    };
    let data = train::data::load_dataset(&PathBuf::from(dir))?;
    let (w, h) = (data.camera.width as usize, data.camera.height as usize);
    for model_dir in models {
        let loaded = train::export::load_model(&PathBuf::from(model_dir))?;
        let model = &loaded.model;
        let cast = loaded.cast();
        let d = model.config.latent_dim;
        let slots = model.frame_indices.len();
        let mut mean = vec![0.0f32; d];
        for s in 0..slots {
            for (m, &v) in mean.iter_mut().zip(model.latent(s)) {
                *m += v / slots as f32;
            }
        }
        // The training frame whose blurred box is closest to its sharp reference.
        let mut sharpest = (f64::MIN, 0usize);
        for (s, &index) in model.frame_indices.iter().enumerate() {
            let Some(f) = data.frames.iter().find(|f| f.index == index) else {
                continue;
            };
            let (Some(sharp), Some(mask)) = (f.sharp.as_deref(), f.mask.as_deref()) else {
                continue;
            };
            let Some(b) = mask_bbox(mask, w, h) else {
                continue;
            };
            let p = box_psnr(&f.image, sharp, w, h, b);
            if p > sharpest.0 {
                sharpest = (p, s);
            }
        }
        let zero = vec![0.0f32; d];
        let variants: [(&str, Option<&[f32]>); 4] = [
            ("nearest", None),
            ("mean", Some(&mean)),
            ("zero", Some(&zero)),
            ("sharpest", Some(model.latent(sharpest.1))),
        ];
        print!("{model_dir}: box PSNR (dB)");
        for (name, latent) in variants {
            let mut se = 0.0f64;
            let mut n = 0usize;
            for f in data.frames.iter().filter(|f| f.split == scene::Split::Test) {
                let (Some(sharp), Some(mask)) = (f.sharp.as_deref(), f.mask.as_deref()) else {
                    return Err(format!("frame {}: no sharp reference or mask", f.index).into());
                };
                let Some(b) = mask_bbox(mask, w, h) else {
                    continue;
                };
                let pose = cast.prepare(&model.corrected_params(f.index, &f.smpl), &f.others)?;
                let latent = latent.unwrap_or_else(|| model.latent_for(f.index));
                let r = model.render_frame(f.index, &f.camera, &pose, latent)?;
                // Per-frame PSNR averaged, as the evaluation does.
                se += box_psnr(&r.rgb, sharp, w, h, b);
                n += 1;
            }
            print!("  {name} {:.2}", se / n.max(1) as f64);
        }
        println!();
    }
    Ok(())
}
