//! The event-generation loss of EventNeRF / E-NeRF, the alternative to the flow loss that the paper's
//! Table 6 compares against: the log-intensity change between the renders of frames k and k+1 should
//! equal the contrast threshold times the signed number of events each pixel fired in between.
//!
//! L_ev = (1/N) Σ_p (ΔL(p) − C·E(p))², ΔL = log(Y_{k+1} + ε) − log(Y_k + ε), with Y the Rec. 709 luma
//! of the linear RGB render (the grey image the ESIM simulator of `events` turns into events, negative
//! values clamped to 0 as there), E(p) = #positive − #negative events of pixel p in [t_k, t_{k+1}),
//! C the contrast threshold and ε the simulator's `log_eps`. It needs the sensor's threshold, which a
//! flow does not (the paper's argument for flow).
//!
//! That squared penalty assumes every threshold crossing fired. A real pixel drops the crossings
//! that come within its refractory period of its previous event while its reference level still
//! moves, so a count under-states a fast change (on the benchmark's 1 ms sensor, C·E recovers 22–54 %
//! of the true change of a moving edge): pulling ΔL to C·E then pulls moving texture towards less
//! contrast. [`EventPenalty::Bound`] reads a count as what it is on such a sensor — a lower bound on
//! the size of the change, with the sign of the events — and a pixel without events as a change
//! smaller than a threshold:
//!
//! r(p) = min(0, ΔL − (C+·n⁺ − C−·n⁻ − m·C+)) where the events sum positive,
//! r(p) = max(0, ΔL − (C+·n⁺ − C−·n⁻ + m·C−)) where they sum negative,
//! r(p) = sign(ΔL)·max(0, |ΔL| − z·C) without events (C the mean of C±),
//! L_ev = (1/N) Σ_p w(p)·min(r(p)², τ²), with the margin m for the quantisation of the counts (the change
//! between two crossings is up to one threshold either side) and the dead zone z; w = 1 but for an
//! overshoot past the count (ΔL beyond C+·n⁺ − C−·n⁻ ± m·C in the events' direction), which costs
//! its squared excess times the overshoot weight o (0: a pure bound; 1 with m = 0: the squared
//! penalty on pixels with events). o between the two trusts an unsaturated count a little: the
//! refractory period hides crossings, it never invents them. The cap τ (∞: none) bounds what one
//! pixel can cost: on a sensor with a refractory period a pixel crossed by texture in both
//! directions within one interval reports a net count whose sign and size are arbitrary, and
//! without a cap those few pixels hold a sharp model's changes to them (measured:
//! `docs/notes/2026-11-28-what-holds-the-blur.md`); in its Huber form the cost beyond τ grows
//! linearly, w·(2τ|r| − τ²), so such a pixel keeps a bounded pull instead of none. An expected change of [`UNCONSTRAINED`] (NaN:
//! the events say nothing of the net change, e.g. a pixel that fired both polarities) costs
//! nothing under either penalty, and a sum of intervals that holds one stays unconstrained.

use nn::Real;

/// How a pixel's log-intensity change is held to its events (see the module doc).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum EventPenalty {
    /// (ΔL − C·E)²: every crossing fired (ideal events; EventNeRF / E-NeRF, the paper).
    Squared,
    /// Counts as lower bounds on the change, no events as a change inside the dead zone.
    Bound {
        /// C+ (log-intensity units).
        c_pos: f64,
        /// C− (log-intensity units, a positive number).
        c_neg: f64,
        /// m: the bound is relaxed by this many thresholds (quantisation of the counts).
        margin: f64,
        /// z: a pixel without events may change by up to z·(C+ + C−)/2 unpenalised; 0 holds it
        /// to no change, as the squared penalty does.
        dead_zone: f64,
        /// o: the weight of the squared overshoot of a change past its count by more than m
        /// thresholds (0: counts are pure lower bounds).
        overshoot: f64,
        /// τ: a pixel's cost is capped at w·τ² (log-intensity units; ∞: no cap), so a pixel
        /// whose residual exceeds τ — a count the sensor's dropped crossings turned into the
        /// wrong sign or size — stops pulling (a truncated quadratic, robust to such outliers).
        cap: f64,
        /// Beyond τ the cost grows linearly, w·(2τ|r| − τ²), instead of staying at w·τ² (the Huber
        /// form: a pixel past the cap keeps the constant pull 2wτ towards its bound instead of
        /// none).
        huber: bool,
    },
}

