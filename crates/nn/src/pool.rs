//! Pooling. 2×2 average pooling with stride 2, `count_include_pad=False` semantics: an output pixel
//! is the mean of the input pixels its window actually covers. For even sizes this is the plain 2×2
//! mean; for an odd size the last output row/column (ceil mode) averages the one or two pixels that
//! exist. Max pooling over k×k windows with any stride, floor mode, no padding (AlexNet's 3/2 pool),
//! with the positions of the maxima kept for the backward pass.

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

/// Shape of a max pooling over square windows of `kernel` pixels with stride `stride`, no padding,
/// floor mode (PyTorch's `MaxPool2d(kernel, stride)` defaults): the output has
/// `(H − kernel) / stride + 1` rows (integer division), likewise columns.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MaxPool2dShape {
    /// Independent planes `B·C`.
    pub planes: usize,
    /// Input height H in pixels.
    pub height: usize,
    /// Input width W in pixels.
    pub width: usize,
    /// Window side in pixels.
    pub kernel: usize,
    /// Step between windows in pixels.
    pub stride: usize,
}

impl MaxPool2dShape {
    /// Output height `(H − kernel) / stride + 1`.
    pub fn out_height(&self) -> usize {
        (self.height - self.kernel) / self.stride + 1
    }
    /// Output width `(W − kernel) / stride + 1`.
    pub fn out_width(&self) -> usize {
        (self.width - self.kernel) / self.stride + 1
    }
    /// Number of input values `planes·H·W`.
    pub fn input_len(&self) -> usize {
        self.planes * self.height * self.width
    }
    /// Number of output values `planes·H_out·W_out`.
    pub fn output_len(&self) -> usize {
        self.planes * self.out_height() * self.out_width()
    }

    fn validate(&self) -> Result<(), NnError> {
        if self.kernel == 0
            || self.stride == 0
            || self.height < self.kernel
            || self.width < self.kernel
        {
            return Err(NnError::Shape(format!(
                "max_pool kernel {} stride {} on a {}x{} image (the window must fit)",
                self.kernel, self.stride, self.height, self.width
            )));
        }
        Ok(())
    }
}

/// Forward: overwrites `output` `(planes, H_out, W_out)` with the window maxima of `input`
/// `(planes, H, W)` and `argmax` (same length as `output`) with the position `y·W + x` inside its
/// plane of each maximum — the first one in row-major window order on ties, as PyTorch's CPU kernel.
pub fn max_pool2d_forward<T: Real>(
    s: MaxPool2dShape,
    input: &[T],
    output: &mut [T],
    argmax: &mut [u32],
) -> Result<(), NnError> {
    s.validate()?;
    check_len("max_pool input", s.input_len(), input.len())?;
    check_len("max_pool output", s.output_len(), output.len())?;
    check_len("max_pool argmax", s.output_len(), argmax.len())?;
    if u32::try_from(s.height * s.width).is_err() {
        return Err(NnError::Shape(format!(
            "max_pool plane {}x{} too large for u32 positions",
            s.height, s.width
        )));
    }
    let (h, w, k, st) = (s.height, s.width, s.kernel, s.stride);
    let (ho, wo) = (s.out_height(), s.out_width());
    if s.planes == 0 {
        return Ok(());
    }
    output
        .par_chunks_mut(ho * wo)
        .zip(argmax.par_chunks_mut(ho * wo))
        .zip(input.par_chunks(h * w))
        .for_each(|((out, arg), inp)| {
            for y in 0..ho {
                for x in 0..wo {
                    let first = y * st * w + x * st;
                    let (mut best, mut at) = (inp[first], first);
                    for iy in y * st..y * st + k {
                        for ix in x * st..x * st + k {
                            let v = inp[iy * w + ix];
                            if v > best {
                                (best, at) = (v, iy * w + ix);
                            }
                        }
                    }
                    out[y * wo + x] = best;
                    arg[y * wo + x] = at as u32;
                }
            }
        });
    Ok(())
}

/// Backward: overwrites `grad_input` `(planes, H, W)` with `∂L/∂in` given `grad_output`
/// `(planes, H_out, W_out)` and the forward's `argmax`: each output's cotangent goes to its maximum,
/// summed in output order where windows overlap.
pub fn max_pool2d_backward<T: Real>(
    s: MaxPool2dShape,
    argmax: &[u32],
    grad_output: &[T],
    grad_input: &mut [T],
) -> Result<(), NnError> {
    s.validate()?;
    check_len("max_pool argmax", s.output_len(), argmax.len())?;
    check_len("max_pool grad_output", s.output_len(), grad_output.len())?;
    check_len("max_pool grad_input", s.input_len(), grad_input.len())?;
    let hw = s.height * s.width;
    if let Some(&bad) = argmax.iter().find(|&&i| i as usize >= hw) {
        return Err(NnError::Shape(format!(
            "max_pool argmax position {bad} outside a {}x{} plane",
            s.height, s.width
        )));
    }
    let n = s.out_height() * s.out_width();
    if s.planes == 0 {
        return Ok(());
    }
    grad_input
        .par_chunks_mut(hw)
        .zip(grad_output.par_chunks(n))
        .zip(argmax.par_chunks(n))
        .for_each(|((gi, go), arg)| {
            gi.fill(T::zero());
            for (&g, &i) in go.iter().zip(arg) {
                gi[i as usize] = gi[i as usize] + g;
            }
        });
    Ok(())
}
