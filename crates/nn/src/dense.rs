//! Fully connected layers on batches: `y = x·Wᵀ + b`, one GEMM per pass.
//!
//! Must never loop over the inner dimension by hand: all products go through [`crate::gemm`].

use crate::{check_len, gemm, NnError, Real};
use rayon::prelude::*;

/// Shape of a dense layer applied to a batch.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DenseShape {
    /// Number of rows (samples) in the batch.
    pub batch: usize,
    /// Input features per sample.
    pub inputs: usize,
    /// Output features per sample.
    pub outputs: usize,
}

/// Forward: `y[b, o] = Σ_i x[b, i]·w[o, i] + bias[o]`.
///
/// `x` is `(batch, inputs)`, `w` is `(outputs, inputs)` (PyTorch `nn.Linear` layout), `bias` is
/// `(outputs)` or absent, `y` is `(batch, outputs)` and is overwritten.
pub fn dense_forward<T: Real>(
    s: DenseShape,
    x: &[T],
    w: &[T],
    bias: Option<&[T]>,
    y: &mut [T],
) -> Result<(), NnError> {
    check_len("dense x", s.batch * s.inputs, x.len())?;
    check_len("dense weight", s.outputs * s.inputs, w.len())?;
    check_len("dense y", s.batch * s.outputs, y.len())?;
    let beta = if let Some(b) = bias {
        check_len("dense bias", s.outputs, b.len())?;
        y.par_chunks_exact_mut(s.outputs.max(1))
            .for_each(|row| row.copy_from_slice(b));
        T::one()
    } else {
        T::zero()
    };
    gemm(
        s.batch,
        s.inputs,
        s.outputs,
        T::one(),
        x,
        false,
        w,
        true,
        beta,
        y,
    );
    Ok(())
}

/// Backward of [`dense_forward`] given `dy = ∂L/∂y` (`(batch, outputs)`).
///
/// - `dx` (`(batch, inputs)`), if given, is **overwritten** with `dy·W`;
/// - `dw` (`(outputs, inputs)`), if given, is **accumulated** with `dyᵀ·x`;
/// - `dbias` (`(outputs)`), if given, is **accumulated** with the column sums of `dy` (summed over the
///   batch in increasing row order).
pub fn dense_backward<T: Real>(
    s: DenseShape,
    x: &[T],
    w: &[T],
    dy: &[T],
    dx: Option<&mut [T]>,
    dw: Option<&mut [T]>,
    dbias: Option<&mut [T]>,
) -> Result<(), NnError> {
    check_len("dense x", s.batch * s.inputs, x.len())?;
    check_len("dense weight", s.outputs * s.inputs, w.len())?;
    check_len("dense dy", s.batch * s.outputs, dy.len())?;
    if let Some(dx) = dx {
        check_len("dense dx", s.batch * s.inputs, dx.len())?;
        gemm(
            s.batch,
            s.outputs,
            s.inputs,
            T::one(),
            dy,
            false,
            w,
            false,
            T::zero(),
            dx,
        );
    }
    if let Some(dw) = dw {
        check_len("dense dw", s.outputs * s.inputs, dw.len())?;
        gemm(
            s.outputs,
            s.batch,
            s.inputs,
            T::one(),
            dy,
            true,
            x,
            false,
            T::one(),
            dw,
        );
    }
    if let Some(db) = dbias {
        check_len("dense dbias", s.outputs, db.len())?;
        // Column groups in parallel; each column is summed over the rows in increasing order.
        const GROUP: usize = 8;
        let outputs = s.outputs.max(1);
        db.par_chunks_mut(GROUP).enumerate().for_each(|(k, d)| {
            let first = k * GROUP;
            for row in dy.chunks_exact(outputs) {
                for (d, &g) in d.iter_mut().zip(&row[first..]) {
                    *d = *d + g;
                }
            }
        });
    }
    Ok(())
}
