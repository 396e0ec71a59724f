//! The per-tile loops of forward and backward ([`forward_tile`], [`backward_tile`]) and the lane
//! arithmetic they share, so that the backward replays the forward's α, T and stop decisions bit
//! for bit. Portable kernels on [`Lanes`] of four (SSE2 for f32 on x86-64, plain arrays for f64);
//! the AVX-512 twins in `avx512` give the same bits. They never allocate and never see the whole
//! image.

use crate::lanes::Lanes;
use crate::{lit, Real, TILE_PIXELS, TILE_SIZE};

use super::Cotangents;

/// The part of a [`Projected`] Gaussian the tile kernels read, copied per (tile, Gaussian) pair in
/// sorted order so that each tile streams its list from contiguous memory.
///
/// [`Projected`]: crate::project::Projected
#[derive(Clone, Copy, Debug)]
pub(super) struct PairSplat<T> {
    pub(super) mean2d: [T; 2],
    pub(super) conic: [T; 3],
    pub(super) opacity: T,
    pub(super) depth: T,
    pub(super) extent: [T; 2],
}

pub(super) const BUF_T: usize = 0;
pub(super) const BUF_D: usize = TILE_PIXELS;
pub(super) const BUF_C: usize = 2 * TILE_PIXELS;
/// Range of pixel columns (or rows) `[lo, hi)` within a tile side of `len` pixels starting at
/// `origin` whose centres lie within `half` of `mean`: lo = ⌈mean − half − ½ − origin⌉ and
/// hi = ⌊mean + half − ½ − origin⌋ + 1, clamped to [0, len] (NaN gives len). Floor and ceiling are
/// taken by truncation inside the clamp range, where the values are positive, so that the tile
/// kernels call no libm rounding function (baseline x86-64 has no rounding instruction).
#[inline(always)]
pub(super) fn pixel_span<T: Real>(mean: T, half: T, origin: T, len: usize) -> (usize, usize) {
    let h: T = lit(0.5);
    let len_t: T = lit(len as f64);
    let lo = mean - half - h - origin;
    let hi = mean + half - h - origin;
    let trunc = |v: T| v.to_usize().unwrap_or(len);
    let lo = if lo <= T::zero() {
        0
    } else if !(lo < len_t) {
        len
    } else {
        let t = trunc(lo);
        t + usize::from(lit::<T>(t as f64) < lo)
    };
    let hi = if hi < T::zero() {
        0
    } else if !(hi < len_t) {
        len
    } else {
        (trunc(hi) + 1).min(len)
    };
    (lo, hi)
}

/// Per-splat constants of the tile kernels, relative to the tile origin.
#[derive(Clone, Copy)]
pub(super) struct SplatLanes<T> {
    pub(super) mx: T,
    pub(super) my: T,
    pub(super) conic: [T; 3],
    pub(super) opacity: T,
    /// Lane x is in the splat's pixel box iff lo < x + 0.5 < hi.
    pub(super) lo: T,
    pub(super) hi: T,
    /// Quads (groups of [`QUAD`] lanes) overlapping the box: q0..q1.
    pub(super) q0: usize,
    pub(super) q1: usize,
}

/// Lanes per group in the tile kernels' row loops: `for q in q0..q1 { … }` visits only the groups
/// overlapping a splat's box, each as one [`Lanes`] value (an SSE register for f32 on x86-64).
const QUAD: usize = 4;
/// Quads per tile row (loops bound their quad index by it so the compiler can drop bounds checks).
const QUADS: usize = TILE_SIZE / QUAD;

/// Per-lane predicate of the working precision's lanes.
type LaneMask<T> = <<T as Real>::V4 as Lanes<T>>::Mask;

/// Constants of the lane functions, splatted once per tile.
struct LaneConsts<T: Real> {
    zero: T::V4,
    one: T::V4,
    neg_half: T::V4,
    max_alpha: T::V4,
    min_alpha: T::V4,
    min_t: T::V4,
}

impl<T: Real> LaneConsts<T> {
    fn new() -> Self {
        let v = |x: f64| T::V4::splat(lit(x));
        Self {
            zero: v(0.0),
            one: v(1.0),
            neg_half: v(-0.5),
            max_alpha: v(0.99),
            min_alpha: v(1.0 / 255.0),
            min_t: v(1e-4),
        }
    }
}

