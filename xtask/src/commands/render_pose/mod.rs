//! `cargo xtask render-pose`: render a reconstructed model (person + scene) in new body poses from the
//! training camera, one PNG per pose, optionally with a posed 3DGS PLY (INRIA's degree-3 layout, colours in the DC term).
//!
//! `POSES.json` is one object or a list of objects `{"pose": [72 floats, axis-angle], "transl": [3],
//! "latent_frame": N (optional: whose appearance latent to use; default the first training frame)}`.
//! `pose` may also be 24 axis-angle triples, as `scene.json` writes a frame's pose.
//!
//! With `--motion FILE` (an AMASS or PeopleSnapshot `.npz`) it animates the person inside the
//! reconstructed scene instead, and a model of several people with one `--motion ID=FILE` per
//! person: see [`animate`].

mod animate;

use anyhow::{bail, Context, Result};
use std::path::PathBuf;

/// Arguments of `render-pose`.
#[derive(clap::Args, Debug)]
#[command(group(clap::ArgGroup::new("source").required(true).args(["poses", "motion"])))]
pub struct Args {
    /// Model directory (the `model/` folder written by `cargo xtask reconstruct`).
    #[arg(long)]
    pub model: PathBuf,
    /// JSON file with one pose or a list of poses: `{"pose": 72 axis-angle values or 24 [x, y, z]
    /// triples as scene.json writes them, "transl": [x, y, z], "latent_frame": N (optional)}`.
    #[arg(long)]
    pub poses: Option<PathBuf>,
    /// A motion to animate the person with: an AMASS-style `.npz` (`poses` N×72 SMPL or N×156
    /// SMPL-H, `trans`, optional `mocap_framerate`), a PeopleSnapshot / InstantAvatar `.npz`
    /// (`global_orient`, `body_pose`, `transl`) or an EasyMocap `smpl/` folder of per-frame JSON
    /// (`Rh`, `Th`, `poses`). Writes an animated GIF (or, when `--out` does not end in `.gif`, a
    /// folder of PNG frames). A model of several people: `--motion ID=FILE` once per person to
    /// move (the scene's person ids); the others stand still.
    #[arg(long, value_parser = animate::parse_motion)]
    pub motion: Vec<animate::MotionArg>,
    /// Output directory (`--poses`), or the GIF file or PNG folder (`--motion`).
    #[arg(long)]
    pub out: PathBuf,
    /// Also write `posed_NNNN.ply` per pose (INRIA's degree-3 3DGS layout, colours in the DC term).
    #[arg(long)]
    pub ply: bool,
    /// Options of `--motion`.
    #[command(flatten)]
    pub animation: animate::AnimationArgs,
}

/// Runs `render-pose`.
pub fn run(args: Args) -> Result<()> {
    let loaded = train::export::load_model(&args.model)
        .with_context(|| format!("loading the model {}", args.model.display()))?;
    if !args.motion.is_empty() {
        if args.ply {
            bail!("--ply writes one PLY per pose of --poses; it does not apply to --motion");
        }
        return animate::run(&loaded, &args.motion, &args.out, &args.animation);
    }
    let Some(poses_path) = &args.poses else {
        bail!("give --poses POSES.json or --motion FILE.npz");
    };
    if loaded.model.people() > 1 {
        bail!(
            "{}: the model reconstructs {} people; --poses poses one person (animate several \
             with --motion ID=FILE, one per person)",
            args.model.display(),
            loaded.model.people()
        );
    }
    let text = std::fs::read_to_string(poses_path)
        .with_context(|| format!("reading {}", poses_path.display()))?;
    let value: serde_json::Value = serde_json::from_str(&text)
        .with_context(|| format!("{}: not JSON", poses_path.display()))?;
    let list = match value {
        serde_json::Value::Array(a) => a,
        v => vec![v],
    };
    if list.is_empty() {
        bail!("{}: no poses", poses_path.display());
    }
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let t = &loaded.model;
    let first = t.frame_indices.first().copied().unwrap_or(0);
    for (k, v) in list.into_iter().enumerate() {
        let (pose, transl, latent_frame) = crate::poses_json::read_entry(v)
            .with_context(|| format!("{}: pose {k}", poses_path.display()))?;
        let params = smpl_deform::SmplParams {
            pose,
            betas: loaded.manifest.betas.clone(),
            transl,
        };
        let pose = loaded.body.prepare(&params)?;
        let r = t.render(
            &loaded.camera,
            &pose,
            t.latent_for(latent_frame.unwrap_or(first)),
        )?;
        let path = args.out.join(format!("render_{k:04}.png"));
        scene::write_rgb(
            &path,
            &scene::Rgb {
                width: loaded.camera.width,
                height: loaded.camera.height,
                data: r.rgb.clone(),
            },
            scene::ImageEncoding::rgb(8, scene::Transfer::Srgb),
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
