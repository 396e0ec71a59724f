//! The semantic blend of E-Sem3DGS (paper §4.2): each Gaussian's posed attributes are a mix, weighted by
//! its human probability p, of its deformed (human) attributes and its static (scene) attributes, so the
//! rendering loss reaches the semantic logits.
//!
//! Exact definition (per Gaussian, p ∈ [0, 1]):
//! - position  x = p·x_def + (1 − p)·x_static
//! - log-scale s = p·s_def + (1 − p)·s_static
//! - rotation  q = p·q_def' + (1 − p)·q_static, where q_def' = ±q_def with the sign that makes
//!   q_def'·q_static ≥ 0 (q and −q are the same rotation; the rasterizer normalises q);
//! - colour    c = p·c_human + (1 − p)·c_scene.
//!
//! The probability comes from the semantic mode (`--semantic`): `OneHot` p = softmax(l)[1] over K = 2
//! logits (paper), `Scalar` p = sigmoid(l) of a single logit, `None` p = 1 for every Gaussian
//! (everything is deformed, as in 3DGS-Avatar).

use num_traits::Float;

/// How a Gaussian's human probability is parameterised (`--semantic`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
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
    /// Deformed log-scales.
    pub s_def: [T; 3],
    /// Static log-scales.
    pub s_static: [T; 3],
    /// Deformed rotation (w, x, y, z), unnormalised.
    pub q_def: [T; 4],
    /// Static rotation (w, x, y, z), unnormalised.
    pub q_static: [T; 4],
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
    /// Log-scales.
    pub s: [T; 3],
    /// Rotation (w, x, y, z), unnormalised.
    pub q: [T; 4],
    /// Colour (linear RGB).
    pub c: [T; 3],
}

fn aligned_sign<T: Float>(q_def: &[T; 4], q_static: &[T; 4]) -> T {
    let dot = (0..4).fold(T::zero(), |acc, k| acc + q_def[k] * q_static[k]);
    if dot < T::zero() {
        -T::one()
    } else {
        T::one()
    }
}

/// Blends one Gaussian's attributes with human probability `p` (see the module docs).
pub fn blend<T: Float>(p: T, a: &BlendInputs<T>) -> Blended<T> {
    let one_m = T::one() - p;
    let sign = aligned_sign(&a.q_def, &a.q_static);
    Blended {
        x: std::array::from_fn(|k| p * a.x_def[k] + one_m * a.x_static[k]),
        s: std::array::from_fn(|k| p * a.s_def[k] + one_m * a.s_static[k]),
        q: std::array::from_fn(|k| p * sign * a.q_def[k] + one_m * a.q_static[k]),
        c: std::array::from_fn(|k| p * a.c_human[k] + one_m * a.c_scene[k]),
    }
}

/// Backward of [`blend`]: given dL/d(blended), returns (dL/dp, dL/d(inputs)).
pub fn blend_backward<T: Float>(p: T, a: &BlendInputs<T>, d: &Blended<T>) -> (T, BlendInputs<T>) {
    let one_m = T::one() - p;
    let sign = aligned_sign(&a.q_def, &a.q_static);
    let mut d_p = T::zero();
    for k in 0..3 {
        d_p = d_p
            + d.x[k] * (a.x_def[k] - a.x_static[k])
            + d.s[k] * (a.s_def[k] - a.s_static[k])
            + d.c[k] * (a.c_human[k] - a.c_scene[k]);
    }
    for k in 0..4 {
        d_p = d_p + d.q[k] * (sign * a.q_def[k] - a.q_static[k]);
    }
    let grads = BlendInputs {
        x_def: d.x.map(|g| g * p),
        x_static: d.x.map(|g| g * one_m),
        s_def: d.s.map(|g| g * p),
        s_static: d.s.map(|g| g * one_m),
        q_def: d.q.map(|g| g * p * sign),
        q_static: d.q.map(|g| g * one_m),
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
        let a = BlendInputs {
            x_def: [1.0f64, 2.0, 3.0],
            x_static: [4.0, 5.0, 6.0],
            s_def: [0.1; 3],
            s_static: [0.2; 3],
            q_def: [-1.0, 0.0, 0.0, 0.0],
            q_static: [1.0, 0.0, 0.0, 0.0],
            c_human: [1.0, 0.0, 0.0],
            c_scene: [0.0, 0.0, 1.0],
        };
        let human = blend(1.0, &a);
        assert_eq!(human.x, a.x_def);
        assert_eq!(
            human.q,
            [1.0, 0.0, 0.0, 0.0],
            "sign aligned to the static rotation"
        );
        let scene = blend(0.0, &a);
        assert_eq!(scene.c, a.c_scene);
        assert_eq!(SemanticMode::None.probability::<f64>(&[]), 1.0);
        assert!((SemanticMode::OneHot.probability(&[-3.0f64, 3.0]) - 0.997_527_376).abs() < 1e-8);
    }
}