/// Lane values of one splat on one quad of a tile row: (exp(power), o·exp(power), the α that
/// blends: 0 outside the box, for power > 0 and for α < 1/255). `cx` are the lanes' pixel-centre
/// x, `dy` = mean y − pixel-centre y and `cc_dy_dy` = (conic c · dy) · dy of the row. One function
/// for forward and backward, so that both make bit-identical decisions.
#[inline(always)]
fn lane_alpha<T: Real>(
    s: &SplatLanes<T>,
    cx: T::V4,
    dy: T,
    cc_dy_dy: T,
    k: &LaneConsts<T>,
) -> (T::V4, T::V4, T::V4) {
    let v = T::V4::splat;
    let [ca, cb, _] = s.conic;
    let dx = v(s.mx) - cx;
    let power = k.neg_half * (v(ca) * dx * dx + v(cc_dy_dy)) - v(cb) * dx * v(dy);
    let gauss = power.exp();
    let raw = v(s.opacity) * gauss;
    let a = T::V4::select(raw.lt(k.max_alpha), raw, k.max_alpha);
    let ok = cx.gt(v(s.lo)) & cx.lt(v(s.hi)) & power.le(k.zero) & a.ge(k.min_alpha);
    (gauss, raw, T::V4::select(ok, a, k.zero))
}

/// Lane step of the blend state shared by forward and backward: with `a` the lanes' α (0 = skip)
/// and `alive` 1/0, returns (weight α·T, new T, new alive, stopped). A stopping splat is excluded.
#[inline(always)]
fn lane_blend<T: Real>(
    a: T::V4,
    t: T::V4,
    alive: T::V4,
    k: &LaneConsts<T>,
) -> (T::V4, T::V4, T::V4, LaneMask<T>) {
    let live = alive.gt(k.zero) & a.gt(k.zero);
    let test_t = t * (k.one - a);
    let stop = live & test_t.lt(k.min_t);
    let contrib = live & !stop;
    (
        T::V4::select(contrib, a * t, k.zero),
        T::V4::select(contrib, test_t, t),
        T::V4::select(stop, k.zero, alive),
        stop,
    )
}

/// Values of one splat at one pixel: the power, exp(power), o·exp(power) and the α that blends (0
/// outside the box, for power > 0 and for α < 1/255). The scalar definition of [`lane_alpha`], which
/// the forward kernel uses (its loops over 16-lane rows auto-vectorise); both give the same bits
/// (unit test), so forward and backward make identical decisions.
#[inline(always)]
fn pixel_alpha<T: Real>(s: &SplatLanes<T>, cx: T, dy: T) -> (T, T, T, T) {
    let half: T = lit(0.5);
    let max_alpha: T = lit(0.99);
    let min_alpha: T = lit(1.0 / 255.0);
    let [ca, cb, cc] = s.conic;
    let dx = s.mx - cx;
    let power = -half * (ca * dx * dx + cc * dy * dy) - cb * dx * dy;
    let gauss = power.splat_exp();
    let raw = s.opacity * gauss;
    let a = if raw < max_alpha { raw } else { max_alpha };
    let ok = (cx > s.lo) & (cx < s.hi) & (power <= T::zero()) & (a >= min_alpha);
    (power, gauss, raw, if ok { a } else { T::zero() })
}

/// Blend step of one pixel: with `a` its α (0 = skip) and `alive` 1/0, returns (weight α·T, new T,
/// new alive, stopped). A stopping splat is excluded. The scalar definition of [`lane_blend`]
/// (same bits, unit test).
#[inline(always)]
fn pixel_blend<T: Real>(a: T, t: T, alive: T) -> (T, T, T, bool) {
    let min_t: T = lit(1e-4);
    let live = (alive > T::zero()) & (a > T::zero());
    let test_t = t * (T::one() - a);
    let stop = live & (test_t < min_t);
    let contrib = live & !stop;
    (
        if contrib { a * t } else { T::zero() },
        if contrib { test_t } else { t },
        if stop { T::zero() } else { alive },
        stop,
    )
}

