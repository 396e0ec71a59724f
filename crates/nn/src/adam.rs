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
        let (b1, b2) = (T::of(c.beta1), T::of(c.beta2));
        let bc1 = T::of(1.0 - c.beta1.powi(self.t as i32));
        let bc2 = T::of(1.0 - c.beta2.powi(self.t as i32));
        let (lr, eps) = (T::of(c.lr), T::of(c.eps));
        for i in 0..params.len() {
            let g = grads[i];
            self.m[i] = b1 * self.m[i] + (T::one() - b1) * g;
            self.v[i] = b2 * self.v[i] + (T::one() - b2) * g * g;
            let mh = self.m[i] / bc1;
            let vh = self.v[i] / bc2;
            params[i] = params[i] - lr * mh / (vh.sqrt() + eps);
        }
        Ok(())
    }
}
