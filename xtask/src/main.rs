//! `cargo xtask`: the project driver. It parses arguments, shows progress and orchestrates file I/O;
//! every algorithm lives in a library crate where it is tested and benchmarked.

use anyhow::Result;
use clap::{Parser, Subcommand};

mod body;
mod body_convert;
mod ply_info;

/// E-Sem3DGS driver: reconstruct people and scenes from blurred video + events, on the CPU.
#[derive(Parser, Debug)]
#[command(name = "cargo xtask", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Print a summary of a 3DGS PLY file (counts, SH degree, extra properties, bounds).
    PlyInfo(ply_info::Args),
    /// Pose a body model (SMPL .npz or builtin:makehuman) with SMPL parameters; write .npy or .obj.
    Body(body::Args),
    /// Convert the CC0 MakeHuman assets into data-fixtures/body/makehuman.npz.
    BodyConvert(body_convert::Args),
}

fn main() -> Result<()> {
    let cli = Cli::parse();
    match cli.command {
        Command::PlyInfo(args) => ply_info::run(args),
        Command::Body(args) => body::run(args),
        Command::BodyConvert(args) => body_convert::run(args),
    }
}