impl EventPenalty {
    /// τ², the largest cost of one pixel before its weight, when the penalty caps it.
    pub fn cap(&self) -> Option<f64> {
        match *self {
            EventPenalty::Bound { cap, .. } if cap.is_finite() => Some(cap),
            _ => None,
        }
    }

    /// Whether the cost beyond the cap grows linearly (the Huber form) rather than staying flat.
    pub fn huber(&self) -> bool {
        matches!(*self, EventPenalty::Bound { huber: true, .. })
    }
}

/// The expected change of a pixel whose events say nothing about its net change (NaN, so that a
/// sum over intervals containing one stays unconstrained): it costs nothing.
pub const UNCONSTRAINED: f32 = f32::NAN;

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
/// log-intensity units), with `log_eps` = ε; the gradient w.r.t. both renders. The squared
/// penalty; [`pair_event_loss_with`] takes any.
pub fn pair_event_loss<T: Real>(
    first: &[T],
    second: &[T],
    expected: &[T],
    log_eps: T,
) -> PairEventLoss<T> {
    pair_event_loss_with(first, second, expected, log_eps, EventPenalty::Squared)
}

/// The residual r(p) of a pixel whose log-intensity change is `change` and whose events sum to
/// `expected` = C+·n⁺ − C−·n⁻, and its weight w(p) (see the module doc): the loss is w·r², its
/// derivative in `change` 2·w·r. An [`UNCONSTRAINED`] (NaN) `expected` gives r = 0.
pub fn event_residual<T: Real>(change: T, expected: T, penalty: EventPenalty) -> (T, T) {
    let one = T::one();
    if expected.is_nan() {
        return (T::zero(), one);
    }
    match penalty {
        EventPenalty::Squared => (change - expected, one),
        EventPenalty::Bound {
            c_pos,
            c_neg,
            margin,
            dead_zone,
            overshoot,
            ..
        } => {
            let zero = T::zero();
            // r outside [low, high], weighted by the side's weight; 0 inside.
            let outside = |low: T, high: T, below: T, above: T| {
                if change < low {
                    (change - low, below)
                } else if change > high {
                    (change - high, above)
                } else {
                    (zero, one)
                }
            };
            let over = T::of(overshoot);
            if expected > zero {
                let m = T::of(margin * c_pos);
                outside(expected - m, expected + m, one, over)
            } else if expected < zero {
                let m = T::of(margin * c_neg);
                outside(expected - m, expected + m, over, one)
            } else {
                let zone = T::of(0.5 * dead_zone * (c_pos + c_neg));
                outside(-zone, zone, one, one)
            }
        }
    }
}

/// [`pair_event_loss`] with the penalty `penalty`.
pub fn pair_event_loss_with<T: Real>(
    first: &[T],
    second: &[T],
    expected: &[T],
    log_eps: T,
    penalty: EventPenalty,
) -> PairEventLoss<T> {
    let n = expected.len();
    let (ya, yb) = (clamped_luma(first, n), clamped_luma(second, n));
    let inv = T::one() / T::of(n.max(1) as f64);
    let (cap, huber) = (rounded_cap(penalty), penalty.huber());
    let mut loss = T::zero();
    let mut d_change = vec![T::zero(); n];
    for i in 0..n {
        let change = (yb[i] + log_eps).ln() - (ya[i] + log_eps).ln();
        let (r, w) = event_residual(change, expected[i], penalty);
        let (cost, g) = capped_cost(r, w, cap, huber, inv);
        loss = loss + cost;
        d_change[i] = g;
    }
    let (d_first, d_second) = renders_backward(&d_change, &ya, &yb, log_eps);
    PairEventLoss {
        loss,
        d_first,
        d_second,
    }
}

/// (τ², τ) of a capped penalty in `T`: τ² rounded once from f64 (the truncated form's bits), τ
/// for the Huber form's pull.
fn rounded_cap<T: Real>(penalty: EventPenalty) -> Option<(T, T)> {
    penalty.cap().map(|tau| (T::of(tau * tau), T::of(tau)))
}

