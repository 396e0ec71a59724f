//! 2-D convolution (cross-correlation, as PyTorch's `Conv2d`): any square kernel size, stride 1,
//! symmetric zero padding, by im2col + GEMM over chunks of output rows.
//!
//! im2col + GEMM was chosen over a direct kernel so that the inner products run in the GEMM crate's
//! packed micro-kernels; a direct kernel has not been written or measured against it yet (open work,
//! together with the flow network's speed targets in docs/BENCHMARKS.md, "Flow network"). Chunks of
//! output rows (a fixed number of rows, independent of the thread count) keep the im2col buffer in
//! cache and give parallelism even for a batch of one; each chunk writes its own part of one scratch
//! buffer; im2col blocks and that scratch are recycled per thread (see `BUFFERS`).
//!
//! The input gradient is itself a convolution of the output gradient with the flipped, transposed
//! kernel (padding `k − 1 − pad`), so it reuses the same fast path. The weight gradient gathers the
//! receptive fields pixel-major (`im2row`) so that the GEMM reads them in place, and is reduced over
//! chunks in a fixed order. This module must never depend on thread timing for any sum.

use crate::{check_len, NnError, Real};
use rayon::prelude::*;

/// Target number of output pixels per im2col chunk of the forward and input-gradient passes. 128
/// keeps the largest im2col block of the flow network (64 channels × 7 × 7 × 128 px × 4 B = 1.6 MB)
/// near L2 size; measured against 32–2048 (docs/notes/benchmarks-history.md, section "flow"): 30 % less CPU time
/// than 512 for the SPyNet forward + input gradient.
const CHUNK_PIXELS: usize = 128;
/// Target output pixels per chunk of the weight-gradient pass, where the chunk is the GEMM's inner
/// dimension (larger chunks mean fewer read-modify-write passes over the weight-gradient buffer).
const WEIGHT_CHUNK_PIXELS: usize = 512;
/// Number of partial weight-gradient buffers (fixed, so the reduction order never depends on threads).
const WEIGHT_GRAD_GROUPS: usize = 4;

/// Shape of a 2-D convolution on a batch of planar images (any stride: stride 1 by im2col + GEMM,
/// a larger one by polyphase decomposition onto stride 1, `crate::conv_strided`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Conv2dShape {
    /// Batch size B.
    pub batch: usize,
    /// Input channels.
    pub c_in: usize,
    /// Output channels.
    pub c_out: usize,
    /// Input height H in pixels.
    pub height: usize,
    /// Input width W in pixels.
    pub width: usize,
    /// Kernel side length k (the kernel is k × k).
    pub kernel: usize,
    /// Step between output pixels, in input pixels (≥ 1).
    pub stride: usize,
    /// Zero padding on each side, in pixels (`(k − 1) / 2` keeps the size at stride 1).
    pub pad: usize,
}

impl Conv2dShape {
    /// Output height `(H + 2·pad − k) / stride + 1` (integer division: PyTorch's floor; 0 when
    /// the kernel is larger than the padded image).
    pub fn out_height(&self) -> usize {
        self.out_side(self.height)
    }
    /// Output width `(W + 2·pad − k) / stride + 1`.
    pub fn out_width(&self) -> usize {
        self.out_side(self.width)
    }
    fn out_side(&self, side: usize) -> usize {
        (side + 2 * self.pad)
            .checked_sub(self.kernel)
            .map_or(0, |span| span / self.stride.max(1) + 1)
    }
    /// Number of input elements `B·C_in·H·W`.
    pub fn input_len(&self) -> usize {
        self.batch * self.c_in * self.height * self.width
    }
    /// Number of output elements `B·C_out·H_out·W_out`.
    pub fn output_len(&self) -> usize {
        self.batch * self.c_out * self.out_height() * self.out_width()
    }
    /// Number of weights `C_out·C_in·k·k` (layout `(C_out, C_in, k, k)`, as PyTorch).
    pub fn weight_len(&self) -> usize {
        self.c_out * self.c_in * self.kernel * self.kernel
    }

    pub(crate) fn validate(&self) -> Result<(), NnError> {
        if self.kernel == 0
            || self.stride == 0
            || self.height + 2 * self.pad < self.kernel
            || self.width + 2 * self.pad < self.kernel
        {
            return Err(NnError::Shape(format!(
                "conv2d kernel {} stride {} on a {}x{} image with pad {}",
                self.kernel, self.stride, self.height, self.width, self.pad
            )));
        }
        Ok(())
    }

