//! `cargo xtask render-pose`: render a reconstructed model (person + scene) in new body poses from the
//! training camera, one PNG per pose, optionally with a posed 3DGS PLY (colours baked to SH degree 0).
//!
//! `POSES.json` is one object or a list of objects `{"pose": [72 floats, axis-angle], "transl": [3],
//! "latent_frame": N (optional: whose appearance latent to use; default the first training frame)}`.

use anyhow::{bail, Context, Result};
use std::path::PathBuf;

/// Arguments of `render-pose`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Model directory (the `model/` folder written by `cargo xtask reconstruct`).
    #[arg(long)]
    pub model: PathBuf,
    /// JSON file with one pose or a list of poses.
    #[arg(long)]
    pub poses: PathBuf,
    /// Output directory (created).
    #[arg(long)]
    pub out: PathBuf,
    /// Also write `posed_NNNN.ply` per pose (standard 3DGS PLY, SH degree 0).
    #[arg(long)]
    pub ply: bool,
}

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct PoseEntry {
    pose: Vec<f32>,
    transl: [f32; 3],
    #[serde(default)]
    latent_frame: Option<u32>,
}

/// Runs `render-pose`.
pub fn run(args: Args) -> Result<()> {
    let loaded = train::export::load_model(&args.model)
        .with_context(|| format!("loading the model {}", args.model.display()))?;
    let text = std::fs::read_to_string(&args.poses)
        .with_context(|| format!("reading {}", args.poses.display()))?;
    let value: serde_json::Value = serde_json::from_str(&text)
        .with_context(|| format!("{}: not JSON", args.poses.display()))?;
    let list = match value {
        serde_json::Value::Array(a) => a,
        v => vec![v],
    };
    if list.is_empty() {
        bail!("{}: no poses", args.poses.display());
    }
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let t = &loaded.model;
    let first = t.frame_indices.first().copied().unwrap_or(0);
    for (k, v) in list.into_iter().enumerate() {
        let e: PoseEntry = serde_json::from_value(v)
            .with_context(|| format!("{}: pose {k}", args.poses.display()))?;
        if e.pose.len() != 72 || e.pose.iter().chain(&e.transl).any(|x| !x.is_finite()) {
            bail!(
                "{}: pose {k}: `pose` must hold 72 finite axis-angle values and `transl` 3 finite values",
                args.poses.display()
            );
        }
        let params = smpl_deform::SmplParams {
            pose: e.pose,
            betas: loaded.manifest.betas.clone(),
            transl: e.transl,
        };
        let pose = loaded.body.prepare(&params)?;
        let r = t.render(
            &loaded.camera,
            &pose,
            t.latent_for(e.latent_frame.unwrap_or(first)),
        )?;
        let path = args.out.join(format!("render_{k:04}.png"));
        scene::write_rgb(
            &path,
            &scene::Rgb {
                width: loaded.camera.width,
                height: loaded.camera.height,
                data: r.rgb.clone(),
            },
            scene::ImageEncoding {
                bit_depth: 8,
                transfer: scene::Transfer::Srgb,
            },
        )
        .with_context(|| format!("writing {}", path.display()))?;
        if args.ply {
            let ply = args.out.join(format!("posed_{k:04}.ply"));
            gaussians::ply::write_ply(&ply, &train::export::posed_set(t, &r.posed))
                .with_context(|| format!("writing {}", ply.display()))?;
        }
        println!("{}", path.display());
    }
    Ok(())
}
