//! Finite-difference check of the image-gradient term (`train::loss::image_gradient`): the L1
//! distance between the right / down finite differences of a prediction and of its target, alone
//! and as part of the exposure model's photometric loss (`train::loss::photometric`, weight μ, the
//! mean of S renders, colour or grey frames), w.r.t. the prediction or every render.
//!
//! Tolerance in f64 with h = 1e-6: the term is piecewise linear, so away from its kinks (a
//! difference of the residual equal to zero) the central difference is exact up to rounding,
//! ≈ ε·|G|/h ≈ 1e-10 for G = O(1). A probe of 1e-6 moves a difference of the residual by at most
//! 2e-6 (the mean's 1/S only shrinks it), so cases where one lies within 1e-5 of zero are rejected
//! (`clear_of_kinks`), as are the photometric L1's (a mean within 1e-5 of the observed value).
//! |num − ana| ≤ 1e-9 + 1e-6·max(|num|, |ana|). The negated gradient, the gradient without the
//! vertical differences, and the photometric loss's gradient without μ's term each fail it
//! (asserted below).

use gradient_checks::{central_differences, compare, rng, GradientChecker, Tolerance};
use proptest::prelude::*;
use rand::Rng;
use train::loss::image::ImageShape;
use train::loss::image_gradient::image_gradient_l1;
use train::loss::photometric::{exposure_loss, PhotometricWeights};

const TOL: Tolerance = Tolerance::new(1e-9, 1e-6);
const H: f64 = 1e-6;
const HEIGHT: usize = 7;
const WIDTH: usize = 9;
const HW: usize = HEIGHT * WIDTH;

/// Whether every right / down difference of `pred − target` (3 planes) is at least 1e-5 from zero.
fn clear_of_kinks(pred: &[f64], target: &[f64]) -> bool {
    let r: Vec<f64> = pred.iter().zip(target).map(|(p, t)| p - t).collect();
    (0..3 * HW).all(|i| {
        let (x, y) = (i % WIDTH, (i / WIDTH) % HEIGHT);
        let right = x + 1 >= WIDTH || (r[i + 1] - r[i]).abs() >= 1e-5;
        let down = y + 1 >= HEIGHT || (r[i + WIDTH] - r[i]).abs() >= 1e-5;
        right && down
    })
}

/// G and its gradient.
fn term(pred: &[f64], target: &[f64]) -> (f64, Vec<f64>) {
    let mut grad = vec![0.0; pred.len()];
    let g = image_gradient_l1(pred, target, (3, HEIGHT, WIDTH), Some(&mut grad));
    (g, grad)
}

/// The photometric loss of S renders (3 planes each, one after the other in `x`) with weights λ, μ.
fn photometric(x: &[f64], observed: &[f64], mu: f64, grey: bool) -> (f64, Vec<f64>, Vec<f64>) {
    let renders: Vec<&[f64]> = x.chunks(3 * HW).collect();
    let shape = ImageShape {
        channels: 3,
        height: HEIGHT,
        width: WIDTH,
    };
    let weights = PhotometricWeights {
        ssim: 0.2,
        image_gradient: mu,
    };
    let out = exposure_loss(&renders, observed, shape, weights, None, 3, grey);
    (out.photometric, out.d_renders.concat(), out.prediction)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(16))]

    #[test]
    fn image_gradient_term_matches(seed in any::<u64>()) {
        let mut rng = rng(seed);
        let pred: Vec<f64> = (0..3 * HW).map(|_| rng.gen_range(0.0..1.0)).collect();
        let target: Vec<f64> = (0..3 * HW).map(|_| rng.gen_range(0.0..1.0)).collect();
        prop_assume!(clear_of_kinks(&pred, &target));
        let (_, analytic) = term(&pred, &target);
        let numeric = central_differences(|p| term(p, &target).0, &pred, H);
        let mut checker = GradientChecker::new();
        checker.check("image-gradient L1", &numeric, &analytic, TOL);
        let negated: Vec<f64> = analytic.iter().map(|g| -g).collect();
        prop_assert!(!compare("negated", &numeric, &negated, TOL).passed());
        // Without the vertical differences: the horizontal ones' gradient alone (each row as a
        // 1 × W image, rescaled to the full term's count) fails.
        let mut horizontal = vec![0.0; 3 * HW];
        let count_all = 3.0 * (HEIGHT * (WIDTH - 1) + (HEIGHT - 1) * WIDTH) as f64;
        for (row, out) in horizontal.chunks_mut(WIDTH).enumerate() {
            let span = row * WIDTH..(row + 1) * WIDTH;
            image_gradient_l1(&pred[span.clone()], &target[span], (1, 1, WIDTH), Some(out));
        }
        let rescaled: Vec<f64> = horizontal.iter().map(|g| g * (WIDTH - 1) as f64 / count_all).collect();
        prop_assert!(!compare("horizontal differences only", &numeric, &rescaled, TOL).passed());
        checker.finish();
    }

    #[test]
    fn photometric_loss_with_the_image_gradient_term_matches(seed in any::<u64>(), which in 0usize..3, grey in any::<bool>()) {
        let subframes = [1, 2, 5][which];
        let mut rng = rng(seed);
        let x: Vec<f64> = (0..subframes * 3 * HW).map(|_| rng.gen_range(0.05..1.0)).collect();
        let mut observed: Vec<f64> = (0..3 * HW).map(|_| rng.gen_range(0.05..1.0)).collect();
        if grey {
            let (first, rest) = observed.split_at_mut(HW);
            rest[..HW].copy_from_slice(first);
            rest[HW..].copy_from_slice(first);
        }
        let (_, _, prediction) = photometric(&x, &observed, 0.5, grey);
        prop_assume!(clear_of_kinks(&prediction, &observed));
        prop_assume!(prediction.iter().zip(&observed).all(|(p, o)| (p - o).abs() >= 1e-5));
        let (_, analytic, _) = photometric(&x, &observed, 0.5, grey);
        let numeric = central_differences(|p| photometric(p, &observed, 0.5, grey).0, &x, H);
        let mut checker = GradientChecker::new();
        checker.check(&format!("photometric with μ = 0.5, S = {subframes}, grey {grey}"), &numeric, &analytic, TOL);
        // The term counts: the photometric gradient without it fails.
        let (_, without, _) = photometric(&x, &observed, 0.0, grey);
        prop_assert!(!compare("without the image-gradient term", &numeric, &without, TOL).passed());
        checker.finish();
    }
}