/// One pixel's cost w·r² over `inv` = 1/N and its derivative in the change, capped at w·τ² (flat
/// beyond, or linear in the Huber form) when `cap` holds (τ², τ).
fn capped_cost<T: Real>(r: T, w: T, cap: Option<(T, T)>, huber: bool, inv: T) -> (T, T) {
    let two = T::of(2.0);
    match cap {
        Some((cap, tau)) if r * r > cap && huber => {
            let pull = if r > T::zero() { tau } else { -tau };
            (w * (two * pull * r - cap) * inv, two * w * pull * inv)
        }
        Some((cap, _)) if r * r > cap => (w * cap * inv, T::zero()),
        _ => (w * r * r * inv, two * w * r * inv),
    }
}

/// [`pair_event_loss_with`] with a spatial reach: a pixel whose events sum to one sign is held
/// through the pixel within `reach` pixels of it (Chebyshev distance, on an image `width` pixels
/// wide) whose change meets its bound best — the largest change for a positive count, the
/// smallest for a negative one (the first in row order on a tie) — and its gradient goes there.
/// A sharp edge the model places a fraction of a pixel off then answers the events it caused from
/// the pixel it moved into, where the per-pixel term charged the pixel that fired for a change it
/// did not see; a smooth change is charged as before, as its neighbourhood holds no larger change.
/// Pixels without events (the dead zone) and unconstrained ones stay per pixel. `reach = 0` is
/// [`pair_event_loss_with`], bit for bit.
pub fn pair_event_loss_reach<T: Real>(
    first: &[T],
    second: &[T],
    expected: &[T],
    log_eps: T,
    penalty: EventPenalty,
    (width, reach): (usize, usize),
) -> PairEventLoss<T> {
    if reach == 0 || width == 0 {
        return pair_event_loss_with(first, second, expected, log_eps, penalty);
    }
    let n = expected.len();
    let height = n / width;
    let (ya, yb) = (clamped_luma(first, n), clamped_luma(second, n));
    let change: Vec<T> = (0..n)
        .map(|i| (yb[i] + log_eps).ln() - (ya[i] + log_eps).ln())
        .collect();
    let inv = T::one() / T::of(n.max(1) as f64);
    let (cap, huber) = (rounded_cap(penalty), penalty.huber());
    let zero = T::zero();
    let mut loss = zero;
    let mut d_change = vec![zero; n];
    for i in 0..n {
        let e = expected[i];
        let at = if !e.is_nan() && e != zero {
            best_in_reach(&change, i, (width, height), reach, e > zero)
        } else {
            i
        };
        let (r, w) = event_residual(change[at], e, penalty);
        let (cost, g) = capped_cost(r, w, cap, huber, inv);
        loss = loss + cost;
        d_change[at] = d_change[at] + g;
    }
    let (d_first, d_second) = renders_backward(&d_change, &ya, &yb, log_eps);
    PairEventLoss {
        loss,
        d_first,
        d_second,
    }
}

/// The pixel within `reach` (Chebyshev) of pixel `i` of a `(width, height)` image with the
/// largest `change` (`largest`) or the smallest, the first in row order on a tie.
fn best_in_reach<T: Real>(
    change: &[T],
    i: usize,
    (width, height): (usize, usize),
    reach: usize,
    largest: bool,
) -> usize {
    let (x, y) = (i % width, i / width);
    let mut best = i;
    for qy in y.saturating_sub(reach)..(y + reach + 1).min(height) {
        for qx in x.saturating_sub(reach)..(x + reach + 1).min(width) {
            let q = qy * width + qx;
            let better = if largest {
                change[q] > change[best]
            } else {
                change[q] < change[best]
            };
            if better || (change[q] == change[best] && q < best) {
                best = q;
            }
        }
    }
    best
}

/// The Rec. 709 luma of a planar (3, H, W) render of `n` pixels, clamped at 0 (as the simulator
/// reads it).
fn clamped_luma<T: Real>(img: &[T], n: usize) -> Vec<T> {
    let luma = LUMA.map(T::of);
    (0..n)
        .map(|i| {
            (luma[0] * img[i] + luma[1] * img[n + i] + luma[2] * img[2 * n + i]).max(T::zero())
        })
        .collect()
}

