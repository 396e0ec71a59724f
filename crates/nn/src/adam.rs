//! Adam optimiser (Kingma & Ba), with PyTorch's update rule and bias corrections:
//! `m ← β₁m + (1−β₁)g`, `v ← β₂v + (1−β₂)g²`, `p ← p − lr·m̂ / (√v̂ + ε)` with
//! `m̂ = m/(1−β₁ᵗ)`, `v̂ = v/(1−β₂ᵗ)`. Holds the moment buffers of one parameter tensor.

use crate::{check_len, NnError, Real};

/// Hyper-parameters of [`Adam`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AdamConfig {
    /// Learning rate (step size, in parameter units).
    pub lr: f64,
    /// Exponential decay of the first moment.
    pub beta1: f64,
    /// Exponential decay of the second moment.
    pub beta2: f64,
    /// Denominator guard added to `√v̂`.
    pub eps: f64,
}

impl Default for AdamConfig {
    /// PyTorch defaults: lr 1e-3, betas (0.9, 0.999), eps 1e-8.
    fn default() -> Self {
        Self {
            lr: 1e-3,
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-8,
        }
    }
}

/// Adam state for one parameter tensor of fixed length.
#[derive(Clone, Debug)]
pub struct Adam<T: Real> {
    /// Hyper-parameters (may be changed between steps, e.g. for a learning-rate schedule).
    pub config: AdamConfig,
    m: Vec<T>,
    v: Vec<T>,
    t: u64,
}

impl<T: Real> Adam<T> {
    /// Zero-initialised moments for a tensor of `len` parameters.
    pub fn new(len: usize, config: AdamConfig) -> Self {
        Self {
            config,
            m: vec![T::zero(); len],
            v: vec![T::zero(); len],
            t: 0,
        }
    }

    /// Rebuilds the state from saved moments and step count (for checkpoints).
    pub fn from_parts(
        config: AdamConfig,
        m: Vec<T>,
        v: Vec<T>,
        steps: u64,
    ) -> Result<Self, NnError> {
        check_len("adam second moment", m.len(), v.len())?;
        Ok(Self {
            config,
            m,
            v,
            t: steps,
        })
    }

    /// First and second moments (for checkpoints).
    pub fn moments(&self) -> (&[T], &[T]) {
        (&self.m, &self.v)
    }

    /// Number of steps taken so far.
    pub fn steps(&self) -> u64 {
        self.t
    }

    /// One update of `params` with gradient `grads` (both of the length given to [`Adam::new`]).
    pub fn step(&mut self, params: &mut [T], grads: &[T]) -> Result<(), NnError> {
        check_len("adam params", self.m.len(), params.len())?;
        check_len("adam grads", self.m.len(), grads.len())?;
        self.t += 1;
        let c = self.config;
        let lr = T::of(c.lr);
        adam_update(
            params,
            grads,
            &mut self.m,
            &mut self.v,
            self.t,
            c.beta1,
            c.beta2,
            c.eps,
            1,
            |_| lr,
        )
    }
}

/// The Adam update shared by every optimiser in the workspace, with PyTorch's operation order:
/// `m ← β₁m + (1−β₁)g`, `v ← β₂v + (1−β₂)g²`, `p ← p − lr/(1−β₁ᵗ) · m / (√v/√(1−β₂ᵗ) + ε)` for step
/// `t` (1-based, already incremented by the caller). Parameter `j` uses learning rate
/// `lr_of_column(j % row_stride)`, so one flat tensor can carry per-column rates (e.g. SH DC and
/// higher-order coefficients). Sequential and element-wise: bit-identical for any thread count.
pub fn adam_update<T: Real>(
    params: &mut [T],
    grads: &[T],
    m: &mut [T],
    v: &mut [T],
    t: u64,
    beta1: f64,
    beta2: f64,
    eps: f64,
    row_stride: usize,
    lr_of_column: impl Fn(usize) -> T,
) -> Result<(), NnError> {
    check_len("adam params", m.len(), params.len())?;
    check_len("adam grads", m.len(), grads.len())?;
    check_len("adam second moment", m.len(), v.len())?;
    let exponent = i32::try_from(t).unwrap_or(i32::MAX);
    let bias1 = T::of(1.0 - beta1.powi(exponent));
    let bias2_sqrt = T::of((1.0 - beta2.powi(exponent)).sqrt());
    let (b1, b2, eps) = (T::of(beta1), T::of(beta2), T::of(eps));
    let stride = row_stride.max(1);
    for j in 0..params.len() {
        let g = grads[j];
        m[j] = b1 * m[j] + (T::one() - b1) * g;
        v[j] = b2 * v[j] + (T::one() - b2) * g * g;
        let step_size = lr_of_column(j % stride) / bias1;
        params[j] = params[j] - step_size * m[j] / (v[j].sqrt() / bias2_sqrt + eps);
    }
    Ok(())
}

/// Lazy Adam over the rows of a matrix of per-item parameters (per-frame pose corrections, per-frame
/// codes), as PyTorch's `SparseAdam`: a step updates only the rows it is given, and each row has its
/// own step count for the bias corrections. Rows that are not trained in a step keep their value
/// and moments, where a dense [`Adam`] with zero gradients would keep moving them by their decaying
/// first moment and would decay their second moment between visits.
#[derive(Clone, Debug)]
pub struct RowAdam<T: Real> {
    /// Hyper-parameters (`lr` for every column unless [`RowAdam::with_column_rates`] set them).
    pub config: AdamConfig,
    row_len: usize,
    column_rates: Option<Vec<f64>>,
    m: Vec<T>,
    v: Vec<T>,
    steps: Vec<u64>,
}

