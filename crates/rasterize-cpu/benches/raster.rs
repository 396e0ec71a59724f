#![allow(missing_docs)] // criterion_group! generates an undocumented function.
//! Criterion benchmarks of the rasterizer on the `cargo xtask bench raster` cases (seeded random
//! scenes): forward, forward + backward with a constant cotangent, and the backward alone with a
//! dense and with a row-sparse cotangent.

use criterion::{criterion_group, criterion_main, Criterion};
use rasterize_cpu::synthetic::SyntheticScene;
use rasterize_cpu::{render, RasterError, RenderOutput, RenderSettings};

/// The backward of `scene` for an image cotangent, reduced to a count so that the work is not
/// optimised away.
fn backward(
    scene: &SyntheticScene,
    settings: &RenderSettings,
    out: &RenderOutput<f32>,
    image: &[f32],
) -> Result<usize, RasterError> {
    scene.backward(settings, out, image).map(|g| g.means.len())
}

fn bench_case(c: &mut Criterion, name: &str, n: usize, w: u32, h: u32) {
    let scene = match SyntheticScene::new(n, w, h, 42) {
        Ok(s) => s,
        Err(e) => panic!("scene: {e}"),
    };
    let settings = RenderSettings::default();
    let d_image = scene.image_cotangent(false);
    let mut group = c.benchmark_group(name);
    group.sample_size(10);
    group.bench_function("fwd", |b| {
        b.iter(|| render(&scene.camera, &scene.splats(), &settings).map(|o| o.num_pairs))
    });
    group.bench_function("fwd_bwd", |b| {
        b.iter(|| {
            let out = render(&scene.camera, &scene.splats(), &settings)?;
            backward(&scene, &settings, &out, &d_image)
        })
    });
    // Backward alone, with the forward done once outside the loop: a dense cotangent, and one that
    // is zero on rows 2, 3, 6, 7, ... as where a loss reads the image through a 1/4 bilinear resize
    // (the flow loss), which the backward skips.
    let out = match render(&scene.camera, &scene.splats(), &settings) {
        Ok(o) => o,
        Err(e) => panic!("render: {e}"),
    };
    let half_rows = scene.image_cotangent(true);
    for (label, cot) in [("bwd", &d_image), ("bwd_half_rows", &half_rows)] {
        group.bench_function(label, |b| b.iter(|| backward(&scene, &settings, &out, cot)));
    }
    group.finish();
}

fn benches(c: &mut Criterion) {
    bench_case(c, "50k_256", 50_000, 256, 256);
    bench_case(c, "100k_256", 100_000, 256, 256);
    if std::env::var_os("RASTER_BENCH_1M").is_some() {
        bench_case(c, "1m_1080p", 1_000_000, 1920, 1080);
    }
}

criterion_group!(raster, benches);
criterion_main!(raster);
