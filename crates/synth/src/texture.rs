//! Textures: RGB albedo images with wrapping bilinear lookup, and the procedural generators that
//! fill them (periodic value noise, planks, bricks, wallpaper, fabrics).
//!
//! Everything is a pure function of `(seed, texel)`, hashed with integer arithmetic, so textures are
//! identical on every platform and thread count. Albedo is linear RGB in [0, 1]. Textures tile
//! seamlessly (noise lattices wrap at the texture's period), which lets room surfaces repeat them.

use glam::Vec3;
use rayon::prelude::*;

/// A tiling RGB albedo texture.
#[derive(Clone, Debug)]
pub struct Texture {
    /// Width (texels).
    pub width: usize,
    /// Height (texels).
    pub height: usize,
    /// Row-major linear RGB albedo; row 0 is `v = 0`.
    pub data: Vec<Vec3>,
}

impl Texture {
    /// Samples `f(u, v)` at texel centres, `u, v` in [0, 1).
    pub fn from_fn(width: usize, height: usize, f: impl Fn(f32, f32) -> Vec3 + Sync) -> Self {
        let data = (0..height)
            .into_par_iter()
            .flat_map_iter(|y| {
                let f = &f;
                (0..width).map(move |x| {
                    f(
                        (x as f32 + 0.5) / width as f32,
                        (y as f32 + 0.5) / height as f32,
                    )
                })
            })
            .collect();
        Self {
            width,
            height,
            data,
        }
    }

    /// Bilinear lookup with wrapping; `(u, v)` in repeats (1.0 = one texture width), texel centres
    /// at `(i + 0.5) / width`.
    pub fn sample(&self, u: f32, v: f32) -> Vec3 {
        let x = u * self.width as f32 - 0.5;
        let y = v * self.height as f32 - 0.5;
        let (xf, yf) = (floor(x), floor(y));
        let (ax, ay) = (x - xf, y - yf);
        let wrap = |i: f32, n: usize| (i as i64).rem_euclid(n as i64) as usize;
        let (x0, y0) = (wrap(xf, self.width), wrap(yf, self.height));
        let x1 = if x0 + 1 == self.width { 0 } else { x0 + 1 };
        let y1 = if y0 + 1 == self.height { 0 } else { y0 + 1 };
        let t = |x: usize, y: usize| self.data[y * self.width + x];
        let top = t(x0, y0) * (1.0 - ax) + t(x1, y0) * ax;
        let bot = t(x0, y1) * (1.0 - ax) + t(x1, y1) * ax;
        top * (1.0 - ay) + bot * ay
    }
}

/// `x.floor()`, bit for bit, without a libm call: the x86-64 baseline has no rounding
/// instruction, so `f32::floor` is a function call, and texture lookups run once per shaded sample.
#[inline]
fn floor(x: f32) -> f32 {
    if x.abs() < 8_388_608.0 {
        // |x| < 2^23: the truncation is exact in i32 and f32.
        let t = x as i32 as f32;
        if t > x {
            t - 1.0
        } else if t == x {
            x // keeps the sign of zero
        } else {
            t
        }
    } else {
        x.floor() // already an integer, or NaN / infinite
    }
}

/// A 32-bit integer hash of a seed and two lattice coordinates (the lowbias32 mixer).
pub fn hash3(seed: u32, x: i32, y: i32) -> u32 {
    let mut h = seed
        ^ (x as u32).wrapping_mul(0x9E37_79B1)
        ^ (y as u32).wrapping_mul(0x85EB_CA77).rotate_left(13);
    h ^= h >> 16;
    h = h.wrapping_mul(0x7FEB_352D);
    h ^= h >> 15;
    h = h.wrapping_mul(0x846C_A68B);
    h ^= h >> 16;
    h
}

/// Hash to a float in [0, 1).
pub fn hashf(seed: u32, x: i32, y: i32) -> f32 {
    (hash3(seed, x, y) >> 8) as f32 / (1u32 << 24) as f32
}

fn smooth(t: f32) -> f32 {
    t * t * (3.0 - 2.0 * t)
}

/// Periodic value noise in [0, 1): `(u, v)` in [0, 1) scaled to `freq` lattice cells per period.
pub fn value_noise(seed: u32, u: f32, v: f32, freq: u32) -> f32 {
    let f = freq.max(1) as i32;
    let (x, y) = (u * f as f32, v * f as f32);
    let (xf, yf) = (x.floor(), y.floor());
    let (tx, ty) = (smooth(x - xf), smooth(y - yf));
    let (x0, y0) = ((xf as i32).rem_euclid(f), (yf as i32).rem_euclid(f));
    let (x1, y1) = ((x0 + 1) % f, (y0 + 1) % f);
    let a = hashf(seed, x0, y0);
    let b = hashf(seed, x1, y0);
    let c = hashf(seed, x0, y1);
    let d = hashf(seed, x1, y1);
    (a * (1.0 - tx) + b * tx) * (1.0 - ty) + (c * (1.0 - tx) + d * tx) * ty
}

