//! Finite-difference check of the event-generation loss (`train::loss::event::pair_event_loss_with`)
//! w.r.t. both renders, with the squared penalty and with the bound penalty (counts as lower
//! bounds, a dead zone without events, a weighted overshoot past the count), and with the bound
//! penalty capped (each pixel's cost at most w·τ²; a kink at |r| = τ like the others) and capped
//! in the Huber form (linear beyond τ: continuous first derivative at the kink); about a
//! fifth of the pixels are unconstrained (their events fired both polarities) and cost nothing. The loss is smooth where the luma is positive (log of a
//! positive value, squared residual); renders are drawn in [0.05, 1] so no probe reaches the clamp
//! at 0. The bound penalty's residual is continuous and piecewise linear in ΔL, so r² has a
//! continuous first derivative; a probe of h = 1e-6 straddles one of its kinks with probability
//! ~1e-6 per pixel, as L1's kinks elsewhere.
//! Tolerance in f64 with h = 1e-6: |num − ana| ≤ 1e-9 + 1e-6·max(|num|, |ana|) (loss O(1): rounding
//! ≈ 1e-10, truncation ≈ h²·|L'''| with |L'''| ≤ ~1e4 at luma ≥ 0.05 gives ≤ 1e-8 relative).

use gradient_checks::{central_differences, compare, GradientChecker, Tolerance};
use proptest::prelude::*;
use train::loss::event::{
    pair_event_loss_pooled, pair_event_loss_reach, pair_event_loss_with, EventPenalty,
    UNCONSTRAINED,
};

const TOL: Tolerance = Tolerance::new(1e-9, 1e-6);
const H: f64 = 1e-6;
const N: usize = 24;

const BOUND: EventPenalty = EventPenalty::Bound {
    c_pos: 0.2,
    c_neg: 0.25,
    margin: 0.5,
    dead_zone: 1.0,
    overshoot: 0.3,
    cap: f64::INFINITY,
    huber: false,
};

/// [`BOUND`] with each pixel's cost capped at τ = 1: random renders in [0.05, 1] give changes of
/// up to ±3, so most draws hold pixels on both sides of the cap.
const CAPPED: EventPenalty = EventPenalty::Bound {
    c_pos: 0.2,
    c_neg: 0.25,
    margin: 0.5,
    dead_zone: 1.0,
    overshoot: 0.3,
    cap: 1.0,
    huber: false,
};

