//! `cargo xtask`: the project driver. It parses arguments, shows progress and orchestrates file I/O;
//! every algorithm lives in a library crate where it is tested and benchmarked.

use anyhow::Result;
use clap::{Parser, Subcommand};

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
}

fn main() -> Result<()> {
    let cli = Cli::parse();
    match cli.command {
        Command::PlyInfo(args) => ply_info::run(args),
    }
}
