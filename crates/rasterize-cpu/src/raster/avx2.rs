//! The tile kernels for f32 on x86-64 CPUs with AVX2 but without AVX-512 (AMD Zen 2 and 3, most
//! Intel client cores): a pair visits each tile row of its box as one 8-lane window when the box
//! spans at most two quads of four columns (most of a person's small splats), else as the row's two
//! halves. The portable kernels run SSE2's four lanes on such CPUs, since the build
//! sets no target flags.
//!
//! Same bits as [`super::kernels::forward_tile`] and [`super::kernels::backward_tile`]: every lane
//! runs the same IEEE operations in the same order (no fused multiply-adds; [`exp`] repeats
//! [`crate::fast_exp_f32`]), and each pixel sees the pairs in list order. The backward walks a
//! pair's box window by window, rows inside (pixels are independent within a pair, and each column
//! still sums its rows in row order), so only one window's seven accumulators are live at a time,
//! and reduces the per-column sums in column order; lanes outside a pair's box add exact zeros to
//! sums that are never −0. The unit test below compares the kernels bit for bit.
//!
//! Selected at run time (`is_x86_feature_detected!("avx2")`), after the AVX-512 kernels.

#![allow(unsafe_code)]

use std::arch::x86_64::*;

use super::kernels::{centres, splat_lanes, BackwardScratch, PairSplat, BUF_C, BUF_D, BUF_T};
use super::Cotangents;
use crate::{lit, TILE_PIXELS, TILE_SIZE};

/// Lanes per register.
const LANES: usize = 8;

/// Whether this CPU has AVX2 (checked once).
fn detected() -> bool {
    static DETECTED: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *DETECTED.get_or_init(|| std::arch::is_x86_feature_detected!("avx2"))
}

/// Whether the kernels of this module run: the CPU has AVX2, and the environment variable
/// `E_SEM3DGS_PORTABLE_KERNELS` is not set (set, the portable kernels run instead, with the same
/// bits: for measuring one against the other on a CPU).
pub(super) fn available() -> bool {
    static AVAILABLE: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *AVAILABLE
        .get_or_init(|| detected() && std::env::var_os("E_SEM3DGS_PORTABLE_KERNELS").is_none())
}

/// Runs [`backward_tile`] and returns `true`, or returns `false` (doing nothing) if the kernels of
/// this module are not [`available`].
#[allow(clippy::too_many_arguments)]
pub(super) fn try_backward_tile(
    list: &[PairSplat<f32>],
    channels: &[f32],
    bg: &[f32],
    c: usize,
    origin: [usize; 2],
    size: [usize; 2],
    width: usize,
    buf: &[f32],
    used: usize,
    cot: &Cotangents<'_, f32>,
    s: &mut BackwardScratch<f32>,
    out: &mut [f32],
) -> bool {
    if !available() {
        return false;
    }
    // SAFETY: the CPU has AVX2 (checked above), the kernel's only requirement.
    unsafe {
        backward_tile(
            list, channels, bg, c, origin, size, width, buf, used, cot, s, out,
        )
    };
    true
}

/// Runs [`forward_tile`] and returns `true`, or returns `false` (doing nothing) if the kernels of
/// this module are not [`available`].
#[allow(clippy::too_many_arguments)]
pub(super) fn try_forward_tile(
    list: &[PairSplat<f32>],
    channels: &[f32],
    c: usize,
    origin: [usize; 2],
    size: [usize; 2],
    buf: &mut [f32],
    used: &mut u32,
    alive: &mut [f32],
) -> bool {
    if !available() {
        return false;
    }
    // SAFETY: the CPU has AVX2 (checked above), the kernel's only requirement.
    unsafe { forward_tile(list, channels, c, origin, size, buf, used, alive) };
    true
}

/// Lanes `s[0..8]` (panics if `s` is shorter).
#[target_feature(enable = "avx2")]
#[inline]
fn load(s: &[f32]) -> __m256 {
    let s = &s[..LANES];
    // SAFETY: `s` holds eight initialised f32; `loadu` has no alignment requirement.
    unsafe { _mm256_loadu_ps(s.as_ptr()) }
}

