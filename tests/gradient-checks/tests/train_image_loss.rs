//! Finite-difference checks of the image losses in `train::loss::image`: SSIM (hence D-SSIM) and L1
//! w.r.t. the predicted image.
//!
//! SSIM is a smooth rational function of blurred moments; with values in [0.05, 0.95] its denominators
//! stay ≥ C1, C2 > 0. Central differences with h = 1e-6 in f64 then have truncation error ~1e-12 and
//! rounding error ~ε·|f|/h ≈ 1e-10, while gradient entries are ~1/N ≈ 1e-3..1e-2 here; we require
//! |num − ana| ≤ 1e-9 + 1e-6·max(|num|, |ana|). L1 is piecewise linear: probes keep every
//! |pred − target| ≥ 1e-3 ≫ h so no kink is crossed, and the same tolerance applies.

use gradient_checks::{central_differences, GradientChecker, Tolerance};
use proptest::prelude::*;
use train::loss::image::{l1, ssim, ImageShape};

const TOL: Tolerance = Tolerance::new(1e-9, 1e-6);
const H: f64 = 1e-6;

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    #[test]
    fn ssim_gradient_matches_finite_differences(
        channels in 1usize..=3,
        height in 3usize..=14,
        width in 3usize..=14,
        seed_values in prop::collection::vec(0.05f64..0.95, 3 * 14 * 14 * 2),
    ) {
        let shape = ImageShape { channels, height, width };
        let n = shape.len();
        let pred = seed_values[..n].to_vec();
        let target = seed_values[n..2 * n].to_vec();
        let mut grad = vec![0.0; n];
        let value = ssim(&pred, &target, shape, Some(&mut grad));
        prop_assert!(value.is_finite() && value <= 1.0);
        let numeric = central_differences(|p| ssim(p, &target, shape, None), &pred, H);
        let mut checker = GradientChecker::new();
        checker.check(&format!("ssim {channels}x{height}x{width}"), &numeric, &grad, TOL);
        checker.finish();
    }

    #[test]
    fn l1_gradient_matches_finite_differences(
        pairs in prop::collection::vec((0.0f64..1.0, 0.001f64..0.5, any::<bool>()), 1..60),
    ) {
        let target: Vec<f64> = pairs.iter().map(|p| p.0).collect();
        let pred: Vec<f64> = pairs.iter().map(|p| if p.2 { p.0 + p.1 } else { p.0 - p.1 }).collect();
        let mut grad = vec![0.0; pred.len()];
        l1(&pred, &target, Some(&mut grad));
        let numeric = central_differences(|p| l1(p, &target, None), &pred, H);
        let mut checker = GradientChecker::new();
        checker.check("l1", &numeric, &grad, TOL);
        checker.finish();
    }
}
