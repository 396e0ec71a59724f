//! `cargo xtask body`: pose a body model with SMPL parameters and write the posed vertices.

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use smpl_deform::{BodyRef, SmplParams};

/// Arguments of `cargo xtask body`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Body model: a SMPL `.npz` path or `builtin:makehuman`.
    #[arg(long)]
    pub model: String,
    /// JSON `{"pose": [72 floats, axis-angle], "betas": [...], "transl": [3]}`.
    #[arg(long)]
    pub params: PathBuf,
    /// Output: `.npy` (float32 (V, 3) posed vertices) or `.obj` (vertices + faces).
    #[arg(long)]
    pub out: PathBuf,
}

/// Runs the command.
pub fn run(args: Args) -> Result<()> {
    let model = BodyRef::parse(&args.model)?
        .load()
        .with_context(|| format!("loading body model {}", args.model))?;
    let text = std::fs::read_to_string(&args.params)
        .with_context(|| format!("reading {}", args.params.display()))?;
    let params: SmplParams = serde_json::from_str(&text)
        .with_context(|| format!("parsing {} (pose/betas/transl)", args.params.display()))?;
    let posed = model
        .pose(&params)
        .with_context(|| format!("posing with {}", args.params.display()))?;
    match args.out.extension().and_then(|e| e.to_str()) {
        Some("npy") => smpl_deform::io::write_npy_vertices(&args.out, &posed.vertices)?,
        Some("obj") => smpl_deform::io::write_obj(&args.out, &posed.vertices, &model.faces)?,
        _ => bail!("--out {}: expected a .npy or .obj path", args.out.display()),
    }
    println!(
        "wrote {} ({} vertices, {} faces)",
        args.out.display(),
        posed.vertices.len(),
        model.faces.len()
    );
    Ok(())
}
