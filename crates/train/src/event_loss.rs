//! The event-generation loss of EventNeRF / E-NeRF, the alternative to the flow loss that the paper's
//! Table 6 compares against: the log-intensity change between the renders of frames k and k+1 should
//! equal the contrast threshold times the signed number of events each pixel fired in between.
//!
//! L_ev = (1/N) Σ_p (ΔL(p) − C·E(p))², ΔL = log(Y_{k+1} + ε) − log(Y_k + ε), with Y the Rec. 709 luma
//! of the linear RGB render (the grey image the ESIM simulator of `events` turns into events, negative
//! values clamped to 0 as there), E(p) = #positive − #negative events of pixel p in [t_k, t_{k+1}),
//! C the contrast threshold and ε the simulator's `log_eps`. It needs the sensor's threshold, which a
//! flow does not (the paper's argument for flow).

use nn::Real;

/// Rec. 709 luma weights of linear R, G, B (the same as `events::grey_from_rgb`).
pub const LUMA: [f64; 3] = [0.2126, 0.7152, 0.0722];

/// [`pair_event_loss`]'s result.
#[derive(Clone, Debug)]
pub struct PairEventLoss<T> {
    /// L_ev (squared log-intensity units).
    pub loss: T,
    /// ∂L_ev/∂(render of frame k), planar (3, H, W).
    pub d_first: Vec<T>,
    /// ∂L_ev/∂(render of frame k+1), planar (3, H, W).
    pub d_second: Vec<T>,
}

/// L_ev of two planar (3, H, W) linear RGB renders against `expected` = C·E per pixel (H × W,
/// log-intensity units), with `log_eps` = ε; the gradient w.r.t. both renders.
pub fn pair_event_loss<T: Real>(
    first: &[T],
    second: &[T],
    expected: &[T],
    log_eps: T,
) -> PairEventLoss<T> {
    let n = expected.len();
    let luma = LUMA.map(T::of);
    let grey =
        |img: &[T], i: usize| luma[0] * img[i] + luma[1] * img[n + i] + luma[2] * img[2 * n + i];
    let inv = T::one() / T::of(n.max(1) as f64);
    let two = T::of(2.0);
    let mut loss = T::zero();
    let mut d_first = vec![T::zero(); 3 * n];
    let mut d_second = vec![T::zero(); 3 * n];
    for i in 0..n {
        let (ya, yb) = (grey(first, i), grey(second, i));
        let (ca, cb) = (ya.max(T::zero()), yb.max(T::zero()));
        let r = (cb + log_eps).ln() - (ca + log_eps).ln() - expected[i];
        loss = loss + r * r * inv;
        let g = two * r * inv;
        // d/dY of log(max(Y, 0) + ε): 1/(Y + ε) above 0, 0 below (the clamp).
        let ga = if ya > T::zero() {
            -g / (ca + log_eps)
        } else {
            T::zero()
        };
        let gb = if yb > T::zero() {
            g / (cb + log_eps)
        } else {
            T::zero()
        };
        for c in 0..3 {
            d_first[c * n + i] = ga * luma[c];
            d_second[c * n + i] = gb * luma[c];
        }
    }
    PairEventLoss {
        loss,
        d_first,
        d_second,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_brightening_that_matches_the_events_costs_nothing() {
        // One pixel brightening by a factor e^0.4 (two events at C = 0.2), another dark and still.
        let n = 2;
        let eps = 1e-3f64;
        let y0 = 0.25;
        let y1 = (y0 + eps) * 0.4f64.exp() - eps;
        let grey = |y: f64| vec![y, 0.0, y, 0.0, y, 0.0];
        let l = pair_event_loss(&grey(y0), &grey(y1), &[0.4, 0.0], eps);
        assert!(l.loss.abs() < 1e-20, "{}", l.loss);
        // Claiming no events for the brightening pixel costs (0.4)² / 2.
        let l = pair_event_loss(&grey(y0), &grey(y1), &[0.0, 0.0], eps);
        assert!((l.loss - 0.08).abs() < 1e-12, "{}", l.loss);
        assert!(l.d_second[0] > 0.0 && l.d_first[0] < 0.0);
        assert_eq!(l.d_first.len(), 3 * n);
    }
}
