//! Chunked forward and backward passes of an `nn::Mlp` for the deformation networks: a batch is cut
//! into chunks of a fixed number of rows (a function of the layer widths only), every product goes
//! through `nn::gemm` (matrixmultiply) on the contiguous chunk, and all buffers are per chunk or per
//! gradient group — nothing is allocated per row.
//!
//! Determinism: chunk boundaries and the [`GRAD_GROUPS`] weight-gradient groups depend only on the
//! batch size and the network shape; a group accumulates its chunks' weight gradients in chunk order
//! and the groups are summed in group order, so results are bit-identical for any thread count.
//!
//! This module must never decide what the rows mean (encoding, softmax, skinning live in
//! `deform_net`).

use std::ops::Range;

use nn::mlp::{Activation, Mlp};
use nn::{gemm, Real};
use rayon::prelude::*;

/// Number of partial weight-gradient buffers a backward pass reduces (fixed, independent of the
/// thread count).
pub(crate) const GRAD_GROUPS: usize = 16;

/// matrixmultiply runs a GEMM on its own threads once `m·k + k·n ≥ 2¹⁵` (two threads); chunks stay
/// below that so the only parallelism is rayon's over chunks (no oversubscription on small machines).
const GEMM_THREAD_THRESHOLD: usize = 1 << 15;

/// Rows per chunk for a network whose widest layer is `width`: the largest multiple of 16 in
/// [16, 256] for which the forward GEMM (`rows × w × w`) and the weight-gradient GEMM
/// (`w × rows × w`) stay single-threaded in matrixmultiply.
pub(crate) fn chunk_rows(width: usize) -> usize {
    let w = width.max(1);
    let mut r = 256;
    while r > 16 && (r * w + w * w >= GEMM_THREAD_THRESHOLD || 2 * r * w >= GEMM_THREAD_THRESHOLD) {
        r -= 16;
    }
    r
}

/// The row ranges of the chunks of an `n`-row batch, in order.
pub(crate) fn chunks(n: usize, rows: usize) -> Vec<Range<usize>> {
    (0..n.div_ceil(rows))
        .map(|c| c * rows..((c + 1) * rows).min(n))
        .collect()
}

/// The chunk-index ranges of the [`GRAD_GROUPS`] gradient groups (contiguous, in order; empty
/// groups are dropped).
pub(crate) fn groups(n_chunks: usize) -> Vec<Range<usize>> {
    let per = n_chunks.div_ceil(GRAD_GROUPS).max(1);
    (0..n_chunks.div_ceil(per))
        .map(|g| g * per..((g + 1) * per).min(n_chunks))
        .collect()
}

/// Runs `f` on every gradient group in parallel and returns the results in group order.
pub(crate) fn map_groups<R: Send>(
    n_chunks: usize,
    f: impl Fn(Range<usize>) -> R + Sync + Send,
) -> Vec<R> {
    groups(n_chunks).into_par_iter().map(f).collect()
}

/// Adds `parts` into `dst` element-wise, in order.
pub(crate) fn sum_into<T: Real>(dst: &mut [T], parts: impl IntoIterator<Item = impl AsRef<[T]>>) {
    for p in parts {
        for (d, &v) in dst.iter_mut().zip(p.as_ref()) {
            *d = *d + v;
        }
    }
}

/// `(negative-side slope, positive-side slope)` of the hidden activation. Both slopes are ≥ 0
/// (checked by the callers), so a post-activation is positive exactly when its pre-activation is:
/// the backward pass reads the slope off the stored post-activations.
#[inline]
pub(crate) fn slopes<T: Real>(a: Activation) -> T {
    match a {
        Activation::Relu => T::zero(),
        Activation::LeakyRelu(s) => T::of(s),
    }
}

/// Per-group scratch buffers (grown on demand, reused across chunks).
#[derive(Default)]
pub(crate) struct Scratch<T> {
    a: Vec<T>,
    b: Vec<T>,
}

fn grow<T: Real>(v: &mut Vec<T>, len: usize) -> &mut [T] {
    if v.len() < len {
        v.resize(len, T::zero());
    }
    &mut v[..len]
}

/// Width of the concatenated hidden activations of one row.
pub(crate) fn hidden_total<T: Real>(mlp: &Mlp<T>) -> usize {
    mlp.sizes[1..mlp.sizes.len() - 1].iter().sum()
}

/// Widest layer (input, hidden or output) of `mlp`.
pub(crate) fn widest<T: Real>(mlp: &Mlp<T>) -> usize {
    mlp.sizes.iter().copied().max().unwrap_or(1)
}

/// Offset of layer `l`'s weight in the flat parameter vector (its bias follows).
fn layer_offset(sizes: &[usize], l: usize) -> usize {
    (0..l).map(|k| sizes[k + 1] * (sizes[k] + 1)).sum()
}

/// Every layer's weight transposed to `(in, out)` row-major, layer after layer: the forward
/// products read it in place instead of transposing the weights for every chunk. Made once per
/// pass by the caller of [`forward_chunk`].
pub(crate) fn transposed_weights<T: Real>(mlp: &Mlp<T>) -> Vec<T> {
    let sizes = &mlp.sizes;
    let mut wt = Vec::with_capacity((0..sizes.len() - 1).map(|l| sizes[l] * sizes[l + 1]).sum());
    for l in 0..sizes.len() - 1 {
        let (i_dim, o_dim) = (sizes[l], sizes[l + 1]);
        let o = layer_offset(sizes, l);
        let w = &mlp.params[o..o + o_dim * i_dim];
        for i in 0..i_dim {
            wt.extend((0..o_dim).map(|j| w[j * i_dim + i]));
        }
    }
    wt
}