/// Writes the lanes to `s[0..8]` (panics if `s` is shorter).
#[target_feature(enable = "avx2")]
#[inline]
fn store(v: __m256, s: &mut [f32]) {
    let s = &mut s[..LANES];
    // SAFETY: `s` has room for eight f32; `storeu` has no alignment requirement.
    unsafe { _mm256_storeu_ps(s.as_mut_ptr(), v) }
}

/// `if m { a } else { b }` per lane (`m` a comparison's all-ones / all-zeros lanes).
#[target_feature(enable = "avx2")]
#[inline]
fn select(m: __m256, a: __m256, b: __m256) -> __m256 {
    _mm256_blendv_ps(b, a, m)
}

/// `a && b` per lane of two comparison masks.
#[target_feature(enable = "avx2")]
#[inline]
fn and(a: __m256, b: __m256) -> __m256 {
    _mm256_and_ps(a, b)
}

/// `a && !b` per lane of two comparison masks.
#[target_feature(enable = "avx2")]
#[inline]
fn and_not(a: __m256, b: __m256) -> __m256 {
    _mm256_andnot_ps(b, a)
}

/// The lanes where the mask holds, one bit each (lane 0 the lowest).
#[target_feature(enable = "avx2")]
#[inline]
fn bits(m: __m256) -> u32 {
    _mm256_movemask_ps(m) as u32
}

/// [`crate::fast_exp_f32`] lane by lane, operation for operation.
#[target_feature(enable = "avx2")]
#[inline]
fn exp(x: __m256) -> __m256 {
    const LOG2E: f32 = std::f32::consts::LOG2_E;
    const LN2_HI: f32 = 0.693_145_75;
    const LN2_LO: f32 = 1.428_606_8e-6;
    const ROUND: f32 = 12_582_912.0;
    const ROUND_BITS: i32 = 0x4B40_0000;
    let s = _mm256_set1_ps;
    let (add, sub, mul) = (_mm256_add_ps, _mm256_sub_ps, _mm256_mul_ps);
    let x = select(_mm256_cmp_ps::<_CMP_LT_OQ>(x, s(-87.0)), s(-87.0), x);
    let x = select(_mm256_cmp_ps::<_CMP_GT_OQ>(x, s(0.0)), s(0.0), x);
    let kr = add(mul(x, s(LOG2E)), s(ROUND));
    let k = sub(kr, s(ROUND));
    let r = sub(sub(x, mul(k, s(LN2_HI))), mul(k, s(LN2_LO)));
    let mut p = s(1.0 / 720.0);
    for c in [1.0 / 120.0, 1.0 / 24.0, 1.0 / 6.0, 0.5, 1.0, 1.0] {
        p = add(s(c), mul(r, p));
    }
    let bits = _mm256_sub_epi32(_mm256_castps_si256(kr), _mm256_set1_epi32(ROUND_BITS - 127));
    mul(p, _mm256_castsi256_ps(_mm256_slli_epi32::<23>(bits)))
}

/// The 8-column windows of a tile row a pair visits, from its box's quads of four columns
/// `q0..q1`: one window starting at the box's first quad when the box spans at most two quads
/// (shifted left to stay inside the row), else the row's two halves. Each column of the box lies
/// in exactly one window.
fn windows(q0: usize, q1: usize) -> impl Iterator<Item = usize> {
    const QUAD: usize = 4;
    let last = TILE_SIZE - LANES;
    let (first, count) = if q1 <= q0 + 2 {
        ((q0 * QUAD).min(last), 1)
    } else {
        (0, 2)
    };
    (0..count).map(move |i| first + i * LANES)
}

/// One pair's α on eight lanes of a row: (exp(power), α where the 0.99 clamp is inactive else 0,
/// the α that blends), as `lane_alpha`.
struct RowAlpha {
    gauss: __m256,
    slope: __m256,
    a: __m256,
}

/// The constants of one pair on one window of 8 columns: dx per lane, the box mask, the conic
/// and the opacity.
#[derive(Clone, Copy)]
struct WindowSplat {
    dx: __m256,
    in_box: __m256,
    ca: __m256,
    cb: __m256,
    opacity: __m256,
}