/// The splat's lane constants and pixel box (rows y0..y1) in a tile, or `None` if the box is empty.
#[inline(always)]
pub(super) fn splat_lanes<T: Real>(
    p: &PairSplat<T>,
    ox: T,
    oy: T,
    size: [usize; 2],
) -> Option<(SplatLanes<T>, usize, usize)> {
    let (x0, x1) = pixel_span(p.mean2d[0], p.extent[0], ox, size[0]);
    let (y0, y1) = pixel_span(p.mean2d[1], p.extent[1], oy, size[1]);
    if x0 >= x1 || y0 >= y1 {
        return None;
    }
    Some((
        SplatLanes {
            mx: p.mean2d[0] - ox,
            my: p.mean2d[1] - oy,
            conic: p.conic,
            opacity: p.opacity,
            lo: lit(x0 as f64),
            hi: lit(x1 as f64),
            q0: x0 / QUAD,
            q1: x1.div_ceil(QUAD).min(QUADS),
        },
        y0,
        y1,
    ))
}

/// Pixel-centre offsets 0.5, 1.5, … within a tile.
pub(super) fn centres<T: Real>() -> [T; TILE_SIZE] {
    std::array::from_fn(|i| lit(i as f64 + 0.5))
}

/// Pixel-centre x offsets of each quad's lanes.
fn quad_centres<T: Real>() -> [T::V4; QUADS] {
    let c = centres::<T>();
    std::array::from_fn(|q| T::V4::load(&c[q * QUAD..]))
}

/// Blends one tile front to back into `buf` ([T | depth | channels] × 256); `used` receives the
/// number of list entries blended before every pixel stopped, `alive` (256) 1 for each pixel that
/// never stopped and 0 for one that did.
///
/// Splat-major: each row of a splat's (margin-padded) pixel box is a few fixed 16-lane passes (one
/// lane per pixel column; lanes outside the box, already stopped, with power > 0 or α < 1/255 get
/// weight 0), written as simple select-only loops so that the compiler vectorises them. Adding a
/// zero weight leaves every sum bit-identical to skipping the pixel (all values are finite).
#[allow(clippy::too_many_arguments)]
pub(super) fn forward_tile<T: Real>(
    list: &[PairSplat<T>],
    channels: &[T],
    c: usize,
    origin: [usize; 2],
    size: [usize; 2],
    buf: &mut [T],
    used: &mut u32,
    alive: &mut [T],
) {
    buf[BUF_T..BUF_T + TILE_PIXELS].fill(T::one());
    // 1 while a pixel still blends, 0 once it stopped (a T so that every lane is T-wide).
    alive[..TILE_PIXELS].fill(T::one());
    *used = list.len() as u32;
    if list.is_empty() {
        return;
    }
    let (tbuf, rest) = buf.split_at_mut(BUF_D);
    let (dbuf, cbuf) = rest.split_at_mut(TILE_PIXELS);
    let mut n_done = 0u32;
    let n_pixels = (size[0] * size[1]) as u32;
    let ox: T = lit(origin[0] as f64);
    let oy: T = lit(origin[1] as f64);
    let centre = centres::<T>();
    let mut w = [T::zero(); TILE_SIZE];
    let mut alpha = [T::zero(); TILE_SIZE];
    for (k, p) in list.iter().enumerate() {
        let Some((sl, y0, y1)) = splat_lanes(p, ox, oy, size) else {
            continue;
        };
        let ch = &channels[k * c..(k + 1) * c];
        let z = p.depth;
        for y in y0..y1 {
            let dy = sl.my - centre[y];
            let row = y * TILE_SIZE;
            for q in sl.q0..sl.q1.min(QUADS) {
                for l in 0..QUAD {
                    let x = q * QUAD + l;
                    alpha[x] = pixel_alpha(&sl, centre[x], dy).3;
                }
            }
            let t_row = &mut tbuf[row..row + TILE_SIZE];
            let alive_row = &mut alive[row..row + TILE_SIZE];
            let mut stops = 0u32;
            for q in sl.q0..sl.q1.min(QUADS) {
                for l in 0..QUAD {
                    let x = q * QUAD + l;
                    let (wx, t, al, stop) = pixel_blend(alpha[x], t_row[x], alive_row[x]);
                    w[x] = wx;
                    t_row[x] = t;
                    alive_row[x] = al;
                    stops += u32::from(stop);
                }
            }
            n_done += stops;
            for (j, &v) in ch.iter().enumerate() {
                let dst = &mut cbuf[j * TILE_PIXELS + row..j * TILE_PIXELS + row + TILE_SIZE];
                for q in sl.q0..sl.q1.min(QUADS) {
                    for l in 0..QUAD {
                        let x = q * QUAD + l;
                        dst[x] = dst[x] + w[x] * v;
                    }
                }
            }
            let dst = &mut dbuf[row..row + TILE_SIZE];
            for q in sl.q0..sl.q1.min(QUADS) {
                for l in 0..QUAD {
                    let x = q * QUAD + l;
                    dst[x] = dst[x] + w[x] * z;
                }
            }
        }
        if n_done == n_pixels {
            *used = k as u32 + 1;
            break;
        }
    }
}