/// Periodic fractal value noise in [0, 1): `octaves` layers from `freq` cells, doubling frequency
/// and halving amplitude.
pub fn fbm(seed: u32, u: f32, v: f32, freq: u32, octaves: u32) -> f32 {
    let (mut sum, mut amp, mut norm, mut f) = (0.0, 1.0, 0.0, freq);
    for o in 0..octaves {
        sum += amp * value_noise(seed.wrapping_add(o.wrapping_mul(7919)), u, v, f);
        norm += amp;
        amp *= 0.5;
        f *= 2;
    }
    sum / norm
}

fn hsv(h: f32, s: f32, v: f32) -> Vec3 {
    let h = h.rem_euclid(1.0) * 6.0;
    let c = v * s;
    let x = c * (1.0 - ((h % 2.0) - 1.0).abs());
    let (r, g, b) = match h as u32 {
        0 => (c, x, 0.0),
        1 => (x, c, 0.0),
        2 => (0.0, c, x),
        3 => (0.0, x, c),
        4 => (x, 0.0, c),
        _ => (c, 0.0, x),
    };
    Vec3::new(r, g, b) + Vec3::splat(v - c)
}

/// Wooden floor planks: `rows` planks across the period, random lengths, grain, dark gaps.
pub fn planks(seed: u32, size: usize) -> Texture {
    let rows = 8;
    Texture::from_fn(size, size, move |u, v| {
        let row = (v * rows as f32).floor() as i32;
        let fv = v * rows as f32 - row as f32;
        let offset = hashf(seed, row, 99);
        let seg = ((u + offset) * 3.0).floor() as i32; // three planks per row per period
        let fu = ((u + offset) * 3.0).fract();
        let id = hashf(seed ^ 0x55, row, seg.rem_euclid(3));
        let base = hsv(0.06 + 0.04 * id, 0.55 + 0.2 * id, 0.35 + 0.35 * id);
        let grain = fbm(seed ^ 0xA1, u, v * 0.25 + id, 4, 5);
        let stripes = (0.5 + 0.5 * (60.0 * v + 8.0 * grain).sin()).powf(3.0);
        let knots = fbm(seed ^ 0xB2, u, v, 32, 3);
        let mut c = base * (0.75 + 0.35 * grain - 0.2 * stripes) * (0.85 + 0.3 * knots);
        if fv < 0.04 || fu < 0.006 {
            c *= 0.25;
        }
        c.clamp(Vec3::ZERO, Vec3::ONE)
    })
}

/// Bricks with mortar, per-brick colour variation and speckles.
pub fn bricks(seed: u32, size: usize, hue: f32) -> Texture {
    let rows = 16;
    let cols = 6;
    Texture::from_fn(size, size, move |u, v| {
        let row = (v * rows as f32).floor() as i32;
        let fv = v * rows as f32 - row as f32;
        let shift = if row % 2 == 0 { 0.0 } else { 0.5 };
        let cu = u * cols as f32 + shift;
        let col = cu.floor() as i32;
        let fu = cu - col as f32;
        let id = hashf(seed, row, col.rem_euclid(cols));
        let speck = value_noise(seed ^ 0x77, u, v, 256);
        let coarse = fbm(seed ^ 0x13, u, v, 8, 4);
        if fv < 0.08 || fu < 0.03 {
            return Vec3::splat(0.55 + 0.1 * speck) * (0.8 + 0.3 * coarse);
        }
        let base = hsv(hue + 0.05 * (id - 0.5), 0.5 + 0.3 * id, 0.3 + 0.3 * id);
        (base * (0.7 + 0.4 * coarse) * (0.85 + 0.3 * speck)).clamp(Vec3::ZERO, Vec3::ONE)
    })
}

/// Wallpaper: large soft colour clouds, a grid of circles and diamonds, fine paper noise and a few
/// stripe "posters"; rich at several scales for flow estimation.
pub fn wallpaper(seed: u32, size: usize) -> Texture {
    let hue0 = hashf(seed, 1, 2);
    Texture::from_fn(size, size, move |u, v| {
        let cloud = fbm(seed ^ 0x21, u, v, 3, 4);
        let mut c = hsv(hue0 + 0.15 * cloud, 0.35, 0.45 + 0.35 * cloud);
        // Motif grid.
        let n = 12.0;
        let (gx, gy) = ((u * n).floor() as i32, (v * n).floor() as i32);
        let (fx, fy) = ((u * n).fract() - 0.5, (v * n).fract() - 0.5);
        let id = hashf(seed ^ 0x31, gx, gy);
        let motif_col = hsv(hue0 + 0.5 + 0.3 * id, 0.6, 0.25 + 0.5 * id);
        let r = (fx * fx + fy * fy).sqrt();
        let inside = if (gx + gy) % 2 == 0 {
            (0.18..0.3).contains(&r)
        } else {
            fx.abs() + fy.abs() < 0.25
        };
        if inside {
            c = motif_col;
        }
        // Posters: three rectangles with stripes.
        for p in 0..3 {
            let x0 = hashf(seed ^ 0x41, p, 0) * 0.8;
            let y0 = hashf(seed ^ 0x41, p, 1) * 0.8;
            let (w, h) = (
                0.1 + 0.1 * hashf(seed ^ 0x41, p, 2),
                0.1 + 0.1 * hashf(seed ^ 0x41, p, 3),
            );
            if u > x0 && u < x0 + w && v > y0 && v < y0 + h {
                let s = ((u - x0) * 80.0 + (v - y0) * 40.0 * p as f32).sin();
                c = hsv(
                    hashf(seed ^ 0x51, p, 0),
                    0.8,
                    if s > 0.0 { 0.8 } else { 0.15 },
                );
            }
        }
        let paper = value_noise(seed ^ 0x61, u, v, 512);
        (c * (0.9 + 0.2 * paper)).clamp(Vec3::ZERO, Vec3::ONE)
    })
}

