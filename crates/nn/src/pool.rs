//! 2×2 average pooling with stride 2, `count_include_pad=False` semantics: an output pixel is the mean
//! of the input pixels its window actually covers. For even sizes this is the plain 2×2 mean; for an
//! odd size the last output row/column (ceil mode) averages the one or two pixels that exist.

use crate::{check_len, NnError, Real};
use rayon::prelude::*;

/// Pooled length of one axis: `ceil(n / 2)`.
pub fn pooled_size(n: usize) -> usize {
    n.div_ceil(2)
}

/// Forward: `input` `(planes, H, W)` → `output` `(planes, ceil(H/2), ceil(W/2))` (overwritten), where
/// `planes = B·C`.
pub fn avg_pool2x2_forward<T: Real>(
    planes: usize,
    h: usize,
    w: usize,
    input: &[T],
    output: &mut [T],
) -> Result<(), NnError> {
    let (ho, wo) = (pooled_size(h), pooled_size(w));
    check_len("avg_pool input", planes * h * w, input.len())?;
    check_len("avg_pool output", planes * ho * wo, output.len())?;
    if planes == 0 || ho == 0 || wo == 0 {
        return Ok(());
    }
    output
        .par_chunks_mut(ho * wo)
        .zip(input.par_chunks(h * w))
        .for_each(|(out, inp)| {
            for y in 0..ho {
                let y1 = (2 * y + 2).min(h);
                for x in 0..wo {
                    let x1 = (2 * x + 2).min(w);
                    let mut acc = T::zero();
                    for iy in 2 * y..y1 {
                        for ix in 2 * x..x1 {
                            acc = acc + inp[iy * w + ix];
                        }
                    }
                    let count = ((y1 - 2 * y) * (x1 - 2 * x)) as f64;
                    out[y * wo + x] = acc / T::of(count);
                }
            }
        });
    Ok(())
}

/// Backward: overwrites `grad_input` `(planes, H, W)` with `∂L/∂in` given `grad_output`
/// `(planes, ceil(H/2), ceil(W/2))`.
pub fn avg_pool2x2_backward<T: Real>(
    planes: usize,
    h: usize,
    w: usize,
    grad_output: &[T],
    grad_input: &mut [T],
) -> Result<(), NnError> {
    let (ho, wo) = (pooled_size(h), pooled_size(w));
    check_len("avg_pool grad_output", planes * ho * wo, grad_output.len())?;
    check_len("avg_pool grad_input", planes * h * w, grad_input.len())?;
    if planes == 0 || h == 0 || w == 0 {
        return Ok(());
    }
    grad_input
        .par_chunks_mut(h * w)
        .zip(grad_output.par_chunks(ho * wo))
        .for_each(|(gi, go)| {
            for iy in 0..h {
                let y = iy / 2;
                let ny = (2 * y + 2).min(h) - 2 * y;
                for ix in 0..w {
                    let x = ix / 2;
                    let nx = (2 * x + 2).min(w) - 2 * x;
                    gi[iy * w + ix] = go[y * wo + x] / T::of((ny * nx) as f64);
                }
            }
        });
    Ok(())
}