/// Per-thread scratch of the backward tile kernels (allocated once per rayon job split, not per
/// pixel).
pub(super) struct BackwardScratch<T: Real> {
    pub(super) t: Vec<T>,
    pub(super) alive: Vec<T>,
    pub(super) pre: Vec<T>,
    pub(super) g_img: Vec<T>,
    pub(super) g_alpha: Vec<T>,
    pub(super) g_depth: Vec<T>,
    /// Per-column channel-gradient accumulators of the current pair, C × [`TILE_SIZE`] (column x
    /// sums the pair's pixels in tile column x).
    pub(super) acc_channels: Vec<T>,
    /// Tile rows with a non-zero cotangent (image, alpha or depth). A row whose cotangents are all
    /// zero adds only exact zeros to every gradient, so the kernels skip it: same bits, less work
    /// when a loss reads a subset of the pixels (the flow loss's 1/4 resize reads half the rows).
    pub(super) live_rows: [bool; TILE_SIZE],
    /// The channels, in order, with a non-zero image cotangent somewhere in the tile. A channel
    /// without one adds only exact zeros (its colour gradient stays +0 and its share of dL/dα is
    /// ±0 added to a sum that is never −0), so the kernels skip it: same bits, a quarter less
    /// channel work when a caller supervises RGB and renders a fourth channel it does not.
    pub(super) live_channels: Vec<usize>,
    /// `false` only in tests, to compare with the kernels that replay every row and channel.
    pub(super) skip_zero_cotangents: bool,
}

impl<T: Real> BackwardScratch<T> {
    pub(super) fn new(c: usize) -> Self {
        Self {
            t: vec![T::zero(); TILE_PIXELS],
            alive: vec![T::zero(); TILE_PIXELS],
            pre: vec![T::zero(); (c + 1) * TILE_PIXELS],
            g_img: vec![T::zero(); c * TILE_PIXELS],
            g_alpha: vec![T::zero(); TILE_PIXELS],
            g_depth: vec![T::zero(); TILE_PIXELS],
            acc_channels: vec![T::zero(); c * TILE_SIZE],
            live_rows: [false; TILE_SIZE],
            live_channels: Vec::with_capacity(c),
            skip_zero_cotangents: true,
        }
    }

    /// Resets the blend state and copies the tile's cotangents into tile-major rows.
    pub(super) fn prepare(
        &mut self,
        c: usize,
        origin: [usize; 2],
        size: [usize; 2],
        width: usize,
        cot: &Cotangents<'_, T>,
    ) {
        let hw = cot.image.len() / c.max(1);
        self.t.fill(T::one());
        self.alive.fill(T::one());
        self.pre.fill(T::zero());
        self.g_img.fill(T::zero());
        self.g_alpha.fill(T::zero());
        self.g_depth.fill(T::zero());
        for y in 0..size[1] {
            let idx = y * TILE_SIZE;
            let pix = (origin[1] + y) * width + origin[0];
            for j in 0..c {
                self.g_img[j * TILE_PIXELS + idx..j * TILE_PIXELS + idx + size[0]]
                    .copy_from_slice(&cot.image[j * hw + pix..j * hw + pix + size[0]]);
            }
            if let Some(a) = cot.alpha {
                self.g_alpha[idx..idx + size[0]].copy_from_slice(&a[pix..pix + size[0]]);
            }
            if let Some(d) = cot.depth {
                self.g_depth[idx..idx + size[0]].copy_from_slice(&d[pix..pix + size[0]]);
            }
        }
        for (y, live) in self.live_rows.iter_mut().enumerate() {
            let row = y * TILE_SIZE..(y + 1) * TILE_SIZE;
            let nonzero = |v: &[T]| v.iter().any(|&x| x != T::zero());
            *live = !self.skip_zero_cotangents
                || nonzero(&self.g_alpha[row.clone()])
                || nonzero(&self.g_depth[row.clone()])
                || (0..c).any(|j| nonzero(&self.g_img[j * TILE_PIXELS..][row.clone()]));
        }
        self.live_channels.clear();
        self.live_channels.extend((0..c).filter(|&j| {
            !self.skip_zero_cotangents
                || self.g_img[j * TILE_PIXELS..(j + 1) * TILE_PIXELS]
                    .iter()
                    .any(|&x| x != T::zero())
        }));
    }
}

