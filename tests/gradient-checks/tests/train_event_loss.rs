//! Finite-difference check of the event-generation loss (`train::event_loss::pair_event_loss`)
//! w.r.t. both renders. The loss is smooth where the luma is positive (log of a positive value,
//! squared residual); renders are drawn in [0.05, 1] so no probe reaches the clamp at 0.
//! Tolerance in f64 with h = 1e-6: |num − ana| ≤ 1e-9 + 1e-6·max(|num|, |ana|) (loss O(1): rounding
//! ≈ 1e-10, truncation ≈ h²·|L'''| with |L'''| ≤ ~1e4 at luma ≥ 0.05 gives ≤ 1e-8 relative).

use gradient_checks::{central_differences, compare, GradientChecker, Tolerance};
use proptest::prelude::*;
use train::event_loss::pair_event_loss;

const TOL: Tolerance = Tolerance::new(1e-9, 1e-6);
const H: f64 = 1e-6;
const N: usize = 12;

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn event_loss_gradient_matches(
        images in prop::collection::vec(0.05f64..1.0, 2 * 3 * N),
        counts in prop::collection::vec(-3i32..4, N),
    ) {
        let expected: Vec<f64> = counts.iter().map(|&c| 0.2 * f64::from(c)).collect();
        let eval = |x: &[f64]| pair_event_loss(&x[..3 * N], &x[3 * N..], &expected, 1e-3).loss;
        let out = pair_event_loss(&images[..3 * N], &images[3 * N..], &expected, 1e-3);
        let analytic: Vec<f64> = out.d_first.iter().chain(&out.d_second).copied().collect();
        let numeric = central_differences(eval, &images, H);
        let mut checker = GradientChecker::new();
        checker.check("event loss d(render k, render k+1)", &numeric, &analytic, TOL);
        let neg: Vec<f64> = analytic.iter().map(|a| -a).collect();
        prop_assert!(!compare("negated", &numeric, &neg, TOL).passed());
        checker.finish();
    }
}