/// ∂L/∂(render k, render k+1), planar (3, H, W), from `d_change` = ∂L/∂ΔL per pixel, ΔL =
/// log(Y_k+1 + ε) − log(Y_k + ε) of the clamped lumas `ya`, `yb`: ∓g/(Y + ε) through the luma
/// weights, 0 where the luma is clamped.
fn renders_backward<T: Real>(d_change: &[T], ya: &[T], yb: &[T], log_eps: T) -> (Vec<T>, Vec<T>) {
    let n = d_change.len();
    let (luma, zero) = (LUMA.map(T::of), T::zero());
    let mut d_first = vec![zero; 3 * n];
    let mut d_second = vec![zero; 3 * n];
    for i in 0..n {
        let g = d_change[i];
        let ga = if ya[i] > zero {
            -g / (ya[i] + log_eps)
        } else {
            zero
        };
        let gb = if yb[i] > zero {
            g / (yb[i] + log_eps)
        } else {
            zero
        };
        for c in 0..3 {
            d_first[c * n + i] = ga * luma[c];
            d_second[c * n + i] = gb * luma[c];
        }
    }
    (d_first, d_second)
}

/// The squared penalty on `block` × `block` pixel blocks of an image `width` pixels wide (the last
/// row and column of blocks may be partial): each block's mean change over its constrained pixels
/// is held to their mean C·E, L = (1/N) Σ_b m_b·(mean_b ΔL − mean_b C·E)², m_b the block's
/// constrained pixels ([`UNCONSTRAINED`] ones left out). Each pair's count quantises the change by
/// up to one threshold per pixel, independently from pixel to pixel, so a block's mean carries 1/m_b
/// of that noise while a change a few pixels wide keeps its size; and an edge the model places a
/// pixel off still changes its block as the events say. `block = 1` is
/// [`pair_event_loss_with`]'s squared penalty, bit for bit.
pub fn pair_event_loss_pooled<T: Real>(
    first: &[T],
    second: &[T],
    expected: &[T],
    log_eps: T,
    width: usize,
    block: usize,
) -> PairEventLoss<T> {
    if block <= 1 || width == 0 {
        return pair_event_loss_with(first, second, expected, log_eps, EventPenalty::Squared);
    }
    let n = expected.len();
    let height = n / width;
    let (ya, yb) = (clamped_luma(first, n), clamped_luma(second, n));
    let inv = T::one() / T::of(n.max(1) as f64);
    let two = T::of(2.0);
    let mut loss = T::zero();
    // dL/dΔL per pixel: 2·r_b/N for the constrained pixels of block b.
    let mut d_change = vec![T::zero(); n];
    for by in (0..height).step_by(block) {
        for bx in (0..width).step_by(block) {
            let pixels = || {
                (by..(by + block).min(height))
                    .flat_map(move |y| (bx..(bx + block).min(width)).map(move |x| y * width + x))
                    .filter(|&i| !expected[i].is_nan())
            };
            let (mut sum, mut m) = (T::zero(), 0usize);
            for i in pixels() {
                let change = (yb[i] + log_eps).ln() - (ya[i] + log_eps).ln();
                sum = sum + (change - expected[i]);
                m += 1;
            }
            if m == 0 {
                continue;
            }
            let r = sum / T::of(m as f64);
            loss = loss + T::of(m as f64) * r * r * inv;
            for i in pixels() {
                d_change[i] = two * r * inv;
            }
        }
    }
    let (d_first, d_second) = renders_backward(&d_change, &ya, &yb, log_eps);
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

    #[test]
    fn pooling_averages_a_block_and_one_pixel_blocks_are_the_squared_penalty() {
        // Four pixels of a 2 × 2 image: one brightening by 0.4 where the events say 0.2 and one
        // still where they say 0.2: pooled, the block's mean change (0.1) meets the mean count (0.1).
        let eps = 1e-3f64;
        let y1 = (0.25 + eps) * 0.4f64.exp() - eps;
        let first = vec![0.25; 12];
        let mut second = first.clone();
        for c in 0..3 {
            second[c * 4] = y1;
        }
        let expected = [0.2, 0.0, 0.0, 0.2];
        let pooled = pair_event_loss_pooled(&first, &second, &expected, eps, 2, 2);
        assert!(pooled.loss.abs() < 1e-20, "{}", pooled.loss);
        let per_pixel = pair_event_loss(&first, &second, &expected, eps);
        assert!((per_pixel.loss - 0.02).abs() < 1e-12, "{}", per_pixel.loss);
        let one = pair_event_loss_pooled(&first, &second, &expected, eps, 2, 1);
        assert_eq!(one.loss.to_bits(), per_pixel.loss.to_bits());
        assert_eq!(one.d_second, per_pixel.d_second);
    }

    #[test]
    fn the_bound_penalty_reads_counts_as_lower_bounds() {
        let bound = EventPenalty::Bound {
            c_pos: 0.2,
            c_neg: 0.25,
            margin: 0.5,
            dead_zone: 1.0,
            overshoot: 0.0,
            cap: f64::INFINITY,
            huber: false,
        };
        let r = |change: f64, expected: f64, penalty| event_residual(change, expected, penalty).0;
        // Two positive events (0.4): any change above 0.3 is free, a smaller one costs.
        let (over, weight) = event_residual(0.9f64, 0.4, bound);
        assert!((over - 0.4).abs() < 1e-12 && weight == 0.0);
        assert_eq!(r(0.31, 0.4, bound), 0.0);
        assert!((r(0.1, 0.4, bound) + 0.2).abs() < 1e-12);
        // A change against the events' sign always costs.
        assert!(r(-0.1, 0.4, bound) < 0.0);
        // One negative event (−0.25): the change must fall below −0.125.
        assert_eq!(event_residual(-0.6, -0.25, bound).1, 0.0);
        assert!((r(0.0, -0.25, bound) - 0.125).abs() < 1e-12);
        // No events: free inside ±0.225 (the mean threshold), linear beyond.
        assert_eq!(r(0.2, 0.0, bound), 0.0);
        assert_eq!(event_residual(-0.3, 0.0, bound).1, 1.0);
        assert!((r(-0.3, 0.0, bound) + 0.075).abs() < 1e-12);
        // The squared penalty is the plain difference.
        assert_eq!(event_residual(0.9, 0.4, EventPenalty::Squared), (0.5, 1.0));
    }

    #[test]
    fn an_overshoot_past_the_count_costs_its_weight() {
        let bound = EventPenalty::Bound {
            c_pos: 0.2,
            c_neg: 0.25,
            margin: 0.5,
            dead_zone: 1.0,
            overshoot: 0.1,
            cap: f64::INFINITY,
            huber: false,
        };
        // Two positive events: free in [0.3, 0.5]; 0.9 overshoots by 0.4 at weight 0.1.
        let (r, w) = event_residual(0.9f64, 0.4, bound);
        assert!((r - 0.4).abs() < 1e-12 && w == 0.1);
        assert_eq!(event_residual(0.45, 0.4, bound), (0.0, 1.0));
        // One negative event: free in [−0.375, −0.125]; −0.6 overshoots downwards.
        let (r, w) = event_residual(-0.6f64, -0.25, bound);
        assert!((r + 0.225).abs() < 1e-12 && w == 0.1);
        // Falling short still costs in full.
        assert_eq!(event_residual(0.0, -0.25, bound).1, 1.0);
    }

    #[test]
    fn a_capped_pixel_costs_its_cap_and_pulls_no_more() {
        let capped_as = |cap, huber| EventPenalty::Bound {
            c_pos: 0.2,
            c_neg: 0.2,
            margin: 0.5,
            dead_zone: 1.0,
            overshoot: 0.0,
            cap,
            huber,
        };
        let capped = |cap| capped_as(cap, false);
        let eps = 1e-3f64;
        let grey = |y: f64| vec![y, y, y];
        let (y0, y1) = (0.2, (0.2 + eps) * 0.5f64.exp() - eps);
        // Two negative events against a brightening by 0.5: r = 0.5 − (−0.4 + 0.1) = 0.8.
        let free = pair_event_loss_with(&grey(y0), &grey(y1), &[-0.4], eps, capped(f64::INFINITY));
        assert!((free.loss - 0.64).abs() < 1e-12, "{}", free.loss);
        let cut = pair_event_loss_with(&grey(y0), &grey(y1), &[-0.4], eps, capped(0.3));
        assert!((cut.loss - 0.09).abs() < 1e-12, "{}", cut.loss);
        assert!(cut.d_first.iter().chain(&cut.d_second).all(|&d| d == 0.0));
        // Below the cap nothing changes.
        let near = pair_event_loss_with(&grey(y0), &grey(y1), &[-0.4], eps, capped(0.9));
        assert_eq!(near.loss, free.loss);
        assert_eq!(near.d_second, free.d_second);
        assert_eq!(capped(f64::INFINITY).cap(), None);
        // The Huber form: past the cap the cost grows linearly, 2τ|r| − τ² = 0.6·0.8 − 0.09, and
        // the pixel keeps pulling with 2τ (the uncapped pull times τ/|r|).
        let lin = pair_event_loss_with(&grey(y0), &grey(y1), &[-0.4], eps, capped_as(0.3, true));
        assert!((lin.loss - (0.48 - 0.09)).abs() < 1e-12, "{}", lin.loss);
        let ratio = lin.d_second[0] / free.d_second[0];
        assert!((ratio - 0.3 / 0.8).abs() < 1e-12, "{ratio}");
        let near_lin =
            pair_event_loss_with(&grey(y0), &grey(y1), &[-0.4], eps, capped_as(0.9, true));
        assert_eq!(near_lin.loss, free.loss);
    }

    #[test]
    fn an_unconstrained_pixel_costs_nothing_under_either_penalty() {
        let eps = 1e-3f64;
        let nan = f64::from(UNCONSTRAINED);
        let (y0, y1) = (0.2, (0.2 + eps) * 0.5f64.exp() - eps);
        // Two pixels brightening by 0.5: one unconstrained, one held to no change.
        let first = [y0, y0, y0, y0, y0, y0];
        let second = [y1, y1, y1, y1, y1, y1];
        let bound = EventPenalty::Bound {
            c_pos: 0.2,
            c_neg: 0.2,
            margin: 0.5,
            dead_zone: 1.0,
            overshoot: 0.0,
            cap: f64::INFINITY,
            huber: false,
        };
        for penalty in [EventPenalty::Squared, bound] {
            let free = pair_event_loss_with(&first, &second, &[nan, 0.0], eps, penalty);
            let held = pair_event_loss_with(&first, &second, &[0.0, 0.0], eps, penalty);
            assert!(free.loss.is_finite() && free.loss > 0.0);
            assert!((2.0 * free.loss - held.loss).abs() < 1e-12, "{penalty:?}");
            for c in 0..3 {
                assert_eq!((free.d_first[2 * c], free.d_second[2 * c]), (0.0, 0.0));
                assert_eq!(free.d_second[2 * c + 1], held.d_second[2 * c + 1]);
            }
        }
    }

    #[test]
    fn a_count_is_met_by_the_neighbour_an_edge_moved_into() {
        let penalty = EventPenalty::Bound {
            c_pos: 0.2,
            c_neg: 0.2,
            margin: 1.0,
            dead_zone: 1.0,
            overshoot: 0.0,
            cap: f64::INFINITY,
            huber: false,
        };
        // A row of three grey pixels: the middle one fired three positive events (its change is
        // more than 0.4), the model brightens its right neighbour by 0.5 instead.
        let eps = 1e-3f64;
        let planes = |y: [f64; 3]| [y, y, y].concat();
        let before = planes([0.2; 3]);
        let brighter = (0.2 + eps) * 0.5f64.exp() - eps;
        let after = planes([0.2, 0.2, brighter]);
        let expected = [0.0, 0.6, 0.0];
        let per_pixel = pair_event_loss_with(&before, &after, &expected, eps, penalty);
        let held = pair_event_loss_reach(&before, &after, &expected, eps, penalty, (3, 1));
        // Per pixel: the middle pixel falls 0.4 short, the right one overshoots its dead zone.
        let dead = 0.5 - 0.2;
        assert!((per_pixel.loss - (0.16 + dead * dead) / 3.0).abs() < 1e-12);
        // With reach 1 the middle pixel's bound is met by its neighbour; the neighbour's own
        // silence still costs, and the middle pixel gets no gradient.
        assert!(
            (held.loss - dead * dead / 3.0).abs() < 1e-12,
            "{}",
            held.loss
        );
        assert!((0..3).all(|c| held.d_second[3 * c + 1] == 0.0));
        // Reach 0 is the per-pixel term, bit for bit.
        let zero = pair_event_loss_reach(&before, &after, &expected, eps, penalty, (3, 0));
        assert_eq!(zero.loss, per_pixel.loss);
        assert_eq!(zero.d_second, per_pixel.d_second);
        // A negative count looks for the smallest change: the brightening does not meet it.
        let negative = [0.0, -0.6, 0.0];
        let neg = pair_event_loss_reach(&before, &after, &negative, eps, penalty, (3, 1));
        assert!(
            (neg.loss - (0.16 + dead * dead) / 3.0).abs() < 1e-12,
            "{}",
            neg.loss
        );
    }
}
