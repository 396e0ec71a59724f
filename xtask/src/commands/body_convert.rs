//! `cargo xtask body-convert`: convert the CC0 MakeHuman assets into the built-in body
//! `data-fixtures/body/makehuman.npz` (see `smpl_deform::makehuman` for what the conversion does).

use std::path::PathBuf;

use anyhow::{Context, Result};

/// Arguments of `cargo xtask body-convert`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Directory with `base.obj`, `rig.game_engine.json`, `weights.game_engine.json`, `LICENSE.md`
    /// (default: `<workspace>/../shared/assets/makehuman-cc0`).
    #[arg(long)]
    pub assets: Option<PathBuf>,
    /// Output directory (default: `<workspace>/data-fixtures/body`).
    #[arg(long)]
    pub out_dir: Option<PathBuf>,
}

/// Runs the command.
pub fn run(args: Args) -> Result<()> {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
    let assets = args
        .assets
        .unwrap_or_else(|| root.join("../shared/assets/makehuman-cc0"));
    let out_dir = args
        .out_dir
        .unwrap_or_else(|| root.join("data-fixtures/body"));
    let body = smpl_deform::makehuman::convert_makehuman(&assets)
        .with_context(|| format!("converting {}", assets.display()))?;
    std::fs::create_dir_all(&out_dir).with_context(|| format!("creating {}", out_dir.display()))?;
    let out = out_dir.join("makehuman.npz");
    body.save_body_npz(&out)?;
    let licence = std::fs::read(assets.join("LICENSE.md"))
        .with_context(|| format!("reading the CC0 licence in {}", assets.display()))?;
    let licence_out = out_dir.join("LICENSE.md");
    // The source may be read-only, and so a previous copy: replace rather than overwrite.
    if licence_out.exists() {
        std::fs::remove_file(&licence_out)
            .with_context(|| format!("replacing {}", licence_out.display()))?;
    }
    std::fs::write(&licence_out, licence)
        .with_context(|| format!("writing {}", licence_out.display()))?;
    println!(
        "wrote {} ({} vertices, {} faces)",
        out.display(),
        body.num_vertices(),
        body.faces.len()
    );
    Ok(())
}