/// Sum of a pair's per-column partial sums in column order, starting from zero: the fixed
/// reduction order of every backward kernel, so that they all give the same bits.
#[inline(always)]
pub(super) fn column_sum<T: Real>(columns: &[T]) -> T {
    columns.iter().fold(T::zero(), |s, &x| s + x)
}

/// Replays one tile front to back (the forward's first `used` list entries, with bit-identical
/// α, T and stop decisions) and writes each pair's gradient slot
/// [mean2d x, y | conic a, b, c | opacity | depth | channels C].
///
/// Every row of a pair is a few quads of four lanes, each quad one pass through α, blend state,
/// dL/dα and per-column accumulators; each pair's per-column partial sums are reduced in column
/// order at the end of the pair, so the result does not depend on threads — nor on the lane width:
/// the AVX-512 kernel (16 lanes, one register per row) gives the same bits.
#[allow(clippy::too_many_arguments)]
pub(super) fn backward_tile<T: Real>(
    list: &[PairSplat<T>],
    channels: &[T],
    bg: &[T],
    c: usize,
    origin: [usize; 2],
    size: [usize; 2],
    width: usize,
    buf: &[T],
    used: usize,
    cot: &Cotangents<'_, T>,
    s: &mut BackwardScratch<T>,
    out: &mut [T],
) {
    let slot = 7 + c;
    s.prepare(c, origin, size, width, cot);
    let t_final = &buf[BUF_T..BUF_T + TILE_PIXELS];
    let d_final = &buf[BUF_D..BUF_D + TILE_PIXELS];
    let c_final = &buf[BUF_C..];
    let ox: T = lit(origin[0] as f64);
    let oy: T = lit(origin[1] as f64);
    let centre = centres::<T>();
    let cx = quad_centres::<T>();
    let k = LaneConsts::<T>::new();
    let v = T::V4::splat;
    let half = v(lit(0.5));
    let has_alpha = cot.alpha.is_some();
    let has_depth = cot.depth.is_some();
    for (idx, p) in list.iter().enumerate().take(used) {
        let Some((sl, y0, y1)) = splat_lanes(p, ox, oy, size) else {
            continue;
        };
        let ch = &channels[idx * c..(idx + 1) * c];
        let [ca, cb, cc] = p.conic;
        let (v_ca, v_cb, v_mx) = (v(ca), v(cb), v(sl.mx));
        let z = v(p.depth);
        s.acc_channels.fill(T::zero());
        // Per-column accumulators: mean x, y, conic a, b, c, opacity, depth; quad q holds columns
        // 4q..4q+4.
        let mut geo = [[k.zero; QUADS]; 7];
        for y in (y0..y1).filter(|&y| s.live_rows[y]) {
            let dy = sl.my - centre[y];
            let cc_dy_dy = cc * dy * dy;
            let (v_dy, v_cb_dy, v_cc_dy) = (v(dy), v(cb * dy), v(cc * dy));
            let row = y * TILE_SIZE;
            for (q, &cxq) in cx.iter().enumerate().take(sl.q1).skip(sl.q0) {
                let at = row + q * QUAD;
                let (gauss, raw, a) = lane_alpha(&sl, cxq, dy, cc_dy_dy, &k);
                // α where the clamp is inactive (else 0): dα/dpower = α there.
                let slope = T::V4::select(raw.lt(k.max_alpha), a, k.zero);
                let t_old = T::V4::load(&s.t[at..]);
                let alive = T::V4::load(&s.alive[at..]);
                let (w, t_new, alive, stop) = lane_blend(a, t_old, alive, &k);
                // Non-contributing lanes: w = 0 and T unchanged.
                let contrib = w.ne(k.zero);
                if T::V4::count(contrib | stop) == 0 {
                    // Nothing changes in this quad and every gradient term below is a zero (the
                    // accumulators start at +0 and are never −0, so adding ±0 is a no-op).
                    continue;
                }
                t_new.store(&mut s.t[at..]);
                alive.store(&mut s.alive[at..]);
                let inv = k.one / (k.one - T::V4::select(contrib, a, k.zero));
                let tn = T::V4::load(&t_final[at..]);
                // dL/dα per lane, accumulated over alpha, channels and depth.
                let mut d_alpha = if has_alpha {
                    T::V4::load(&s.g_alpha[at..]) * tn * inv
                } else {
                    k.zero
                };
                for &j in &s.live_channels {
                    let (value, b) = (v(ch[j]), v(bg[j]));
                    let o = j * TILE_PIXELS + at;
                    let pre = T::V4::load(&s.pre[o..]) + w * value;
                    pre.store(&mut s.pre[o..]);
                    let behind = T::V4::load(&c_final[o..]) - pre + tn * b;
                    let gi = T::V4::load(&s.g_img[o..]);
                    d_alpha = d_alpha + gi * (t_old * value - behind * inv);
                    let acc = &mut s.acc_channels[j * TILE_SIZE + q * QUAD..];
                    (T::V4::load(acc) + w * gi).store(acc);
                }
                // Without a depth cotangent the depth terms are exact zeros: skip them.
                if has_depth {
                    let o = c * TILE_PIXELS + at;
                    let pre = T::V4::load(&s.pre[o..]) + w * z;
                    pre.store(&mut s.pre[o..]);
                    let behind = T::V4::load(&d_final[at..]) - pre;
                    let gd = T::V4::load(&s.g_depth[at..]);
                    d_alpha = d_alpha + gd * (t_old * z - behind * inv);
                    geo[6][q] = geo[6][q] + w * gd;
                }
                // Only contributing lanes carry a gradient; where α is clamped at 0.99 its
                // derivative w.r.t. opacity and power is zero.
                let dx = v_mx - cxq;
                let da = T::V4::select(contrib, d_alpha, k.zero);
                let d_power = slope * da;
                geo[0][q] = geo[0][q] - d_power * (v_ca * dx + v_cb_dy);
                geo[1][q] = geo[1][q] - d_power * (v_cc_dy + v_cb * dx);
                geo[2][q] = geo[2][q] - half * d_power * dx * dx;
                geo[3][q] = geo[3][q] - d_power * dx * v_dy;
                geo[4][q] = geo[4][q] - half * d_power * v_dy * v_dy;
                geo[5][q] = geo[5][q] + T::V4::select(slope.ne(k.zero), gauss * da, k.zero);
            }
        }
        let dst = &mut out[idx * slot..(idx + 1) * slot];
        for (d, quads) in dst.iter_mut().zip(&geo) {
            let columns: [T; TILE_SIZE] =
                std::array::from_fn(|x| quads[x / QUAD].to_array()[x % QUAD]);
            *d = column_sum(&columns);
        }
        for (d, columns) in dst[7..]
            .iter_mut()
            .zip(s.acc_channels.chunks_exact(TILE_SIZE))
        {
            *d = column_sum(columns);
        }
    }
}

