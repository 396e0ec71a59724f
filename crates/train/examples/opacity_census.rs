//! How opaque are a model's Gaussians, and where do the faint ones sit? For each saved model, the
//! person's and the scene's Gaussians (the class a Gaussian's semantic logits favour) are counted
//! by opacity band, with the median and 90th-percentile distance of each band to the nearest
//! *opaque* Gaussian (opacity ≥ 0.5) of the same class, in canonical space, and how many lie
//! beyond 2 cm of every opaque one. A blur-trained model
//! that keeps a haze of faint Gaussians around the body, which a sharp-trained one does not, shows
//! as a large faint band far from the opaque ones. Each class's largest axis scale (canonical
//! space, mm) is given by its quartiles: the blur-trained person's Gaussians are larger.
//!
//! ```text
//! cargo run --release -p train --example opacity_census -- MODEL_DIR...
//! ```
//!
//! Each `MODEL_DIR` a run's `model/` (its `canonical.ply` is read).

use kiddo::immutable::float::kdtree::ImmutableKdTree;
use kiddo::SquaredEuclidean;
use std::path::PathBuf;

/// Opacity bands: [lower, upper).
const BANDS: [(f32, f32); 4] = [(0.0, 0.05), (0.05, 0.2), (0.2, 0.5), (0.5, 1.01)];
/// Opacity from which a Gaussian counts as opaque.
const OPAQUE: f32 = 0.5;
/// Distance (metres) beyond which a Gaussian counts as away from every opaque one.
const FAR: f32 = 0.02;

/// The `q`-quantile (0..1) of sorted `values`, `None` for none.
fn quantile(values: &[f32], q: f64) -> Option<f32> {
    let last = values.len().checked_sub(1)?;
    Some(values[(q * last as f64).round() as usize])
}

/// Prints one class's census: `members` are indices into `set`.
fn census(label: &str, set: &gaussians::GaussianSet, members: &[usize]) {
    let opaque: Vec<[f32; 3]> = members
        .iter()
        .filter(|&&i| set.opacity(i) >= OPAQUE)
        .map(|&i| set.means[i])
        .collect();
    // The same k-d tree the initial scales' neighbours come from (`gaussians::init`).
    let tree: ImmutableKdTree<f32, u64, 3, 32> = ImmutableKdTree::new_from_slice(&opaque);
    println!("  {label}: {} Gaussians", members.len());
    let mut largest: Vec<f32> = members
        .iter()
        .map(|&i| set.log_scales[i].into_iter().fold(f32::MIN, f32::max).exp())
        .collect();
    largest.sort_by(f32::total_cmp);
    let mm = |q| quantile(&largest, q).map_or("-".into(), |s| format!("{:.2}", s * 1e3));
    println!(
        "    largest axis scale (mm): quartiles {} / {} / {}, p90 {}",
        mm(0.25),
        mm(0.5),
        mm(0.75),
        mm(0.9)
    );
    for (lo, hi) in BANDS {
        let band: Vec<usize> = members
            .iter()
            .copied()
            .filter(|&i| (lo..hi).contains(&set.opacity(i)))
            .collect();
        let mut near: Vec<f32> = band
            .iter()
            .filter(|_| !opaque.is_empty())
            .map(|&i| {
                tree.nearest_one::<SquaredEuclidean>(&set.means[i])
                    .distance
                    .sqrt()
            })
            .collect();
        let far = near.iter().filter(|&&d| d > FAR).count();
        near.sort_by(f32::total_cmp);
        let mm = |q| quantile(&near, q).map_or("-".into(), |d| format!("{:.1}", d * 1e3));
        println!(
            "    opacity [{lo:.2}, {hi:.2}): {:6} ({:4.1} %); nearest opaque one: median {} mm, \
             p90 {} mm; beyond {} mm: {far} ({:.1} %)",
            band.len(),
            100.0 * band.len() as f64 / members.len().max(1) as f64,
            mm(0.5),
            mm(0.9),
            FAR * 1e3,
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
