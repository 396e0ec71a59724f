//! The Gaussian parameter set as structure-of-arrays, in stored (pre-activation) form.
//!
//! One `Vec` per attribute, all indexed by Gaussian. Appearance is SH coefficients of degree 0–3
//! (coefficient-major per Gaussian, see [`crate::sh`]); a set may also carry a free per-Gaussian feature
//! vector (decoded by a network upstream) and K raw semantic logits. Row operations (select, retain,
//! append) act on every attribute at once so arrays can never fall out of alignment; the same
//! operations exist for optimiser state in [`crate::adam`].

use crate::sh::num_sh_coeffs;
use crate::GaussianError;

/// Per-Gaussian parameters of N Gaussians, stored pre-activation as in the INRIA 3DGS PLY layout.
#[derive(Clone, Debug, PartialEq)]
pub struct GaussianSet {
    /// Centres in world (or canonical) space, metres.
    pub means: Vec<[f32; 3]>,
    /// Natural log of the three axis scales (metres).
    pub log_scales: Vec<[f32; 3]>,
    /// Rotations as unnormalised (w, x, y, z) quaternions, normalised on use.
    pub quats: Vec<[f32; 4]>,
    /// Opacity logits: opacity = sigmoid(logit).
    pub opacity_logits: Vec<f32>,
    /// SH degree (0..=3) of `sh`.
    pub sh_degree: usize,
    /// SH coefficients, N × K × 3 flattened: `sh[(i * K + k) * 3 + c]`, K = (sh_degree + 1)².
    pub sh: Vec<f32>,
    /// Length of the per-Gaussian feature vector (0 when the set has none).
    pub feature_dim: usize,
    /// Per-Gaussian features, N × `feature_dim` flattened.
    pub features: Vec<f32>,
    /// Number of semantic classes K (0 when the set has none; 2 in E-Sem3DGS: 0 = scene, 1 = human).
    pub semantic_classes: usize,
    /// Raw semantic logits, N × `semantic_classes` flattened.
    pub semantic_logits: Vec<f32>,
}

impl GaussianSet {
    /// An empty set with the given SH degree, feature length and number of semantic classes.
    pub fn new(sh_degree: usize, feature_dim: usize, semantic_classes: usize) -> Self {
        Self {
            means: Vec::new(),
            log_scales: Vec::new(),
            quats: Vec::new(),
            opacity_logits: Vec::new(),
            sh_degree,
            sh: Vec::new(),
            feature_dim,
            features: Vec::new(),
            semantic_classes,
            semantic_logits: Vec::new(),
        }
    }

    /// A set of `n` Gaussians with every parameter zero (handy as a gradient accumulator).
    pub fn zeros(n: usize, sh_degree: usize, feature_dim: usize, semantic_classes: usize) -> Self {
        Self {
            means: vec![[0.0; 3]; n],
            log_scales: vec![[0.0; 3]; n],
            quats: vec![[0.0; 4]; n],
            opacity_logits: vec![0.0; n],
            sh_degree,
            sh: vec![0.0; n * num_sh_coeffs(sh_degree) * 3],
            feature_dim,
            features: vec![0.0; n * feature_dim],
            semantic_classes,
            semantic_logits: vec![0.0; n * semantic_classes],
        }
    }

    /// A zero set with the same shapes as `self` (a gradient buffer).
    pub fn zeros_like(&self) -> Self {
        Self::zeros(
            self.len(),
            self.sh_degree,
            self.feature_dim,
            self.semantic_classes,
        )
    }

    /// Number of Gaussians.
    pub fn len(&self) -> usize {
        self.means.len()
    }

    /// True when the set holds no Gaussian.
    pub fn is_empty(&self) -> bool {
        self.means.is_empty()
    }

    /// SH coefficients per channel, K = (sh_degree + 1)².
    pub fn sh_coeffs_per_channel(&self) -> usize {
        num_sh_coeffs(self.sh_degree)
    }

    /// SH coefficients of Gaussian `i` (K × 3, coefficient-major).
    pub fn sh_of(&self, i: usize) -> &[f32] {
        let stride = self.sh_coeffs_per_channel() * 3;
        &self.sh[i * stride..(i + 1) * stride]
    }

    /// Opacity of Gaussian `i` in [0, 1] (sigmoid of the logit).
    pub fn opacity(&self, i: usize) -> f32 {
        sigmoid(self.opacity_logits[i])
    }

    /// Axis scales of Gaussian `i` in metres (exp of the log-scales).
    pub fn scales(&self, i: usize) -> [f32; 3] {
        self.log_scales[i].map(f32::exp)
    }

    /// Semantic probabilities of Gaussian `i` (softmax of its logits) into `out[..K]`.
    pub fn semantic_probabilities(&self, i: usize, out: &mut [f32]) {
        let k = self.semantic_classes;
        softmax(&self.semantic_logits[i * k..(i + 1) * k], &mut out[..k]);
    }

