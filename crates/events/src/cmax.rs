//! Event-only dense optical flow by contrast maximisation (Gallego et al., CVPR 2018), per tile.
//!
//! Events of a window `[t_a, t_b)` are warped to the middle of the window with a per-tile constant
//! velocity: `x' = x − s·v(x)`, `s = (t − t_a)/(t_b − t_a) − 1/2` ∈ [−1/2, 1/2), where `v` (pixels per
//! window; the symmetric reference halves the error of evaluating `v` at the observed position)
//! is the bilinear interpolation of the tile velocities at the event's pixel. The warped events vote
//! bilinearly into an image of warped events (IWE), blurred by a Gaussian (σ = 0.7 px by default),
//! and the sharpness objective `variance(IWE) − λ·Σ_neighbour‖v_i − v_j‖² − κ·mean‖Δ²v‖² −
//! μ·mean(div v)²` is maximised with its analytic gradient, coarse to fine: level 0 fits one affine
//! field (6 parameters, represented on 2×2 tiles), then tile grids of 2×2, 4×4, 8×8, … start from
//! the coarser result. The dense flow is the bilinear interpolation of the tile velocities: the
//! displacement from frame k (at `t_a`) to frame k+1 (at `t_b`), in pixels (constant-velocity
//! model).
//!
//! Accuracy (tests/cmax.rs, 96×96 textured plane): translation (2.5, −1.5) px: average end-point
//! error 0.14 px; rotation 0.04 rad + translation (1.5, 1) px: 0.46 px (was 0.99 px with a constant
//! level 0, per-parameter Adam and the first-order smoothness term, which pulls a rotation towards
//! a translation; the curvature term κ leaves every affine field free instead).
//!
//! The objective is evaluated in f64 so that the finite-difference check in `tests/gradient-checks`
//! can hold it to tight tolerances. This module knows nothing of frames or the flow network.

use crate::error::{EventsError, Result};
use crate::flowio::Flow;
use crate::stream::{EventSlice, SensorSize};

/// Contrast-maximisation settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CmaxConfig {
    /// Pyramid levels: level l has 2^l × 2^l tiles (level 0 = one global flow).
    pub levels: usize,
    /// Optimiser iterations per tile level.
    pub iterations: usize,
    /// Optimiser iterations of the affine level 0 (one field `v(p) = a + B·(p − c)`, 6 parameters,
    /// on a 2×2 tile grid); 0 replaces it by one constant flow (1×1 tile). A constant cannot
    /// follow a rotation: it settles on the velocity of the busiest region, and the finer levels
    /// then start up to a pixel off.
    pub affine_iterations: usize,
    /// Optimiser step at the start of level 0 (pixels per window; level l uses step/(l+1)); decays
    /// to a tenth by the end of each level.
    pub learning_rate: f64,
    /// Weight λ of the first-order smoothness penalty `λ·Σ_neighbours‖v_i − v_j‖²` (relative to the
    /// IWE variance). It pulls every field towards a translation (a 0.04 rad rotation lost half its
    /// amplitude at λ = 0.001), so the default is 0 and [`CmaxConfig::curvature`] regularises.
    pub smoothness: f64,
    /// Weight κ of the curvature penalty `κ·mean(‖v_{i−1} − 2·v_i + v_{i+1}‖²)` over the second
    /// differences of neighbouring tiles along rows and columns (pixels per window). It
    /// vanishes on every affine field (translation, rotation, zoom, shear), so it suppresses the
    /// noise of per-tile estimates without pulling a rotation towards a translation the way the
    /// first-order term λ does.
    pub curvature: f64,
    /// Weight μ of the divergence penalty `μ·mean_cells(div v)²` (div of the tile field in
    /// 1/window, per cell of 2×2 neighbouring tiles). Per-tile contrast maximisation suffers "event
    /// collapse" (Shiba et al., Sensors 2022): converging fields squeeze events together and score
    /// high; translation and rotation have zero divergence, so this term does not bias them.
    pub divergence: f64,
    /// Standard deviation of the Gaussian blur of the IWE (pixels).
    pub blur_sigma: f64,
    /// Dither each event uniformly inside its pixel (deterministic hash of the event index). Events
    /// sit on the integer grid, which makes the objective favour integer displacements (aliasing);
    /// dithering removes that bias.
    pub dither: bool,
}