#[cfg(test)]
mod tests {
    /// The forward kernel decides per pixel with the scalar `pixel_alpha` / `pixel_blend`, the
    /// backward per quad with `lane_alpha` / `lane_blend`: every output must be the same bits, or
    /// the backward would replay a different blend than the forward rendered.
    #[test]
    fn lane_and_pixel_decisions_are_bit_identical() {
        use super::*;
        let mut state = 0x0dd5_eed5_u64;
        let mut uniform = |lo: f32, hi: f32| {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            lo + (hi - lo) * ((state >> 40) as f32 / (1u64 << 24) as f32)
        };
        let k = LaneConsts::<f32>::new();
        let centre = centres::<f32>();
        let cx = quad_centres::<f32>();
        let mut decisions = [0usize; 3];
        for _ in 0..20_000 {
            let (a, b) = (uniform(0.01, 3.0), uniform(0.01, 3.0));
            let cb = uniform(-0.9, 0.9) * (a * b).sqrt();
            let lo = uniform(-2.0, 10.0).floor().max(0.0);
            let sl = SplatLanes {
                mx: uniform(-4.0, 20.0),
                my: uniform(-4.0, 20.0),
                conic: [a, cb, b],
                opacity: uniform(0.0, 1.0).powi(3).max(uniform(0.95, 1.0) * 1.001),
                lo,
                hi: lo + uniform(1.0, 12.0).floor(),
                q0: 0,
                q1: QUADS,
            };
            let y = (uniform(0.0, 16.0) as usize).min(TILE_SIZE - 1);
            let dy = sl.my - centre[y];
            let cc_dy_dy = sl.conic[2] * dy * dy;
            for (q, &cxq) in cx.iter().enumerate() {
                let t: [f32; 4] = std::array::from_fn(|_| uniform(0.0, 1.0).powi(4));
                let alive: [f32; 4] = std::array::from_fn(|_| f32::from(uniform(0.0, 1.0) < 0.8));
                let (gauss, raw, alpha) = lane_alpha(&sl, cxq, dy, cc_dy_dy, &k);
                let (w, t_new, alive_new, stop) =
                    lane_blend(alpha, <f32 as Real>::V4::load(&t), Lanes::load(&alive), &k);
                let stops = <f32 as Real>::V4::count(stop);
                let mut pixel_stops = 0;
                for l in 0..QUAD {
                    let (_, g, r, al) = pixel_alpha(&sl, centre[q * QUAD + l], dy);
                    assert_eq!(g.to_bits(), gauss.to_array()[l].to_bits());
                    assert_eq!(r.to_bits(), raw.to_array()[l].to_bits());
                    assert_eq!(al.to_bits(), alpha.to_array()[l].to_bits());
                    let (pw, pt, pa, ps) = pixel_blend(al, t[l], alive[l]);
                    assert_eq!(pw.to_bits(), w.to_array()[l].to_bits());
                    assert_eq!(pt.to_bits(), t_new.to_array()[l].to_bits());
                    assert_eq!(pa.to_bits(), alive_new.to_array()[l].to_bits());
                    pixel_stops += u32::from(ps);
                    decisions[usize::from(al > 0.0) + usize::from(ps)] += 1;
                }
                assert_eq!(stops, pixel_stops);
            }
        }
        // The random lanes reach all three outcomes: skipped, blended and stopping.
        assert!(decisions.iter().all(|&d| d > 100), "{decisions:?}");
    }
    /// The span by the rounding-function definition it replaces.
    fn span_by_rounding(mean: f32, half: f32, origin: f32, len: usize) -> (usize, usize) {
        let lo = (mean - half - 0.5 - origin).ceil();
        let hi = (mean + half - 0.5 - origin).floor() + 1.0;
        let clamp = |v: f32| {
            if v <= 0.0 {
                0
            } else if v.is_nan() {
                len
            } else {
                (v as usize).min(len)
            }
        };
        (clamp(lo), clamp(hi))
    }