    /// Appends one Gaussian. `sh`, `features` and `semantic_logits` must have this set's per-Gaussian
    /// lengths.
    pub fn push(
        &mut self,
        mean: [f32; 3],
        log_scale: [f32; 3],
        quat: [f32; 4],
        opacity_logit: f32,
        sh: &[f32],
        features: &[f32],
        semantic_logits: &[f32],
    ) -> Result<(), GaussianError> {
        let sh_len = self.sh_coeffs_per_channel() * 3;
        for (name, got, want) in [
            ("sh", sh.len(), sh_len),
            ("features", features.len(), self.feature_dim),
            (
                "semantic_logits",
                semantic_logits.len(),
                self.semantic_classes,
            ),
        ] {
            if got != want {
                return Err(GaussianError::Shape {
                    field: name.to_string(),
                    expected: want,
                    found: got,
                });
            }
        }
        self.means.push(mean);
        self.log_scales.push(log_scale);
        self.quats.push(quat);
        self.opacity_logits.push(opacity_logit);
        self.sh.extend_from_slice(sh);
        self.features.extend_from_slice(features);
        self.semantic_logits.extend_from_slice(semantic_logits);
        Ok(())
    }

    /// Checks that every attribute has N rows, the SH degree is supported, every value is finite and no
    /// quaternion is zero. Errors name the field and the first offending Gaussian.
    pub fn validate(&self) -> Result<(), GaussianError> {
        let n = self.len();
        if self.sh_degree > crate::sh::MAX_SH_DEGREE {
            return Err(GaussianError::ShDegree(self.sh_degree));
        }
        let shapes = [
            ("log_scales", self.log_scales.len(), n),
            ("quats", self.quats.len(), n),
            ("opacity_logits", self.opacity_logits.len(), n),
            ("sh", self.sh.len(), n * self.sh_coeffs_per_channel() * 3),
            ("features", self.features.len(), n * self.feature_dim),
            (
                "semantic_logits",
                self.semantic_logits.len(),
                n * self.semantic_classes,
            ),
        ];
        for (field, found, expected) in shapes {
            if found != expected {
                return Err(GaussianError::Shape {
                    field: field.to_string(),
                    expected,
                    found,
                });
            }
        }
        let check = |field: &str, values: &[f32], stride: usize| -> Result<(), GaussianError> {
            match values.iter().position(|v| !v.is_finite()) {
                Some(p) => Err(GaussianError::NonFinite {
                    field: field.to_string(),
                    index: p / stride.max(1),
                }),
                None => Ok(()),
            }
        };
        check("means", self.means.as_flattened(), 3)?;
        check("log_scales", self.log_scales.as_flattened(), 3)?;
        check("quats", self.quats.as_flattened(), 4)?;
        check("opacity_logits", &self.opacity_logits, 1)?;
        check("sh", &self.sh, self.sh_coeffs_per_channel() * 3)?;
        check("features", &self.features, self.feature_dim)?;
        check(
            "semantic_logits",
            &self.semantic_logits,
            self.semantic_classes,
        )?;
        if let Some(i) = self.quats.iter().position(|q| q.iter().all(|&v| v == 0.0)) {
            return Err(GaussianError::ZeroQuaternion { index: i });
        }
        Ok(())
    }

    /// A new set made of the rows `indices` (in that order; repeats allowed).
    pub fn select(&self, indices: &[usize]) -> Self {
        Self {
            means: gather_rows(&self.means, 1, indices),
            log_scales: gather_rows(&self.log_scales, 1, indices),
            quats: gather_rows(&self.quats, 1, indices),
            opacity_logits: gather_rows(&self.opacity_logits, 1, indices),
            sh_degree: self.sh_degree,
            sh: gather_rows(&self.sh, self.sh_coeffs_per_channel() * 3, indices),
            feature_dim: self.feature_dim,
            features: gather_rows(&self.features, self.feature_dim, indices),
            semantic_classes: self.semantic_classes,
            semantic_logits: gather_rows(&self.semantic_logits, self.semantic_classes, indices),
        }
    }

    /// Keeps the Gaussians whose `keep` flag is true, in order. `keep.len()` must equal `len()`.
    pub fn retain(&mut self, keep: &[bool]) {
        assert_eq!(keep.len(), self.len(), "retain mask length");
        let sh_stride = self.sh_coeffs_per_channel() * 3;
        retain_rows(&mut self.means, 1, keep);
        retain_rows(&mut self.log_scales, 1, keep);
        retain_rows(&mut self.quats, 1, keep);
        retain_rows(&mut self.opacity_logits, 1, keep);
        retain_rows(&mut self.sh, sh_stride, keep);
        retain_rows(&mut self.features, self.feature_dim, keep);
        retain_rows(&mut self.semantic_logits, self.semantic_classes, keep);
    }

