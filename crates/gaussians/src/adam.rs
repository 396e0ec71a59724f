//! Adam with PyTorch's update rule, for flat parameter slices and for whole Gaussian sets with one
//! learning rate per parameter group (the 3DGS optimiser).
//!
//! The moments live beside the parameters they belong to and support the same row operations as
//! [`GaussianSet`] (retain, append zero rows, reset), so density control can never misalign them.
//! The update rule itself is `nn::adam_update` (one Adam for the whole workspace); updates are
//! element-wise and sequential: bit-identical whatever the thread count.

use crate::set::{gather_rows, retain_rows, GaussianSet};
use crate::GaussianError;

/// Adam hyper-parameters shared by every group.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AdamConfig {
    /// Exponential decay of the first moment.
    pub beta1: f32,
    /// Exponential decay of the second moment.
    pub beta2: f32,
    /// Denominator epsilon; 1e-15 in the 3DGS code (a deliberately tiny value).
    pub eps: f32,
}

impl Default for AdamConfig {
    /// The 3DGS settings: β = (0.9, 0.999), ε = 1e-15.
    fn default() -> Self {
        Self {
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-15,
        }
    }
}

/// First/second moments and step count of one parameter group (a flat array of `m.len()` values).
#[derive(Clone, Debug, PartialEq, Default)]
pub struct AdamState {
    /// First moment, one per parameter.
    pub m: Vec<f32>,
    /// Second moment, one per parameter.
    pub v: Vec<f32>,
    /// Number of steps taken (for bias correction).
    pub step: u64,
}

impl AdamState {
    /// Zero moments for `len` parameters.
    pub fn new(len: usize) -> Self {
        Self {
            m: vec![0.0; len],
            v: vec![0.0; len],
            step: 0,
        }
    }

    /// One Adam step with a single learning rate: `p -= lr/(1−β1ᵗ) · m / (√v/√(1−β2ᵗ) + ε)`.
    pub fn step(
        &mut self,
        config: &AdamConfig,
        lr: f32,
        params: &mut [f32],
        grads: &[f32],
    ) -> Result<(), GaussianError> {
        self.step_with_lr(config, params, grads, 1, |_| lr)
    }

    /// One Adam step where parameter `j` uses learning rate `lr_of_column(j % row_stride)` (e.g. SH DC
    /// and higher-order coefficients of one Gaussian with different rates).
    pub fn step_with_lr(
        &mut self,
        config: &AdamConfig,
        params: &mut [f32],
        grads: &[f32],
        row_stride: usize,
        lr_of_column: impl Fn(usize) -> f32,
    ) -> Result<(), GaussianError> {
        if params.len() != self.m.len() || grads.len() != self.m.len() {
            return Err(GaussianError::Incompatible(format!(
                "Adam state has {} values, parameters {}, gradients {}",
                self.m.len(),
                params.len(),
                grads.len()
            )));
        }
        self.step += 1;
        nn::adam_update(
            params,
            grads,
            &mut self.m,
            &mut self.v,
            self.step,
            f64::from(config.beta1),
            f64::from(config.beta2),
            f64::from(config.eps),
            row_stride,
            lr_of_column,
        )
        .map_err(|e| GaussianError::Incompatible(e.to_string()))
    }

    /// Keeps rows of `stride` values whose flag is set.
    pub fn retain_rows(&mut self, stride: usize, keep: &[bool]) {
        retain_rows(&mut self.m, stride, keep);
        retain_rows(&mut self.v, stride, keep);
    }

    /// Appends `rows` rows of `stride` zero moments (new parameters start with fresh moments, as in 3DGS).
    pub fn append_zero_rows(&mut self, stride: usize, rows: usize) {
        self.m.resize(self.m.len() + stride * rows, 0.0);
        self.v.resize(self.v.len() + stride * rows, 0.0);
    }

    /// Moments of the rows `indices` (for copying state along with parameters).
    pub fn gather_rows(&self, stride: usize, indices: &[usize]) -> Self {
        Self {
            m: gather_rows(&self.m, stride, indices),
            v: gather_rows(&self.v, stride, indices),
            step: self.step,
        }
    }

    /// Sets every moment to zero (keeps the step count, as the 3DGS optimiser does on a reset).
    pub fn reset(&mut self) {
        self.m.iter_mut().for_each(|x| *x = 0.0);
        self.v.iter_mut().for_each(|x| *x = 0.0);
    }
}

/// Learning rates of the 3DGS parameter groups (per step; the caller applies schedules).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GaussianLearningRates {
    /// Means (m/step); 3DGS uses 1.6e-4 × scene extent, decayed by the caller.
    pub means: f32,
    /// Log-scales.
    pub log_scales: f32,
    /// Quaternions.
    pub quats: f32,
    /// Opacity logits.
    pub opacity_logits: f32,
    /// SH DC coefficients.
    pub sh_dc: f32,
    /// Higher-order SH coefficients (3DGS: DC rate / 20).
    pub sh_rest: f32,
    /// Per-Gaussian features.
    pub features: f32,
    /// Semantic logits.
    pub semantic_logits: f32,
}

impl Default for GaussianLearningRates {
    /// The INRIA 3DGS / 3DGS-Avatar rates for a unit scene extent; the semantic-logit rate (not given by
    /// either) is this project's choice.
    fn default() -> Self {
        Self {
            means: 1.6e-4,
            log_scales: 5e-3,
            quats: 1e-3,
            opacity_logits: 5e-2,
            sh_dc: 2.5e-3,
            sh_rest: 2.5e-3 / 20.0,
            features: 1e-3,
            semantic_logits: 1e-2,
        }
    }
}