impl Default for CmaxConfig {
    /// 4 levels (affine, 2×2, 4×4, 8×8 tiles), 150 affine + 3 × 30 tile iterations (the same 240
    /// objective evaluations as the former 4 × 60), step 0.15 px, λ = 0, κ = 0.3, μ = 50, σ = 0.7 px,
    /// dithering on.
    fn default() -> Self {
        Self {
            levels: 4,
            iterations: 30,
            affine_iterations: 150,
            learning_rate: 0.15,
            smoothness: 0.0,
            curvature: 0.3,
            divergence: 50.0,
            blur_sigma: 0.7,
            dither: true,
        }
    }
}

/// Bilinear weights of the 4 tile centres around pixel (x, y) for a `tx × ty` tile grid over a
/// `w × h` image (clamped at the borders): `(tile index, weight)`.
fn tile_weights(x: f64, y: f64, w: usize, h: usize, tx: usize, ty: usize) -> [(u32, f64); 4] {
    let axis = |p: f64, size: usize, n: usize| -> (usize, usize, f64) {
        if n == 1 {
            return (0, 0, 0.0);
        }
        let u = (p + 0.5) * n as f64 / size as f64 - 0.5;
        let u = u.clamp(0.0, (n - 1) as f64);
        let i0 = (u.floor() as usize).min(n - 2);
        (i0, i0 + 1, u - i0 as f64)
    };
    let (x0, x1, fx) = axis(x, w, tx);
    let (y0, y1, fy) = axis(y, h, ty);
    [
        ((y0 * tx + x0) as u32, (1.0 - fx) * (1.0 - fy)),
        ((y0 * tx + x1) as u32, fx * (1.0 - fy)),
        ((y1 * tx + x0) as u32, (1.0 - fx) * fy),
        ((y1 * tx + x1) as u32, fx * fy),
    ]
}

/// The contrast-maximisation objective for one tile grid: `f(v) = var(G_σ * IWE(v)) − R(v)` (R: the
/// smoothness and divergence penalties of [`CmaxConfig`]), with
/// parameters `v = [vx_0, vy_0, vx_1, vy_1, …]` (pixels per window, tiles row-major).
pub struct CmaxProblem {
    width: usize,
    height: usize,
    tiles_x: usize,
    tiles_y: usize,
    x: Vec<f64>,
    y: Vec<f64>,
    s: Vec<f64>,
    weights: Vec<[(u32, f64); 4]>,
    kernel: Vec<f64>,
    smoothness: f64,
    curvature: f64,
    divergence: f64,
}

impl CmaxProblem {
    /// Builds the problem for the events of `[t_a_us, t_b_us)` (others are ignored) on a
    /// `tiles_x × tiles_y` grid.
    pub fn new(
        events: &EventSlice<'_>,
        sensor: SensorSize,
        t_a_us: i64,
        t_b_us: i64,
        tiles_x: usize,
        tiles_y: usize,
        config: &CmaxConfig,
    ) -> Result<Self> {
        if t_b_us <= t_a_us {
            return Err(EventsError::arg(
                "t_b_us",
                format!("{t_b_us} us is not after t_a {t_a_us} us"),
            ));
        }
        if tiles_x == 0 || tiles_y == 0 {
            return Err(EventsError::arg(
                "tiles",
                format!("{tiles_x}x{tiles_y} has no tile"),
            ));
        }
        if !(config.blur_sigma.is_finite() && config.blur_sigma > 0.0) {
            return Err(EventsError::arg(
                "blur_sigma",
                format!("{} must be > 0", config.blur_sigma),
            ));
        }
        let (w, h) = (sensor.width as usize, sensor.height as usize);
        let span = (t_b_us - t_a_us) as f64;
        let (mut x, mut y, mut s, mut weights) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        for (idx, e) in events.iter().enumerate() {
            if e.t < t_a_us || e.t >= t_b_us || e.x as usize >= w || e.y as usize >= h {
                continue;
            }
            let (jx, jy) = if config.dither {
                dither(idx as u64)
            } else {
                (0.0, 0.0)
            };
            let (fx, fy) = (e.x as f64 + jx, e.y as f64 + jy);
            x.push(fx);
            y.push(fy);
            s.push((e.t - t_a_us) as f64 / span - 0.5);
            weights.push(tile_weights(fx, fy, w, h, tiles_x, tiles_y));
        }
        let r = (3.0 * config.blur_sigma).ceil() as i64;
        let mut kernel: Vec<f64> = (-r..=r)
            .map(|k| (-(k * k) as f64 / (2.0 * config.blur_sigma * config.blur_sigma)).exp())
            .collect();
        let sum: f64 = kernel.iter().sum();
        kernel.iter_mut().for_each(|k| *k /= sum);
        Ok(Self {
            width: w,
            height: h,
            tiles_x,
            tiles_y,
            x,
            y,
            s,
            weights,
            kernel,
            smoothness: config.smoothness,
            curvature: config.curvature,
            divergence: config.divergence,
        })
    }