/// α of one pair on one window of a row with offset `dy` (mean y − pixel-centre y) and
/// `cc_dy_dy` = (conic c · dy) · dy.
#[target_feature(enable = "avx2")]
#[inline]
fn row_alpha(ws: &WindowSplat, dy: f32, cc_dy_dy: f32) -> RowAlpha {
    let v = _mm256_set1_ps;
    let (add, sub, mul) = (_mm256_add_ps, _mm256_sub_ps, _mm256_mul_ps);
    let zero = v(0.0);
    let max_alpha = v(lit(0.99));
    let power = sub(
        mul(v(-0.5), add(mul(mul(ws.ca, ws.dx), ws.dx), v(cc_dy_dy))),
        mul(mul(ws.cb, ws.dx), v(dy)),
    );
    let gauss = exp(power);
    let raw = mul(ws.opacity, gauss);
    let unclamped = _mm256_cmp_ps::<_CMP_LT_OQ>(raw, max_alpha);
    let a = select(unclamped, raw, max_alpha);
    let ok = and(
        and(ws.in_box, _mm256_cmp_ps::<_CMP_LE_OQ>(power, zero)),
        _mm256_cmp_ps::<_CMP_GE_OQ>(a, v(lit(1.0 / 255.0))),
    );
    let a = select(ok, a, zero);
    RowAlpha {
        gauss,
        slope: select(unclamped, a, zero),
        a,
    }
}

/// The blend step of eight pixels, as `lane_blend`: (weight α·T or 0, new T, new alive, live
/// lanes that blend, lanes that stop).
#[target_feature(enable = "avx2")]
#[inline]
fn blend(a: __m256, t: __m256, alive: __m256) -> (__m256, __m256, __m256, __m256, __m256) {
    let v = _mm256_set1_ps;
    let zero = v(0.0);
    let live = and(
        _mm256_cmp_ps::<_CMP_GT_OQ>(alive, zero),
        _mm256_cmp_ps::<_CMP_GT_OQ>(a, zero),
    );
    let one = v(1.0);
    let test_t = _mm256_mul_ps(t, _mm256_sub_ps(one, a));
    let stop = and(live, _mm256_cmp_ps::<_CMP_LT_OQ>(test_t, v(lit(1e-4))));
    let blends = and_not(live, stop);
    // The new T and alive without a select against the stored values, which the compiler would
    // turn into masked stores (microcoded, slow on AMD): T·(1 − 0) = T and alive − 0 = alive
    // exactly where nothing changes, and a stopping lane is live (alive = 1, so 1 − 1 = +0).
    (
        select(blends, _mm256_mul_ps(a, t), zero),
        _mm256_mul_ps(t, _mm256_sub_ps(one, select(blends, a, zero))),
        _mm256_sub_ps(alive, select(stop, one, zero)),
        blends,
        stop,
    )
}

/// The constants of pair `p` (its lanes `sl`) on the window of a row starting at column `x0`.
#[target_feature(enable = "avx2")]
#[inline]
fn window_splat(
    sl: &super::kernels::SplatLanes<f32>,
    centre: &[f32; TILE_SIZE],
    x0: usize,
) -> WindowSplat {
    let v = _mm256_set1_ps;
    let cx = load(&centre[x0..]);
    WindowSplat {
        dx: _mm256_sub_ps(v(sl.mx), cx),
        in_box: and(
            _mm256_cmp_ps::<_CMP_GT_OQ>(cx, v(sl.lo)),
            _mm256_cmp_ps::<_CMP_LT_OQ>(cx, v(sl.hi)),
        ),
        ca: v(sl.conic[0]),
        cb: v(sl.conic[1]),
        opacity: v(sl.opacity),
    }
}