/// Forward of one chunk of `rows` rows: `x` is `(rows, in)`, `wt` the network's
/// [`transposed_weights`]; the hidden post-activations are written to `act` (`rows · hidden_total`
/// values, layer by layer, each `(rows, h_l)`), the output to `out` (`(rows, out)`).
pub(crate) fn forward_chunk<T: Real>(
    mlp: &Mlp<T>,
    wt: &[T],
    x: &[T],
    rows: usize,
    act: &mut [T],
    out: &mut [T],
) {
    let sizes = &mlp.sizes;
    let layers = sizes.len() - 1;
    let neg = slopes::<T>(mlp.activation);
    let mut prev: Option<usize> = None; // offset in `act` of the current layer's input
    let mut off = 0;
    let mut wt_off = 0;
    for l in 0..layers {
        let (i_dim, o_dim) = (sizes[l], sizes[l + 1]);
        let o = layer_offset(sizes, l);
        let w_t = &wt[wt_off..wt_off + i_dim * o_dim];
        wt_off += i_dim * o_dim;
        let bias = &mlp.params[o + o_dim * i_dim..o + o_dim * (i_dim + 1)];
        let last = l + 1 == layers;
        // Split `act` so the input (an earlier layer) and the output (this layer) can be borrowed
        // together.
        let (done, rest) = act.split_at_mut(off);
        let input: &[T] = match prev {
            None => &x[..rows * i_dim],
            Some(p) => &done[p..p + rows * i_dim],
        };
        let y: &mut [T] = if last {
            &mut out[..rows * o_dim]
        } else {
            &mut rest[..rows * o_dim]
        };
        // y = x·Wᵀ, then the bias and the activation in one pass over y (the same sums as a GEMM
        // into bias-initialised rows: `acc + b` either way).
        gemm(
            rows,
            i_dim,
            o_dim,
            T::one(),
            input,
            false,
            w_t,
            false,
            T::zero(),
            y,
        );
        if last {
            for row in y.chunks_exact_mut(o_dim) {
                for (v, &b) in row.iter_mut().zip(bias) {
                    *v = *v + b;
                }
            }
        } else {
            for row in y.chunks_exact_mut(o_dim) {
                for (v, &b) in row.iter_mut().zip(bias) {
                    let z = *v + b;
                    *v = if z > T::zero() { z } else { z * neg };
                }
            }
            prev = Some(off);
            off += rows * o_dim;
        }
    }
}

/// Backward of one chunk: from `d_out` (`(rows, out)`) and the forward's `x` and `act`,
/// **accumulates** the parameter gradient into `d_params` (the flat layout of `mlp.params`, summed
/// over rows in increasing order within each GEMM) and, if given, **overwrites** `d_x`
/// (`(rows, in)`).
#[allow(clippy::too_many_arguments)]
pub(crate) fn backward_chunk<T: Real>(
    mlp: &Mlp<T>,
    x: &[T],
    act: &[T],
    rows: usize,
    d_out: &[T],
    d_params: &mut [T],
    d_x: Option<&mut [T]>,
    scratch: &mut Scratch<T>,
) {
    let sizes = &mlp.sizes;
    let layers = sizes.len() - 1;
    let neg = slopes::<T>(mlp.activation);
    // Offset in `act` of hidden layer l's output (the input of layer l + 1).
    let act_off = |l: usize| -> usize { (1..=l).map(|k| rows * sizes[k]).sum() };
    // `grad` holds ∂L/∂(output of the current layer), `dx` the next one.
    let mut grad: Vec<T> = std::mem::take(&mut scratch.a);
    let mut dx_buf: Vec<T> = std::mem::take(&mut scratch.b);
    grow(&mut grad, rows * sizes[layers]).copy_from_slice(&d_out[..rows * sizes[layers]]);
    let mut d_x = d_x;
    for l in (0..layers).rev() {
        let (i_dim, o_dim) = (sizes[l], sizes[l + 1]);
        let o = layer_offset(sizes, l);
        let w = &mlp.params[o..o + o_dim * i_dim];
        let g = &grad[..rows * o_dim];
        let input: &[T] = if l == 0 {
            &x[..rows * i_dim]
        } else {
            let a0 = act_off(l - 1);
            &act[a0..a0 + rows * i_dim]
        };
        let (dw, db) = d_params[o..o + o_dim * (i_dim + 1)].split_at_mut(o_dim * i_dim);
        gemm(
            o_dim,
            rows,
            i_dim,
            T::one(),
            g,
            true,
            input,
            false,
            T::one(),
            dw,
        );
        for row in g.chunks_exact(o_dim) {
            for (d, &v) in db.iter_mut().zip(row) {
                *d = *d + v;
            }
        }
        if l == 0 && d_x.is_none() {
            break;
        }
        let dx = grow(&mut dx_buf, rows * i_dim);
        gemm(
            rows,
            o_dim,
            i_dim,
            T::one(),
            g,
            false,
            w,
            false,
            T::zero(),
            dx,
        );
        if l > 0 {
            for (d, &a) in dx.iter_mut().zip(input) {
                *d = if a > T::zero() { *d } else { *d * neg };
            }
            std::mem::swap(&mut grad, &mut dx_buf);
        } else if let Some(out) = d_x.as_deref_mut() {
            out[..rows * i_dim].copy_from_slice(dx);
        }
    }
    scratch.a = grad;
    scratch.b = dx_buf;
}