    /// Number of parameters (2 per tile).
    pub fn num_params(&self) -> usize {
        2 * self.tiles_x * self.tiles_y
    }

    /// Number of events inside the window and the sensor.
    pub fn num_events(&self) -> usize {
        self.x.len()
    }

    fn event_velocity(&self, i: usize, v: &[f64]) -> (f64, f64) {
        let (mut vx, mut vy) = (0.0, 0.0);
        for &(k, wgt) in &self.weights[i] {
            vx += wgt * v[2 * k as usize];
            vy += wgt * v[2 * k as usize + 1];
        }
        (vx, vy)
    }

    /// Separable Gaussian blur with zero padding (self-adjoint, so it also backpropagates).
    ///
    /// Every output sums `kernel[k]·input` over the in-range taps in ascending `k`, starting from
    /// 0.0 (the order fixes the bits); the loops only hoist the range test out of the inner loop,
    /// and the vertical pass runs along rows so it vectorises.
    fn blur(&self, img: &[f64]) -> Vec<f64> {
        let (w, h) = (self.width, self.height);
        let r = self.kernel.len() / 2;
        let taps = self.kernel.len();
        // In-range taps of output index i on an axis of length n: k in [lo, hi).
        let range = |i: usize, n: usize| (r.saturating_sub(i), taps.min(n + r - i));
        let mut tmp = vec![0.0; w * h];
        for (row_in, row_out) in img.chunks_exact(w).zip(tmp.chunks_exact_mut(w)) {
            for (xx, o) in row_out.iter_mut().enumerate() {
                let (lo, hi) = range(xx, w);
                let mut acc = 0.0;
                for k in lo..hi {
                    acc += self.kernel[k] * row_in[xx + k - r];
                }
                *o = acc;
            }
        }
        let mut out = vec![0.0; w * h];
        for (yy, row_out) in out.chunks_exact_mut(w).enumerate() {
            let (lo, hi) = range(yy, h);
            for k in lo..hi {
                let kv = self.kernel[k];
                let sy = yy + k - r;
                let row_in = &tmp[sy * w..(sy + 1) * w];
                for (o, &t) in row_out.iter_mut().zip(row_in) {
                    *o += kv * t;
                }
            }
        }
        out
    }

    /// Warped position of event i as its bilinear cell: (ix, iy, fx, fy).
    #[inline]
    fn warp(&self, i: usize, v: &[f64]) -> Cell {
        let (vx, vy) = self.event_velocity(i, v);
        let wx = self.x[i] - self.s[i] * vx;
        let wy = self.y[i] - self.s[i] * vy;
        let (ix, iy) = (floor_i64(wx), floor_i64(wy));
        (ix, iy, wx - ix as f64, wy - iy as f64)
    }

    /// Warps every event once: its bilinear cells, and the unblurred IWE voted from them.
    fn warp_all(&self, v: &[f64]) -> (Vec<Cell>, Vec<f64>) {
        let cells: Vec<_> = (0..self.x.len()).map(|i| self.warp(i, v)).collect();
        let img = self.vote(&cells);
        (cells, img)
    }

