//! `cargo xtask bench lpips [--quick] [--threads 1,2]`: times LPIPS (the shipped AlexNet v0.1 weights)
//! on seeded random images and prints one JSON line per case
//! `{"case","width","height","threads","features_ms","distance_ms","gradient_ms","steal_pct"}`
//! (medians over repeats): `features_ms` one image's trunk (what a cached reference costs once),
//! `distance_ms` a distance between two images (two trunks), `gradient_ms` the training term's work
//! per step (the reference's trunk, then the prediction's trunk and backward).

use crate::common::shipped_lpips_weights;
use anyhow::{Context, Result};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::time::Instant;

/// Arguments of `bench lpips`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Fewer repeats (a smoke run).
    #[arg(long)]
    pub quick: bool,
    /// Thread counts to run (default: 1 and all available).
    #[arg(long, value_delimiter = ',')]
    pub threads: Vec<usize>,
}

/// Milliseconds of `f`.
fn ms<T>(f: impl FnOnce() -> Result<T>) -> Result<f64> {
    let s = Instant::now();
    f()?;
    Ok(s.elapsed().as_secs_f64() * 1e3)
}

/// Runs the benchmark cases.
pub fn run(args: Args) -> Result<()> {
    let threads = crate::common::bench_threads(&args.threads);
    let repeats = if args.quick { 3 } else { 9 };
    let weights = shipped_lpips_weights();
    let net = lpips::load_safetensors(&weights)
        .with_context(|| format!("loading the LPIPS weights {}", weights.display()))?;
    for (name, size) in [("pair_64", 64usize), ("pair_256", 256)] {
        let n = 3 * size * size;
        let mut rng = ChaCha8Rng::seed_from_u64(0x1234_5678);
        let a: Vec<f32> = (0..n).map(|_| rng.gen()).collect();
        let b: Vec<f32> = (0..n).map(|_| rng.gen()).collect();
        super::per_thread_count(&threads, |_| {
            let mut times: [Vec<f64>; 3] = Default::default();
            for _ in 0..repeats {
                times[0].push(ms(|| Ok(net.features(&a, size, size)?))?);
                times[1].push(ms(|| Ok(net.distance(&a, &b, size, size)?))?);
                times[2].push(ms(|| {
                    let reference = net.features(&b, size, size)?;
                    Ok(net.distance_and_gradient(&a, size, size, &reference)?)
                })?);
            }
            let [features, distance, gradient] = times.map(crate::common::median);
            Ok(serde_json::json!({
                "case": name, "width": size, "height": size,
                "features_ms": features, "distance_ms": distance, "gradient_ms": gradient,
            }))
        })?;
    }
    Ok(())
}
