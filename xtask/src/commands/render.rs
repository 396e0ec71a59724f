//! `cargo xtask render`: renders a standard 3DGS PLY from a camera to PNG (8-bit, clamped to [0, 1],
//! no colour-space conversion) or EXR (RGBA f32); with `--loss-weights W.npy` (float32, shape
//! (H, W, 3)) it also evaluates L = Σ render·W and writes dL/d(raw stored PLY parameters) to an
//! `.npz`: float32 `means (N,3)`, `log_scales (N,3)`, `quats (N,4)` (raw wxyz), `opacity_logits (N,)`,
//! `sh (N,K,3)` (coefficient-major, K = (deg+1)²).

use std::fs::File;
use std::io::{BufReader, BufWriter};
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use npyz::WriterBuilder;
use rasterize_cpu::{render_sh, render_sh_backward, Cotangents, RenderSettings, ShSplats};

/// Arguments of `render`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// 3DGS PLY (INRIA layout).
    #[arg(long)]
    pub ply: PathBuf,
    /// Camera: the project's camera JSON (or a scene format v1 `scene.json`, whose camera is used),
    /// or an INRIA `cameras.json` list (see `--cam-index`).
    #[arg(long)]
    pub camera: PathBuf,
    /// Index into an INRIA `cameras.json` list.
    #[arg(long, default_value_t = 0)]
    pub cam_index: usize,
    /// Output image, `.png` (8-bit RGB) or `.exr` (RGBA f32).
    #[arg(long)]
    pub out: PathBuf,
    /// Background colour (linear RGB).
    #[arg(long, num_args = 3, value_names = ["R", "G", "B"])]
    pub bg: Option<Vec<f64>>,
    /// Near plane (metres of view depth).
    #[arg(long, default_value_t = rasterize_cpu::DEFAULT_NEAR_PLANE)]
    pub near: f64,
    /// float32 .npy of shape (H, W, 3): loss weights W for L = Σ render·W.
    #[arg(long, requires = "grads_out")]
    pub loss_weights: Option<PathBuf>,
    /// Output .npz of dL/d(stored parameters).
    #[arg(long, requires = "loss_weights")]
    pub grads_out: Option<PathBuf>,
}

/// Renders (and optionally differentiates) the PLY.
pub fn run(args: Args) -> Result<()> {
    let set = gaussians::ply::read_ply(&args.ply)
        .with_context(|| format!("reading PLY {}", args.ply.display()))?;
    let camera_context = || format!("reading camera {}", args.camera.display());
    let cam =
        scene::camera_files::read_any(&args.camera, args.cam_index).with_context(camera_context)?;
    cam.validate().with_context(camera_context)?;
    let settings = RenderSettings {
        near_plane: args.near,
        background: args.bg.clone().unwrap_or_default(),
    };
    let splats = ShSplats {
        means: &set.means,
        log_scales: &set.log_scales,
        quats: &set.quats,
        opacity_logits: &set.opacity_logits,
        sh: &set.sh,
        sh_degree: set.sh_degree,
    };
    let t0 = std::time::Instant::now();
    let fwd = render_sh::<f32>(&cam, &splats, &settings).with_context(|| {
        format!(
            "rendering {} with camera {}",
            args.ply.display(),
            args.camera.display()
        )
    })?;
    eprintln!(
        "rendered {} Gaussians at {}x{} in {:.1} ms ({} tile pairs)",
        set.means.len(),
        cam.width,
        cam.height,
        t0.elapsed().as_secs_f64() * 1e3,
        fwd.output.num_pairs
    );
    write_image(
        &args.out,
        &fwd.output.image,
        &fwd.output.alpha,
        cam.width,
        cam.height,
    )?;

    if let (Some(wpath), Some(gpath)) = (&args.loss_weights, &args.grads_out) {
        let (w, h) = (cam.width as usize, cam.height as usize);
        let weights = read_weights(wpath, h, w)?;
        // (H, W, 3) interleaved → planar (3, H, W) cotangent.
        let hw = w * h;
        let mut d_image = vec![0.0f32; 3 * hw];
        for p in 0..hw {
            for c in 0..3 {
                d_image[c * hw + p] = weights[p * 3 + c];
            }
        }
        let loss: f64 = fwd
            .output
            .image
            .iter()
            .zip(&d_image)
            .map(|(a, b)| f64::from(*a) * f64::from(*b))
            .sum();
        let g = render_sh_backward(
            &cam,
            &splats,
            &settings,
            &fwd,
            &Cotangents {
                image: &d_image,
                alpha: None,
                depth: None,
            },
        )
        .context("backward pass")?;
        let k = gaussians::sh::num_sh_coeffs(set.sh_degree) as u64;
        let n = set.means.len() as u64;
        let file = File::create(gpath).with_context(|| format!("creating {}", gpath.display()))?;
        let mut npz = npyz::npz::NpzWriter::new(BufWriter::new(file));
        let mut put =
            |name: &str, shape: &[u64], data: &mut dyn Iterator<Item = f32>| -> Result<()> {
                let mut wr = npz
                    .array::<f32>(name, Default::default())
                    .and_then(|b| b.default_dtype().shape(shape).begin_nd())
                    .with_context(|| format!("writing {name} to {}", gpath.display()))?;
                wr.extend(data)
                    .with_context(|| format!("writing {name} to {}", gpath.display()))?;
                wr.finish()
                    .with_context(|| format!("writing {name} to {}", gpath.display()))?;
                Ok(())
            };
        put("means", &[n, 3], &mut g.means.iter().flatten().copied())?;
        put(
            "log_scales",
            &[n, 3],
            &mut g.log_scales.iter().flatten().copied(),
        )?;
        put("quats", &[n, 4], &mut g.quats.iter().flatten().copied())?;
        put(
            "opacity_logits",
            &[n],
            &mut g.opacity_logits.iter().copied(),
        )?;
        put("sh", &[n, k, 3], &mut g.sh.iter().copied())?;
        println!(
            "{}",
            serde_json::json!({ "loss": loss, "grads": gpath.display().to_string() })
        );
    }
    Ok(())
}

