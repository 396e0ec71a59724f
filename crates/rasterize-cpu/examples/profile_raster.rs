//! Profiling driver: renders (and optionally differentiates) one seeded synthetic scene a few times,
//! printing per-run timings and FNV-1a hashes of the image/alpha/depth bits and of every gradient's
//! bits (to check that an optimisation leaves the results unchanged). Meant for `perf record` / `valgrind --tool=callgrind`:
//!
//! `cargo build --release -p rasterize-cpu --example profile_raster`, then
//! `RAYON_NUM_THREADS=1 target/release/examples/profile_raster [N W H [fwd|bwd [REPEATS]]]`
//! (defaults: 50000 256 256 fwd 1).

use rasterize_cpu::synthetic::SyntheticScene;
use rasterize_cpu::{render, render_backward, Cotangents, RasterError, RenderSettings};

fn main() -> Result<(), RasterError> {
    let args: Vec<String> = std::env::args().collect();
    let arg = |i: usize, default: usize| -> usize {
        args.get(i).and_then(|s| s.parse().ok()).unwrap_or(default)
    };
    let n = arg(1, 50_000);
    let w = arg(2, 256) as u32;
    let h = arg(3, 256) as u32;
    let bwd = args.get(4).is_some_and(|s| s == "bwd");
    let reps = arg(5, 1);
    let scene = SyntheticScene::new(n, w, h, 42)?;
    let settings = RenderSettings::default();
    let d_image = vec![1.0f32; 3 * (w as usize) * (h as usize)];
    for _ in 0..reps {
        let t0 = std::time::Instant::now();
        let out = render(&scene.camera, &scene.splats(), &settings)?;
        let t_fwd = t0.elapsed().as_secs_f64() * 1e3;
        let mut hash = 0xcbf2_9ce4_8422_2325u64;
        for v in out.image.iter().chain(&out.alpha).chain(&out.depth) {
            hash = (hash ^ u64::from(v.to_bits())).wrapping_mul(0x0100_0000_01b3);
        }
        let mut grad_sum = 0.0f64;
        let mut grad_hash = 0xcbf2_9ce4_8422_2325u64;
        if bwd {
            let cot = Cotangents {
                image: &d_image,
                alpha: None,
                depth: None,
            };
            let g = render_backward(&scene.camera, &scene.splats(), &settings, &out, &cot)?;
            grad_sum = g.means.iter().map(|m| f64::from(m[0])).sum();
            let all = g
                .means
                .iter()
                .flatten()
                .chain(g.log_scales.iter().flatten());
            let all = all.chain(g.quats.iter().flatten()).chain(&g.opacity_logits);
            let all = all.chain(&g.channels).chain(g.means_2d.iter().flatten());
            for v in all.chain(&g.background) {
                grad_hash = (grad_hash ^ u64::from(v.to_bits())).wrapping_mul(0x0100_0000_01b3);
            }
        }
        let t_all = t0.elapsed().as_secs_f64() * 1e3;
        println!(
            "fwd {t_fwd:.2} ms, total {t_all:.2} ms, pairs {}, image hash {hash:016x}, sum dL/dx {grad_sum:.9e}, gradient hash {grad_hash:016x}",
            out.num_pairs
        );
    }
    Ok(())
}