    /// Bilinear voting of warped events into an `H × W` image.
    fn vote(&self, cells: &[Cell]) -> Vec<f64> {
        let (w, h) = (self.width as i64, self.height as i64);
        let mut img = vec![0.0; self.width * self.height];
        for &(ix, iy, fx, fy) in cells {
            for (dx, dy, wgt) in [
                (0, 0, (1.0 - fx) * (1.0 - fy)),
                (1, 0, fx * (1.0 - fy)),
                (0, 1, (1.0 - fx) * fy),
                (1, 1, fx * fy),
            ] {
                let (px, py) = (ix + dx, iy + dy);
                if px >= 0 && px < w && py >= 0 && py < h {
                    img[(py * w + px) as usize] += wgt;
                }
            }
        }
        img
    }

    /// The image of warped events (bilinear voting, unblurred), `H × W`.
    pub fn iwe(&self, v: &[f64]) -> Vec<f64> {
        self.warp_all(v).1
    }

    fn smoothness_term(&self, v: &[f64], grad: Option<&mut [f64]>) -> f64 {
        let (tx, ty) = (self.tiles_x, self.tiles_y);
        let mut r = 0.0;
        let mut pairs = Vec::new();
        for j in 0..ty {
            for i in 0..tx {
                let k = j * tx + i;
                if i + 1 < tx {
                    pairs.push((k, k + 1));
                }
                if j + 1 < ty {
                    pairs.push((k, k + tx));
                }
            }
        }
        let mut g = grad;
        for (a, b) in pairs {
            for c in 0..2 {
                let d = v[2 * a + c] - v[2 * b + c];
                r += d * d;
                if let Some(g) = g.as_deref_mut() {
                    g[2 * a + c] -= self.smoothness * 2.0 * d;
                    g[2 * b + c] += self.smoothness * 2.0 * d;
                }
            }
        }
        let mut r = self.smoothness * r;
        if self.curvature != 0.0 {
            // Second differences (a, b, c) along rows and columns: ‖v_a − 2 v_b + v_c‖².
            let mut triples = Vec::new();
            for j in 0..ty {
                for i in 0..tx {
                    let k = j * tx + i;
                    if i + 2 < tx {
                        triples.push((k, k + 1, k + 2));
                    }
                    if j + 2 < ty {
                        triples.push((k, k + tx, k + 2 * tx));
                    }
                }
            }
            let scale = self.curvature / triples.len().max(1) as f64;
            for (a, b, c) in triples {
                for comp in 0..2 {
                    let d = v[2 * a + comp] - 2.0 * v[2 * b + comp] + v[2 * c + comp];
                    r += scale * d * d;
                    if let Some(g) = g.as_deref_mut() {
                        g[2 * a + comp] -= scale * 2.0 * d;
                        g[2 * b + comp] += scale * 4.0 * d;
                        g[2 * c + comp] -= scale * 2.0 * d;
                    }
                }
            }
        }
        if tx > 1 && ty > 1 && self.divergence != 0.0 {
            let (sx, sy) = (
                self.width as f64 / tx as f64,
                self.height as f64 / ty as f64,
            );
            let cells = ((tx - 1) * (ty - 1)) as f64;
            for j in 0..ty - 1 {
                for i in 0..tx - 1 {
                    let (k00, k10) = (j * tx + i, j * tx + i + 1);
                    let (k01, k11) = (k00 + tx, k10 + tx);
                    let du = 0.5 * (v[2 * k10] + v[2 * k11] - v[2 * k00] - v[2 * k01]) / sx;
                    let dv = 0.5
                        * (v[2 * k01 + 1] + v[2 * k11 + 1] - v[2 * k00 + 1] - v[2 * k10 + 1])
                        / sy;
                    let d = du + dv;
                    r += self.divergence * d * d / cells;
                    if let Some(g) = g.as_deref_mut() {
                        let c = self.divergence * 2.0 * d / cells;
                        g[2 * k10] -= c * 0.5 / sx;
                        g[2 * k11] -= c * 0.5 / sx;
                        g[2 * k00] += c * 0.5 / sx;
                        g[2 * k01] += c * 0.5 / sx;
                        g[2 * k01 + 1] -= c * 0.5 / sy;
                        g[2 * k11 + 1] -= c * 0.5 / sy;
                        g[2 * k00 + 1] += c * 0.5 / sy;
                        g[2 * k10 + 1] += c * 0.5 / sy;
                    }
                }
            }
        }
        r
    }

