//! `cargo xtask import <layout>`: a scene (format v1) from the data people have. Each layout writes
//! a validated scene directory that `cargo xtask reconstruct --data SCENE` trains on.

use anyhow::Result;
use clap::Subcommand;

mod frames;

/// The layouts `import` reads.
#[derive(Subcommand, Debug)]
pub enum Command {
    /// A folder of video frames (PNG) plus one SMPL pose per frame. Optionally synthesises what the
    /// paper synthesised for ZJU-MoCap-Blur: blur by averaging K consecutive frames (the middle
    /// frame kept as the sharp reference) and events by ESIM over the frames.
    Frames(frames::Args),
}

/// Runs `import`.
pub fn run(command: Command) -> Result<()> {
    match command {
        Command::Frames(args) => frames::run(args),
    }
}
