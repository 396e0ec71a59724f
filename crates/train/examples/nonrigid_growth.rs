//! Does a model's pose-conditioned non-rigid network grow the person's Gaussians where the body
//! moves fast, i.e. absorb the motion blur into the person's shape? For each saved model and each
//! held-out frame, the person's Gaussians (human probability ≥ 0.5) are posed and each one's size
//! change is measured as ½ ln(tr Σ_posed / tr Σ_canonical) (skinning's rotations keep the trace;
//! only the network's Δlog-scale changes it), opacity-weighted over the person. Printed per
//! model: the mean over frames, the mean of the fastest and slowest thirds of the frames (by the
//! blurred frame's mean absolute difference from its sharp reference in the person's box), and the
//! correlation of growth with that motion over the frames.
//!
//! ```text
//! cargo run --release -p train --example nonrigid_growth -- DATA MODEL_DIR...
//! ```
//!
//! `DATA` a synthetic scene with sharp references and masks; each `MODEL_DIR` a run's `model/`.

use std::path::PathBuf;
use train::eval::mask_bbox;

/// Pearson correlation of two equal-length series (NaN for fewer than two values).
fn correlation(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len() as f64;
    let (ma, mb) = (a.iter().sum::<f64>() / n, b.iter().sum::<f64>() / n);
    let cov: f64 = a.iter().zip(b).map(|(x, y)| (x - ma) * (y - mb)).sum();
    let va: f64 = a.iter().map(|x| (x - ma).powi(2)).sum();
    let vb: f64 = b.iter().map(|y| (y - mb).powi(2)).sum();
    cov / (va * vb).sqrt()
}

fn trace(m: &[[f32; 3]; 3]) -> f64 {
    f64::from(m[0][0] + m[1][1] + m[2][2])
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some((dir, models)) = args.split_first() else {
        return Err("usage: nonrigid_growth DATA MODEL_DIR...".into());
    };
    let data = train::data::load_dataset(&PathBuf::from(dir))?;
    let (w, h) = (data.camera.width as usize, data.camera.height as usize);
    let plane = w * h;
    // Each held-out frame's motion: mean |blurred − sharp| over its person box and channels.
    let mut motion = Vec::new();
    for f in data.frames.iter().filter(|f| f.split == scene::Split::Test) {
        let (Some(sharp), Some(mask)) = (f.sharp.as_deref(), f.mask.as_deref()) else {
            return Err(format!("frame {}: no sharp reference or mask", f.index).into());
        };
        let (x0, y0, x1, y1) = mask_bbox(mask, w, h).ok_or("a frame without the person")?;
        let mut sum = 0.0;
        for c in 0..3 {
            for y in y0..y1 {
                for x in x0..x1 {
                    let i = c * plane + y * w + x;
                    sum += f64::from((f.image[i] - sharp[i]).abs());
                }
            }
        }
        motion.push(sum / (3 * (x1 - x0) * (y1 - y0)) as f64);
    }
    let mut order: Vec<usize> = (0..motion.len()).collect();
    order.sort_by(|&a, &b| motion[a].total_cmp(&motion[b]));
    let third = motion.len() / 3;
    for model_dir in models {
        let loaded = train::export::load_model(&PathBuf::from(model_dir))?;
        let model = &loaded.model;
        let cast = loaded.cast();
        let person: Vec<usize> = (0..model.set.len())
            .filter(|&i| model.probability(i) >= 0.5)
            .collect();
        let canonical: Vec<f64> = person
            .iter()
            .map(|&i| {
                model.set.log_scales[i]
                    .iter()
                    .map(|&s| f64::from(2.0 * s).exp())
                    .sum()
            })
            .collect();
        let mut growth = Vec::new();
        for f in data.frames.iter().filter(|f| f.split == scene::Split::Test) {
            let pose = cast.prepare(&model.corrected_params(f.index, &f.smpl), &f.others)?;
            let r = model.render_frame(f.index, &f.camera, &pose, model.latent_for(f.index))?;
            let (mut sum, mut weight) = (0.0, 0.0);
            for (&i, &c) in person.iter().zip(&canonical) {
                let o = f64::from(model.set.opacity(i));
                sum += o * 0.5 * (trace(&r.posed.covariances[i]) / c).ln();
                weight += o;
            }
            growth.push(sum / weight.max(f64::MIN_POSITIVE));
        }
        let mean = |idx: &[usize]| idx.iter().map(|&k| growth[k]).sum::<f64>() / idx.len() as f64;
        let all: Vec<usize> = (0..growth.len()).collect();
        println!(
            "{model_dir}: {} person Gaussians; size change ½ln(tr ratio) mean {:+.4}, slowest third {:+.4}, fastest third {:+.4}; correlation with motion {:+.3}",
            person.len(),
            mean(&all),
            mean(&order[..third]),
            mean(&order[order.len() - third..]),
            correlation(&growth, &motion)
        );
    }
    Ok(())
}