    /// The objective `var(G_σ * IWE) − λ·Σ‖v_i − v_j‖² − μ·mean(div v)²` (to be maximised).
    pub fn objective(&self, v: &[f64]) -> f64 {
        let b = self.blur(&self.iwe(v));
        variance(&b) - self.smoothness_term(v, None)
    }

    /// The objective and its analytic gradient with respect to the tile velocities.
    pub fn objective_and_gradient(&self, v: &[f64]) -> (f64, Vec<f64>) {
        let (w, h) = (self.width as i64, self.height as i64);
        let (cells, img) = self.warp_all(v);
        let b = self.blur(&img);
        let n = b.len() as f64;
        let mean = b.iter().sum::<f64>() / n;
        let var = b.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / n;
        // d var / d B = 2 (B − mean) / N (the mean's own derivative sums to zero).
        let g_b: Vec<f64> = b.iter().map(|x| 2.0 * (x - mean) / n).collect();
        let g_img = self.blur(&g_b);
        let mut grad = vec![0.0; self.num_params()];
        let at = |px: i64, py: i64| -> f64 {
            if px >= 0 && px < w && py >= 0 && py < h {
                g_img[(py * w + px) as usize]
            } else {
                0.0
            }
        };
        for (i, &(ix, iy, fx, fy)) in cells.iter().enumerate() {
            let (g00, g10, g01, g11) = (
                at(ix, iy),
                at(ix + 1, iy),
                at(ix, iy + 1),
                at(ix + 1, iy + 1),
            );
            let d_wx = (1.0 - fy) * (g10 - g00) + fy * (g11 - g01);
            let d_wy = (1.0 - fx) * (g01 - g00) + fx * (g11 - g10);
            // x' = x − s·Σ w_k vx_k.
            for &(k, wgt) in &self.weights[i] {
                grad[2 * k as usize] -= d_wx * self.s[i] * wgt;
                grad[2 * k as usize + 1] -= d_wy * self.s[i] * wgt;
            }
        }
        let r = self.smoothness_term(v, Some(&mut grad));
        (var - r, grad)
    }

    /// Dense velocity (pixels per window) by bilinear interpolation of tile velocities `v`.
    pub fn dense(&self, v: &[f64]) -> Flow {
        dense_from_tiles(v, self.width, self.height, self.tiles_x, self.tiles_y)
    }
}

/// A warped event's bilinear cell: integer pixel (ix, iy) and fractions (fx, fy) ∈ [0, 1).
type Cell = (i64, i64, f64, f64);

/// `x.floor() as i64` without the libm call (the baseline x86-64 target has no SSE4.1 `roundsd`):
/// the same value for every finite `x` in the i64 range.
#[inline]
fn floor_i64(x: f64) -> i64 {
    let i = x as i64;
    if (i as f64) > x {
        i - 1
    } else {
        i
    }
}

/// Two deterministic offsets in [-0.5, 0.5) from a SplitMix64 hash of `i`.
fn dither(i: u64) -> (f64, f64) {
    let mut z = i.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    let a = (z >> 40) as f64 / (1u64 << 24) as f64 - 0.5;
    let b = ((z >> 16) & 0xFF_FFFF) as f64 / (1u64 << 24) as f64 - 0.5;
    (a, b)
}

fn variance(b: &[f64]) -> f64 {
    let n = b.len() as f64;
    let mean = b.iter().sum::<f64>() / n;
    b.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / n
}

/// Dense `(2, H, W)` flow from `tx × ty` tile values `v = [vx_0, vy_0, …]` by bilinear interpolation
/// between tile centres (clamped at the borders).
pub fn dense_from_tiles(v: &[f64], w: usize, h: usize, tx: usize, ty: usize) -> Flow {
    let mut f = Flow::zeros(w, h);
    for y in 0..h {
        for x in 0..w {
            let (mut u, mut vv) = (0.0, 0.0);
            for (k, wgt) in tile_weights(x as f64, y as f64, w, h, tx, ty) {
                u += wgt * v[2 * k as usize];
                vv += wgt * v[2 * k as usize + 1];
            }
            f.set(x, y, u as f32, vv as f32);
        }
    }
    f
}

