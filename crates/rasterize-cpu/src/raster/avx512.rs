//! The tile kernels for f32 on CPUs with AVX-512: one 16-lane register per tile row, so a pair's
//! row is one pass whatever its width (the portable kernels loop over 1–4 groups of four), and 32
//! vector registers hold the backward's per-pair accumulators without spilling.
//!
//! Same bits as [`super::kernels::forward_tile`] and [`super::kernels::backward_tile`]: every lane
//! runs the same IEEE operations in the same order (no fused multiply-adds; [`exp`] repeats
//! [`crate::fast_exp_f32`]), the backward's per-column accumulators are reduced in column order,
//! and lanes outside a pair's box add exact zeros to sums that are never −0 (they start at +0, and
//! a sum that cancels to zero is +0). The unit test below compares the kernels bit for bit.
//!
//! Selected at run time (`is_x86_feature_detected!("avx512f")`), so the build needs no target flags.

#![allow(unsafe_code)]

use std::arch::x86_64::*;

use super::kernels::{centres, splat_lanes, BackwardScratch, PairSplat, BUF_C, BUF_D, BUF_T};
use super::Cotangents;
use crate::{lit, TILE_PIXELS, TILE_SIZE};

/// Whether this CPU runs the kernels of this module: it has AVX-512F, and the environment variable
/// `E_SEM3DGS_PORTABLE_KERNELS` is not set (set, the portable kernels run instead, with the same
/// bits: for measuring one against the other on a CPU).
pub(super) fn available() -> bool {
    static AVAILABLE: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *AVAILABLE.get_or_init(|| {
        std::arch::is_x86_feature_detected!("avx512f")
            && std::env::var_os("E_SEM3DGS_PORTABLE_KERNELS").is_none()
    })
}

/// Runs [`backward_tile`] and returns `true`, or returns `false` (doing nothing) if this CPU lacks
/// AVX-512F.
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
    // SAFETY: the CPU has AVX-512F (checked above), the kernel's only requirement.
    unsafe {
        backward_tile(
            list, channels, bg, c, origin, size, width, buf, used, cot, s, out,
        )
    };
    true
}

/// Runs [`forward_tile`] and returns `true`, or returns `false` (doing nothing) if this CPU lacks
/// AVX-512F.
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
    // SAFETY: the CPU has AVX-512F (checked above), the kernel's only requirement.
    unsafe { forward_tile(list, channels, c, origin, size, buf, used, alive) };
    true
}

/// Lanes `s[0..16]` (panics if `s` is shorter).
#[target_feature(enable = "avx512f")]
#[inline]
fn load(s: &[f32]) -> __m512 {
    let s = &s[..16];
    // SAFETY: `s` holds sixteen initialised f32; `loadu` has no alignment requirement.
    unsafe { _mm512_loadu_ps(s.as_ptr()) }
}

/// Writes the lanes to `s[0..16]` (panics if `s` is shorter).
#[target_feature(enable = "avx512f")]
#[inline]
fn store(v: __m512, s: &mut [f32]) {
    let s = &mut s[..16];
    // SAFETY: `s` has room for sixteen f32; `storeu` has no alignment requirement.
    unsafe { _mm512_storeu_ps(s.as_mut_ptr(), v) }
}

/// `if m { a } else { b }` per lane.
#[target_feature(enable = "avx512f")]
#[inline]
fn select(m: __mmask16, a: __m512, b: __m512) -> __m512 {
    _mm512_mask_blend_ps(m, b, a)
}

/// Sum of the lanes in lane order, starting from zero ([`super::kernels::column_sum`]'s order).
#[target_feature(enable = "avx512f")]
#[inline]
fn column_sum(v: __m512) -> f32 {
    let mut a = [0.0f32; 16];
    store(v, &mut a);
    super::kernels::column_sum(&a)
}

