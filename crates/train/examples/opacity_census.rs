//! How opaque are a model's Gaussians, and where do the faint ones sit? For each saved model, the
//! person's and the scene's Gaussians (the class a Gaussian's semantic logits favour) are counted
//! by opacity band, with the median and 90th-percentile distance of each band to the nearest
//! *opaque* Gaussian (opacity ≥ 0.5) of the same class, in canonical space. A blur-trained model
//! that keeps a haze of faint Gaussians around the body, which a sharp-trained one does not, shows
//! as a large faint band far from the opaque ones.
//!
//! ```text
//! cargo run --release -p train --example opacity_census -- MODEL_DIR...
//! ```
//!
//! Each `MODEL_DIR` a run's `model/` (its `canonical.ply` is read).

use std::collections::HashMap;
use std::path::PathBuf;

/// Opacity bands: [lower, upper).
const BANDS: [(f32, f32); 4] = [(0.0, 0.05), (0.05, 0.2), (0.2, 0.5), (0.5, 1.01)];
/// Opacity from which a Gaussian counts as opaque.
const OPAQUE: f32 = 0.5;
/// Cell of the grid the opaque Gaussians are hashed into (metres); the search looks one cell
/// around, so distances up to this are exact and larger ones are reported as "≥ CELL".
const CELL: f32 = 0.02;

/// The grid cell of a point.
fn cell_of(p: [f32; 3]) -> [i32; 3] {
    p.map(|v| (v / CELL).floor() as i32)
}

/// Distance from `p` to the nearest point in `grid` within one cell, or `None` when none is.
fn nearest(grid: &HashMap<[i32; 3], Vec<[f32; 3]>>, p: [f32; 3]) -> Option<f32> {
    let c = cell_of(p);
    let mut best: Option<f32> = None;
    for dx in -1..=1 {
        for dy in -1..=1 {
            for dz in -1..=1 {
                let Some(points) = grid.get(&[c[0] + dx, c[1] + dy, c[2] + dz]) else {
                    continue;
                };
                for q in points {
                    let d = (0..3).map(|k| (p[k] - q[k]).powi(2)).sum::<f32>().sqrt();
                    best = Some(best.map_or(d, |b| b.min(d)));
                }
            }
        }
    }
    best.filter(|&d| d <= CELL)
}

/// The `q`-quantile (0..1) of sorted `values`, `None` for none.
fn quantile(values: &[f32], q: f64) -> Option<f32> {
    let last = values.len().checked_sub(1)?;
    Some(values[(q * last as f64).round() as usize])
}

/// Prints one class's census: `members` are indices into `set`.
fn census(label: &str, set: &gaussians::GaussianSet, members: &[usize]) {
    let mut grid: HashMap<[i32; 3], Vec<[f32; 3]>> = HashMap::new();
    for &i in members.iter().filter(|&&i| set.opacity(i) >= OPAQUE) {
        grid.entry(cell_of(set.means[i]))
            .or_default()
            .push(set.means[i]);
    }
    println!("  {label}: {} Gaussians", members.len());
    for (lo, hi) in BANDS {
        let band: Vec<usize> = members
            .iter()
            .copied()
            .filter(|&i| (lo..hi).contains(&set.opacity(i)))
            .collect();
        let mut near: Vec<f32> = Vec::new();
        let mut far = 0usize;
        for &i in &band {
            match nearest(&grid, set.means[i]) {
                Some(d) => near.push(d),
                None => far += 1,
            }
        }
        near.sort_by(f32::total_cmp);
        let mm = |q| quantile(&near, q).map_or("-".into(), |d| format!("{:.1}", d * 1e3));
        println!(
            "    opacity [{lo:.2}, {hi:.2}): {:6} ({:4.1} %); nearest opaque within {} mm: \
             median {} mm, p90 {} mm; farther: {far} ({:.1} %)",
            band.len(),
            100.0 * band.len() as f64 / members.len().max(1) as f64,
            CELL * 1e3,
            mm(0.5),
            mm(0.9),
            100.0 * far as f64 / band.len().max(1) as f64,
        );
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let dirs: Vec<PathBuf> = std::env::args().skip(1).map(PathBuf::from).collect();
    if dirs.is_empty() {
        return Err("usage: opacity_census MODEL_DIR...".into());
    }
    for dir in dirs {
        let set = gaussians::read_ply(dir.join("canonical.ply"))?;
        let classes = set.semantic_classes;
        if classes < 2 {
            return Err(format!(
                "{}: no semantic classes to tell the person by",
                dir.display()
            )
            .into());
        }
        let mut probabilities = vec![0.0f32; classes];
        let (mut person, mut scene) = (Vec::new(), Vec::new());
        for i in 0..set.len() {
            set.semantic_probabilities(i, &mut probabilities);
            // Class 0 is the scene; every other class a person.
            if probabilities[0] < 0.5 {
                person.push(i);
            } else {
                scene.push(i);
            }
        }
        println!("{}", dir.display());
        census("person", &set, &person);
        census("scene", &set, &scene);
    }
    Ok(())
}