    /// Output rows per chunk for a target of `pixels` output pixels per chunk.
    fn rows_per_chunk(&self, pixels: usize) -> usize {
        (pixels / self.out_width().max(1)).max(1)
    }

    /// (batch index, first output row, end output row) of every chunk of about `pixels` output
    /// pixels, in a fixed order (independent of the thread count).
    fn chunks(&self, pixels: usize) -> Vec<(usize, usize, usize)> {
        let rows = self.rows_per_chunk(pixels);
        let ho = self.out_height();
        let mut v = Vec::new();
        for b in 0..self.batch {
            let mut r0 = 0;
            while r0 < ho {
                let r1 = (r0 + rows).min(ho);
                v.push((b, r0, r1));
                r0 = r1;
            }
        }
        v
    }
}

/// Fills `col` (`(C_in·k·k) × ((r1 − r0)·W_out)`, row-major) with the receptive fields of output
/// rows `r0..r1` of image `img` (`(C_in, H, W)`).
fn im2col<T: Real>(s: &Conv2dShape, img: &[T], r0: usize, r1: usize, col: &mut [T]) {
    let (h, w, k, p) = (s.height, s.width, s.kernel, s.pad);
    let wo = s.out_width();
    let n = (r1 - r0) * wo;
    for ci in 0..s.c_in {
        let plane = &img[ci * h * w..(ci + 1) * h * w];
        for ky in 0..k {
            for kx in 0..k {
                let row = (ci * k + ky) * k + kx;
                let dst = &mut col[row * n..(row + 1) * n];
                // Valid output columns x: 0 <= x + kx - p < w.
                let x_lo = p.saturating_sub(kx).min(wo);
                let x_hi = (w + p).saturating_sub(kx).min(wo).max(x_lo);
                for r in r0..r1 {
                    let d = &mut dst[(r - r0) * wo..(r - r0 + 1) * wo];
                    let iy = r + ky;
                    if iy < p || iy - p >= h {
                        d.fill(T::zero());
                        continue;
                    }
                    let src = &plane[(iy - p) * w..(iy - p + 1) * w];
                    d[..x_lo].fill(T::zero());
                    d[x_hi..].fill(T::zero());
                    if x_hi > x_lo {
                        let s0 = x_lo + kx - p;
                        d[x_lo..x_hi].copy_from_slice(&src[s0..s0 + (x_hi - x_lo)]);
                    }
                }
            }
        }
    }
}

/// The transpose of [`im2col`]: fills `rows` (`((r1 − r0)·W_out) × (C_in·k·k)`, row-major) with the
/// receptive field of every output pixel of rows `r0..r1`, so that the weight gradient's GEMM reads
/// it with contiguous rows instead of gathering a transposed im2col block element by element.
fn im2row<T: Real>(s: &Conv2dShape, img: &[T], r0: usize, r1: usize, rows: &mut [T]) {
    let (h, w, k, p) = (s.height, s.width, s.kernel, s.pad);
    let wo = s.out_width();
    let ckk = s.c_in * k * k;
    for r in r0..r1 {
        for x in 0..wo {
            let dst = &mut rows[((r - r0) * wo + x) * ckk..((r - r0) * wo + x + 1) * ckk];
            // Valid kernel columns kx: 0 <= x + kx - p < w.
            let kx_lo = p.saturating_sub(x).min(k);
            let kx_hi = (w + p).saturating_sub(x).min(k).max(kx_lo);
            for ci in 0..s.c_in {
                let plane = &img[ci * h * w..(ci + 1) * h * w];
                for ky in 0..k {
                    let d = &mut dst[(ci * k + ky) * k..(ci * k + ky + 1) * k];
                    let iy = r + ky;
                    if iy < p || iy - p >= h {
                        d.fill(T::zero());
                        continue;
                    }
                    let src = &plane[(iy - p) * w..(iy - p + 1) * w];
                    if k == 7 && kx_lo == 0 && kx_hi == 7 {
                        // The flow network's interior case as a fixed-size copy instead of a
                        // call to memmove per 7 values: a joint train-flow step is ≈ 12 % faster
                        // (30 steps 7.3–7.5 s against 8.2–8.6 s, same bits).
                        copy_fixed::<T, 7>(&src[x - p..], d);
                        continue;
                    }
                    d[..kx_lo].fill(T::zero());
                    d[kx_hi..].fill(T::zero());
                    if kx_hi > kx_lo {
                        let s0 = x + kx_lo - p;
                        d[kx_lo..kx_hi].copy_from_slice(&src[s0..s0 + (kx_hi - kx_lo)]);
                    }
                }
            }
        }
    }
}

