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
//!
//! With several people (`OneHot` only) a Gaussian has K = 1 + P logits, class 0 the scene and class
//! j the person j − 1 ([`SemanticMode::logits_for`]): its human probability is p = 1 − softmax(l)[0]
//! (the sum of the people's), each person's own probability softmax(l)[j] is rendered as that
//! person's mask ([`person_probabilities`]), and its human branch is deformed by its most probable
//! person ([`most_probable_person`]; locally constant, so it adds no gradient).

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
    /// Number of stored logits per Gaussian with one person.
    pub fn logits_per_gaussian(self) -> usize {
        self.logits_for(1)
    }

    /// Number of stored logits per Gaussian of a model of `people` people: K = 1 + `people` for
    /// `OneHot` (the scene, then each person), else as with one person (only `OneHot` tells people
    /// apart).
    pub fn logits_for(self, people: usize) -> usize {
        match self {
            Self::OneHot => 1 + people.max(1),
            Self::Scalar => 1,
            Self::None => 0,
        }
    }

    /// Human probability from the Gaussian's logits (with K > 2 one-hot logits: 1 − softmax(l)[0]).
    pub fn probability<T: Float>(self, logits: &[T]) -> T {
        match self {
            Self::OneHot if logits.len() > 2 => T::one() - class_probability(logits, 0),
            Self::OneHot => sigmoid(logits[1] - logits[0]),
            Self::Scalar => sigmoid(logits[0]),
            Self::None => T::one(),
        }
    }

    /// Adds dL/dlogits given dL/dp into `d_logits`.
    pub fn probability_backward<T: Float>(self, logits: &[T], d_p: T, d_logits: &mut [T]) {
        match self {
            Self::OneHot if logits.len() > 2 => {
                // p = 1 − s₀: ∂p/∂l₀ = −s₀(1 − s₀), ∂p/∂l_k = s₀ s_k (k ≥ 1).
                let (m, sum) = softmax_norm(logits);
                let s0 = (logits[0] - m).exp() / sum;
                d_logits[0] = d_logits[0] - d_p * s0 * (T::one() - s0);
                for k in 1..logits.len() {
                    d_logits[k] = d_logits[k] + d_p * s0 * ((logits[k] - m).exp() / sum);
                }
            }
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

/// The softmax's shift and normaliser of `logits`: (max l, Σ exp(l − max l)). Computed per
/// Gaussian without allocating (the posing calls it for every Gaussian of every pass).
fn softmax_norm<T: Float>(logits: &[T]) -> (T, T) {
    let m = logits.iter().fold(T::neg_infinity(), |m, &l| m.max(l));
    let sum = logits.iter().fold(T::zero(), |a, &l| a + (l - m).exp());
    (m, sum)
}

/// softmax(l)[class].
fn class_probability<T: Float>(logits: &[T], class: usize) -> T {
    let (m, sum) = softmax_norm(logits);
    (logits[class] - m).exp() / sum
}

/// Each person's probability of a Gaussian with K = 1 + P one-hot logits: softmax(l)[1..] into
/// `out` (P values).
pub fn person_probabilities<T: Float>(logits: &[T], out: &mut [T]) {
    let (m, sum) = softmax_norm(logits);
    for (o, &l) in out.iter_mut().zip(&logits[1..]) {
        *o = (l - m).exp() / sum;
    }
}

/// Adds dL/dlogits given dL/d [`person_probabilities`] (`d_q`, P values) into `d_logits` (K values):
/// ∂s_j/∂l_k = s_j (δ_jk − s_k).
pub fn person_probabilities_backward<T: Float>(logits: &[T], d_q: &[T], d_logits: &mut [T]) {
    let (m, sum) = softmax_norm(logits);
    let s = |k: usize| (logits[k] - m).exp() / sum;
    // Σ_j d_q_j s_j, over the people's classes j ≥ 1.
    let weighted = d_q
        .iter()
        .enumerate()
        .fold(T::zero(), |a, (j, &d)| a + d * s(j + 1));
    for k in 0..logits.len() {
        let own = if k >= 1 { d_q[k - 1] } else { T::zero() };
        d_logits[k] = d_logits[k] + s(k) * (own - weighted);
    }
}

/// The person (0-based) whose class has the largest logit among K = 1 + P one-hot logits (the
/// first on a tie); 0 with one person.
pub fn most_probable_person<T: Float>(logits: &[T]) -> usize {
    let mut best = 0;
    for j in 1..logits.len().saturating_sub(1) {
        if logits[1 + j] > logits[1 + best] {
            best = j;
        }
    }
    best
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

    #[test]
    fn several_people_share_the_human_probability_and_own_their_class() {
        let mode = SemanticMode::OneHot;
        assert_eq!((mode.logits_for(1), mode.logits_for(3)), (2, 4));
        assert_eq!(SemanticMode::Scalar.logits_for(3), 1);
        // Person 1 of three labelled as the initialisation labels it.
        let logits = [-3.0f64, -3.0, 3.0, -3.0];
        let mut q = [0.0; 3];
        person_probabilities(&logits, &mut q);
        let p = mode.probability(&logits);
        assert!((q.iter().sum::<f64>() - p).abs() < 1e-15, "{q:?} {p}");
        assert!(q[1] > 0.99 && q[0] < 0.003 && q[2] < 0.003, "{q:?}");
        assert_eq!(most_probable_person(&logits), 1);
        // The scene's logits keep every person's probability below the default gate of 0.01.
        assert!(mode.probability(&[3.0f64, -3.0, -3.0, -3.0, -3.0]) < 0.01);
        // Two logits: the paper's sigmoid, bit for bit.
        assert_eq!(mode.probability(&[0.3f32, 1.1]), sigmoid(1.1f32 - 0.3));
        assert_eq!(most_probable_person(&[0.3f32, 1.1]), 0);
    }
}