/// Centres of the 2×2 tiles relative to the image centre, in units of the image size: the
/// position `p` of a tile centre is `c + (dx·W, dy·H)`.
const AFFINE_CENTRES: [(f64, f64); 4] =
    [(-0.25, -0.25), (0.25, -0.25), (-0.25, 0.25), (0.25, 0.25)];

/// The 2×2 tile velocities `[vx_0, vy_0, …]` (pixels per window) of the affine field
/// `v(p) = a + B·((p_x − c_x)/(W/2), (p_y − c_y)/(H/2))` with
/// `theta = [a_x, a_y, B_xx, B_xy, B_yx, B_yy]` (pixels per window); bilinear interpolation of these
/// tiles reproduces the field between the tile centres. Level 0 of [`flow_from_events`] optimises
/// `theta` through this map on a 2×2 [`CmaxProblem`].
pub fn affine_tiles(theta: &[f64]) -> Vec<f64> {
    let mut v = vec![0.0; 8];
    for (k, &(dx, dy)) in AFFINE_CENTRES.iter().enumerate() {
        let (ux, uy) = (2.0 * dx, 2.0 * dy);
        v[2 * k] = theta[0] + theta[2] * ux + theta[3] * uy;
        v[2 * k + 1] = theta[1] + theta[4] * ux + theta[5] * uy;
    }
    v
}

/// The gradient with respect to `theta` of a function of [`affine_tiles`]`(theta)`, given its
/// gradient `g` with respect to the 8 tile velocities (the transpose of the linear map).
pub fn affine_pullback(g: &[f64]) -> Vec<f64> {
    let mut gt = vec![0.0; 6];
    for (k, &(dx, dy)) in AFFINE_CENTRES.iter().enumerate() {
        let (ux, uy) = (2.0 * dx, 2.0 * dy);
        gt[0] += g[2 * k];
        gt[2] += g[2 * k] * ux;
        gt[3] += g[2 * k] * uy;
        gt[1] += g[2 * k + 1];
        gt[4] += g[2 * k + 1] * ux;
        gt[5] += g[2 * k + 1] * uy;
    }
    gt
}

/// Maximises an objective from `init` given its gradient: Adam's first moment with one shared
/// second moment (so the relative step sizes follow the gradient); the step decays linearly
/// from `lr` to `lr/10`.
fn adam(
    mut gradient: impl FnMut(&[f64]) -> Vec<f64>,
    init: Vec<f64>,
    iterations: usize,
    lr: f64,
) -> Vec<f64> {
    let mut v = init;
    let mut m = vec![0.0; v.len()];
    let mut s2 = 0.0;
    let (b1, b2, eps) = (0.9, 0.999, 1e-12);
    for it in 0..iterations {
        let g = gradient(&v);
        let step = lr * (1.0 - 0.9 * it as f64 / iterations.max(1) as f64);
        let t = (it + 1) as i32;
        // One second moment for all parameters (the mean square of the gradient): tiles with
        // few events get proportionally small steps instead of Adam's full-size noisy ones.
        let g2 = g.iter().map(|x| x * x).sum::<f64>() / g.len().max(1) as f64;
        s2 = b2 * s2 + (1.0 - b2) * g2;
        let sh = s2 / (1.0 - b2.powi(t));
        for k in 0..v.len() {
            m[k] = b1 * m[k] + (1.0 - b1) * g[k];
            let mh = m[k] / (1.0 - b1.powi(t));
            v[k] += step * mh / (sh.sqrt() + eps); // ascent
        }
    }
    v
}

