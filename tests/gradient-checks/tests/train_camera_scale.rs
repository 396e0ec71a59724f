//! Finite-difference check of the camera corrections' scale prior
//! (`train::pose::camera_scale::scale_prior_terms`) w.r.t. every stored correction value.
//!
//! The prior is a quadratic form in the corrections, so central differences carry no truncation
//! error; with values of order 1 and h = 1e-6 their rounding error is ~1e-10. Tolerance:
//! |num − ana| ≤ 1e-8 + 1e-7·max(|num|, |ana|). Injected errors — the gradient negated, the
//! gradient missing on one axis, the rotations given the shifts' gradient — each fail it.

use gradient_checks::{
    central_differences, compare, symmetric_from_seed, GradientChecker, Tolerance,
};
use proptest::prelude::*;
use train::pose::camera_correction::CAMERA_CORRECTION_VALUES;
use train::pose::camera_scale::scale_prior_terms;

const TOL: Tolerance = Tolerance::new(1e-8, 1e-7);
const H: f64 = 1e-6;

proptest! {
    #![proptest_config(ProptestConfig::with_cases(32))]

    #[test]
    fn scale_prior_gradients_match(seed in any::<u64>(), frames in 3usize..12) {
        let n = CAMERA_CORRECTION_VALUES;
        let corrections: Vec<f64> =
            symmetric_from_seed(seed, frames * n).iter().map(|v| 0.01 * v).collect();
        let deviations: Vec<[f64; 3]> = symmetric_from_seed(seed ^ 0x5ca1e, frames * 3)
            .chunks(3)
            .map(|c| [0.03 * c[0], 0.03 * c[1], 0.03 * c[2]])
            .collect();
        let weights = (0.7, 0.01);
        let mut analytic = vec![0.0; corrections.len()];
        scale_prior_terms(&corrections, &deviations, weights, &mut analytic);
        let numeric = central_differences(
            |p| scale_prior_terms(p, &deviations, weights, &mut vec![0.0; p.len()]),
            &corrections,
            H,
        );
        let mut checker = GradientChecker::new();
        checker.check("scale prior", &numeric, &analytic, TOL);
        let negated: Vec<f64> = analytic.iter().map(|a| -a).collect();
        prop_assert!(!compare("negated", &numeric, &negated, TOL).passed());
        let mut one_axis_missing = analytic.clone();
        for row in one_axis_missing.chunks_mut(n) {
            row[4] = 0.0;
        }
        prop_assert!(!compare("one axis missing", &numeric, &one_axis_missing, TOL).passed());
        let mut on_rotations = analytic.clone();
        for row in on_rotations.chunks_mut(n) {
            let (rotation, shift) = row.split_at_mut(3);
            rotation.copy_from_slice(&shift[..3]);
        }
        prop_assert!(!compare("on the rotations", &numeric, &on_rotations, TOL).passed());
        checker.finish();
    }
}
