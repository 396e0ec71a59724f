//! Procedural FlyingChairs-style training pairs: a textured background and 1–3 textured foreground
//! layers (ellipses and rectangles), each moving by its own random affine motion (rotation, scale,
//! translation about its centre), plus brightness jitter of the second frame. Ground-truth flow is
//! exact: for every pixel of frame 1, the displacement of the topmost layer covering it.
//!
//! Textures: multi-octave value noise, stripes, checkers and Gaussian blobs, mixed with random colours.
//! Everything is a pure function of the seed (no global RNG, no threads), so a data set is
//! reproducible bit for bit.

/// One training pair: two planar RGB images `(3, H, W)` in `[0, 1]` and the forward flow `(2, H, W)`.
#[derive(Clone, Debug)]
pub struct Pair {
    /// Image height in pixels.
    pub height: usize,
    /// Image width in pixels.
    pub width: usize,
    /// Frame 1, planar RGB.
    pub img1: Vec<f32>,
    /// Frame 2, planar RGB.
    pub img2: Vec<f32>,
    /// Ground-truth flow from frame 1 to frame 2, pixels.
    pub flow: Vec<f32>,
    /// Per-pixel weight `(H, W)` of the training loss, normalised per pair (the loss is
    /// `Σ wᵢ lᵢ / Σ wᵢ` at every level, with `w` 2×2-averaged like the flow); `None` = uniform.
    pub weight: Option<Vec<f32>>,
}

/// Knobs of the generator.
#[derive(Clone, Copy, Debug)]
pub struct PairConfig {
    /// Image side length in pixels (square images).
    pub size: usize,
    /// Largest background translation per axis, as a fraction of the size.
    pub max_translation: f32,
    /// Largest rotation in radians.
    pub max_rotation: f32,
    /// Largest relative scale change.
    pub max_scale: f32,
    /// Largest number of moving foreground layers (a pair has between `min(1, max)` and `max`).
    pub max_foreground_layers: usize,
    /// Highest texture frequency in cycles per pixel; `0` = unlimited (the original generator:
    /// base frequencies of 3–12 cycles per image and value-noise octaves up to 16× that, i.e. mostly
    /// above Nyquist on small images). With a limit `f`, base frequencies are log-uniform in
    /// `[max(f/16, 2 cycles per image), f]` and value-noise octaves above `f` are dropped, so the texture is resolved at the
    /// image's own resolution and sub-pixel motion is visible in it.
    pub max_cycles_per_pixel: f32,
    /// Samples per pixel side for the images (`s × s` box-filtered samples); `1` = point sampling at
    /// pixel centres (the original generator). With point sampling a hard edge moving by less than a
    /// pixel often does not change the image at all; area sampling makes the images' change
    /// proportional to the motion. The ground-truth flow is always taken at pixel centres.
    pub supersampling: usize,
    /// Scale of the second frame's brightness jitter (gain `1 ± 0.1·j`, offset `± 0.05·j`); `1` is the
    /// original generator, `0` turns it off (draws the same random numbers either way).
    pub brightness_jitter: f32,
    /// Probability that the background does not move (a static camera, as in the project's
    /// synthetic benchmark: only the foreground layers move and the flow is exactly zero elsewhere).
    /// `0` draws exactly the pairs of the generator before this knob existed.
    pub static_background: f32,
}

impl Default for PairConfig {
    fn default() -> Self {
        Self {
            size: 64,
            max_translation: 0.12,
            max_rotation: 0.15,
            max_scale: 0.1,
            max_foreground_layers: 3,
            max_cycles_per_pixel: 0.25,
            supersampling: 3,
            brightness_jitter: 1.0,
            static_background: 0.0,
        }
    }
}

impl PairConfig {
    /// The original generator (before the texture-frequency limit and area sampling) at `size`:
    /// draws the same pairs as the first trainer's runs recorded in `docs/notes/benchmarks-history.md` (flow).
    pub fn original(size: usize) -> Self {
        Self {
            size,
            max_cycles_per_pixel: 0.0,
            supersampling: 1,
            ..Self::default()
        }
    }
}

/// Small deterministic generator (SplitMix64), the flow crate's only one: training pairs, weight
/// initialisation and the trainer's pair mixing all draw from it.
pub(crate) struct Rng(pub(crate) u64);
impl Rng {
    pub(crate) fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    fn f(&mut self) -> f32 {
        ((self.next_u64() >> 40) as f32) / ((1u64 << 24) as f32)
    }
    /// Uniform in [-a, a).
    fn sym(&mut self, a: f32) -> f32 {
        (2.0 * self.f() - 1.0) * a
    }
    /// Uniform in [-1, 1) with 53 random bits.
    pub(crate) fn symmetric_f64(&mut self) -> f64 {
        ((self.next_u64() >> 11) as f64) / ((1u64 << 53) as f64) * 2.0 - 1.0
    }
}

