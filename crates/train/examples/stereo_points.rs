//! How well does the plane sweep of `train::init::stereo` find a synthetic scene's room? Runs the
//! sweep the trainer runs for `--scene-init stereo` over a scene's training frames (the person
//! left out: its mask's box) and measures each point's distance to the benchmark's
//! room planes (`synth::room`: floor y = 0, back wall z = −1.6, side walls x = ±2; props are not
//! planes, so a few points near them count as far).
//!
//! ```text
//! cargo run --release -p train --example stereo_points -- DATA [UNIQUENESS [MIN_TEXTURE [MAX_COST]]]
//! ```

use std::path::PathBuf;
use train::init::stereo::{surface_points, SweepConfig, SweepView};

/// Pixels added around the person's mask box.
const MARGIN_PX: f64 = 12.0;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let dir = PathBuf::from(std::env::args().nth(1).ok_or("usage: stereo_points DATA")?);
    let data = train::data::load_dataset(&dir)?;
    let train: Vec<usize> = (0..data.frames.len())
        .filter(|&k| data.frames[k].split == scene::Split::Train)
        .collect();
    let cameras: Vec<_> = train.iter().map(|&k| data.scene.camera_of(k)).collect();
    // The person's box from the benchmark's masks (the trainer poses the body instead).
    let boxes: Vec<Option<[f64; 4]>> = train
        .iter()
        .map(|&k| {
            let mask = data.frames[k].mask.as_ref()?;
            let w = data.camera.width as usize;
            let mut b = [
                f64::INFINITY,
                f64::INFINITY,
                f64::NEG_INFINITY,
                f64::NEG_INFINITY,
            ];
            for (i, _) in mask.iter().enumerate().filter(|(_, &m)| m) {
                let (x, y) = ((i % w) as f64, (i / w) as f64);
                b = [
                    b[0].min(x),
                    b[1].min(y),
                    b[2].max(x + 1.0),
                    b[3].max(y + 1.0),
                ];
            }
            Some([
                b[0] - MARGIN_PX,
                b[1] - MARGIN_PX,
                b[2] + MARGIN_PX,
                b[3] + MARGIN_PX,
            ])
        })
        .collect();
    let views: Vec<SweepView<'_>> = train
        .iter()
        .enumerate()
        .map(|(i, &k)| SweepView {
            image: &data.frames[k].image,
            camera: &cameras[i],
            exclude: boxes[i],
        })
        .collect();
    let arg = |i: usize, default: f64| -> Result<f64, Box<dyn std::error::Error>> {
        Ok(match std::env::args().nth(i) {
            Some(s) => s.parse()?,
            None => default,
        })
    };
    let defaults = SweepConfig::default();
    let config = SweepConfig {
        near: 0.75,
        far: 12.0,
        uniqueness: arg(2, defaults.uniqueness)?,
        min_texture: arg(3, defaults.min_texture)?,
        max_cost: arg(4, defaults.max_cost)?,
        ..defaults
    };
    let start = std::time::Instant::now();
    let points = surface_points(&views, &config);
    let seconds = start.elapsed().as_secs_f64();
    let mut distances: Vec<f64> = points
        .iter()
        .map(|p| {
            let [x, y, z] = p.map(f64::from);
            [y.abs(), (z + 1.6).abs(), (x + 2.0).abs(), (x - 2.0).abs()]
                .into_iter()
                .fold(f64::INFINITY, f64::min)
        })
        .collect();
    distances.sort_by(f64::total_cmp);
    let share = |d: f64| {
        distances.iter().filter(|&&v| v <= d).count() as f64 / distances.len().max(1) as f64
    };
    println!(
        "{} points from {} training frames in {seconds:.2} s",
        points.len(),
        train.len()
    );
    if let Some(&median) = distances.get(distances.len() / 2) {
        println!(
            "distance to the nearest room plane: median {:.3} m; within 2 / 5 / 10 / 25 cm: {:.1} / {:.1} / {:.1} / {:.1} %",
            median,
            100.0 * share(0.02),
            100.0 * share(0.05),
            100.0 * share(0.10),
            100.0 * share(0.25)
        );
    }
    Ok(())
}
