//! `cargo xtask flow-import-t7 --dir DIR --variant F|C|K|3|4 --out W.safetensors`: converts the
//! original SPyNet per-layer Torch7 files (which the user must obtain and may not redistribute) into
//! the project's safetensors layout.

use anyhow::{bail, Context, Result};
use std::path::PathBuf;

/// Arguments of `flow-import-t7`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Directory holding `modelL{level}_{variant}-{conv}-{weight|bias}.t7`.
    #[arg(long)]
    pub dir: PathBuf,
    /// Model variant letter: F, C, K, 3 or 4.
    #[arg(long)]
    pub variant: String,
    /// Output safetensors file.
    #[arg(long)]
    pub out: PathBuf,
}

/// Runs the command.
pub fn run(args: Args) -> Result<()> {
    if !["F", "C", "K", "3", "4"].contains(&args.variant.as_str()) {
        bail!(
            "unknown variant {:?} (expected F, C, K, 3 or 4)",
            args.variant
        );
    }
    let net = flow::t7::import_dir(&args.dir, &args.variant)
        .with_context(|| format!("importing Torch7 files from {}", args.dir.display()))?;
    flow::save_safetensors(&net, &args.out)
        .with_context(|| format!("writing {}", args.out.display()))?;
    eprintln!(
        "imported {} levels ({} parameters) into {}",
        net.num_levels(),
        net.num_parameters(),
        args.out.display()
    );
    Ok(())
}