/// Estimates the forward flow (pixels) from frame time `t_a_us` to `t_b_us` using only the events
/// of that window: coarse-to-fine per-tile contrast maximisation, then bilinear densification.
pub fn flow_from_events(
    events: &EventSlice<'_>,
    sensor: SensorSize,
    t_a_us: i64,
    t_b_us: i64,
    config: &CmaxConfig,
) -> Result<Flow> {
    if config.levels == 0 {
        return Err(EventsError::arg("levels", "must be at least 1".to_string()));
    }
    let (w, h) = (sensor.width as usize, sensor.height as usize);
    let mut tiles = (1usize, 1usize);
    let mut v = vec![0.0; 2];
    for level in 0..config.levels {
        if level > 0 {
            let next = ((tiles.0 * 2).min(w), (tiles.1 * 2).min(h));
            // Initialise the finer grid from the coarser dense field at the new tile centres.
            let coarse = dense_from_tiles(&v, w, h, tiles.0, tiles.1);
            let mut nv = vec![0.0; 2 * next.0 * next.1];
            for j in 0..next.1 {
                for i in 0..next.0 {
                    let cx = (((i as f64 + 0.5) * w as f64 / next.0 as f64) as usize).min(w - 1);
                    let cy = (((j as f64 + 0.5) * h as f64 / next.1 as f64) as usize).min(h - 1);
                    let (u, vv) = coarse.at(cx, cy);
                    nv[2 * (j * next.0 + i)] = u as f64;
                    nv[2 * (j * next.0 + i) + 1] = vv as f64;
                }
            }
            tiles = next;
            v = nv;
        }
        let lr = config.learning_rate / (1 + level) as f64;
        if level == 0 && config.affine_iterations > 0 && w >= 2 && h >= 2 {
            // Level 0: one affine field v(p) = a + B·(p − c)/r on a 2×2 tile grid (6 parameters
            // θ = [a_x, a_y, B_xx, B_xy, B_yx, B_yy], r = half the image size so B is in pixels).
            let problem = CmaxProblem::new(events, sensor, t_a_us, t_b_us, 2, 2, config)?;
            if problem.num_events() == 0 {
                break;
            }
            let theta = adam(
                |th| affine_pullback(&problem.objective_and_gradient(&affine_tiles(th)).1),
                vec![0.0; 6],
                config.affine_iterations,
                lr,
            );
            tiles = (2, 2);
            v = affine_tiles(&theta);
            continue;
        }
        let problem = CmaxProblem::new(events, sensor, t_a_us, t_b_us, tiles.0, tiles.1, config)?;
        if problem.num_events() == 0 {
            break;
        }
        v = adam(
            |x| problem.objective_and_gradient(x).1,
            v,
            config.iterations,
            lr,
        );
    }
    Ok(dense_from_tiles(&v, w, h, tiles.0, tiles.1))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The affine pull-back is the exact transpose of `affine_tiles` (`<A θ, g> = <θ, Aᵀ g>`), and
    /// the tiles of a pure rotation lie where the rotation puts the 2×2 tile centres.
    #[test]
    fn affine_parametrisation_and_its_transpose_agree() {
        let theta = [0.3, -1.1, 0.7, -2.0, 1.3, 0.4];
        let g = [0.5, -0.25, 1.5, 2.0, -0.75, 0.1, 0.9, -1.3];
        let at = affine_tiles(&theta);
        let lhs: f64 = at.iter().zip(&g).map(|(a, b)| a * b).sum();
        let rhs: f64 = affine_pullback(&g)
            .iter()
            .zip(&theta)
            .map(|(a, b)| a * b)
            .sum();
        assert!((lhs - rhs).abs() < 1e-12, "{lhs} vs {rhs}");
        // Rotation by ω about the centre of a 96×64 image: v = ω·(−(y − c_y), x − c_x).
        let (w, h, om) = (96.0, 64.0, 0.04);
        let rot = affine_tiles(&[0.0, 0.0, 0.0, -om * h / 2.0, om * w / 2.0, 0.0]);
        for (k, &(dx, dy)) in AFFINE_CENTRES.iter().enumerate() {
            // Tile centres of a 2×2 grid sit at a quarter and three quarters of each axis.
            let (px, py) = (dx * w, dy * h);
            assert!((rot[2 * k] + om * py).abs() < 1e-12, "tile {k} x");
            assert!((rot[2 * k + 1] - om * px).abs() < 1e-12, "tile {k} y");
        }
    }
}