/// Copies the first `N` values of `src` into `dst` (both at least `N` long) with a length known at
/// compile time.
#[inline(always)]
fn copy_fixed<T: Copy, const N: usize>(src: &[T], dst: &mut [T]) {
    dst[..N].copy_from_slice(&src[..N]);
}

/// The im2col + GEMM forward used by both the forward and the input-gradient pass.
fn conv_core<T: Real>(
    s: &Conv2dShape,
    input: &[T],
    weight: &[T],
    bias: Option<&[T]>,
    output: &mut [T],
) {
    let (ho, wo) = (s.out_height(), s.out_width());
    let ckk = s.c_in * s.kernel * s.kernel;
    let in_img = s.c_in * s.height * s.width;
    let out_img = s.c_out * ho * wo;
    let chunks = s.chunks(CHUNK_PIXELS);
    let max_n = s.rows_per_chunk(CHUNK_PIXELS).min(ho) * wo;
    // One chunk-major scratch buffer per call (no allocation per chunk): chunk j owns
    // `c_out × n_j` values, split off in order so that the chunks can be filled in parallel.
    // Every element of the scratch is overwritten (bias fill or a β = 0 GEMM), so a recycled buffer
    // is as good as a zeroed one.
    let mut scratch = take_buffer::<T>(s.batch * out_img);
    let mut parts: Vec<&mut [T]> = Vec::with_capacity(chunks.len());
    let mut rest = &mut scratch[..s.batch * out_img];
    for &(_, r0, r1) in &chunks {
        let (part, tail) = rest.split_at_mut(s.c_out * (r1 - r0) * wo);
        parts.push(part);
        rest = tail;
    }
    parts.into_par_iter().zip(chunks.par_iter()).for_each_init(
        || ReusedBuffer(take_buffer::<T>(ckk * max_n)),
        |ReusedBuffer(col), (out, &(b, r0, r1))| {
            let n = (r1 - r0) * wo;
            let col = &mut col[..ckk * n];
            im2col(s, &input[b * in_img..(b + 1) * in_img], r0, r1, col);
            let beta = if let Some(bias) = bias {
                for (co, row) in out.chunks_exact_mut(n).enumerate() {
                    row.fill(bias[co]);
                }
                T::one()
            } else {
                T::zero()
            };
            crate::gemm(
                s.c_out,
                ckk,
                n,
                T::one(),
                weight,
                false,
                col,
                false,
                beta,
                out,
            );
        },
    );
    let mut offset = 0;
    for &(b, r0, r1) in &chunks {
        let n = (r1 - r0) * wo;
        for co in 0..s.c_out {
            let dst = b * out_img + co * ho * wo + r0 * wo;
            output[dst..dst + n].copy_from_slice(&scratch[offset + co * n..offset + (co + 1) * n]);
        }
        offset += s.c_out * n;
    }
    give_back(scratch);
}

thread_local! {
    /// Per-thread recycled scratch buffers (`Vec<T>` boxed as `Any`, any `T`): im2col blocks and
    /// GEMM outputs whose every element is written before it is read. Zero-filling a fresh 1.6 MB
    /// im2col block per rayon job and a fresh output scratch per call was ≈ 10 % of the flow
    /// network's forward + input gradient (perf, 64² pair). A thread holds one buffer per
    /// convolution it is inside of — more than one when, waiting in a convolution, it runs another
    /// convolution's rayon work — and keeps at most [`POOLED_BUFFERS`] of them, none above
    /// [`POOLED_MAX_BYTES`].
    static BUFFERS: std::cell::RefCell<Vec<Box<dyn std::any::Any>>> =
        const { std::cell::RefCell::new(Vec::new()) };
}

/// Most buffers a thread keeps for reuse.
const POOLED_BUFFERS: usize = 8;
/// Largest buffer (bytes of capacity) a thread keeps for reuse; larger ones are freed.
const POOLED_MAX_BYTES: usize = 64 << 20;

