//! `cargo xtask bench raster [--quick]`: times the rasterizer on seeded random scenes and prints one
//! JSON line per case `{"case","gaussians","width","height","threads","fwd_ms","fwd_bwd_ms"}`
//! (medians over repeats; plus `fwd_bwd_half_rows_ms`, forward + backward with a cotangent that is
//! zero on every other pair of rows as behind the flow loss's 1/4 resize, and `pairs`, the number of
//! tile–Gaussian pairs), for 1 thread and for the
//! machine's threads; plus `steal_pct`, the hypervisor's steal time during the case (null off
//! Linux). Scene generation and timing live in `rasterize_cpu::synthetic`.

use anyhow::{Context, Result};
use rasterize_cpu::synthetic::{time_case, SyntheticScene};

/// Arguments of `bench raster`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Fewer repeats and no 1M-Gaussian case (a smoke run).
    #[arg(long)]
    pub quick: bool,
    /// Thread counts to run (default: 1 and all available).
    #[arg(long, value_delimiter = ',')]
    pub threads: Vec<usize>,
    /// Scene seed.
    #[arg(long, default_value_t = 42)]
    pub seed: u64,
    /// Run only these cases (comma-separated: 50k_256, 100k_256, 1m_1080p); all by default (the
    /// 1M case is skipped by `--quick` unless named here).
    #[arg(long, value_delimiter = ',')]
    pub only: Vec<String>,
}

/// The cases: name, Gaussians, width, height, repeats.
const CASES: [(&str, usize, u32, u32, usize); 3] = [
    ("50k_256", 50_000, 256, 256, 15),
    ("100k_256", 100_000, 256, 256, 11),
    ("1m_1080p", 1_000_000, 1920, 1080, 5),
];

/// Runs the benchmark cases.
pub fn run(args: Args) -> Result<()> {
    if let Some(bad) = args
        .only
        .iter()
        .find(|c| !CASES.iter().any(|(name, ..)| name == c))
    {
        let names: Vec<&str> = CASES.iter().map(|(name, ..)| *name).collect();
        anyhow::bail!("--only: unknown case `{bad}` (cases: {})", names.join(", "));
    }
    let cases = CASES.into_iter().filter(|(name, ..)| {
        if args.only.is_empty() {
            !(args.quick && *name == "1m_1080p")
        } else {
            args.only.iter().any(|c| c == name)
        }
    });
    let threads = crate::common::bench_threads(&args.threads);
    for (name, n, w, h, repeats) in cases {
        let scene =
            SyntheticScene::new(n, w, h, args.seed).context("building the benchmark scene")?;
        // (`time_case` runs its own pool of `t` threads.)
        super::per_thread_count(&threads, |t| {
            let r = time_case(&scene, t, if args.quick { 3 } else { repeats })
                .with_context(|| format!("timing case {name} with {t} threads"))?;
            let round = |v: f64| (v * 100.0).round() / 100.0;
            Ok(serde_json::json!({
                "case": name,
                "gaussians": n,
                "width": w,
                "height": h,
                "fwd_ms": round(r.fwd_ms),
                "fwd_bwd_ms": round(r.fwd_bwd_ms),
                "fwd_bwd_half_rows_ms": round(r.fwd_bwd_half_rows_ms),
                "pairs": r.pairs,
            }))
        })?;
    }
    Ok(())
}
