//! `cargo xtask ply-info`: summarise a 3DGS PLY file as one JSON object (counts, SH degree, extra
//! channels, bounds and parameter ranges), so a user can check a file before rendering or training.

use anyhow::{Context, Result};
use std::path::PathBuf;

/// Arguments of `ply-info`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The 3DGS PLY file to read (INRIA layout; binary or ASCII).
    pub ply: PathBuf,
}

/// Runs `ply-info`: prints `{"file","gaussians","sh_degree","semantic_classes","feature_dim",
/// "bounds_min","bounds_max","opacity_mean","scale_min_m","scale_max_m"}`.
pub fn run(args: Args) -> Result<()> {
    let set = gaussians::read_ply(&args.ply)
        .with_context(|| format!("reading Gaussians from {}", args.ply.display()))?;
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    for m in &set.means {
        for a in 0..3 {
            lo[a] = lo[a].min(m[a]);
            hi[a] = hi[a].max(m[a]);
        }
    }
    let n = set.len();
    let opacity_mean = (0..n).map(|i| f64::from(set.opacity(i))).sum::<f64>() / n.max(1) as f64;
    let scales = set.log_scales.as_flattened().iter().map(|l| l.exp());
    let (smin, smax) = scales.fold((f32::INFINITY, 0.0f32), |(a, b), s| (a.min(s), b.max(s)));
    let info = serde_json::json!({
        "file": args.ply.display().to_string(),
        "gaussians": n,
        "sh_degree": set.sh_degree,
        "semantic_classes": set.semantic_classes,
        "feature_dim": set.feature_dim,
        "bounds_min": if n > 0 { Some(lo) } else { None },
        "bounds_max": if n > 0 { Some(hi) } else { None },
        "opacity_mean": opacity_mean,
        "scale_min_m": if n > 0 { Some(smin) } else { None },
        "scale_max_m": if n > 0 { Some(smax) } else { None },
    });
    println!("{info}");
    Ok(())
}
