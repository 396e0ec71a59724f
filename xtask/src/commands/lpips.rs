//! `cargo xtask lpips A.png B.png [--weights W.safetensors] [--linear]`: the LPIPS distance (AlexNet,
//! v0.1; the `lpips` crate) between two images of the same size, at least 31 × 31 pixels. Inputs:
//! PNG / PPM / PNM (8 or 16 bit) or EXR, read with their values as stored — what LPIPS expects of an
//! 8-bit image, i.e. sRGB-encoded values (the project's PNGs are; `cargo xtask render` writes the same
//! values to PNG and EXR). `--linear` says the files hold linear intensities instead, which are
//! sRGB-encoded (clamped to [0, 1]) first. The distance is the last line of stdout; size and time go
//! to stderr.

use crate::common::{read_rgb, shipped_lpips_weights};
use anyhow::{Context, Result};
use std::path::PathBuf;

/// Arguments of `lpips`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// First image (PNG 8/16 bit, PPM/PNM or EXR).
    pub a: PathBuf,
    /// Second image, the same size as the first.
    pub b: PathBuf,
    /// LPIPS weights (safetensors, see the `lpips` crate docs); default: the shipped
    /// data-fixtures/lpips/alexnet-lpips-v0.1.safetensors.
    #[arg(long)]
    pub weights: Option<PathBuf>,
    /// The files hold linear intensities: sRGB-encode them before LPIPS (which was trained on
    /// sRGB-encoded images).
    #[arg(long)]
    pub linear: bool,
}

/// Runs the command.
pub fn run(args: Args) -> Result<()> {
    let weights = args.weights.clone().unwrap_or_else(shipped_lpips_weights);
    let net = lpips::load_safetensors(&weights)
        .with_context(|| format!("loading the LPIPS weights {}", weights.display()))?;
    let (mut a, ha, wa) = read_rgb(&args.a)?;
    let (mut b, hb, wb) = read_rgb(&args.b)?;
    if args.linear {
        for v in a.iter_mut().chain(b.iter_mut()) {
            *v = scene::image_io::srgb_from_linear(*v);
        }
    }
    let t = std::time::Instant::now();
    let reference = net
        .features(&b, hb, wb)
        .with_context(|| format!("{}", args.b.display()))?;
    let d = net
        .distance_to(&a, ha, wa, &reference)
        .with_context(|| format!("{} against {}", args.a.display(), args.b.display()))?;
    eprintln!(
        "lpips (AlexNet, v0.1): {wa}x{ha}, {:.0} ms, weights {}",
        t.elapsed().as_secs_f64() * 1e3,
        weights.display()
    );
    println!("{d}");
    Ok(())
}