/// [`crate::fast_exp_f32`] lane by lane, operation for operation.
#[target_feature(enable = "avx512f")]
#[inline]
fn exp(x: __m512) -> __m512 {
    const LOG2E: f32 = std::f32::consts::LOG2_E;
    const LN2_HI: f32 = 0.693_145_75;
    const LN2_LO: f32 = 1.428_606_8e-6;
    const ROUND: f32 = 12_582_912.0;
    const ROUND_BITS: i32 = 0x4B40_0000;
    let s = _mm512_set1_ps;
    let (add, sub, mul) = (_mm512_add_ps, _mm512_sub_ps, _mm512_mul_ps);
    let x = select(_mm512_cmp_ps_mask::<_CMP_LT_OQ>(x, s(-87.0)), s(-87.0), x);
    let x = select(_mm512_cmp_ps_mask::<_CMP_GT_OQ>(x, s(0.0)), s(0.0), x);
    let kr = add(mul(x, s(LOG2E)), s(ROUND));
    let k = sub(kr, s(ROUND));
    let r = sub(sub(x, mul(k, s(LN2_HI))), mul(k, s(LN2_LO)));
    let mut p = s(1.0 / 720.0);
    for c in [1.0 / 120.0, 1.0 / 24.0, 1.0 / 6.0, 0.5, 1.0, 1.0] {
        p = add(s(c), mul(r, p));
    }
    let bits = _mm512_sub_epi32(_mm512_castps_si512(kr), _mm512_set1_epi32(ROUND_BITS - 127));
    mul(p, _mm512_castsi512_ps(_mm512_slli_epi32::<23>(bits)))
}

/// [`super::kernels::backward_tile`] for f32, one register per row. Same arguments and output.
#[allow(clippy::too_many_arguments)]
#[target_feature(enable = "avx512f")]
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
    let cx = load(&centre);
    let v = _mm512_set1_ps;
    let (add, sub, mul) = (_mm512_add_ps, _mm512_sub_ps, _mm512_mul_ps);
    let (zero, one, half, neg_half) = (v(0.0), v(1.0), v(0.5), v(-0.5));
    let (max_alpha, min_alpha, min_t) = (v(lit(0.99)), v(lit(1.0 / 255.0)), v(lit(1e-4)));
    let has_alpha = cot.alpha.is_some();
    let has_depth = cot.depth.is_some();
    for (idx, p) in list.iter().enumerate().take(used) {
        let Some((sl, y0, y1)) = splat_lanes(p, ox, oy, size) else {
            continue;
        };
        let ch = &channels[idx * c..(idx + 1) * c];
        let [ca, cb, cc] = p.conic;
        let (v_ca, v_cb) = (v(ca), v(cb));
        let dx = sub(v(sl.mx), cx);
        let in_box = _mm512_cmp_ps_mask::<_CMP_GT_OQ>(cx, v(sl.lo))
            & _mm512_cmp_ps_mask::<_CMP_LT_OQ>(cx, v(sl.hi));
        let z = v(p.depth);
        s.acc_channels.fill(0.0);
        let [mut a_mx, mut a_my, mut a_ca, mut a_cb, mut a_cc, mut a_op, mut a_z] = [zero; 7];
        for y in (y0..y1).filter(|&y| s.live_rows[y]) {
            let dy = sl.my - centre[y];
            let cc_dy_dy = cc * dy * dy;
            let v_dy = v(dy);
            let at = y * TILE_SIZE;
            // α, as `lane_alpha`.
            let power = sub(
                mul(neg_half, add(mul(mul(v_ca, dx), dx), v(cc_dy_dy))),
                mul(mul(v_cb, dx), v_dy),
            );
            let gauss = exp(power);
            let raw = mul(v(sl.opacity), gauss);
            let unclamped = _mm512_cmp_ps_mask::<_CMP_LT_OQ>(raw, max_alpha);
            let a = select(unclamped, raw, max_alpha);
            let ok = in_box
                & _mm512_cmp_ps_mask::<_CMP_LE_OQ>(power, zero)
                & _mm512_cmp_ps_mask::<_CMP_GE_OQ>(a, min_alpha);
            let a = select(ok, a, zero);
            let slope = select(unclamped, a, zero);
            // Blend state, as `lane_blend`.
            let t_old = load(&s.t[at..]);
            let alive = load(&s.alive[at..]);
            let live = _mm512_cmp_ps_mask::<_CMP_GT_OQ>(alive, zero)
                & _mm512_cmp_ps_mask::<_CMP_GT_OQ>(a, zero);
            let test_t = mul(t_old, sub(one, a));
            let stop = live & _mm512_cmp_ps_mask::<_CMP_LT_OQ>(test_t, min_t);
            let blends = live & !stop;
            let w = select(blends, mul(a, t_old), zero);
            let contrib = _mm512_cmp_ps_mask::<_CMP_NEQ_UQ>(w, zero);
            if contrib | stop == 0 {
                continue;
            }
            store(select(blends, test_t, t_old), &mut s.t[at..]);
            store(select(stop, zero, alive), &mut s.alive[at..]);
            let inv = _mm512_div_ps(one, sub(one, select(contrib, a, zero)));
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
                let acc = &mut s.acc_channels[j * TILE_SIZE..];
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
            let da = select(contrib, d_alpha, zero);
            let d_power = mul(slope, da);
            a_mx = sub(a_mx, mul(d_power, add(mul(v_ca, dx), v(cb * dy))));
            a_my = sub(a_my, mul(d_power, add(v(cc * dy), mul(v_cb, dx))));
            a_ca = sub(a_ca, mul(mul(mul(half, d_power), dx), dx));
            a_cb = sub(a_cb, mul(mul(d_power, dx), v_dy));
            a_cc = sub(a_cc, mul(mul(mul(half, d_power), v_dy), v_dy));
            let has_slope = _mm512_cmp_ps_mask::<_CMP_NEQ_UQ>(slope, zero);
            a_op = add(a_op, select(has_slope, mul(gauss, da), zero));
        }
        let dst = &mut out[idx * slot..(idx + 1) * slot];
        for (d, acc) in dst
            .iter_mut()
            .zip([a_mx, a_my, a_ca, a_cb, a_cc, a_op, a_z])
        {
            *d = column_sum(acc);
        }
        for (d, columns) in dst[7..]
            .iter_mut()
            .zip(s.acc_channels.chunks_exact(TILE_SIZE))
        {
            *d = super::kernels::column_sum(columns);
        }
    }
}