/// [`super::kernels::backward_tile`] for f32 on 8-lane windows. Same arguments and output.
#[allow(clippy::too_many_arguments)]
#[target_feature(enable = "avx2")]
fn backward_tile(
    list: &[PairSplat<f32>],
    channels: &[f32],
    bg: &[f32],
    c: usize,
    origin: [usize; 2],
    size: [usize; 2],
    width: usize,
    buf: &[f32],
    used: usize,
    cot: &Cotangents<'_, f32>,
    s: &mut BackwardScratch<f32>,
    out: &mut [f32],
) {
    let slot = 7 + c;
    s.prepare(c, origin, size, width, cot);
    let t_final = &buf[BUF_T..BUF_T + TILE_PIXELS];
    let d_final = &buf[BUF_D..BUF_D + TILE_PIXELS];
    let c_final = &buf[BUF_C..];
    let ox: f32 = lit(origin[0] as f64);
    let oy: f32 = lit(origin[1] as f64);
    let centre = centres::<f32>();
    let v = _mm256_set1_ps;
    let (add, sub, mul) = (_mm256_add_ps, _mm256_sub_ps, _mm256_mul_ps);
    let (zero, one, half) = (v(0.0), v(1.0), v(0.5));
    let has_alpha = cot.alpha.is_some();
    let has_depth = cot.depth.is_some();
    for (idx, p) in list.iter().enumerate().take(used) {
        let Some((sl, y0, y1)) = splat_lanes(p, ox, oy, size) else {
            continue;
        };
        let ch = &channels[idx * c..(idx + 1) * c];
        let [_, cb, cc] = p.conic;
        let z = v(p.depth);
        s.acc_channels.fill(0.0);
        // Per-column sums of mean x, y, conic a, b, c, opacity, depth.
        let mut geo = [[0.0f32; TILE_SIZE]; 7];
        for x0 in windows(sl.q0, sl.q1) {
            let ws = window_splat(&sl, &centre, x0);
            let [mut a_mx, mut a_my, mut a_ca, mut a_cb, mut a_cc, mut a_op, mut a_z] = [zero; 7];
            for y in (y0..y1).filter(|&y| s.live_rows[y]) {
                let dy = sl.my - centre[y];
                let v_dy = v(dy);
                let at = y * TILE_SIZE + x0;
                let RowAlpha { gauss, slope, a } = row_alpha(&ws, dy, cc * dy * dy);
                let t_old = load(&s.t[at..]);
                let (w, t_new, alive, _, stop) = blend(a, t_old, load(&s.alive[at..]));
                let contrib = _mm256_cmp_ps::<_CMP_NEQ_UQ>(w, zero);
                if bits(_mm256_or_ps(contrib, stop)) == 0 {
                    continue;
                }
                store(t_new, &mut s.t[at..]);
                store(alive, &mut s.alive[at..]);
                let inv = _mm256_div_ps(one, sub(one, select(contrib, a, zero)));
                let tn = load(&t_final[at..]);
                let mut d_alpha = if has_alpha {
                    mul(mul(load(&s.g_alpha[at..]), tn), inv)
                } else {
                    zero
                };
                for &j in &s.live_channels {
                    let (value, b) = (v(ch[j]), v(bg[j]));
                    let o = j * TILE_PIXELS + at;
                    let pre = add(load(&s.pre[o..]), mul(w, value));
                    store(pre, &mut s.pre[o..]);
                    let behind = add(sub(load(&c_final[o..]), pre), mul(tn, b));
                    let gi = load(&s.g_img[o..]);
                    d_alpha = add(d_alpha, mul(gi, sub(mul(t_old, value), mul(behind, inv))));
                    let acc = &mut s.acc_channels[j * TILE_SIZE + x0..];
                    store(add(load(acc), mul(w, gi)), acc);
                }
                if has_depth {
                    let o = c * TILE_PIXELS + at;
                    let pre = add(load(&s.pre[o..]), mul(w, z));
                    store(pre, &mut s.pre[o..]);
                    let behind = sub(load(&d_final[at..]), pre);
                    let gd = load(&s.g_depth[at..]);
                    d_alpha = add(d_alpha, mul(gd, sub(mul(t_old, z), mul(behind, inv))));
                    a_z = add(a_z, mul(w, gd));
                }
                let dx = ws.dx;
                let da = select(contrib, d_alpha, zero);
                let d_power = mul(slope, da);
                a_mx = sub(a_mx, mul(d_power, add(mul(ws.ca, dx), v(cb * dy))));
                a_my = sub(a_my, mul(d_power, add(v(cc * dy), mul(ws.cb, dx))));
                a_ca = sub(a_ca, mul(mul(mul(half, d_power), dx), dx));
                a_cb = sub(a_cb, mul(mul(d_power, dx), v_dy));
                a_cc = sub(a_cc, mul(mul(mul(half, d_power), v_dy), v_dy));
                let has_slope = _mm256_cmp_ps::<_CMP_NEQ_UQ>(slope, zero);
                a_op = add(a_op, select(has_slope, mul(gauss, da), zero));
            }
            for (columns, acc) in geo
                .iter_mut()
                .zip([a_mx, a_my, a_ca, a_cb, a_cc, a_op, a_z])
            {
                store(acc, &mut columns[x0..]);
            }
        }
        let dst = &mut out[idx * slot..(idx + 1) * slot];
        for (d, columns) in dst.iter_mut().zip(&geo) {
            *d = super::kernels::column_sum(columns);
        }
        for (d, columns) in dst[7..]
            .iter_mut()
            .zip(s.acc_channels.chunks_exact(TILE_SIZE))
        {
            *d = super::kernels::column_sum(columns);
        }
    }
}

