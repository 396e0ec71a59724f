//! Same cases as `cargo xtask bench raster`, runnable without building the whole workspace:
//! `cargo run --release -p rasterize-cpu --example bench_raster [quick]`.

use rasterize_cpu::synthetic::{time_case, SyntheticScene};

fn main() -> Result<(), rasterize_cpu::RasterError> {
    let quick = std::env::args().any(|a| a == "quick");
    let mut cases = vec![
        ("50k_256", 50_000usize, 256u32, 256u32, 15usize),
        ("100k_256", 100_000, 256, 256, 11),
    ];
    if !quick {
        cases.push(("1m_1080p", 1_000_000, 1920, 1080, 3));
    }
    for (name, n, w, h, reps) in cases {
        let scene = SyntheticScene::new(n, w, h, 42)?;
        for threads in [1, 2] {
            let t = time_case(&scene, threads, if quick { 3 } else { reps })?;
            println!(
                "{}",
                serde_json::json!({"case": name, "gaussians": n, "width": w, "height": h, "threads": threads,
                    "fwd_ms": (t.fwd_ms * 100.0).round() / 100.0, "fwd_bwd_ms": (t.fwd_bwd_ms * 100.0).round() / 100.0,
                    "fwd_bwd_half_rows_ms": (t.fwd_bwd_half_rows_ms * 100.0).round() / 100.0, "pairs": t.pairs})
            );
        }
    }
    Ok(())
}
