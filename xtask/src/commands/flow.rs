//! `cargo xtask flow --img1 A.png --img2 B.png --out F.flo [--weights W.safetensors] [--viz F.png]`:
//! optical flow between two images with the SPyNet-style network. Inputs: PNG / PPM / PNM (8 or 16 bit,
//! values scaled to [0, 1] as stored, i.e. sRGB-encoded as the network was trained) or EXR (f32 RGB as
//! stored). The number of pyramid levels comes from the weights file. Output format by extension
//! (`.flo`, `.png` 16-bit KITTI-style, `.npy`, `.exr`, via the `events` crate).

use crate::common::read_rgb;
use anyhow::{bail, Context, Result};
use std::path::PathBuf;

/// Arguments of `flow`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// First image (frame k).
    #[arg(long)]
    pub img1: PathBuf,
    /// Second image (frame k+1).
    #[arg(long)]
    pub img2: PathBuf,
    /// Output flow file (.flo, .png, .npy or .exr).
    #[arg(long)]
    pub out: PathBuf,
    /// Network weights (safetensors, see the `flow` crate docs; default: the project's own,
    /// `data-fixtures/flow/spynet-synthetic.safetensors` of the workspace, from any directory).
    #[arg(long)]
    pub weights: Option<PathBuf>,
    /// Optional colour-coded visualisation (Middlebury colour wheel) as PNG.
    #[arg(long)]
    pub viz: Option<PathBuf>,
}

/// Runs the command.
pub fn run(args: Args) -> Result<()> {
    let (a, h1, w1) = read_rgb(&args.img1)?;
    let (b, h2, w2) = read_rgb(&args.img2)?;
    if (h1, w1) != (h2, w2) {
        bail!(
            "image sizes differ: {} is {w1}x{h1}, {} is {w2}x{h2}",
            args.img1.display(),
            args.img2.display()
        );
    }
    let weights = args
        .weights
        .clone()
        .unwrap_or_else(crate::common::shipped_flow_network);
    let net = flow::load_safetensors(&weights)
        .with_context(|| format!("loading flow weights {}", weights.display()))?;
    let t = std::time::Instant::now();
    let tape = net.forward(&a, &b, h1, w1)?;
    eprintln!(
        "flow: {w1}x{h1}, {} of {} levels, {:.1} ms",
        net.levels_run(h1, w1),
        net.num_levels(),
        t.elapsed().as_secs_f64() * 1e3
    );
    let f = events::Flow::from_planar(w1, h1, tape.flow)?;
    events::write_flow(&args.out, &f).with_context(|| format!("writing {}", args.out.display()))?;
    if let Some(viz) = &args.viz {
        events::write_flow_colour_png(viz, &f, None)
            .with_context(|| format!("writing {}", viz.display()))?;
    }
    Ok(())
}
