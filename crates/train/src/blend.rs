//! The semantic blend of E-Sem3DGS (paper §4.2): each Gaussian's posed attributes are a mix, weighted by
//! its human probability p, of its deformed (human) attributes and its static (scene) attributes, so the
//! rendering loss reaches the semantic logits.
//!
//! Exact definition (per Gaussian, p ∈ [0, 1]):
//! - position   x = p·x_def + (1 − p)·x_static
//! - covariance Σ = p·Σ_def + (1 − p)·Σ_static (a convex combination of positive semi-definite
//!   matrices stays positive semi-definite; the deformed covariance is M·diag(e^{2s})·Mᵀ with M the
//!   skinning-blended rotation, which is not a rotation, so blending covariances — not quaternions —
//!   is the exact, well-defined choice)
//! - colour     c = p·c_human + (1 − p)·c_scene.
//!
//! Once p is near 0 or 1, which the semantic logits are initialised to (±3) and trained towards, the
//! blend is exactly the static or the deformed Gaussian.
//!
//! The probability comes from the semantic mode (`--semantic`): `OneHot` p = softmax(l)[1] over K = 2
//! logits (paper), `Scalar` p = sigmoid(l) of a single logit, `None` p = 1 for every Gaussian
//! (everything is deformed, as in 3DGS-Avatar).

use num_traits::Float;

/// How a Gaussian's human probability is parameterised (`--semantic`).
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize, clap::ValueEnum,
)]
#[serde(rename_all = "kebab-case")]
pub enum SemanticMode {
    /// Two logits (scene, human); p = softmax(l)[1] (the paper's one-hot semantics).
    OneHot,
    /// One logit; p = sigmoid(l).
    Scalar,
    /// No semantics: p = 1 (every Gaussian deformed).
    None,
}

impl SemanticMode {
    /// Number of stored logits per Gaussian.
    pub fn logits_per_gaussian(self) -> usize {
        match self {
            Self::OneHot => 2,
            Self::Scalar => 1,
            Self::None => 0,
        }
    }

    /// Human probability from the Gaussian's logits.
    pub fn probability<T: Float>(self, logits: &[T]) -> T {
        match self {
            Self::OneHot => sigmoid(logits[1] - logits[0]),
            Self::Scalar => sigmoid(logits[0]),
            Self::None => T::one(),
        }
    }

    /// Adds dL/dlogits given dL/dp into `d_logits`.
    pub fn probability_backward<T: Float>(self, logits: &[T], d_p: T, d_logits: &mut [T]) {
        match self {
            Self::OneHot => {
                let p = sigmoid(logits[1] - logits[0]);
                let g = d_p * p * (T::one() - p);
                d_logits[1] = d_logits[1] + g;
                d_logits[0] = d_logits[0] - g;
            }
            Self::Scalar => {
                let p = sigmoid(logits[0]);
                d_logits[0] = d_logits[0] + d_p * p * (T::one() - p);
            }
            Self::None => {}
        }
    }
}

#[inline]
fn sigmoid<T: Float>(x: T) -> T {
    T::one() / (T::one() + (-x).exp())
}

/// Deformed (human) and static (scene) attributes of one Gaussian, and its colour under each.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BlendInputs<T> {
    /// Deformed position (m).
    pub x_def: [T; 3],
    /// Static position (m).
    pub x_static: [T; 3],
    /// Deformed covariance (m²), rows.
    pub cov_def: [[T; 3]; 3],
    /// Static covariance (m²), rows.
    pub cov_static: [[T; 3]; 3],
    /// Human colour (linear RGB).
    pub c_human: [T; 3],
    /// Scene colour (linear RGB).
    pub c_scene: [T; 3],
}

/// Blended attributes of one Gaussian.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Blended<T> {
    /// Position (m).
    pub x: [T; 3],
    /// Covariance (m²), rows.
    pub cov: [[T; 3]; 3],
    /// Colour (linear RGB).
    pub c: [T; 3],
}

/// Blends one Gaussian's attributes with human probability `p` (see the module docs).
pub fn blend<T: Float>(p: T, a: &BlendInputs<T>) -> Blended<T> {
    let one_m = T::one() - p;
    Blended {
        x: std::array::from_fn(|k| p * a.x_def[k] + one_m * a.x_static[k]),
        cov: std::array::from_fn(|r| {
            std::array::from_fn(|c| p * a.cov_def[r][c] + one_m * a.cov_static[r][c])
        }),
        c: std::array::from_fn(|k| p * a.c_human[k] + one_m * a.c_scene[k]),
    }
}

/// Backward of [`blend`]: given dL/d(blended), returns (dL/dp, dL/d(inputs)).
pub fn blend_backward<T: Float>(p: T, a: &BlendInputs<T>, d: &Blended<T>) -> (T, BlendInputs<T>) {
    let one_m = T::one() - p;
    let mut d_p = T::zero();
    for k in 0..3 {
        d_p = d_p + d.x[k] * (a.x_def[k] - a.x_static[k]) + d.c[k] * (a.c_human[k] - a.c_scene[k]);
        for c in 0..3 {
            d_p = d_p + d.cov[k][c] * (a.cov_def[k][c] - a.cov_static[k][c]);
        }
    }
    let grads = BlendInputs {
        x_def: d.x.map(|g| g * p),
        x_static: d.x.map(|g| g * one_m),
        cov_def: d.cov.map(|row| row.map(|g| g * p)),
        cov_static: d.cov.map(|row| row.map(|g| g * one_m)),
        c_human: d.c.map(|g| g * p),
        c_scene: d.c.map(|g| g * one_m),
    };
    (d_p, grads)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn extreme_probabilities_select_one_side() {
        let eye = [[1.0f64, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        let a = BlendInputs {
            x_def: [1.0f64, 2.0, 3.0],
            x_static: [4.0, 5.0, 6.0],
            cov_def: eye,
            cov_static: eye.map(|r| r.map(|v| 2.0 * v)),
            c_human: [1.0, 0.0, 0.0],
            c_scene: [0.0, 0.0, 1.0],
        };
        let human = blend(1.0, &a);
        assert_eq!(human.x, a.x_def);
        assert_eq!(human.cov, a.cov_def);
        let scene = blend(0.0, &a);
        assert_eq!(scene.c, a.c_scene);
        assert_eq!(blend(0.5, &a).cov[1][1], 1.5);
        assert_eq!(SemanticMode::None.probability::<f64>(&[]), 1.0);
        assert!((SemanticMode::OneHot.probability(&[-3.0f64, 3.0]) - 0.997_527_376).abs() < 1e-8);
    }
}