/// [`CAPPED`] in the Huber form: beyond τ the cost grows linearly.
const HUBER: EventPenalty = EventPenalty::Bound {
    c_pos: 0.2,
    c_neg: 0.25,
    margin: 0.5,
    dead_zone: 1.0,
    overshoot: 0.3,
    cap: 1.0,
    huber: true,
};

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn event_loss_gradient_matches(
        images in prop::collection::vec(0.05f64..1.0, 2 * 3 * N),
        counts in prop::collection::vec(-3i32..4, N),
        which in 0u8..4,
        silent in prop::collection::vec(prop::bool::weighted(0.2), N),
    ) {
        let (bound, penalty) = match which {
            0 => (false, EventPenalty::Squared),
            1 => (true, BOUND),
            2 => (true, CAPPED),
            _ => (true, HUBER),
        };
        // About a fifth of the pixels are unconstrained (fired both polarities).
        let held: Vec<f64> = counts
            .iter()
            .map(|&c| if c > 0 { 0.2 * f64::from(c) } else { 0.25 * f64::from(c) })
            .collect();
        let expected: Vec<f64> = held
            .iter()
            .zip(&silent)
            .map(|(&e, &s)| if s { f64::from(UNCONSTRAINED) } else { e })
            .collect();
        let loss = |x: &[f64]| pair_event_loss_with(&x[..3 * N], &x[3 * N..], &expected, 1e-3, penalty);
        let out = loss(&images);
        let analytic: Vec<f64> = out.d_first.iter().chain(&out.d_second).copied().collect();
        let numeric = central_differences(|x| loss(x).loss, &images, H);
        let mut checker = GradientChecker::new();
        checker.check(&format!("event loss d(render k, render k+1), {penalty:?}"), &numeric, &analytic, TOL);
        // Fails on a wrong sign, and the gradient is not trivially zero (24 random pixels all
        // inside their bounds has probability ≈ 2^-24).
        let neg: Vec<f64> = analytic.iter().map(|a| -a).collect();
        prop_assert!(!compare("negated", &numeric, &neg, TOL).passed());
        prop_assert!(analytic.iter().any(|&a| a != 0.0));
        // The unconstrained pixels are free: where their counts would pull one of them (a
        // non-zero gradient there; a capped or satisfied pixel does not pull), holding them to
        // their counts gives another gradient.
        let counted = pair_event_loss_with(&images[..3 * N], &images[3 * N..], &held, 1e-3, penalty);
        let other: Vec<f64> = counted.d_first.iter().chain(&counted.d_second).copied().collect();
        let pulled = (0..2 * 3 * N).any(|k| silent[k % N] && other[k].abs() > 1e-6);
        if pulled {
            prop_assert!(!compare("held for unconstrained", &numeric, &other, TOL).passed());
        }
        if bound {
            // The bound is not the squared penalty: the squared gradient fails it.
            let squared = pair_event_loss_with(&images[..3 * N], &images[3 * N..], &expected, 1e-3, EventPenalty::Squared);
            let other: Vec<f64> = squared.d_first.iter().chain(&squared.d_second).copied().collect();
            prop_assert!(!compare("squared for bound", &numeric, &other, TOL).passed());
            // The overshoot term is there: where a pixel overshoots (the losses differ), the
            // gradient of the pure bound fails it.
            let pure = EventPenalty::Bound { c_pos: 0.2, c_neg: 0.25, margin: 0.5, dead_zone: 1.0, overshoot: 0.0, cap: f64::INFINITY, huber: false };
            let pure = pair_event_loss_with(&images[..3 * N], &images[3 * N..], &expected, 1e-3, pure);
            if pure.loss != out.loss && which == 1 {
                let other: Vec<f64> = pure.d_first.iter().chain(&pure.d_second).copied().collect();
                prop_assert!(!compare("pure bound for bound with overshoot", &numeric, &other, TOL).passed());
            }
            // The cap is there: where a pixel is capped (the losses differ), the uncapped
            // gradient fails it.
            if which >= 2 {
                let uncapped = pair_event_loss_with(&images[..3 * N], &images[3 * N..], &expected, 1e-3, BOUND);
                if uncapped.loss != out.loss {
                    let other: Vec<f64> = uncapped.d_first.iter().chain(&uncapped.d_second).copied().collect();
                    prop_assert!(!compare("uncapped for capped", &numeric, &other, TOL).passed());
                }
            }
            // The Huber form is not the truncation: where a pixel is past the cap (the losses
            // differ), the truncated gradient (no pull there) fails it.
            if which == 3 {
                let cut = pair_event_loss_with(&images[..3 * N], &images[3 * N..], &expected, 1e-3, CAPPED);
                if cut.loss != out.loss {
                    let other: Vec<f64> = cut.d_first.iter().chain(&cut.d_second).copied().collect();
                    prop_assert!(!compare("truncated for huber", &numeric, &other, TOL).passed());
                }
            }
        }
        checker.finish();
    }

    /// The squared penalty pooled on blocks (`pair_event_loss_pooled`) on a 6 × 4 image, blocks
    /// of 2 and 3 pixels (the last column of 3-blocks is partial), about a fifth of the pixels
    /// unconstrained: the gradient against central differences, failing when negated and when
    /// the per-pixel penalty's gradient stands in for it. Same tolerance as above (the loss is a
    /// smooth square of a mean of logs).
    #[test]
    fn pooled_event_loss_gradient_matches(
        images in prop::collection::vec(0.05f64..1.0, 2 * 3 * N),
        counts in prop::collection::vec(-3i32..4, N),
        block in 2usize..4,
        silent in prop::collection::vec(prop::bool::weighted(0.2), N),
    ) {
        let expected: Vec<f64> = counts
            .iter()
            .zip(&silent)
            .map(|(&c, &s)| if s { f64::from(UNCONSTRAINED) } else { 0.2 * f64::from(c) })
            .collect();
        let width = 6;
        let loss = |x: &[f64]| pair_event_loss_pooled(&x[..3 * N], &x[3 * N..], &expected, 1e-3, width, block);
        let out = loss(&images);
        let analytic: Vec<f64> = out.d_first.iter().chain(&out.d_second).copied().collect();
        let numeric = central_differences(|x| loss(x).loss, &images, H);
        let mut checker = GradientChecker::new();
        checker.check(&format!("pooled event loss, {block} x {block} blocks"), &numeric, &analytic, TOL);
        let neg: Vec<f64> = analytic.iter().map(|a| -a).collect();
        prop_assert!(!compare("negated", &numeric, &neg, TOL).passed());
        let per_pixel = pair_event_loss_with(&images[..3 * N], &images[3 * N..], &expected, 1e-3, EventPenalty::Squared);
        let other: Vec<f64> = per_pixel.d_first.iter().chain(&per_pixel.d_second).copied().collect();
        prop_assert!(!compare("per pixel for pooled", &numeric, &other, TOL).passed());
        checker.finish();
    }

    /// The bound penalty with a spatial reach (`pair_event_loss_reach`) on a 6 × 4 image, reach 1
    /// or 2, uncapped or capped, about a fifth of the pixels unconstrained and a fifth silent: the
    /// gradient against central differences (the neighbourhood's largest or smallest change is a
    /// max / min, whose kinks at ties a probe of h = 1e-6 straddles with probability ~1e-6, as the
    /// bound's own kinks; same tolerance as above), failing when negated, when all zero, and when
    /// the per-pixel penalty's gradient stands in for it wherever a pixel is held through a
    /// neighbour (the losses differ).
    #[test]
    fn reach_event_loss_gradient_matches(
        images in prop::collection::vec(0.05f64..1.0, 2 * 3 * N),
        counts in prop::collection::vec(-3i32..4, N),
        reach in 1usize..3,
        capped in prop::bool::ANY,
        silent in prop::collection::vec(prop::bool::weighted(0.2), N),
    ) {
        let penalty = if capped { CAPPED } else { BOUND };
        let expected: Vec<f64> = counts
            .iter()
            .zip(&silent)
            .map(|(&c, &s)| {
                if s {
                    f64::from(UNCONSTRAINED)
                } else if c > 0 {
                    0.2 * f64::from(c)
                } else {
                    0.25 * f64::from(c)
                }
            })
            .collect();
        let width = 6;
        let loss = |x: &[f64]| {
            pair_event_loss_reach(&x[..3 * N], &x[3 * N..], &expected, 1e-3, penalty, (width, reach))
        };
        let out = loss(&images);
        let analytic: Vec<f64> = out.d_first.iter().chain(&out.d_second).copied().collect();
        let numeric = central_differences(|x| loss(x).loss, &images, H);
        let mut checker = GradientChecker::new();
        checker.check(&format!("event loss with reach {reach}, {penalty:?}"), &numeric, &analytic, TOL);
        let neg: Vec<f64> = analytic.iter().map(|a| -a).collect();
        prop_assert!(!compare("negated", &numeric, &neg, TOL).passed());
        prop_assert!(analytic.iter().any(|&a| a != 0.0));
        let per_pixel = pair_event_loss_with(&images[..3 * N], &images[3 * N..], &expected, 1e-3, penalty);
        if per_pixel.loss != out.loss {
            let other: Vec<f64> = per_pixel.d_first.iter().chain(&per_pixel.d_second).copied().collect();
            prop_assert!(!compare("per pixel for reach", &numeric, &other, TOL).passed());
        }
        checker.finish();
    }
}
