//! `cargo xtask bench <what>`: benchmarks printed as JSON lines, and the harness they share (one
//! rayon pool per thread count, the hypervisor's steal time beside every figure).

mod deform;
mod events;
mod flow;
mod lpips;
mod raster;
mod step;

use anyhow::{Context, Result};

/// `cargo xtask bench <what>`.
#[derive(clap::Subcommand, Debug)]
pub enum Command {
    /// Event voxelising and reading throughput of every format the `events` crate writes.
    Events(events::Args),
    /// SPyNet forward and forward + input-gradient times.
    Flow(flow::Args),
    /// LPIPS (shipped AlexNet weights): one image's features, a distance, a distance with its gradient.
    Lpips(lpips::Args),
    /// Posing N human Gaussians (non-rigid net + skinning field + LBS), forward and backward times.
    Deform(deform::Args),
    /// Rasterizer forward and forward + backward times on seeded random scenes.
    Raster(raster::Args),
    /// The training step's stage breakdown from a saved checkpoint (a few unsaved steps).
    Step(step::Args),
}

/// Runs a benchmark.
pub fn run(command: Command) -> Result<()> {
    match command {
        Command::Events(args) => events::run(args),
        Command::Flow(args) => flow::run(args),
        Command::Lpips(args) => lpips::run(args),
        Command::Deform(args) => deform::run(args),
        Command::Raster(args) => raster::run(args),
        Command::Step(args) => step::run(args),
    }
}

/// Runs `case` once per thread count of `threads` inside a rayon pool of that many threads, and
/// prints the JSON object it returns with `threads` and `steal_pct` (the hypervisor's steal time
/// during the case; null off Linux) added: one line per thread count.
fn per_thread_count(
    threads: &[usize],
    mut case: impl FnMut(usize) -> Result<serde_json::Value> + Send,
) -> Result<()> {
    for &t in threads {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(t)
            .build()
            .context("building thread pool")?;
        let steal = crate::steal::Meter::start();
        let mut line = pool.install(|| case(t))?;
        if let Some(obj) = line.as_object_mut() {
            obj.insert("threads".into(), serde_json::json!(t));
            obj.insert("steal_pct".into(), serde_json::json!(steal.percent()));
        }
        println!("{line}");
    }
    Ok(())
}
