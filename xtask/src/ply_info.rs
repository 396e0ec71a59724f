//! `cargo xtask ply-info`: summarise a 3DGS PLY file.

use anyhow::Result;
use std::path::PathBuf;

/// Arguments of `ply-info`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The PLY file to read.
    pub ply: PathBuf,
}

/// Runs `ply-info`.
pub fn run(args: Args) -> Result<()> {
    println!("{}", args.ply.display());
    Ok(())
}
