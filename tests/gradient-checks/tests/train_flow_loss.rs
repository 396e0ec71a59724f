//! Finite-difference check of the masked flow L1 (`train::loss::optical_flow::masked_l1`) w.r.t. the predicted
//! flow. The loss is piecewise linear; predictions are kept at least 1e-3 away from the target (≫ h),
//! so no kink is crossed and central differences are exact up to rounding (~1e-10). Tolerance
//! |num − ana| ≤ 1e-9 + 1e-6·max(|num|, |ana|). Unsupervised pixels must get exactly zero gradient,
//! which the zero-pattern check of `GradientChecker` enforces.

use gradient_checks::{central_differences, GradientChecker, Tolerance};
use proptest::prelude::*;
use train::loss::optical_flow::{masked_l1, prepare_target};

const TOL: Tolerance = Tolerance::new(1e-9, 1e-6);
const H: f64 = 1e-6;

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn masked_l1_gradient_matches(
        flow in prop::collection::vec(-6.0f64..6.0, 2 * 8 * 8),
        valid in prop::collection::vec(any::<bool>(), 8 * 8),
        offsets in prop::collection::vec((0.001f64..1.0, any::<bool>()), 2 * 4 * 4),
    ) {
        let target = prepare_target(&flow, Some(&valid), 8, 8, 4, 4, 0.5).expect("sizes match");
        let pred: Vec<f64> = target
            .flow
            .iter()
            .zip(&offsets)
            .map(|(t, (o, up))| if *up { t + o } else { t - o })
            .collect();
        let mut grad = vec![0.0; pred.len()];
        masked_l1(&pred, &target, Some(&mut grad));
        let numeric = central_differences(|p| masked_l1(p, &target, None), &pred, H);
        let mut checker = GradientChecker::new();
        checker.check("masked flow l1", &numeric, &grad, TOL);
        checker.finish();
    }
}