/// [`super::kernels::forward_tile`] for f32, one register per row. Same arguments and output.
#[allow(clippy::too_many_arguments)]
#[target_feature(enable = "avx512f")]
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
    let cx = load(&centre);
    let v = _mm512_set1_ps;
    let (add, sub, mul) = (_mm512_add_ps, _mm512_sub_ps, _mm512_mul_ps);
    let (zero, one, neg_half) = (v(0.0), v(1.0), v(-0.5));
    let (max_alpha, min_alpha, min_t) = (v(lit(0.99)), v(lit(1.0 / 255.0)), v(lit(1e-4)));
    for (k, p) in list.iter().enumerate() {
        let Some((sl, y0, y1)) = splat_lanes(p, ox, oy, size) else {
            continue;
        };
        let ch = &channels[k * c..(k + 1) * c];
        let [ca, cb, cc] = p.conic;
        let (v_ca, v_cb) = (v(ca), v(cb));
        let dx = sub(v(sl.mx), cx);
        let in_box = _mm512_cmp_ps_mask::<_CMP_GT_OQ>(cx, v(sl.lo))
            & _mm512_cmp_ps_mask::<_CMP_LT_OQ>(cx, v(sl.hi));
        let z = v(p.depth);
        for y in y0..y1 {
            let dy = sl.my - centre[y];
            let at = y * TILE_SIZE;
            // α, as `pixel_alpha`.
            let power = sub(
                mul(neg_half, add(mul(mul(v_ca, dx), dx), v(cc * dy * dy))),
                mul(mul(v_cb, dx), v(dy)),
            );
            let raw = mul(v(sl.opacity), exp(power));
            let a = select(
                _mm512_cmp_ps_mask::<_CMP_LT_OQ>(raw, max_alpha),
                raw,
                max_alpha,
            );
            let ok = in_box
                & _mm512_cmp_ps_mask::<_CMP_LE_OQ>(power, zero)
                & _mm512_cmp_ps_mask::<_CMP_GE_OQ>(a, min_alpha);
            let a = select(ok, a, zero);
            // Blend state, as `pixel_blend`.
            let t = load(&tbuf[at..]);
            let al = load(&alive[at..]);
            let live = _mm512_cmp_ps_mask::<_CMP_GT_OQ>(al, zero)
                & _mm512_cmp_ps_mask::<_CMP_GT_OQ>(a, zero);
            let test_t = mul(t, sub(one, a));
            let stop = live & _mm512_cmp_ps_mask::<_CMP_LT_OQ>(test_t, min_t);
            let blends = live & !stop;
            if blends | stop == 0 {
                continue;
            }
            let w = select(blends, mul(a, t), zero);
            store(select(blends, test_t, t), &mut tbuf[at..]);
            store(select(stop, zero, al), &mut alive[at..]);
            n_done += stop.count_ones();
            for (j, &value) in ch.iter().enumerate() {
                let dst = &mut cbuf[j * TILE_PIXELS + at..];
                store(add(load(dst), mul(w, v(value))), dst);
            }
            let dst = &mut dbuf[at..];
            store(add(load(dst), mul(w, z)), dst);
        }
        if n_done == n_pixels {
            *used = k as u32 + 1;
            break;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::{available, try_backward_tile, try_forward_tile};
    use crate::raster::kernels::{backward_tile, forward_tile, BackwardScratch};
    use crate::raster::{render, Cotangents, RenderSettings};
    use crate::synthetic::SyntheticScene;
    use crate::{TILE_PIXELS, TILE_SIZE};

    /// The AVX-512 kernels give the portable kernels' bits, tile by tile: the image buffers and
    /// stop counts of the forward, and every pair's gradient slot of the backward with image,
    /// alpha and depth cotangents, on scenes whose size leaves partial tiles at the borders.
    #[test]
    fn avx512_kernels_equal_the_portable_kernels_bit_for_bit() {
        if !available() {
            eprintln!("skipped: this CPU has no AVX-512F");
            return;
        }
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
            let (mut d_image, mut d_alpha, mut d_depth) = (noise(c * hw), noise(hw), noise(hw));
            // Rows 2, 3, 6, 7, ... have no cotangent (as where the flow loss's 1/4 resize reads
            // nothing), so the kernels' zero-row skip is exercised.
            for y in (0..height).filter(|y| y % 4 >= 2) {
                let row = y * width..(y + 1) * width;
                d_alpha[row.clone()].fill(0.0);
                d_depth[row.clone()].fill(0.0);
                for j in 0..c {
                    d_image[j * hw..][row.clone()].fill(0.0);
                }
            }
            // Channel 1 has no cotangent left of column 24 (as the human-probability channel,
            // which no loss reads), so the kernels' zero-channel skip is exercised.
            for y in 0..height {
                d_image[hw + y * width..][..24].fill(0.0);
            }
            let cot = Cotangents {
                image: &d_image,
                alpha: Some(&d_alpha),
                depth: Some(&d_depth),
            };
            let (mut checked_pairs, mut skipped_rows, mut skipped_channels) = (0, 0, 0);
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
                forward_tile(
                    list,
                    channels,
                    c,
                    origin,
                    size,
                    &mut buf_p,
                    &mut used_p,
                    &mut alive_p,
                );
                assert!(try_forward_tile(
                    list,
                    channels,
                    c,
                    origin,
                    size,
                    &mut buf_v,
                    &mut used_v,
                    &mut alive_v,
                ));
                assert_eq!(used_p, used_v, "tile {tile}");
                assert_eq!(alive_p, alive_v, "tile {tile}");
                assert!(buf_p
                    .iter()
                    .zip(&buf_v)
                    .all(|(a, b)| a.to_bits() == b.to_bits()));
                let slots = range.len() * (7 + c);
                let (mut out_p, mut out_v) = (vec![0.0f32; slots], vec![0.0f32; slots]);
                let (mut s_p, mut s_v) = (BackwardScratch::new(c), BackwardScratch::new(c));
                let args = (&st.background, &buf_p, used_p as usize);
                backward_tile(
                    list, channels, args.0, c, origin, size, width, args.1, args.2, &cot, &mut s_p,
                    &mut out_p,
                );
                assert!(try_backward_tile(
                    list, channels, args.0, c, origin, size, width, args.1, args.2, &cot, &mut s_v,
                    &mut out_v,
                ));
                let same_bits =
                    |a: &[f32], b: &[f32]| a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits());
                assert!(same_bits(&out_p, &out_v), "tile {tile}");
                // Skipping the rows and channels without a cotangent gives the bits of replaying
                // every row and channel.
                let mut out_all = vec![0.0f32; slots];
                let mut s_all = BackwardScratch::new(c);
                s_all.skip_zero_cotangents = false;
                backward_tile(
                    list,
                    channels,
                    args.0,
                    c,
                    origin,
                    size,
                    width,
                    args.1,
                    args.2,
                    &cot,
                    &mut s_all,
                    &mut out_all,
                );
                assert!(
                    same_bits(&out_p, &out_all),
                    "tile {tile}: skipping zero rows and channels changed the gradients"
                );
                skipped_rows += s_p.live_rows[..size[1]].iter().filter(|&&l| !l).count();
                skipped_channels += c - s_p.live_channels.len();
                checked_pairs += out_p
                    .chunks(7 + c)
                    .filter(|g| g.iter().any(|&v| v != 0.0))
                    .count();
            }
            // The comparison is not vacuous: many pairs carry gradients, and rows were skipped.
            assert!(
                checked_pairs > n / 4,
                "{checked_pairs} pairs with gradients"
            );
            assert!(skipped_rows > 0, "no row was skipped");
            assert!(skipped_channels > 0, "no channel was skipped");
        }
    }
}