/// A checkerboard of two colours with noise, for props.
pub fn checker(seed: u32, size: usize, a: Vec3, b: Vec3, cells: u32) -> Texture {
    Texture::from_fn(size, size, move |u, v| {
        let (i, j) = (
            (u * cells as f32).floor() as i32,
            (v * cells as f32).floor() as i32,
        );
        let base = if (i + j) % 2 == 0 { a } else { b };
        let n = fbm(seed, u, v, 16, 4);
        (base * (0.7 + 0.6 * n)).clamp(Vec3::ZERO, Vec3::ONE)
    })
}

/// Horizontal stripes (along v) of alternating colours with a woven fine texture.
pub fn stripes(seed: u32, size: usize, a: Vec3, b: Vec3, count: u32) -> Texture {
    Texture::from_fn(size, size, move |u, v| {
        let s = (v * count as f32).fract();
        let base = if s < 0.5 { a } else { b };
        let weave = 0.5 + 0.5 * ((u * 300.0).sin() * (v * 300.0).sin());
        let n = fbm(seed, u, v, 8, 4);
        (base * (0.8 + 0.15 * weave + 0.2 * n)).clamp(Vec3::ZERO, Vec3::ONE)
    })
}

/// Bold plaid: alternating bands of two colours along u and v (their product gives checks) with thin
/// dark lines and a fine weave; blurs under motion in any direction.
pub fn plaid(seed: u32, size: usize, a: Vec3, b: Vec3, count: u32) -> Texture {
    Texture::from_fn(size, size, move |u, v| {
        let (su, sv) = ((u * count as f32).fract(), (v * count as f32).fract());
        let (bu, bv) = (su < 0.5, sv < 0.5);
        let mut c = match (bu, bv) {
            (true, true) => a,
            (false, false) => b,
            _ => (a + b) * 0.5,
        };
        if (su - 0.75).abs() < 0.04 || (sv - 0.75).abs() < 0.04 {
            c = Vec3::splat(0.05);
        }
        let weave = 0.5 + 0.5 * ((u * 300.0).sin() * (v * 300.0).sin());
        let n = fbm(seed, u, v, 8, 4);
        (c * (0.8 + 0.15 * weave + 0.2 * n)).clamp(Vec3::ZERO, Vec3::ONE)
    })
}

/// Denim-like fabric: a base colour with diagonal twill and mottling.
pub fn denim(seed: u32, size: usize, base: Vec3) -> Texture {
    Texture::from_fn(size, size, move |u, v| {
        let twill = 0.5 + 0.5 * ((u + v) * 250.0).sin();
        let mottle = fbm(seed, u, v, 6, 5);
        let seam = if (u * 4.0).fract() < 0.02 { 0.6 } else { 1.0 };
        (base * (0.7 + 0.2 * twill + 0.4 * mottle) * seam).clamp(Vec3::ZERO, Vec3::ONE)
    })
}

/// Near-uniform material (skin, hair, shoes) with low-amplitude noise; `streaks` stretches the
/// noise along v (hair).
pub fn mottled(seed: u32, size: usize, base: Vec3, amount: f32, streaks: bool) -> Texture {
    Texture::from_fn(size, size, move |u, v| {
        let n = if streaks {
            fbm(seed, u, v * 0.125, 64, 3)
        } else {
            fbm(seed, u, v, 8, 4)
        };
        (base * (1.0 - amount + 2.0 * amount * n)).clamp(Vec3::ZERO, Vec3::ONE)
    })
}

#[cfg(test)]
mod tests {
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn floor_matches_the_standard_library_bit_for_bit() {
        let mut specials = vec![
            0.0f32,
            -0.0,
            0.5,
            -0.5,
            1.0,
            -1.0,
            0.999_999_9,
            -0.999_999_9,
            8_388_607.5,
            -8_388_607.5,
            8_388_608.0,
            -8_388_609.0,
            1e30,
            -1e30,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::MIN_POSITIVE,
            -f32::MIN_POSITIVE,
        ];
        let mut rng = ChaCha8Rng::seed_from_u64(0x1234_5678);
        specials.extend((0..100_000).map(|_| f32::from_bits(rng.gen())));
        for x in specials {
            let (a, b) = (super::floor(x), x.floor());
            assert!(
                a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()),
                "{x}: {a} vs {b}"
            );
        }
    }
}