/// Adam state for every parameter group of a [`GaussianSet`], kept row-aligned with it.
#[derive(Clone, Debug, PartialEq)]
pub struct GaussianAdam {
    /// Shared hyper-parameters.
    pub config: AdamConfig,
    /// Moments of the means (3 per Gaussian).
    pub means: AdamState,
    /// Moments of the log-scales (3 per Gaussian).
    pub log_scales: AdamState,
    /// Moments of the quaternions (4 per Gaussian).
    pub quats: AdamState,
    /// Moments of the opacity logits (1 per Gaussian).
    pub opacity_logits: AdamState,
    /// Moments of the SH coefficients (K × 3 per Gaussian).
    pub sh: AdamState,
    /// Moments of the features.
    pub features: AdamState,
    /// Moments of the semantic logits.
    pub semantic_logits: AdamState,
}

impl GaussianAdam {
    /// Fresh (zero) state shaped like `set`.
    pub fn new(set: &GaussianSet, config: AdamConfig) -> Self {
        Self {
            config,
            means: AdamState::new(set.len() * 3),
            log_scales: AdamState::new(set.len() * 3),
            quats: AdamState::new(set.len() * 4),
            opacity_logits: AdamState::new(set.len()),
            sh: AdamState::new(set.sh.len()),
            features: AdamState::new(set.features.len()),
            semantic_logits: AdamState::new(set.semantic_logits.len()),
        }
    }

    /// Number of Gaussians the state is shaped for.
    pub fn len(&self) -> usize {
        self.opacity_logits.m.len()
    }

    /// True when shaped for zero Gaussians.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// One Adam step on every group of `set` with gradients `grads` (shaped like `set`).
    pub fn step(
        &mut self,
        set: &mut GaussianSet,
        grads: &GaussianSet,
        lr: &GaussianLearningRates,
    ) -> Result<(), GaussianError> {
        if grads.len() != set.len() || self.len() != set.len() {
            return Err(GaussianError::Incompatible(format!(
                "set has {} Gaussians, gradients {}, Adam state {}",
                set.len(),
                grads.len(),
                self.len()
            )));
        }
        let c = self.config;
        self.means.step(
            &c,
            lr.means,
            set.means.as_flattened_mut(),
            grads.means.as_flattened(),
        )?;
        self.log_scales.step(
            &c,
            lr.log_scales,
            set.log_scales.as_flattened_mut(),
            grads.log_scales.as_flattened(),
        )?;
        self.quats.step(
            &c,
            lr.quats,
            set.quats.as_flattened_mut(),
            grads.quats.as_flattened(),
        )?;
        self.opacity_logits.step(
            &c,
            lr.opacity_logits,
            &mut set.opacity_logits,
            &grads.opacity_logits,
        )?;
        let sh_stride = set.sh_coeffs_per_channel() * 3;
        self.sh
            .step_with_lr(&c, &mut set.sh, &grads.sh, sh_stride, |col| {
                if col < 3 {
                    lr.sh_dc
                } else {
                    lr.sh_rest
                }
            })?;
        self.features
            .step(&c, lr.features, &mut set.features, &grads.features)?;
        self.semantic_logits.step(
            &c,
            lr.semantic_logits,
            &mut set.semantic_logits,
            &grads.semantic_logits,
        )?;
        Ok(())
    }

    fn strides(set_like: &GaussianSet) -> [usize; 7] {
        [
            3,
            3,
            4,
            1,
            set_like.sh_coeffs_per_channel() * 3,
            set_like.feature_dim,
            set_like.semantic_classes,
        ]
    }

    fn groups_mut(&mut self) -> [&mut AdamState; 7] {
        [
            &mut self.means,
            &mut self.log_scales,
            &mut self.quats,
            &mut self.opacity_logits,
            &mut self.sh,
            &mut self.features,
            &mut self.semantic_logits,
        ]
    }

    /// Keeps the rows whose flag is set; `shape` is the set (only its shape is read).
    pub fn retain(&mut self, shape: &GaussianSet, keep: &[bool]) {
        let strides = Self::strides(shape);
        for (g, s) in self.groups_mut().into_iter().zip(strides) {
            g.retain_rows(s, keep);
        }
    }

    /// Appends zero moments for `rows` new Gaussians shaped like `shape`.
    pub fn append_zero_rows(&mut self, shape: &GaussianSet, rows: usize) {
        let strides = Self::strides(shape);
        for (g, s) in self.groups_mut().into_iter().zip(strides) {
            g.append_zero_rows(s, rows);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn first_adam_step_moves_by_lr_against_the_gradient_sign() {
        // With bias correction, the first step is lr · g/|g| (up to ε).
        let mut p = vec![1.0f32, -2.0, 0.5];
        let g = [0.3f32, -4.0, 0.0];
        let mut s = AdamState::new(3);
        s.step(&AdamConfig::default(), 0.1, &mut p, &g).unwrap();
        assert!((p[0] - 0.9).abs() < 1e-6);
        assert!((p[1] - (-1.9)).abs() < 1e-6);
        assert_eq!(p[2], 0.5);
    }

    #[test]
    fn adam_minimises_a_quadratic() {
        let mut p = vec![3.0f32, -2.0];
        let mut s = AdamState::new(2);
        for _ in 0..2000 {
            let g: Vec<f32> = p.iter().map(|x| 2.0 * (x - 1.0)).collect();
            s.step(&AdamConfig::default(), 0.01, &mut p, &g).unwrap();
        }
        assert!(p.iter().all(|x| (x - 1.0).abs() < 1e-2), "{p:?}");
    }

    #[test]
    fn mismatched_lengths_are_an_error() {
        let mut s = AdamState::new(2);
        let err = s.step(&AdamConfig::default(), 0.1, &mut [0.0; 3], &[0.0; 3]);
        assert!(matches!(err, Err(GaussianError::Incompatible(_))));
    }
}