fn hash2(seed: u64, x: i64, y: i64) -> f32 {
    let mut r = Rng(seed
        ^ (x as u64).wrapping_mul(0x8CB9_2BA7_2F3D_8DD7)
        ^ (y as u64).wrapping_mul(0xD6E8_FEB8_6659_FD93));
    r.f()
}

#[derive(Clone, Copy)]
enum Kind {
    Noise,
    Stripes,
    Checkers,
    Blobs,
}

#[derive(Clone, Copy)]
struct Texture {
    kind: Kind,
    seed: u64,
    c0: [f32; 3],
    c1: [f32; 3],
    freq: f32,
    angle: f32,
    /// Value-noise octaves above this frequency (cycles per pixel) are dropped.
    max_freq: f32,
}

impl Texture {
    fn random(r: &mut Rng, size: f32, max_cycles: f32) -> Self {
        let kind = match r.next_u64() % 4 {
            0 => Kind::Noise,
            1 => Kind::Stripes,
            2 => Kind::Checkers,
            _ => Kind::Blobs,
        };
        let col = |r: &mut Rng| [r.f(), r.f(), r.f()];
        Self {
            kind,
            seed: r.next_u64(),
            c0: col(r),
            c1: col(r),
            freq: if max_cycles > 0.0 {
                // Log-uniform in [lo, max_cycles], lo = max(max_cycles / 16, 2 cycles per image).
                let lo = (max_cycles / 16.0).max(2.0 / size).min(max_cycles);
                lo * (max_cycles / lo).powf(r.f())
            } else {
                (3.0 + 9.0 * r.f()) / size
            },
            angle: r.sym(std::f32::consts::PI),
            max_freq: if max_cycles > 0.0 {
                max_cycles
            } else {
                f32::INFINITY
            },
        }
    }

    fn value_noise(&self, x: f32, y: f32) -> f32 {
        let (mut total, mut norm) = (0.0, 0.0);
        let mut amp = 0.5;
        let mut f = self.freq * 2.0;
        for o in 0..4 {
            if o > 0 && f > self.max_freq {
                break;
            }
            let (px, py) = (x * f, y * f);
            let (ix, iy) = (px.floor(), py.floor());
            let (fx, fy) = (px - ix, py - iy);
            let (sx, sy) = (fx * fx * (3.0 - 2.0 * fx), fy * fy * (3.0 - 2.0 * fy));
            let s = self.seed.wrapping_add(o);
            let (ix, iy) = (ix as i64, iy as i64);
            let a = hash2(s, ix, iy);
            let b = hash2(s, ix + 1, iy);
            let c = hash2(s, ix, iy + 1);
            let d = hash2(s, ix + 1, iy + 1);
            total += amp * (a + (b - a) * sx + (c - a) * sy + (a - b - c + d) * sx * sy);
            norm += amp;
            amp *= 0.5;
            f *= 2.0;
        }
        total / norm
    }

    /// Colour at layer-local coordinates (pixels).
    fn sample(&self, x: f32, y: f32) -> [f32; 3] {
        let (ca, sa) = (self.angle.cos(), self.angle.sin());
        let (u, v) = (ca * x + sa * y, -sa * x + ca * y);
        let t = match self.kind {
            Kind::Noise => self.value_noise(x, y),
            Kind::Stripes => {
                0.5 + 0.5 * (u * self.freq * std::f32::consts::TAU).sin() * 0.8
                    + 0.2 * (self.value_noise(x, y) - 0.5)
            }
            Kind::Checkers => {
                let a = ((u * self.freq).floor() + (v * self.freq).floor()) as i64;
                0.15 + 0.7 * (a.rem_euclid(2) as f32) + 0.15 * self.value_noise(x, y)
            }
            Kind::Blobs => {
                let cell = 1.0 / self.freq;
                let (gx, gy) = ((x / cell).floor() as i64, (y / cell).floor() as i64);
                let mut acc = 0.0f32;
                for dy in -1..=1 {
                    for dx in -1..=1 {
                        let (cx, cy) = (gx + dx, gy + dy);
                        let ox = (cx as f32 + hash2(self.seed, cx, cy)) * cell;
                        let oy = (cy as f32 + hash2(self.seed ^ 1, cx, cy)) * cell;
                        let r2 = ((x - ox).powi(2) + (y - oy).powi(2)) / (0.18 * cell * cell);
                        acc += (-r2).exp();
                    }
                }
                acc.min(1.0)
            }
        };
        let t = t.clamp(0.0, 1.0);
        [0, 1, 2].map(|c| self.c0[c] + (self.c1[c] - self.c0[c]) * t)
    }
}

