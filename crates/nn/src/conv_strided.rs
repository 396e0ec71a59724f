//! Strided 2-D convolution (cross-correlation, as PyTorch's `Conv2d(stride = s)`), by polyphase
//! decomposition onto the stride-1 convolution of [`crate::conv`]: no second im2col kernel.
//! `conv2d_forward` and its backward send a [`Conv2dShape`] with stride > 1 here.
//!
//! With stride s, output pixel (y, x) reads the zero-padded input at (s·y + ky, s·x + kx). Writing
//! ky = s·a + p (0 ≤ p < s) splits the input into s² phase images
//! `P[(c·s + p)·s + q][Y, X] = in_padded[c, s·Y + p, s·X + q]` and the kernel into
//! `w'[o, (c·s + p)·s + q, a, b] = w[o, c, s·a + p, s·b + q]` (zero where s·a + p ≥ k), a
//! ⌈k/s⌉ × ⌈k/s⌉ kernel: the strided convolution is the stride-1, unpadded convolution of the phase
//! images with w'. It costs (s·⌈k/s⌉ / k)² times the direct multiply-adds (≈ 1.19 for AlexNet's
//! 11 × 11 / 4 stem) and inherits the stride-1 kernels' speed and determinism. The input and weight
//! gradients are the stride-1 ones mapped back through the same (bijective where it matters)
//! re-indexing. The phase images and kernel are rebuilt per call; both are small next to the
//! convolution's work.

use crate::conv::{conv2d_backward_input, conv2d_backward_weight, conv2d_forward, Conv2dShape};
use crate::{check_len, NnError, Real};

impl Conv2dShape {
    /// Side of the phase kernel, ⌈k / s⌉.
    fn phase_kernel(&self) -> usize {
        self.kernel.div_ceil(self.stride)
    }

    /// The stride-1 convolution over the phase images that computes this one.
    fn phase_shape(&self) -> Conv2dShape {
        let kp = self.phase_kernel();
        Conv2dShape {
            batch: self.batch,
            c_in: self.c_in * self.stride * self.stride,
            c_out: self.c_out,
            height: self.out_height() + kp - 1,
            width: self.out_width() + kp - 1,
            kernel: kp,
            stride: 1,
            pad: 0,
        }
    }

    /// Calls `f(phase_index, input_index)` for every phase-image element that reads an input pixel
    /// (the others are padding and stay zero), in phase-image order.
    fn for_each_phase_pixel(&self, mut f: impl FnMut(usize, usize)) {
        let (s, pad) = (self.stride, self.pad);
        let ps = self.phase_shape();
        let (hp, wp) = (ps.height, ps.width);
        let (h, w) = (self.height, self.width);
        for b in 0..self.batch {
            for c in 0..self.c_in {
                for p in 0..s {
                    for q in 0..s {
                        let plane = ((b * self.c_in + c) * s + p) * s + q;
                        for yy in 0..hp {
                            let Some(iy) = (s * yy + p).checked_sub(pad).filter(|&v| v < h) else {
                                continue;
                            };
                            for xx in 0..wp {
                                let Some(ix) = (s * xx + q).checked_sub(pad).filter(|&v| v < w)
                                else {
                                    continue;
                                };
                                f(
                                    (plane * hp + yy) * wp + xx,
                                    ((b * self.c_in + c) * h + iy) * w + ix,
                                );
                            }
                        }
                    }
                }
            }
        }
    }

    /// The phase images of `input` (see the module docs).
    fn phase_input<T: Real>(&self, input: &[T]) -> Vec<T> {
        let mut out = vec![T::zero(); self.phase_shape().input_len()];
        self.for_each_phase_pixel(|dst, src| out[dst] = input[src]);
        out
    }

    /// Calls `f(phase_weight_index, weight_index)` for every phase-kernel tap that is a tap of the
    /// kernel (the others are zero).
    fn for_each_phase_tap(&self, mut f: impl FnMut(usize, usize)) {
        let (s, k, kp) = (self.stride, self.kernel, self.phase_kernel());
        for o in 0..self.c_out {
            for c in 0..self.c_in {
                for p in 0..s {
                    for q in 0..s {
                        let cp = (c * s + p) * s + q;
                        for a in 0..kp {
                            let ky = s * a + p;
                            if ky >= k {
                                continue;
                            }
                            for bb in 0..kp {
                                let kx = s * bb + q;
                                if kx >= k {
                                    continue;
                                }
                                f(
                                    ((o * self.c_in * s * s + cp) * kp + a) * kp + bb,
                                    ((o * self.c_in + c) * k + ky) * k + kx,
                                );
                            }
                        }
                    }
                }
            }
        }
    }

    /// The phase kernel of `weight` (see the module docs).
    fn phase_weight<T: Real>(&self, weight: &[T]) -> Vec<T> {
        let mut out = vec![T::zero(); self.phase_shape().weight_len()];
        self.for_each_phase_tap(|dst, src| out[dst] = weight[src]);
        out
    }
}