    /// Appends all Gaussians of `other`, which must have the same SH degree, feature length and number
    /// of semantic classes.
    pub fn append(&mut self, other: &GaussianSet) -> Result<(), GaussianError> {
        if other.sh_degree != self.sh_degree
            || other.feature_dim != self.feature_dim
            || other.semantic_classes != self.semantic_classes
        {
            return Err(GaussianError::Incompatible(format!(
                "cannot append a set with (sh degree {}, features {}, classes {}) to one with ({}, {}, {})",
                other.sh_degree,
                other.feature_dim,
                other.semantic_classes,
                self.sh_degree,
                self.feature_dim,
                self.semantic_classes
            )));
        }
        self.means.extend_from_slice(&other.means);
        self.log_scales.extend_from_slice(&other.log_scales);
        self.quats.extend_from_slice(&other.quats);
        self.opacity_logits.extend_from_slice(&other.opacity_logits);
        self.sh.extend_from_slice(&other.sh);
        self.features.extend_from_slice(&other.features);
        self.semantic_logits
            .extend_from_slice(&other.semantic_logits);
        Ok(())
    }
}

/// Gathers rows of `stride` elements at `indices` from a flat array.
pub fn gather_rows<T: Copy>(values: &[T], stride: usize, indices: &[usize]) -> Vec<T> {
    let mut out = Vec::with_capacity(indices.len() * stride);
    for &i in indices {
        out.extend_from_slice(&values[i * stride..(i + 1) * stride]);
    }
    out
}

/// Keeps the rows of `stride` elements whose flag is set, in order, in place.
pub fn retain_rows<T: Copy>(values: &mut Vec<T>, stride: usize, keep: &[bool]) {
    if stride == 0 {
        return;
    }
    let mut write = 0;
    for (row, &k) in keep.iter().enumerate() {
        if k {
            if write != row {
                values.copy_within(row * stride..(row + 1) * stride, write * stride);
            }
            write += 1;
        }
    }
    values.truncate(write * stride);
}

/// Logistic sigmoid 1 / (1 + e^(−x)).
#[inline]
pub fn sigmoid(x: f32) -> f32 {
    1.0 / (1.0 + (-x).exp())
}

/// Inverse of [`sigmoid`] for p in (0, 1): ln(p / (1 − p)).
#[inline]
pub fn inverse_sigmoid(p: f32) -> f32 {
    (p / (1.0 - p)).ln()
}

/// Numerically stable softmax of `logits` into `out` (same length).
pub fn softmax(logits: &[f32], out: &mut [f32]) {
    let max = logits.iter().copied().fold(f32::NEG_INFINITY, f32::max);
    let mut sum = 0.0;
    for (o, &l) in out.iter_mut().zip(logits) {
        *o = (l - max).exp();
        sum += *o;
    }
    for o in out.iter_mut() {
        *o /= sum;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(n: usize) -> GaussianSet {
        let mut s = GaussianSet::new(1, 2, 2);
        for i in 0..n {
            let f = i as f32;
            s.push(
                [f, f + 0.1, f + 0.2],
                [-f, -f, -f],
                [1.0, f, 0.0, 0.0],
                f * 0.5,
                &[f; 12],
                &[f, -f],
                &[f, 2.0 * f],
            )
            .unwrap();
        }
        s
    }

    #[test]
    fn retain_and_select_keep_rows_aligned() {
        let mut s = sample(5);
        let picked = s.select(&[1, 3]);
        s.retain(&[false, true, false, true, false]);
        assert_eq!(s, picked);
        assert_eq!(s.means[1], [3.0, 3.1, 3.2]);
        assert_eq!(s.sh_of(1), &[3.0; 12]);
        assert_eq!(s.features, vec![1.0, -1.0, 3.0, -3.0]);
        assert_eq!(s.semantic_logits, vec![1.0, 2.0, 3.0, 6.0]);
        s.validate().unwrap();
    }

    #[test]
    fn validate_rejects_zero_quaternions_and_nan() {
        let mut s = sample(3);
        s.quats[2] = [0.0; 4];
        assert!(matches!(
            s.validate(),
            Err(GaussianError::ZeroQuaternion { index: 2 })
        ));
        let mut s = sample(3);
        s.sh[13] = f32::NAN;
        assert!(matches!(
            s.validate(),
            Err(GaussianError::NonFinite { index: 1, .. })
        ));
    }

    #[test]
    fn push_rejects_wrong_lengths() {
        let mut s = GaussianSet::new(0, 0, 2);
        let err = s.push(
            [0.0; 3],
            [0.0; 3],
            [1.0, 0.0, 0.0, 0.0],
            0.0,
            &[0.0; 3],
            &[],
            &[1.0],
        );
        assert!(matches!(
            err,
            Err(GaussianError::Shape {
                expected: 2,
                found: 1,
                ..
            })
        ));
    }

    #[test]
    fn softmax_and_sigmoid_are_consistent() {
        let mut p = [0.0; 2];
        softmax(&[-3.0, 3.0], &mut p);
        assert!((p[1] - sigmoid(6.0)).abs() < 1e-6);
        assert!((inverse_sigmoid(sigmoid(0.7)) - 0.7).abs() < 1e-5);
    }
}