/// Affine motion about a centre: `p2 = A·(p1 − c) + c + t`.
#[derive(Clone, Copy)]
struct Motion {
    a: [f32; 4],
    c: [f32; 2],
    t: [f32; 2],
}

impl Motion {
    fn random(r: &mut Rng, c: [f32; 2], max_t: f32, max_rot: f32, max_scale: f32) -> Self {
        let th = r.sym(max_rot);
        let s = 1.0 + r.sym(max_scale);
        let (co, si) = (th.cos() * s, th.sin() * s);
        Self {
            a: [co, -si, si, co],
            c,
            t: [r.sym(max_t), r.sym(max_t)],
        }
    }
    fn forward(&self, p: [f32; 2]) -> [f32; 2] {
        let (x, y) = (p[0] - self.c[0], p[1] - self.c[1]);
        [
            self.a[0] * x + self.a[1] * y + self.c[0] + self.t[0],
            self.a[2] * x + self.a[3] * y + self.c[1] + self.t[1],
        ]
    }
    fn inverse(&self, q: [f32; 2]) -> [f32; 2] {
        let (x, y) = (q[0] - self.c[0] - self.t[0], q[1] - self.c[1] - self.t[1]);
        let det = self.a[0] * self.a[3] - self.a[1] * self.a[2];
        [
            (self.a[3] * x - self.a[1] * y) / det + self.c[0],
            (-self.a[2] * x + self.a[0] * y) / det + self.c[1],
        ]
    }
}

#[derive(Clone, Copy)]
struct Layer {
    tex: Texture,
    motion: Motion,
    /// Shape in frame-1 coordinates: centre, half-axes, rotation, ellipse (true) or rectangle.
    centre: [f32; 2],
    half: [f32; 2],
    rot: f32,
    ellipse: bool,
}

impl Layer {
    fn covers(&self, p: [f32; 2]) -> bool {
        let (dx, dy) = (p[0] - self.centre[0], p[1] - self.centre[1]);
        let (c, s) = (self.rot.cos(), self.rot.sin());
        let (u, v) = (
            (c * dx + s * dy) / self.half[0],
            (-s * dx + c * dy) / self.half[1],
        );
        if self.ellipse {
            u * u + v * v <= 1.0
        } else {
            u.abs() <= 1.0 && v.abs() <= 1.0
        }
    }
}

/// The layers of pair `index` of data set `seed` (background first, topmost last) and the second
/// frame's brightness gain and offset.
fn draw_layers(seed: u64, index: u64, cfg: &PairConfig) -> (Vec<Layer>, f32, f32) {
    let mut r = Rng(seed.wrapping_mul(0x2545_F491_4F6C_DD1D) ^ index.wrapping_mul(0x9E37_79B9));
    let n = cfg.size;
    let nf = n as f32;
    let centre = [nf / 2.0, nf / 2.0];
    let mut layers = vec![Layer {
        tex: Texture::random(&mut r, nf, cfg.max_cycles_per_pixel),
        motion: Motion::random(
            &mut r,
            centre,
            cfg.max_translation * nf,
            cfg.max_rotation,
            cfg.max_scale,
        ),
        centre,
        half: [1e9, 1e9],
        rot: 0.0,
        ellipse: false,
    }];
    let count = match cfg.max_foreground_layers {
        0 => 0,
        m => 1 + (r.next_u64() % m as u64) as usize,
    };
    for _ in 0..count {
        let c = [r.f() * nf, r.f() * nf];
        layers.push(Layer {
            tex: Texture::random(&mut r, nf, cfg.max_cycles_per_pixel),
            motion: Motion::random(
                &mut r,
                c,
                1.3 * cfg.max_translation * nf,
                2.0 * cfg.max_rotation,
                1.5 * cfg.max_scale,
            ),
            centre: c,
            half: [nf * (0.1 + 0.2 * r.f()), nf * (0.1 + 0.2 * r.f())],
            rot: r.sym(std::f32::consts::PI),
            ellipse: r.f() < 0.5,
        });
    }
    let gain = 1.0 + r.sym(0.1) * cfg.brightness_jitter;
    let bias = r.sym(0.05) * cfg.brightness_jitter;
    // Drawn last and only when enabled, so that `static_background = 0` keeps every earlier pair.
    if cfg.static_background > 0.0 && r.f() < cfg.static_background {
        layers[0].motion = Motion {
            a: [1.0, 0.0, 0.0, 1.0],
            c: centre,
            t: [0.0, 0.0],
        };
    }
    (layers, gain, bias)
}

