//! `cargo xtask`: the project driver. It parses arguments, shows progress and orchestrates file I/O;
//! every algorithm lives in a library crate where it is tested and benchmarked. `commands/` holds one
//! module per command (named after it), `outputs/` what several commands write (the run report,
//! its pictures, the pose report), and the rest the driver's own plumbing (paths, allocator,
//! hypervisor steal).

use anyhow::Result;
use clap::{Parser, Subcommand};

mod allocator;
mod commands;
mod common;
mod outputs;
mod poses_json;
mod steal;
mod training;

use commands::{
    ablate, bench, body, body_convert, deblur_edi, eval, events, flow, flow_import_t7, fuzz,
    import, lpips, ply_info, reconstruct, render, render_pose, synth, train_flow,
};

/// E-Sem3DGS driver: reconstruct people and scenes from blurred video + events, on the CPU.
#[derive(Parser, Debug)]
#[command(name = "cargo xtask", bin_name = "cargo xtask", version, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Train E-Sem3DGS (person + scene) on a scene directory — by default the synthetic benchmark —
    /// then evaluate the test split and write the model, metrics.json, strips and report.html.
    ///
    /// Every training option below overrides the preset and the --config file. The default is the
    /// best method measured within the `quick` preset's time budget: the physical model of the blur (each training frame the mean of 9 renders
    /// over its exposure) with the events between those renders when the scene has events, their
    /// counts read as lower bounds on the change as a sensor with a refractory period gives them
    /// (with a fixed camera each event read as 1.25 of the sensor's thresholds, for the crossings
    /// it drops),
    /// each pixel's cost capped at one threshold, a pixel that fired both polarities left
    /// unconstrained and the event term at weight 2, falling to a tenth after densification
    /// (`--event-weight-final-fraction 1` keeps it; `--event-loss off`: the
    /// exposure model alone), and with one person the body's change over each exposure learned per frame around
    /// the band-limited interpolation of the given poses; when the camera moves, each training
    /// frame's camera corrected from the images (`--camera-correction off` keeps the given
    /// cameras). The previous default is `--event-weight-final-fraction 1`; before it `--event-threshold-scale 1`; before it `--exposure-motion
    /// given --body-interpolation local --lr-means 1.6e-4`; before it `--event-weight 1`, then also `--subframes 5
    /// --event-ignore-mixed off`, then also `--event-residual-cap 0`; the squared event loss is `--event-penalty squared
    /// --event-weight 0.3 --event-modulation off --event-threshold-scale 1`. The 2-D cascade baseline (every
    /// frame deblurred by EDI first) is `--train-on edi --blur-model none --event-loss off`. The
    /// paper's own configuration (one render per frame, the event-flow loss) is
    /// `--blur-model none --event-loss off --flow-loss on --flow-source events`.
    Reconstruct(reconstruct::Args),
    /// The paper's ablation set (semantics none/scalar/one-hot, event loss, flow loss with
    /// ground-truth and event-only flow) plus the exposure model, the exposure model with events and
    /// the sharp-trained ceiling: one reconstruct run each, a Markdown table, ablation.json and an
    /// image grid.
    Ablate(ablate::Args),
    /// Evaluate a saved model on a scene's test split (metrics.json + comparison strips).
    Eval(eval::Args),
    /// Render a saved model in new body poses (PNG, optionally posed 3DGS PLY).
    RenderPose(render_pose::Args),
    /// Print a summary of a 3DGS PLY file (counts, SH degree, extra properties, bounds).
    PlyInfo(ply_info::Args),
    /// Pose a body model (SMPL .npz or builtin:makehuman) with SMPL parameters; write .npy or .obj.
    Body(body::Args),
    /// Convert the CC0 MakeHuman assets into data-fixtures/body/makehuman.npz.
    BodyConvert(body_convert::Args),
    /// Generate the synthetic motion-blur benchmark (scene format v1) into a directory.
    Synth(synth::Args),
    /// Optical flow between two images with the SPyNet-style network.
    Flow(flow::Args),
    /// LPIPS distance (AlexNet, v0.1) between two images of the same size; the number is the last
    /// line printed.
    Lpips(lpips::Args),
    /// Convert the original SPyNet Torch7 files into a safetensors weights file.
    FlowImportT7(flow_import_t7::Args),
    /// Train SPyNet-style weights on procedural pairs (coarse to fine, EPE loss).
    TrainFlow(train_flow::Args),
    /// Render a 3DGS PLY from a camera to PNG/EXR (optionally with gradients of Σ render·W to .npz).
    Render(render::Args),
    /// Event streams: info, convert, voxelize, simulate, flow (contrast maximisation).
    Events(events::Args),
    /// Deblur every frame of a scene on its own by the event double integral (EDI) and write the
    /// frames as PNG, scored against the sharp references when the scene has them (the 2-D
    /// baseline that `reconstruct --train-on edi` trains on).
    DeblurEdi(deblur_edi::Args),
    /// Bring your own data: a scene (format v1) from the layouts people have.
    #[command(subcommand)]
    Import(import::Command),
    /// Fuzz the parsers of user files with mutated inputs (worker processes under a memory and a
    /// time limit); any panic, abort, hang or over-allocation fails, its input saved under
    /// target/fuzz/TARGET/.
    Fuzz(fuzz::Args),
    /// Benchmarks, printed as JSON lines.
    #[command(subcommand)]
    Bench(bench::Command),
}

fn main() -> Result<()> {
    allocator::keep_freed_pages();
    let cli = Cli::parse();
    match cli.command {
        Command::Reconstruct(args) => reconstruct::run(args),
        Command::Ablate(args) => ablate::run(args),
        Command::Eval(args) => eval::run(args),
        Command::RenderPose(args) => render_pose::run(args),
        Command::PlyInfo(args) => ply_info::run(args),
        Command::Body(args) => body::run(args),
        Command::BodyConvert(args) => body_convert::run(args),
        Command::Synth(args) => synth::run(args),
        Command::Flow(args) => flow::run(args),
        Command::Lpips(args) => lpips::run(args),
        Command::FlowImportT7(args) => flow_import_t7::run(args),
        Command::TrainFlow(args) => train_flow::run(args),
        Command::Events(args) => events::run(args),
        Command::DeblurEdi(args) => deblur_edi::run(args),
        Command::Bench(command) => bench::run(command),
        Command::Render(args) => render::run(args),
        Command::Fuzz(args) => fuzz::run(args),
        Command::Import(command) => import::run(command),
    }
}