fn read_weights(path: &Path, h: usize, w: usize) -> Result<Vec<f32>> {
    let f = File::open(path).with_context(|| format!("opening loss weights {}", path.display()))?;
    let npy = npyz::NpyFile::new(BufReader::new(f))
        .with_context(|| format!("reading npy header of {}", path.display()))?;
    let shape = npy.shape().to_vec();
    if shape != [h as u64, w as u64, 3] {
        bail!(
            "loss weights {} have shape {shape:?}, expected ({h}, {w}, 3) to match the camera",
            path.display()
        );
    }
    if npy.order() != npyz::Order::C {
        bail!(
            "loss weights {}: Fortran order is not supported",
            path.display()
        );
    }
    let descr = npy.dtype().descr();
    if !descr.contains("f4") {
        bail!(
            "loss weights {}: dtype {descr} is not float32",
            path.display()
        );
    }
    let v: Vec<f32> = npy
        .into_vec()
        .with_context(|| format!("reading loss weights {}", path.display()))?;
    if let Some(i) = v.iter().position(|x| !x.is_finite()) {
        bail!("loss weights {}: entry {i} is not finite", path.display());
    }
    Ok(v)
}

fn write_image(path: &Path, image: &[f32], alpha: &[f32], width: u32, height: u32) -> Result<()> {
    let hw = (width * height) as usize;
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .unwrap_or_default();
    match ext.as_str() {
        "png" => {
            let mut buf = vec![0u8; 3 * hw];
            for p in 0..hw {
                for c in 0..3 {
                    buf[p * 3 + c] = (image[c * hw + p].clamp(0.0, 1.0) * 255.0).round() as u8;
                }
            }
            image::save_buffer(path, &buf, width, height, image::ExtendedColorType::Rgb8)
                .with_context(|| format!("writing PNG {}", path.display()))
        }
        "exr" => {
            use exr::prelude::*;
            let plane = |c: usize| image[c * hw..(c + 1) * hw].to_vec();
            let channels = AnyChannels::sort(SmallVec::from_vec(vec![
                AnyChannel::new("R", FlatSamples::F32(plane(0))),
                AnyChannel::new("G", FlatSamples::F32(plane(1))),
                AnyChannel::new("B", FlatSamples::F32(plane(2))),
                AnyChannel::new("A", FlatSamples::F32(alpha.to_vec())),
            ]));
            let layer = Layer::new(
                (width as usize, height as usize),
                LayerAttributes::named("render"),
                Encoding::SMALL_LOSSLESS,
                channels,
            );
            Image::from_layer(layer)
                .write()
                .to_file(path)
                .with_context(|| format!("writing EXR {}", path.display()))
        }
        other => bail!(
            "output {}: unknown extension {other:?} (png or exr)",
            path.display()
        ),
    }
}
