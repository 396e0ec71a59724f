//! Backward warping of an image by a flow field: `out[c, y, x] = img[c, y + v(y, x), x + u(y, x)]`,
//! sampled bilinearly in pixel units with border padding — PyTorch's
//! `grid_sample(mode="bilinear", padding_mode="border", align_corners=True)` with the grid
//! `(x + u, y + v)`. The sample coordinate is clamped to `[0, W−1] × [0, H−1]`; where it is clamped
//! (on or beyond the border) its gradient is zero, as in PyTorch.
//!
//! Layouts: `img` and `out` are `(B, C, H, W)`, `flow` is `(B, 2, H, W)` with channel 0 = u
//! (horizontal, pixels, +x right) and channel 1 = v (vertical, pixels, +y down).

use crate::{check_len, NnError, Real};
use rayon::prelude::*;

/// Clamped sample position along one axis: (lower index, upper index, weight of upper, d clamp / d s).
#[inline]
fn sample_axis<T: Real>(s: T, n: usize) -> (usize, usize, T, T) {
    let max = T::of((n - 1) as f64);
    let (c, grad) = if s <= T::zero() {
        (T::zero(), T::zero())
    } else if s >= max {
        (max, T::zero())
    } else {
        (s, T::one())
    };
    let i0f = c.floor();
    let i0 = i0f.to_usize().unwrap_or(0).min(n - 1);
    let i1 = (i0 + 1).min(n - 1);
    (i0, i1, c - i0f, grad)
}

/// Forward warp: overwrites `out` `(B, C, H, W)` with `img` sampled at `(x + u, y + v)`.
pub fn warp_forward<T: Real>(
    batch: usize,
    channels: usize,
    h: usize,
    w: usize,
    img: &[T],
    flow: &[T],
    out: &mut [T],
) -> Result<(), NnError> {
    let n = batch * channels * h * w;
    check_len("warp image", n, img.len())?;
    check_len("warp flow", batch * 2 * h * w, flow.len())?;
    check_len("warp output", n, out.len())?;
    if n == 0 {
        return Ok(());
    }
    let hw = h * w;
    out.par_chunks_mut(hw).enumerate().for_each(|(plane, o)| {
        let b = plane / channels;
        let src = &img[plane * hw..(plane + 1) * hw];
        let u = &flow[b * 2 * hw..b * 2 * hw + hw];
        let v = &flow[b * 2 * hw + hw..(b + 1) * 2 * hw];
        for y in 0..h {
            for x in 0..w {
                let p = y * w + x;
                let (x0, x1, lx, _) = sample_axis(T::of(x as f64) + u[p], w);
                let (y0, y1, ly, _) = sample_axis(T::of(y as f64) + v[p], h);
                let top = src[y0 * w + x0] + (src[y0 * w + x1] - src[y0 * w + x0]) * lx;
                let bot = src[y1 * w + x0] + (src[y1 * w + x1] - src[y1 * w + x0]) * lx;
                o[p] = top + (bot - top) * ly;
            }
        }
    });
    Ok(())
}

/// Backward of [`warp_forward`] given `grad_out = ∂L/∂out`. `grad_img` (`(B, C, H, W)`) and
/// `grad_flow` (`(B, 2, H, W)`), when given, are **overwritten**. The flow gradient sums over channels
/// in increasing channel order.
pub fn warp_backward<T: Real>(
    batch: usize,
    channels: usize,
    h: usize,
    w: usize,
    img: &[T],
    flow: &[T],
    grad_out: &[T],
    grad_img: Option<&mut [T]>,
    grad_flow: Option<&mut [T]>,
) -> Result<(), NnError> {
    let n = batch * channels * h * w;
    check_len("warp image", n, img.len())?;
    check_len("warp flow", batch * 2 * h * w, flow.len())?;
    check_len("warp grad_out", n, grad_out.len())?;
    let hw = h * w;
    if let Some(gi) = grad_img {
        check_len("warp grad_img", n, gi.len())?;
        if n > 0 {
            gi.par_chunks_mut(hw).enumerate().for_each(|(plane, gi)| {
                gi.fill(T::zero());
                let b = plane / channels;
                let go = &grad_out[plane * hw..(plane + 1) * hw];
                let u = &flow[b * 2 * hw..b * 2 * hw + hw];
                let v = &flow[b * 2 * hw + hw..(b + 1) * 2 * hw];
                for y in 0..h {
                    for x in 0..w {
                        let p = y * w + x;
                        let (x0, x1, lx, _) = sample_axis(T::of(x as f64) + u[p], w);
                        let (y0, y1, ly, _) = sample_axis(T::of(y as f64) + v[p], h);
                        let g = go[p];
                        let gt = g * (T::one() - ly);
                        let gb = g * ly;
                        gi[y0 * w + x0] = gi[y0 * w + x0] + gt * (T::one() - lx);
                        gi[y0 * w + x1] = gi[y0 * w + x1] + gt * lx;
                        gi[y1 * w + x0] = gi[y1 * w + x0] + gb * (T::one() - lx);
                        gi[y1 * w + x1] = gi[y1 * w + x1] + gb * lx;
                    }
                }
            });
        }
    }
    if let Some(gf) = grad_flow {
        check_len("warp grad_flow", batch * 2 * hw, gf.len())?;
        if batch * hw > 0 {
            gf.par_chunks_mut(2 * hw).enumerate().for_each(|(b, gf)| {
                let (gu, gv) = gf.split_at_mut(hw);
                let u = &flow[b * 2 * hw..b * 2 * hw + hw];
                let v = &flow[b * 2 * hw + hw..(b + 1) * 2 * hw];
                for y in 0..h {
                    for x in 0..w {
                        let p = y * w + x;
                        let (x0, x1, lx, dxs) = sample_axis(T::of(x as f64) + u[p], w);
                        let (y0, y1, ly, dys) = sample_axis(T::of(y as f64) + v[p], h);
                        let (mut au, mut av) = (T::zero(), T::zero());
                        for c in 0..channels {
                            let plane = (b * channels + c) * hw;
                            let src = &img[plane..plane + hw];
                            let g = grad_out[plane + p];
                            let (a, bb) = (src[y0 * w + x0], src[y0 * w + x1]);
                            let (cc, d) = (src[y1 * w + x0], src[y1 * w + x1]);
                            let d_dx = (bb - a) * (T::one() - ly) + (d - cc) * ly;
                            let top = a + (bb - a) * lx;
                            let bot = cc + (d - cc) * lx;
                            au = au + g * d_dx;
                            av = av + g * (bot - top);
                        }
                        gu[p] = au * dxs;
                        gv[p] = av * dys;
                    }
                }
            });
        }
    }
    Ok(())
}