/// Generates the pair number `index` of the data set `seed` (pairs are independent of each other).
pub fn generate_pair(seed: u64, index: u64, cfg: &PairConfig) -> Pair {
    let (layers, gain, bias) = draw_layers(seed, index, cfg);
    let n = cfg.size;
    let ss = cfg.supersampling.max(1);
    let inv_samples = 1.0 / (ss * ss) as f32;
    let hw = n * n;
    let mut img1 = vec![0.0f32; 3 * hw];
    let mut img2 = vec![0.0f32; 3 * hw];
    let mut flow = vec![0.0f32; 2 * hw];
    for y in 0..n {
        for x in 0..n {
            let p = [x as f32 + 0.5, y as f32 + 0.5];
            let i = y * n + x;
            // Ground truth at the pixel centre: the topmost layer covering it in frame 1.
            if let Some(l) = layers.iter().rev().find(|l| l.covers(p)) {
                let q = l.motion.forward(p);
                flow[i] = q[0] - p[0];
                flow[hw + i] = q[1] - p[1];
            }
            let (mut c1, mut c2) = ([0.0f32; 3], [0.0f32; 3]);
            for sy in 0..ss {
                for sx in 0..ss {
                    let p = [
                        x as f32 + (sx as f32 + 0.5) / ss as f32,
                        y as f32 + (sy as f32 + 0.5) / ss as f32,
                    ];
                    // Frame 1: topmost layer covering p.
                    if let Some(l) = layers.iter().rev().find(|l| l.covers(p)) {
                        let col = l.tex.sample(p[0], p[1]);
                        for c in 0..3 {
                            c1[c] += col[c];
                        }
                    }
                    // Frame 2: topmost layer whose moved shape covers p.
                    if let Some((l, src)) = layers
                        .iter()
                        .rev()
                        .map(|l| (l, l.motion.inverse(p)))
                        .find(|(l, src)| l.covers(*src))
                    {
                        let col = l.tex.sample(src[0], src[1]);
                        for c in 0..3 {
                            c2[c] += (col[c] * gain + bias).clamp(0.0, 1.0);
                        }
                    }
                }
            }
            for c in 0..3 {
                img1[c * hw + i] = c1[c] * inv_samples;
                img2[c * hw + i] = c2[c] * inv_samples;
            }
        }
    }
    Pair {
        height: n,
        width: n,
        img1,
        img2,
        flow,
        weight: None,
    }
}

/// Which pixels of [`generate_pair`]`(seed, index, cfg)` are *matched* (`H × W`, row-major), in the
/// sense of Sintel's "matched / unmatched" EPE: the surface seen at the pixel centre in frame 1,
/// moved by its layer's motion, lands inside frame 2 and is still the topmost surface there. At
/// unmatched pixels (out of frame, or occluded in frame 2) the images do not show where the point
/// went; its flow can only be inferred from the neighbours.
pub fn matched_pixels(seed: u64, index: u64, cfg: &PairConfig) -> Vec<bool> {
    let (layers, _, _) = draw_layers(seed, index, cfg);
    let n = cfg.size;
    let nf = n as f32;
    let mut matched = vec![false; n * n];
    for y in 0..n {
        for x in 0..n {
            let p = [x as f32 + 0.5, y as f32 + 0.5];
            let Some(first) = layers.iter().rposition(|l| l.covers(p)) else {
                continue;
            };
            let q = layers[first].motion.forward(p);
            if !(0.0..nf).contains(&q[0]) || !(0.0..nf).contains(&q[1]) {
                continue;
            }
            // Frame 2 at q: the topmost layer whose moved shape covers q, as `generate_pair` draws it.
            let second = layers.iter().rposition(|l| l.covers(l.motion.inverse(q)));
            matched[y * n + x] = second == Some(first);
        }
    }
    matched
}

/// Average end-point error `mean_p ‖f(p) − g(p)‖₂` of two `(2, H, W)` flows (pixels).
pub fn average_epe(flow: &[f32], truth: &[f32]) -> f64 {
    let hw = truth.len() / 2;
    if hw == 0 {
        return 0.0;
    }
    let mut acc = 0.0f64;
    for i in 0..hw {
        let du = (flow[i] - truth[i]) as f64;
        let dv = (flow[hw + i] - truth[hw + i]) as f64;
        acc += (du * du + dv * dv).sqrt();
    }
    acc / hw as f64
}
