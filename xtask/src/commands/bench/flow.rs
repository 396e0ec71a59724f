//! `cargo xtask bench flow [--quick]`: times the SPyNet forward pass and forward + input-gradient pass
//! on seeded random images and prints one JSON line per case
//! `{"case","width","height","levels","threads","fwd_ms","fwd_bwd_ms"}` (medians over repeats), for
//! 1 thread and for the machine's threads; plus `steal_pct`, the hypervisor's steal time during the
//! case (null off Linux).

use anyhow::Result;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::time::Instant;

/// Arguments of `bench flow`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Fewer repeats (a smoke run).
    #[arg(long)]
    pub quick: bool,
    /// Thread counts to run (default: 1 and all available).
    #[arg(long, value_delimiter = ',')]
    pub threads: Vec<usize>,
    /// Pyramid levels of the (randomly initialised) network.
    #[arg(long, default_value_t = 4)]
    pub levels: usize,
}

/// Runs the benchmark cases.
pub fn run(args: Args) -> Result<()> {
    let threads = crate::common::bench_threads(&args.threads);
    let repeats = if args.quick { 3 } else { 9 };
    let net = flow::SpyNet::<f32>::random(args.levels, 1);
    for (name, size) in [("pair_64", 64usize), ("pair_256", 256)] {
        let n = 3 * size * size;
        let mut rng = ChaCha8Rng::seed_from_u64(0x1234_5678);
        let a: Vec<f32> = (0..n).map(|_| rng.gen()).collect();
        let b: Vec<f32> = (0..n).map(|_| rng.gen()).collect();
        super::per_thread_count(&threads, |_| {
            let (mut fwd, mut both) = (Vec::new(), Vec::new());
            for _ in 0..repeats {
                let s = Instant::now();
                let tape = net.forward(&a, &b, size, size)?;
                fwd.push(s.elapsed().as_secs_f64() * 1e3);
                let g = vec![1.0f32; tape.flow.len()];
                let s = Instant::now();
                let tape = net.forward(&a, &b, size, size)?;
                let _grads = net.backward(&tape, &g, None)?;
                both.push(s.elapsed().as_secs_f64() * 1e3);
            }
            Ok(serde_json::json!({
                "case": name, "width": size, "height": size, "levels": args.levels,
                "fwd_ms": crate::common::median(fwd), "fwd_bwd_ms": crate::common::median(both),
            }))
        })?;
    }
    Ok(())
}
