//! `cargo xtask flow --img1 A.png --img2 B.png --out F.flo [--weights W.safetensors] [--viz F.png]`:
//! optical flow between two images with the SPyNet-style network. Inputs: PNG / PPM / PNM (8 or 16 bit,
//! values scaled to [0, 1] as stored, i.e. sRGB-encoded as the network was trained) or EXR (f32 RGB as
//! stored). The number of pyramid levels comes from the weights file. Output format by extension
//! (`.flo`, `.png` 16-bit KITTI-style, `.npy`, `.exr`, via the `events` crate).

use anyhow::{bail, Context, Result};
use std::path::{Path, PathBuf};

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
    /// Network weights (safetensors, see the `flow` crate docs).
    #[arg(
        long,
        default_value = "data-fixtures/flow/spynet-synthetic.safetensors"
    )]
    pub weights: PathBuf,
    /// Optional colour-coded visualisation (Middlebury colour wheel) as PNG.
    #[arg(long)]
    pub viz: Option<PathBuf>,
}

/// Reads an RGB image as planar `(3, H, W)` f32; returns (data, height, width).
pub fn read_rgb(path: &Path) -> Result<(Vec<f32>, usize, usize)> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    if ext == "exr" {
        use exr::prelude::*;
        let img = read_first_rgba_layer_from_file(
            path,
            |res, _| {
                (
                    res.width(),
                    res.height(),
                    vec![0f32; 3 * res.width() * res.height()],
                )
            },
            |(w, h, px): &mut (usize, usize, Vec<f32>),
             pos,
             (r, g, b, _a): (f32, f32, f32, f32)| {
                let i = pos.y() * *w + pos.x();
                let n = *w * *h;
                px[i] = r;
                px[n + i] = g;
                px[2 * n + i] = b;
            },
        )
        .with_context(|| format!("reading EXR {}", path.display()))?;
        let (w, h, px) = img.layer_data.channel_data.pixels;
        return Ok((px, h, w));
    }
    let img = image::open(path)
        .with_context(|| format!("reading image {}", path.display()))?
        .to_rgb32f();
    let (w, h) = (img.width() as usize, img.height() as usize);
    let n = w * h;
    let mut out = vec![0f32; 3 * n];
    for (i, p) in img.pixels().enumerate() {
        for c in 0..3 {
            out[c * n + i] = p.0[c];
        }
    }
    Ok((out, h, w))
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
    let net = flow::load_safetensors(&args.weights)
        .with_context(|| format!("loading flow weights {}", args.weights.display()))?;
    let t = std::time::Instant::now();
    let tape = net.forward(&a, &b, h1, w1)?;
    eprintln!(
        "flow: {w1}x{h1}, {} levels, {:.1} ms",
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