/// A buffer of at least `len` elements from this thread's pool — the smallest that is large
/// enough, else the largest grown to `len` — or a fresh zeroed one. Contents are unspecified:
/// callers overwrite what they read.
fn take_buffer<T: Real>(len: usize) -> Vec<T> {
    let found = BUFFERS.with(|pool| {
        let mut pool = pool.borrow_mut();
        let capacity = |b: &Box<dyn std::any::Any>| b.downcast_ref::<Vec<T>>().map(Vec::len);
        let fits = pool
            .iter()
            .enumerate()
            .filter_map(|(i, b)| capacity(b).map(|c| (i, c)))
            .filter(|&(_, c)| c >= len)
            .min_by_key(|&(_, c)| c);
        let pick = fits.or_else(|| {
            pool.iter()
                .enumerate()
                .filter_map(|(i, b)| capacity(b).map(|c| (i, c)))
                .max_by_key(|&(_, c)| c)
        })?;
        pool.swap_remove(pick.0).downcast::<Vec<T>>().ok()
    });
    let mut v = found.map_or_else(Vec::new, |b| *b);
    if v.len() < len {
        v.resize(len, T::zero());
    }
    v
}

/// Returns a buffer from [`take_buffer`] to this thread's pool.
fn give_back<T: Real>(v: Vec<T>) {
    if v.capacity() * std::mem::size_of::<T>() > POOLED_MAX_BYTES {
        return;
    }
    BUFFERS.with(|pool| {
        let mut pool = pool.borrow_mut();
        if pool.len() < POOLED_BUFFERS {
            pool.push(Box::new(v));
        }
    });
}

/// An im2col block that goes back to the pool of the thread that drops it.
struct ReusedBuffer<T: Real>(Vec<T>);

impl<T: Real> Drop for ReusedBuffer<T> {
    fn drop(&mut self) {
        give_back(std::mem::take(&mut self.0));
    }
}

/// Forward convolution: `out[b, o, y, x] = bias[o] + Σ_{c, dy, dx} w[o, c, dy, dx]·in[b, c, y + dy − pad, x + dx − pad]`
/// with zeros outside the image.
///
/// `input` is `(B, C_in, H, W)`, `weight` `(C_out, C_in, k, k)`, `bias` `(C_out)` or absent,
/// `output` `(B, C_out, H_out, W_out)` (overwritten).
pub fn conv2d_forward<T: Real>(
    s: Conv2dShape,
    input: &[T],
    weight: &[T],
    bias: Option<&[T]>,
    output: &mut [T],
) -> Result<(), NnError> {
    if s.stride > 1 {
        return crate::conv_strided::forward(s, input, weight, bias, output);
    }
    s.validate()?;
    check_len("conv2d input", s.input_len(), input.len())?;
    check_len("conv2d weight", s.weight_len(), weight.len())?;
    check_len("conv2d output", s.output_len(), output.len())?;
    if let Some(b) = bias {
        check_len("conv2d bias", s.c_out, b.len())?;
    }
    conv_core(&s, input, weight, bias, output);
    Ok(())
}

/// Input gradient: overwrites `grad_input` (`(B, C_in, H, W)`) with `∂L/∂in` given
/// `grad_output = ∂L/∂out`. Requires `pad ≤ k − 1` (always true for "same" convolutions).
pub fn conv2d_backward_input<T: Real>(
    s: Conv2dShape,
    grad_output: &[T],
    weight: &[T],
    grad_input: &mut [T],
) -> Result<(), NnError> {
    if s.stride > 1 {
        return crate::conv_strided::backward_input(s, grad_output, weight, grad_input);
    }
    s.validate()?;
    check_len("conv2d grad_output", s.output_len(), grad_output.len())?;
    check_len("conv2d weight", s.weight_len(), weight.len())?;
    check_len("conv2d grad_input", s.input_len(), grad_input.len())?;
    if s.pad + 1 > s.kernel {
        return Err(NnError::Shape(format!(
            "conv2d backward needs pad <= kernel - 1 (pad {}, kernel {})",
            s.pad, s.kernel
        )));
    }
    let k = s.kernel;
    // Flipped, transposed kernel: wt[c, o, ky, kx] = w[o, c, k-1-ky, k-1-kx].
    let mut wt = vec![T::zero(); weight.len()];
    for o in 0..s.c_out {
        for c in 0..s.c_in {
            for ky in 0..k {
                for kx in 0..k {
                    wt[((c * s.c_out + o) * k + ky) * k + kx] =
                        weight[((o * s.c_in + c) * k + (k - 1 - ky)) * k + (k - 1 - kx)];
                }
            }
        }
    }
    let t = Conv2dShape {
        batch: s.batch,
        c_in: s.c_out,
        c_out: s.c_in,
        height: s.out_height(),
        width: s.out_width(),
        kernel: k,
        stride: 1,
        pad: k - 1 - s.pad,
    };
    conv_core(&t, grad_output, &wt, None, grad_input);
    Ok(())
}

