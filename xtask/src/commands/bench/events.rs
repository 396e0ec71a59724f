//! `cargo xtask bench events [--quick]`: throughput of the `events` crate on seeded synthetic
//! streams, one JSON line per case `{"bench":"events","case","events","threads","seconds","mev_per_s",
//! "target_mev_per_s"}`: voxelising (5 bins, 640x480), then reading every format the crate writes:
//! text, npz, AEDAT 4 (uncompressed, LZ4, zstd), Prophesee EVT 2.0, EVT 3.0 and `.dat`.
//! Files go to a temporary directory that is removed afterwards. Every line also carries `steal_pct`,
//! the hypervisor's steal time during the case (see `steal.rs`; null off Linux).

use std::time::Instant;

use anyhow::{Context, Result};
use events::io::aedat4::{write_aedat4, Compression};
use events::io::prophesee::{write_dat, write_raw, PropheseeFormat};
use events::{Event, EventStream, SensorSize};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Arguments of `bench events`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Fewer events (a smoke run: 2 M instead of 20 M).
    #[arg(long)]
    pub quick: bool,
    /// Run only these cases (comma-separated names as in the JSON lines, e.g.
    /// `read_aedat4_zstd,read_evt3`); all by default.
    #[arg(long, value_delimiter = ',')]
    pub only: Vec<String>,
}

/// `n` events at uniformly random pixels and polarities, 0 or 1 µs apart (seeded, ChaCha8).
fn synthetic(n: usize, sensor: SensorSize) -> EventStream {
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let mut s = EventStream::with_capacity(n);
    s.sensor = Some(sensor);
    let mut t = 0i64;
    for _ in 0..n {
        t += i64::from(rng.gen::<bool>());
        s.push(Event {
            t,
            x: rng.gen_range(0..sensor.width) as u16,
            y: rng.gen_range(0..sensor.height) as u16,
            p: if rng.gen::<bool>() { 1 } else { -1 },
        });
    }
    s
}

fn line(case: &str, n: usize, secs: f64, target: f64, steal: &crate::steal::Meter) {
    let threads = rayon::current_num_threads();
    println!(
        "{}",
        serde_json::json!({
            "bench": "events", "case": case, "events": n, "threads": threads,
            "seconds": secs, "mev_per_s": n as f64 / secs / 1e6, "target_mev_per_s": target,
            "steal_pct": steal.percent(),
        })
    );
}

fn best_of(repeats: usize, mut f: impl FnMut() -> Result<()>) -> Result<f64> {
    let mut best = f64::INFINITY;
    for _ in 0..repeats {
        let t = Instant::now();
        f()?;
        best = best.min(t.elapsed().as_secs_f64());
    }
    Ok(best)
}

/// Names of the cases, in the order they run.
const CASES: [&str; 9] = [
    "voxelize_5bins_640x480",
    "read_text",
    "read_npz",
    "read_aedat4",
    "read_aedat4_lz4",
    "read_aedat4_zstd",
    "read_evt2",
    "read_evt3",
    "read_dat",
];

/// Runs the benchmark cases.
pub fn run(args: Args) -> Result<()> {
    let n = if args.quick { 2_000_000 } else { 20_000_000 };
    let repeats = if args.quick { 2 } else { 3 };
    let sensor = SensorSize::new(640, 480);
    let s = synthetic(n, sensor);
    if let Some(bad) = args.only.iter().find(|c| !CASES.contains(&c.as_str())) {
        anyhow::bail!("--only: unknown case `{bad}` (cases: {})", CASES.join(", "));
    }
    let wanted = |case: &str| args.only.is_empty() || args.only.iter().any(|c| c == case);
    let (t0, t1) = (s.t[0], s.t[n - 1] + 1);
    if wanted("voxelize_5bins_640x480") {
        let steal = crate::steal::Meter::start();
        let secs = best_of(repeats, || {
            let g = events::voxel_grid(&s.as_slice(), sensor, 5, t0, t1, false)?;
            std::hint::black_box(g);
            Ok(())
        })?;
        line("voxelize_5bins_640x480", n, secs, 50.0, &steal);
    }

    let dir = std::env::temp_dir().join(format!("xtask-bench-events-{}", std::process::id()));
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let result = (|| -> Result<()> {
        type Writer = fn(&std::path::Path, &EventStream) -> events::Result<()>;
        let cases: [(&str, &str, f64, Writer); 8] = [
            ("read_text", "e.txt", 5.0, |p, s| events::write_events(p, s)),
            ("read_npz", "e.npz", 30.0, |p, s| events::write_events(p, s)),
            ("read_aedat4", "e.aedat4", 30.0, |p, s| {
                write_aedat4(p, s, Compression::None)
            }),
            ("read_aedat4_lz4", "l.aedat4", 30.0, |p, s| {
                write_aedat4(p, s, Compression::Lz4)
            }),
            ("read_aedat4_zstd", "z.aedat4", 30.0, |p, s| {
                write_aedat4(p, s, Compression::Zstd)
            }),
            ("read_evt2", "e2.raw", 30.0, |p, s| {
                write_raw(p, s, PropheseeFormat::Evt2)
            }),
            ("read_evt3", "e3.raw", 30.0, |p, s| {
                write_raw(p, s, PropheseeFormat::Evt3)
            }),
            ("read_dat", "e.dat", 30.0, |p, s| write_dat(p, s)),
        ];
        for (case, file, target, write) in cases {
            if !wanted(case) {
                continue;
            }
            let p = dir.join(file);
            write(&p, &s).with_context(|| format!("writing {}", p.display()))?;
            let steal = crate::steal::Meter::start();
            let secs = best_of(repeats, || {
                let r = events::read_events(&p)?;
                anyhow::ensure!(r.len() == n, "{case}: read {} of {n} events", r.len());
                Ok(())
            })?;
            line(case, n, secs, target, &steal);
            let _ = std::fs::remove_file(&p);
        }
        Ok(())
    })();
    let _ = std::fs::remove_dir_all(&dir);
    result
}
