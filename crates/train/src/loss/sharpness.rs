//! Priors on the person's Gaussians that choose, among the shapes a blurred frame cannot tell
//! apart, the sharper one: a penalty on their size and one on their opacity's indecision.
//!
//! A blurred frame is the mean of the sharp images over its exposure, so a person drawn softer —
//! larger, fainter Gaussians — can explain it as well as a sharp one; the events, which fire only
//! where the log intensity crosses a threshold, do not tell the two apart below it. Trained on
//! blurred frames the person's Gaussians end up larger and fainter than the same model's trained
//! on the sharp frames (`docs/notes/2026-12-06-eval-curves-and-sharpness-priors.md`). Off by
//! default (weights 0).
//!
//! - size: `w_s · mean_i Σ_a s_ia / 1 cm`, the mean over the person's Gaussians of the sum of the
//!   three axis scales `s_ia = exp(log_scale_ia)` in centimetres;
//! - indecision: `w_o · mean_i H(σ(x_i))`, the binary entropy (nats) of each Gaussian's opacity
//!   `σ(x_i)` from its logit `x_i`: zero for a Gaussian fully opaque or fully transparent,
//!   ln 2 at one half. Its derivative is `dH/dx = −x · σ(x) · (1 − σ(x))`.

use num_traits::Float;

/// The length (m) the size prior measures scales in: 1 cm.
pub const SIZE_UNIT_M: f64 = 0.01;

/// The size prior `weight · mean_{i ∈ index} Σ_a exp(log_scales[i][a]) / SIZE_UNIT_M`; adds its
/// gradient w.r.t. the log scales into `d_log_scales` when given. Zero for an empty `index`.
pub fn size_prior<T: Float>(
    log_scales: &[[T; 3]],
    index: &[usize],
    weight: T,
    mut d_log_scales: Option<&mut [[T; 3]]>,
) -> T {
    if index.is_empty() {
        return T::zero();
    }
    let unit = T::from(SIZE_UNIT_M).unwrap_or_else(T::one);
    let per = weight / (T::from(index.len()).unwrap_or_else(T::one) * unit);
    let mut sum = T::zero();
    for &i in index {
        for a in 0..3 {
            let s = log_scales[i][a].exp();
            sum = sum + s;
            if let Some(d) = d_log_scales.as_deref_mut() {
                d[i][a] = d[i][a] + per * s;
            }
        }
    }
    per * sum
}

/// The indecision prior `weight · mean_{i ∈ index} H(σ(logits[i]))` (binary entropy in nats);
/// adds its gradient w.r.t. the logits into `d_logits` when given. Zero for an empty `index`.
pub fn opacity_entropy<T: Float>(
    logits: &[T],
    index: &[usize],
    weight: T,
    mut d_logits: Option<&mut [T]>,
) -> T {
    if index.is_empty() {
        return T::zero();
    }
    let per = weight / T::from(index.len()).unwrap_or_else(T::one);
    // softplus(x) = ln(1 + eˣ), without overflow for large |x|.
    let softplus = |x: T| x.max(T::zero()) + (-x.abs()).exp().ln_1p();
    let mut sum = T::zero();
    for &i in index {
        let x = logits[i];
        let o = T::one() / (T::one() + (-x).exp());
        // −o·ln o − (1 − o)·ln(1 − o), with ln o = −softplus(−x) and ln(1 − o) = −softplus(x).
        sum = sum + o * softplus(-x) + (T::one() - o) * softplus(x);
        if let Some(d) = d_logits.as_deref_mut() {
            d[i] = d[i] - per * x * o * (T::one() - o);
        }
    }
    per * sum
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_at_known_points() {
        // One Gaussian of 1 cm on every axis: 3 (cm) × weight.
        let l = (0.01f64).ln();
        assert!((size_prior(&[[l; 3]], &[0], 2.0, None) - 6.0).abs() < 1e-12);
        // Opacity one half: ln 2; far from it, almost zero.
        assert!((opacity_entropy(&[0.0f64], &[0], 1.0, None) - 2f64.ln()).abs() < 1e-15);
        assert!(opacity_entropy(&[40.0f64, -40.0], &[0, 1], 1.0, None) < 1e-15);
        // Only the indexed Gaussians count.
        assert_eq!(opacity_entropy(&[0.0f64, 3.0], &[], 1.0, None), 0.0);
    }
}