/// Weight and bias gradients: **accumulates** `∂L/∂w` into `grad_weight` (`(C_out, C_in, k, k)`) and,
/// if given, `∂L/∂bias` into `grad_bias` (`(C_out)`), given the forward `input` and `grad_output`.
pub fn conv2d_backward_weight<T: Real>(
    s: Conv2dShape,
    input: &[T],
    grad_output: &[T],
    grad_weight: &mut [T],
    grad_bias: Option<&mut [T]>,
) -> Result<(), NnError> {
    if s.stride > 1 {
        return crate::conv_strided::backward_weight(s, input, grad_output, grad_weight, grad_bias);
    }
    s.validate()?;
    check_len("conv2d input", s.input_len(), input.len())?;
    check_len("conv2d grad_output", s.output_len(), grad_output.len())?;
    check_len("conv2d grad_weight", s.weight_len(), grad_weight.len())?;
    let (ho, wo) = (s.out_height(), s.out_width());
    let hwo = ho * wo;
    let ckk = s.c_in * s.kernel * s.kernel;
    let in_img = s.c_in * s.height * s.width;
    let out_img = s.c_out * hwo;
    let chunks = s.chunks(WEIGHT_CHUNK_PIXELS);
    let groups = WEIGHT_GRAD_GROUPS.min(chunks.len()).max(1);
    let per_group = chunks.len().div_ceil(groups);
    let max_n = s.rows_per_chunk(WEIGHT_CHUNK_PIXELS).min(ho) * wo;
    let partials: Vec<Vec<T>> = chunks
        .par_chunks(per_group.max(1))
        .map(|group| {
            let mut rows = ReusedBuffer(take_buffer::<T>(max_n * ckk));
            let mut dw = vec![T::zero(); s.c_out * ckk];
            for &(b, r0, r1) in group {
                let n = (r1 - r0) * wo;
                let rows = &mut rows.0[..n * ckk];
                im2row(&s, &input[b * in_img..(b + 1) * in_img], r0, r1, rows);
                let dy = &grad_output[b * out_img + r0 * wo..];
                // dw (C_out × ckk) += dy_chunk (C_out × n, row stride H_out·W_out) · rows (n × ckk);
                // the same products summed in the same pixel order as with a transposed im2col.
                T::gemm_unchecked(
                    s.c_out,
                    n,
                    ckk,
                    T::one(),
                    dy,
                    hwo as isize,
                    1,
                    rows,
                    ckk as isize,
                    1,
                    T::one(),
                    &mut dw,
                    ckk as isize,
                    1,
                );
            }
            dw
        })
        .collect();
    for p in &partials {
        for (g, &v) in grad_weight.iter_mut().zip(p) {
            *g = *g + v;
        }
    }
    if let Some(gb) = grad_bias {
        check_len("conv2d grad_bias", s.c_out, gb.len())?;
        for b in 0..s.batch {
            for (co, g) in gb.iter_mut().enumerate() {
                let plane = &grad_output[b * out_img + co * hwo..b * out_img + (co + 1) * hwo];
                let mut acc = T::zero();
                for &v in plane {
                    acc = acc + v;
                }
                *g = *g + acc;
            }
        }
    }
    Ok(())
}

/// Slow, obviously-correct direct convolution at any stride (the oracle for tests): same contract
/// as [`conv2d_forward`], one multiply-add per loop iteration.
pub fn conv2d_reference<T: Real>(
    s: Conv2dShape,
    input: &[T],
    weight: &[T],
    bias: Option<&[T]>,
    output: &mut [T],
) -> Result<(), NnError> {
    crate::conv_strided::reference(s, input, weight, bias, output)
}
