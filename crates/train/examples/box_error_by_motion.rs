//! Where in the person's box does a model's error sit? For each saved model, every held-out frame
//! is rendered and its squared error against the sharp reference inside the person's box is split
//! by what the pixel is: on the person or on the scene behind, how far it moved during the
//! exposure (the blurred frame's difference from its sharp reference, max over channels: static
//! < 0.02 ≤ slow < 0.1 ≤ fast), and whether the sharp reference has an edge there (the largest
//! central difference over channels ≥ 0.05: "edge", else "flat"). Holding a blur-trained model
//! against a sharp-trained one shows which pixels hold the box's PSNR below the ceiling.
//!
//! ```text
//! cargo run --release -p train --example box_error_by_motion -- DATA MODEL_DIR...
//! ```
//!
//! `DATA` a synthetic scene with sharp references and masks; each `MODEL_DIR` a run's `model/`.

use std::path::PathBuf;
use train::eval::mask_bbox;

/// Motion classes by the blurred frame's max-channel difference from its sharp reference.
const MOTION: [&str; 3] = ["static", "slow", "fast"];
/// Texture classes by the sharp reference's max-channel central difference.
const TEXTURE: [&str; 2] = ["flat", "edge"];

/// Squared-error sums and pixel counts of one class.
#[derive(Clone, Copy, Default)]
struct Tally {
    se: f64,
    pixels: f64,
}

/// Tallies indexed [on the person][motion][texture].
type Classes = [[[Tally; 2]; 3]; 2];

fn motion_class(blurred: &[f32], sharp: &[f32], i: usize, plane: usize) -> usize {
    let d = (0..3)
        .map(|c| (blurred[c * plane + i] - sharp[c * plane + i]).abs())
        .fold(0.0f32, f32::max);
    if d < 0.02 {
        0
    } else if d < 0.1 {
        1
    } else {
        2
    }
}

fn texture_class(sharp: &[f32], x: usize, y: usize, w: usize, h: usize) -> usize {
    let plane = w * h;
    let at = |c: usize, x: usize, y: usize| sharp[c * plane + y * w + x];
    let (xl, xr) = (x.saturating_sub(1), (x + 1).min(w - 1));
    let (yu, yd) = (y.saturating_sub(1), (y + 1).min(h - 1));
    let g = (0..3)
        .map(|c| {
            let gx = (at(c, xr, y) - at(c, xl, y)).abs();
            let gy = (at(c, x, yd) - at(c, x, yu)).abs();
            gx.max(gy)
        })
        .fold(0.0f32, f32::max);
    usize::from(g >= 0.05)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some((dir, models)) = args.split_first() else {
        return Err("usage: box_error_by_motion DATA MODEL_DIR...".into());
    };
    let data = train::data::load_dataset(&PathBuf::from(dir))?;
    let (w, h) = (data.camera.width as usize, data.camera.height as usize);
    let plane = w * h;
    for model_dir in models {
        let loaded = train::export::load_model(&PathBuf::from(model_dir))?;
        let model = &loaded.model;
        let cast = loaded.cast();
        let mut classes = Classes::default();
        let mut box_pixels = 0.0;
        for f in data.frames.iter().filter(|f| f.split == scene::Split::Test) {
            let (Some(sharp), Some(mask)) = (f.sharp.as_deref(), f.mask.as_deref()) else {
                return Err(format!("frame {}: no sharp reference or mask", f.index).into());
            };
            let Some((x0, y0, x1, y1)) = mask_bbox(mask, w, h) else {
                continue;
            };
            let pose = cast.prepare(&model.corrected_params(f.index, &f.smpl), &f.others)?;
            let r = model.render_frame(f.index, &f.camera, &pose, model.latent_for(f.index))?;
            for y in y0..y1 {
                for x in x0..x1 {
                    let i = y * w + x;
                    let se: f64 = (0..3)
                        .map(|c| {
                            let d = f64::from(r.rgb[c * plane + i] - sharp[c * plane + i]);
                            d.clamp(-1.0, 1.0).powi(2)
                        })
                        .sum();
                    let m = motion_class(&f.image, sharp, i, plane);
                    let t = texture_class(sharp, x, y, w, h);
                    let tally = &mut classes[usize::from(mask[i])][m][t];
                    tally.se += se;
                    tally.pixels += 1.0;
                    box_pixels += 1.0;
                }
            }
        }
        report(model_dir, &classes, box_pixels);
    }
    Ok(())
}

/// Prints the box PSNR and, per class, its share of the box's pixels, its own MSE and its share
/// of the box's squared error.
fn report(model_dir: &str, classes: &Classes, box_pixels: f64) {
    let total: f64 = classes.iter().flatten().flatten().map(|t| t.se).sum();
    let psnr = -10.0 * (total / (3.0 * box_pixels)).log10();
    println!(
        "{model_dir}: box PSNR {psnr:.2} dB (MSE over channels {:.3e})",
        total / (3.0 * box_pixels)
    );
    println!("  class                 pixels %   MSE        share of box SE %");
    for (on, by_motion) in classes.iter().enumerate() {
        for (m, by_texture) in by_motion.iter().enumerate() {
            for (t, tally) in by_texture.iter().enumerate() {
                let who = if on == 1 { "person" } else { "scene " };
                println!(
                    "  {who} {:<6} {:<4}   {:>7.2}   {:.3e}   {:>6.2}",
                    MOTION[m],
                    TEXTURE[t],
                    100.0 * tally.pixels / box_pixels,
                    tally.se / (3.0 * tally.pixels.max(1.0)),
                    100.0 * tally.se / total
                );
            }
        }
    }
}