impl<T: Real> RowAdam<T> {
    /// Zero-initialised moments for `rows` rows of `row_len` parameters.
    pub fn new(rows: usize, row_len: usize, config: AdamConfig) -> Self {
        Self {
            config,
            row_len,
            column_rates: None,
            m: vec![T::zero(); rows * row_len],
            v: vec![T::zero(); rows * row_len],
            steps: vec![0; rows],
        }
    }

    /// Rebuilds the state from saved moments and per-row step counts (for checkpoints).
    pub fn from_parts(
        config: AdamConfig,
        row_len: usize,
        m: Vec<T>,
        v: Vec<T>,
        steps: Vec<u64>,
    ) -> Result<Self, NnError> {
        check_len("row adam first moment", steps.len() * row_len, m.len())?;
        check_len("row adam second moment", m.len(), v.len())?;
        Ok(Self {
            config,
            row_len,
            column_rates: None,
            m,
            v,
            steps,
        })
    }

    /// The same optimiser with a learning rate per column (one per value of a row, e.g. a slower
    /// rate for a pose's root than for its joints), in place of `config.lr`.
    pub fn with_column_rates(mut self, rates: Vec<f64>) -> Result<Self, NnError> {
        check_len("row adam column rates", self.row_len, rates.len())?;
        self.column_rates = Some(rates);
        Ok(self)
    }

    /// First and second moments (for checkpoints).
    pub fn moments(&self) -> (&[T], &[T]) {
        (&self.m, &self.v)
    }

    /// Steps taken by each row so far.
    pub fn row_steps(&self) -> &[u64] {
        &self.steps
    }

    /// One update of the rows `rows` of `params` with their rows of `grads` (both the full matrix);
    /// a row named twice is updated once.
    pub fn step_rows(
        &mut self,
        params: &mut [T],
        grads: &[T],
        rows: &[usize],
    ) -> Result<(), NnError> {
        self.step_rows_scaled(params, grads, rows, 1.0)
    }

    /// [`RowAdam::step_rows`] with every column's rate multiplied by `rate_scale` (a schedule's
    /// factor; 1 gives `step_rows`' bits).
    pub fn step_rows_scaled(
        &mut self,
        params: &mut [T],
        grads: &[T],
        rows: &[usize],
        rate_scale: f64,
    ) -> Result<(), NnError> {
        self.step_rows_column_scaled(params, grads, rows, |_| rate_scale)
    }

    /// [`RowAdam::step_rows`] with column `j`'s rate multiplied by `column_scale(j)` (schedules
    /// that differ between parts of a row; a constant gives [`RowAdam::step_rows_scaled`]' bits).
    pub fn step_rows_column_scaled(
        &mut self,
        params: &mut [T],
        grads: &[T],
        rows: &[usize],
        column_scale: impl Fn(usize) -> f64,
    ) -> Result<(), NnError> {
        check_len("row adam params", self.m.len(), params.len())?;
        check_len("row adam grads", self.m.len(), grads.len())?;
        let mut done: Vec<usize> = Vec::with_capacity(rows.len());
        for &row in rows {
            if done.contains(&row) {
                continue;
            }
            if row >= self.steps.len() {
                return Err(NnError::Shape(format!(
                    "row adam: row {row} of {} rows",
                    self.steps.len()
                )));
            }
            done.push(row);
            self.steps[row] += 1;
            let span = row * self.row_len..(row + 1) * self.row_len;
            let c = self.config;
            let rates = &self.column_rates;
            adam_update(
                &mut params[span.clone()],
                &grads[span.clone()],
                &mut self.m[span.clone()],
                &mut self.v[span],
                self.steps[row],
                c.beta1,
                c.beta2,
                c.eps,
                self.row_len,
                |j| T::of(rates.as_ref().map_or(c.lr, |r| r[j]) * column_scale(j)),
            )?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn row_adam_moves_only_the_rows_it_is_given_and_matches_a_dense_adam_per_row() {
        let config = AdamConfig {
            lr: 0.1,
            ..AdamConfig::default()
        };
        let mut rows = RowAdam::<f64>::new(3, 2, config);
        let mut params = vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0];
        let grads = vec![0.5, -1.0, 9.0, 9.0, -0.25, 2.0];
        // Row 0 twice, row 2 once; row 1 never (its non-zero gradient is ignored).
        rows.step_rows(&mut params, &grads, &[0, 0]).unwrap();
        rows.step_rows(&mut params, &grads, &[2]).unwrap();
        rows.step_rows(&mut params, &grads, &[0]).unwrap();
        assert_eq!(rows.row_steps(), &[2, 0, 1]);
        assert_eq!(&params[2..4], &[3.0, 4.0]);
        // Row 0 took two dense steps of its own, row 2 one.
        let mut dense0 = Adam::<f64>::new(2, config);
        let mut p0 = vec![1.0, 2.0];
        dense0.step(&mut p0, &grads[0..2]).unwrap();
        dense0.step(&mut p0, &grads[0..2]).unwrap();
        assert_eq!(&params[0..2], p0.as_slice());
        let mut dense2 = Adam::<f64>::new(2, config);
        let mut p2 = vec![5.0, 6.0];
        dense2.step(&mut p2, &grads[4..6]).unwrap();
        assert_eq!(&params[4..6], p2.as_slice());
        assert!(rows.step_rows(&mut params, &grads, &[3]).is_err());
        let (m, v) = rows.moments();
        let back =
            RowAdam::from_parts(config, 2, m.to_vec(), v.to_vec(), rows.row_steps().to_vec());
        assert!(back.is_ok());
        assert!(
            RowAdam::<f64>::from_parts(config, 2, vec![0.0; 5], vec![0.0; 5], vec![0; 3]).is_err()
        );
    }
}