/// [`super::kernels::forward_tile`] for f32 on 8-lane windows. Same arguments and output.
#[allow(clippy::too_many_arguments)]
#[target_feature(enable = "avx2")]
fn forward_tile(
    list: &[PairSplat<f32>],
    channels: &[f32],
    c: usize,
    origin: [usize; 2],
    size: [usize; 2],
    buf: &mut [f32],
    used: &mut u32,
    alive: &mut [f32],
) {
    buf[BUF_T..BUF_T + TILE_PIXELS].fill(1.0);
    alive[..TILE_PIXELS].fill(1.0);
    *used = list.len() as u32;
    if list.is_empty() {
        return;
    }
    let (tbuf, rest) = buf.split_at_mut(BUF_D);
    let (dbuf, cbuf) = rest.split_at_mut(TILE_PIXELS);
    let mut n_done = 0u32;
    let n_pixels = (size[0] * size[1]) as u32;
    let ox: f32 = lit(origin[0] as f64);
    let oy: f32 = lit(origin[1] as f64);
    let centre = centres::<f32>();
    let v = _mm256_set1_ps;
    let (add, mul) = (_mm256_add_ps, _mm256_mul_ps);
    for (k, p) in list.iter().enumerate() {
        let Some((sl, y0, y1)) = splat_lanes(p, ox, oy, size) else {
            continue;
        };
        let ch = &channels[k * c..(k + 1) * c];
        let z = v(p.depth);
        let cc = p.conic[2];
        for x0 in windows(sl.q0, sl.q1) {
            let ws = window_splat(&sl, &centre, x0);
            for y in y0..y1 {
                let dy = sl.my - centre[y];
                let at = y * TILE_SIZE + x0;
                let a = row_alpha(&ws, dy, cc * dy * dy).a;
                let t = load(&tbuf[at..]);
                let (w, t_new, al, blends, stop) = blend(a, t, load(&alive[at..]));
                if bits(_mm256_or_ps(blends, stop)) == 0 {
                    continue;
                }
                store(t_new, &mut tbuf[at..]);
                store(al, &mut alive[at..]);
                n_done += bits(stop).count_ones();
                for (j, &value) in ch.iter().enumerate() {
                    let dst = &mut cbuf[j * TILE_PIXELS + at..];
                    store(add(load(dst), mul(w, v(value))), dst);
                }
                let dst = &mut dbuf[at..];
                store(add(load(dst), mul(w, z)), dst);
            }
        }
        if n_done == n_pixels {
            *used = k as u32 + 1;
            break;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::{backward_tile, detected, forward_tile};
    use crate::raster::kernels;
    use crate::raster::{render, Cotangents, RenderSettings};
    use crate::synthetic::SyntheticScene;
    use crate::{TILE_PIXELS, TILE_SIZE};

    /// The AVX2 kernels give the portable kernels' bits, tile by tile: the image buffers and stop
    /// counts of the forward, and every pair's gradient slot of the backward with image, alpha and
    /// depth cotangents (and without alpha and depth), on scenes whose size leaves partial tiles at
    /// the borders.
    #[test]
    fn avx2_kernels_equal_the_portable_kernels_bit_for_bit() {
        if !detected() {
            eprintln!("skipped: this CPU has no AVX2");
            return;
        }
        let same_bits =
            |a: &[f32], b: &[f32]| a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits());
        for (seed, n, w, h) in [
            (1u64, 3000usize, 53u32, 37u32),
            (2, 800, 40, 70),
            (3, 6000, 64, 48),
        ] {
            let scene = SyntheticScene::new(n, w, h, seed).expect("scene");
            let out =
                render(&scene.camera, &scene.splats(), &RenderSettings::default()).expect("render");
            let st = &out.state;
            let c = 3;
            let stride = (2 + c) * TILE_PIXELS;
            let gx = (w as usize).div_ceil(TILE_SIZE);
            let (width, height) = (w as usize, h as usize);
            let hw = width * height;
            let mut state = seed;
            let mut noise = |len: usize| -> Vec<f32> {
                (0..len)
                    .map(|_| {
                        state = state
                            .wrapping_mul(6_364_136_223_846_793_005)
                            .wrapping_add(1_442_695_040_888_963_407);
                        (state >> 40) as f32 / (1u64 << 23) as f32 - 1.0
                    })
                    .collect()
            };
            let (mut d_image, d_alpha, d_depth) = (noise(c * hw), noise(hw), noise(hw));
            // Channel 1 has no cotangent left of column 24: both kernels skip it there.
            for y in 0..height {
                d_image[hw + y * width..][..24].fill(0.0);
            }
            let with_all = Cotangents {
                image: &d_image,
                alpha: Some(&d_alpha),
                depth: Some(&d_depth),
            };
            let image_only = Cotangents {
                image: &d_image,
                alpha: None,
                depth: None,
            };
            let (mut checked_pairs, mut stopped_pixels) = (0, 0);
            for tile in 0..st.used.len() {
                let range = st.tile_offsets[tile]..st.tile_offsets[tile + 1];
                let origin = [(tile % gx) * TILE_SIZE, (tile / gx) * TILE_SIZE];
                let size = [
                    TILE_SIZE.min(width - origin[0]),
                    TILE_SIZE.min(height - origin[1]),
                ];
                let list = &st.pair_splats[range.clone()];
                let channels = &st.pair_channels[range.start * c..range.end * c];
                let (mut buf_p, mut buf_v) = (vec![0.0f32; stride], vec![0.0f32; stride]);
                let (mut used_p, mut used_v) = (0u32, 0u32);
                let (mut alive_p, mut alive_v) = ([0.0f32; TILE_PIXELS], [0.0f32; TILE_PIXELS]);
                kernels::forward_tile(
                    list,
                    channels,
                    c,
                    origin,
                    size,
                    &mut buf_p,
                    &mut used_p,
                    &mut alive_p,
                );
                // SAFETY: the CPU has AVX2 (checked above).
                unsafe {
                    forward_tile(
                        list,
                        channels,
                        c,
                        origin,
                        size,
                        &mut buf_v,
                        &mut used_v,
                        &mut alive_v,
                    )
                };
                assert_eq!(used_p, used_v, "tile {tile}");
                assert_eq!(alive_p, alive_v, "tile {tile}");
                assert!(same_bits(&buf_p, &buf_v), "tile {tile}");
                stopped_pixels += alive_p.iter().filter(|&&a| a == 0.0).count();
                for cot in [&with_all, &image_only] {
                    let slots = range.len() * (7 + c);
                    let (mut out_p, mut out_v) = (vec![0.0f32; slots], vec![0.0f32; slots]);
                    let mut s_p = kernels::BackwardScratch::new(c);
                    let mut s_v = kernels::BackwardScratch::new(c);
                    let (bg, used) = (&st.background, used_p as usize);
                    kernels::backward_tile(
                        list, channels, bg, c, origin, size, width, &buf_p, used, cot, &mut s_p,
                        &mut out_p,
                    );
                    // SAFETY: the CPU has AVX2 (checked above).
                    unsafe {
                        backward_tile(
                            list, channels, bg, c, origin, size, width, &buf_p, used, cot,
                            &mut s_v, &mut out_v,
                        )
                    };
                    assert!(same_bits(&out_p, &out_v), "tile {tile}");
                    checked_pairs += out_p
                        .chunks(7 + c)
                        .filter(|g| g.iter().any(|&v| v != 0.0))
                        .count();
                }
            }
            // The comparison is not vacuous: many pairs carry gradients, and pixels stopped.
            assert!(
                checked_pairs > n / 4,
                "{checked_pairs} pairs with gradients"
            );
            assert!(stopped_pixels > 0, "no pixel stopped");
        }
    }
}