/// Forward: overwrites `output` (`(B, C_out, H_out, W_out)`) with the strided convolution of `input`
/// (`(B, C_in, H, W)`) with `weight` (`(C_out, C_in, k, k)`) plus `bias` (`(C_out)`) if given.
pub(crate) fn forward<T: Real>(
    s: Conv2dShape,
    input: &[T],
    weight: &[T],
    bias: Option<&[T]>,
    output: &mut [T],
) -> Result<(), NnError> {
    s.validate()?;
    check_len("strided conv2d input", s.input_len(), input.len())?;
    check_len("strided conv2d weight", s.weight_len(), weight.len())?;
    check_len("strided conv2d output", s.output_len(), output.len())?;
    conv2d_forward(
        s.phase_shape(),
        &s.phase_input(input),
        &s.phase_weight(weight),
        bias,
        output,
    )
}

/// Input gradient: overwrites `grad_input` (`(B, C_in, H, W)`) with `∂L/∂in` given
/// `grad_output = ∂L/∂out`. Input pixels no output reads (past the last window) get 0.
pub(crate) fn backward_input<T: Real>(
    s: Conv2dShape,
    grad_output: &[T],
    weight: &[T],
    grad_input: &mut [T],
) -> Result<(), NnError> {
    s.validate()?;
    check_len(
        "strided conv2d grad_output",
        s.output_len(),
        grad_output.len(),
    )?;
    check_len("strided conv2d weight", s.weight_len(), weight.len())?;
    check_len("strided conv2d grad_input", s.input_len(), grad_input.len())?;
    let ps = s.phase_shape();
    let mut grad_phase = vec![T::zero(); ps.input_len()];
    conv2d_backward_input(ps, grad_output, &s.phase_weight(weight), &mut grad_phase)?;
    // Each input pixel is at most one phase-image element, so this is a gather, not a sum.
    grad_input.fill(T::zero());
    s.for_each_phase_pixel(|phase, src| grad_input[src] = grad_phase[phase]);
    Ok(())
}

/// Weight and bias gradients: **accumulates** `∂L/∂w` into `grad_weight` (`(C_out, C_in, k, k)`) and,
/// if given, `∂L/∂bias` into `grad_bias` (`(C_out)`), given the forward `input` and `grad_output`.
pub(crate) fn backward_weight<T: Real>(
    s: Conv2dShape,
    input: &[T],
    grad_output: &[T],
    grad_weight: &mut [T],
    grad_bias: Option<&mut [T]>,
) -> Result<(), NnError> {
    s.validate()?;
    check_len("strided conv2d input", s.input_len(), input.len())?;
    check_len(
        "strided conv2d grad_output",
        s.output_len(),
        grad_output.len(),
    )?;
    check_len(
        "strided conv2d grad_weight",
        s.weight_len(),
        grad_weight.len(),
    )?;
    let ps = s.phase_shape();
    let mut grad_phase = vec![T::zero(); ps.weight_len()];
    conv2d_backward_weight(
        ps,
        &s.phase_input(input),
        grad_output,
        &mut grad_phase,
        grad_bias,
    )?;
    s.for_each_phase_tap(|phase, dst| grad_weight[dst] = grad_weight[dst] + grad_phase[phase]);
    Ok(())
}

/// Slow, obviously-correct direct strided convolution (the oracle for tests): same contract as
/// [`forward`], one multiply-add per loop iteration.
pub(crate) fn reference<T: Real>(
    s: Conv2dShape,
    input: &[T],
    weight: &[T],
    bias: Option<&[T]>,
    output: &mut [T],
) -> Result<(), NnError> {
    s.validate()?;
    check_len("conv2d input", s.input_len(), input.len())?;
    check_len("conv2d weight", s.weight_len(), weight.len())?;
    check_len("conv2d output", s.output_len(), output.len())?;
    let (h, w, k) = (s.height as isize, s.width as isize, s.kernel);
    let (ho, wo) = (s.out_height(), s.out_width());
    for b in 0..s.batch {
        for o in 0..s.c_out {
            for y in 0..ho {
                for x in 0..wo {
                    let mut acc = bias.map_or(T::zero(), |bb| bb[o]);
                    for c in 0..s.c_in {
                        for ky in 0..k {
                            for kx in 0..k {
                                let iy = (y * s.stride + ky) as isize - s.pad as isize;
                                let ix = (x * s.stride + kx) as isize - s.pad as isize;
                                if iy < 0 || ix < 0 || iy >= h || ix >= w {
                                    continue;
                                }
                                let iv = input[((b * s.c_in + c) * s.height + iy as usize)
                                    * s.width
                                    + ix as usize];
                                acc = acc + weight[((o * s.c_in + c) * k + ky) * k + kx] * iv;
                            }
                        }
                    }
                    output[((b * s.c_out + o) * ho + y) * wo + x] = acc;
                }
            }
        }
    }
    Ok(())
}
