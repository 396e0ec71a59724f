//! Bilinear resize of planar images with PyTorch's two `align_corners` conventions.
//!
//! - `align_corners = true`: output pixel `i` samples input coordinate `i·(in − 1)/(out − 1)` (corner
//!   pixel centres coincide);
//! - `align_corners = false`: output pixel `i` samples `max((i + 0.5)·in/out − 0.5, 0)` (pixel areas
//!   coincide; PyTorch's clamp at 0 included).
//!
//! Samples beyond the last pixel use the last pixel (no extrapolation). The backward pass scatters into
//! the input plane by plane, so planes run in parallel without any shared accumulator.

use crate::{check_len, NnError, Real};
use rayon::prelude::*;

/// Per output index along one axis: (lower input index, upper input index, weight of the upper one).
fn axis_weights<T: Real>(n_in: usize, n_out: usize, align_corners: bool) -> Vec<(usize, usize, T)> {
    (0..n_out)
        .map(|i| {
            let src = if align_corners {
                if n_out > 1 {
                    i as f64 * (n_in as f64 - 1.0) / (n_out as f64 - 1.0)
                } else {
                    0.0
                }
            } else {
                ((i as f64 + 0.5) * n_in as f64 / n_out as f64 - 0.5).max(0.0)
            };
            let i0 = (src.floor() as usize).min(n_in - 1);
            let i1 = (i0 + 1).min(n_in - 1);
            let l = if i1 == i0 { 0.0 } else { src - i0 as f64 };
            (i0, i1, T::of(l))
        })
        .collect()
}

/// Forward: `input` `(planes, H, W)` → `output` `(planes, H_out, W_out)` (overwritten).
pub fn resize_bilinear_forward<T: Real>(
    planes: usize,
    h: usize,
    w: usize,
    input: &[T],
    h_out: usize,
    w_out: usize,
    align_corners: bool,
    output: &mut [T],
) -> Result<(), NnError> {
    check_len("resize input", planes * h * w, input.len())?;
    check_len("resize output", planes * h_out * w_out, output.len())?;
    if planes == 0 || h_out == 0 || w_out == 0 {
        return Ok(());
    }
    if h == 0 || w == 0 {
        return Err(NnError::Shape("resize of an empty image".into()));
    }
    let ay = axis_weights::<T>(h, h_out, align_corners);
    let ax = axis_weights::<T>(w, w_out, align_corners);
    output
        .par_chunks_mut(h_out * w_out)
        .zip(input.par_chunks(h * w))
        .for_each(|(out, inp)| {
            for (y, &(y0, y1, ly)) in ay.iter().enumerate() {
                let r0 = &inp[y0 * w..(y0 + 1) * w];
                let r1 = &inp[y1 * w..(y1 + 1) * w];
                for (x, &(x0, x1, lx)) in ax.iter().enumerate() {
                    let top = r0[x0] + (r0[x1] - r0[x0]) * lx;
                    let bot = r1[x0] + (r1[x1] - r1[x0]) * lx;
                    out[y * w_out + x] = top + (bot - top) * ly;
                }
            }
        });
    Ok(())
}

/// Backward: overwrites `grad_input` `(planes, H, W)` with `∂L/∂in` given `grad_output`
/// `(planes, H_out, W_out)`.
pub fn resize_bilinear_backward<T: Real>(
    planes: usize,
    h: usize,
    w: usize,
    h_out: usize,
    w_out: usize,
    align_corners: bool,
    grad_output: &[T],
    grad_input: &mut [T],
) -> Result<(), NnError> {
    check_len(
        "resize grad_output",
        planes * h_out * w_out,
        grad_output.len(),
    )?;
    check_len("resize grad_input", planes * h * w, grad_input.len())?;
    if planes == 0 || h == 0 || w == 0 {
        return Ok(());
    }
    grad_input.fill(T::zero());
    if h_out == 0 || w_out == 0 {
        return Ok(());
    }
    let ay = axis_weights::<T>(h, h_out, align_corners);
    let ax = axis_weights::<T>(w, w_out, align_corners);
    grad_input
        .par_chunks_mut(h * w)
        .zip(grad_output.par_chunks(h_out * w_out))
        .for_each(|(gi, go)| {
            for (y, &(y0, y1, ly)) in ay.iter().enumerate() {
                for (x, &(x0, x1, lx)) in ax.iter().enumerate() {
                    let g = go[y * w_out + x];
                    let gt = g * (T::one() - ly);
                    let gb = g * ly;
                    gi[y0 * w + x0] = gi[y0 * w + x0] + gt * (T::one() - lx);
                    gi[y0 * w + x1] = gi[y0 * w + x1] + gt * lx;
                    gi[y1 * w + x0] = gi[y1 * w + x0] + gb * (T::one() - lx);
                    gi[y1 * w + x1] = gi[y1 * w + x1] + gb * lx;
                }
            }
        });
    Ok(())
}