    #[test]
    fn pixel_span_equals_the_ceil_floor_definition() {
        let mut next = crate::raster::test_uniform(0x2545_F491_4F6C_DD1D);
        let mut cases = vec![
            (f32::NAN, 1.0, 0.0),
            (8.0, f32::NAN, 0.0),
            (1e30, 1.0, 0.0),
            (-1e30, 1.0, 0.0),
            (16.5, 0.0, 0.0),
            (0.5, 0.0, 0.0),
            (-0.5, 0.0, 0.0),
            (16.0, 0.5, 16.0),
        ];
        for _ in 0..200_000 {
            // Integers and half-integers often, to hit the rounding edges exactly.
            let snap = |v: f32, k: f32| if k < 0.3 { (v * 2.0).round() / 2.0 } else { v };
            let mean = snap(next() * 80.0 - 20.0, next());
            let half = snap(next() * 20.0, next());
            let origin = 16.0 * (next() * 4.0).floor();
            cases.push((mean, half, origin));
        }
        for (mean, half, origin) in cases {
            for len in [1, 7, 16] {
                assert_eq!(
                    super::pixel_span(mean, half, origin, len),
                    span_by_rounding(mean, half, origin, len),
                    "mean {mean}, half {half}, origin {origin}, len {len}"
                );
            }
        }
    }
}
