//! Seeded random scenes for benchmarks and tests: Gaussians spread in front of a camera with sizes
//! chosen so that a pixel sees tens of splats. Deterministic from the seed (SplitMix64), independent
//! of thread count. Not a scene model: it must never be used as training data.

use crate::{Camera, RasterError};

/// A random scene in f32, structure-of-arrays, with 3 colour channels.
#[derive(Clone, Debug)]
pub struct SyntheticScene {
    /// The camera (looking down +z from the origin, principal point at the centre, ~60° fov).
    pub camera: Camera,
    /// Means (world, metres).
    pub means: Vec<[f32; 3]>,
    /// Log-scales (ln metres).
    pub log_scales: Vec<[f32; 3]>,
    /// Quaternions (w, x, y, z), unnormalised.
    pub quats: Vec<[f32; 4]>,
    /// Opacity logits.
    pub opacity_logits: Vec<f32>,
    /// RGB channels, N × 3.
    pub channels: Vec<f32>,
}

struct SplitMix(u64);

impl SplitMix {
    fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 53) as f64
    }
    fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.next()
    }
    fn normal(&mut self) -> f64 {
        let u1 = self.next().max(1e-300);
        let u2 = self.next();
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }
}

impl SyntheticScene {
    /// `n` Gaussians for a `width` × `height` view. Screen footprints are log-normal around
    /// 0.9·√(pixels / n) pixels (σ), depths uniform in [2, 8] m, opacities sigmoid(U(−1, 3)).
    pub fn new(n: usize, width: u32, height: u32, seed: u64) -> Result<Self, RasterError> {
        let f = f64::from(width) * 0.85;
        let camera = Camera::looking_down_z(width, height, f, f)?;
        let mut rng = SplitMix(seed);
        let sigma_px = 0.9 * (f64::from(width) * f64::from(height) / n.max(1) as f64).sqrt();
        let mut s = Self {
            camera,
            means: Vec::with_capacity(n),
            log_scales: Vec::with_capacity(n),
            quats: Vec::with_capacity(n),
            opacity_logits: Vec::with_capacity(n),
            channels: Vec::with_capacity(3 * n),
        };
        let (w, h) = (f64::from(width), f64::from(height));
        for _ in 0..n {
            let z = rng.uniform(2.0, 8.0);
            let u = rng.uniform(-0.05 * w, 1.05 * w);
            let v = rng.uniform(-0.05 * h, 1.05 * h);
            let x = (u - w * 0.5) / f * z;
            let y = (v - h * 0.5) / f * z;
            s.means.push([x as f32, y as f32, z as f32]);
            let base = (sigma_px * z / f).ln() + 0.5 * rng.normal();
            let mut ls = [0.0f32; 3];
            for l in &mut ls {
                *l = (base + 0.4 * rng.normal()) as f32;
            }
            s.log_scales.push(ls);
            s.quats.push([
                rng.normal() as f32,
                rng.normal() as f32,
                rng.normal() as f32,
                rng.normal() as f32 + 1e-3,
            ]);
            s.opacity_logits.push(rng.uniform(-1.0, 3.0) as f32);
            for _ in 0..3 {
                s.channels.push(rng.next() as f32);
            }
        }
        Ok(s)
    }

    /// The scene as rasterizer input.
    pub fn splats(&self) -> crate::Splats<'_, f32> {
        crate::Splats {
            means: &self.means,
            log_scales: &self.log_scales,
            quats: &self.quats,
            opacity_logits: &self.opacity_logits,
            channels: &self.channels,
            num_channels: 3,
        }
    }

    /// An image cotangent `(3, H, W)` of ones, zero on rows 2, 3, 6, 7, … when `half_rows` — the
    /// rows a loss that reads the image through a 1/4 bilinear resize (the flow loss) leaves
    /// untouched, which the backward skips.
    pub fn image_cotangent(&self, half_rows: bool) -> Vec<f32> {
        let (w, h) = (self.camera.width as usize, self.camera.height as usize);
        (0..3 * w * h)
            .map(|i| {
                let row = (i % (w * h).max(1)) / w.max(1);
                if half_rows && row % 4 >= 2 {
                    0.0
                } else {
                    1.0
                }
            })
            .collect()
    }

    /// The rasterizer's backward of the scene's render `forward` for an image cotangent `image`
    /// (no alpha or depth cotangent).
    pub fn backward(
        &self,
        settings: &crate::RenderSettings,
        forward: &crate::RenderOutput<f32>,
        image: &[f32],
    ) -> Result<crate::Gradients<f32>, RasterError> {
        let cot = crate::Cotangents {
            image,
            alpha: None,
            depth: None,
        };
        crate::render_backward(&self.camera, &self.splats(), settings, forward, &cot)
    }
}

/// Median timings of one benchmark case (milliseconds).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Timing {
    /// Median forward time.
    pub fwd_ms: f64,
    /// Median forward + backward time (constant cotangent 1 on the image).
    pub fwd_bwd_ms: f64,
    /// Median forward + backward time with the cotangent zero on rows 2, 3, 6, 7, … — the rows a
    /// loss that reads the image through a 1/4 bilinear resize (the flow loss) leaves untouched,
    /// which the backward skips.
    pub fwd_bwd_half_rows_ms: f64,
    /// (tile, Gaussian) pairs of the render.
    pub pairs: usize,
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
}

/// Times `render`, and `render` + `render_backward` with a dense and a row-sparse cotangent, on
/// `scene` in a rayon pool of `threads` threads: one warm-up, then `repeats` timed runs of each;
/// returns medians.
pub fn time_case(
    scene: &SyntheticScene,
    threads: usize,
    repeats: usize,
) -> Result<Timing, RasterError> {
    use std::time::Instant;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|e| {
            RasterError::InvalidSettings(format!("rayon pool of {threads} threads: {e}"))
        })?;
    let settings = crate::RenderSettings::default();
    let (d_image, half_rows) = (scene.image_cotangent(false), scene.image_cotangent(true));
    let forward_backward = |cotangent: &[f32]| -> Result<f64, RasterError> {
        let t0 = Instant::now();
        let out = crate::render(&scene.camera, &scene.splats(), &settings)?;
        let grads = scene.backward(&settings, &out, cotangent)?;
        let elapsed = t0.elapsed().as_secs_f64() * 1e3;
        drop(grads);
        Ok(elapsed)
    };
    pool.install(|| {
        let (mut fwd, mut both, mut sparse, mut pairs) = (Vec::new(), Vec::new(), Vec::new(), 0);
        for rep in 0..=repeats {
            let t0 = Instant::now();
            let out = crate::render(&scene.camera, &scene.splats(), &settings)?;
            let t_fwd = t0.elapsed().as_secs_f64() * 1e3;
            pairs = out.num_pairs;
            drop(out);
            let t_both = forward_backward(&d_image)?;
            let t_sparse = forward_backward(&half_rows)?;
            if rep > 0 {
                fwd.push(t_fwd);
                both.push(t_both);
                sparse.push(t_sparse);
            }
        }
        Ok(Timing {
            fwd_ms: median(fwd),
            fwd_bwd_ms: median(both),
            fwd_bwd_half_rows_ms: median(sparse),
            pairs,
        })
    })
}
