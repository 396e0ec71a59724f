//! Finite-difference check of the priors on the person's size and opacity
//! (`train::loss::sharpness`) w.r.t. every log scale and every opacity logit, over random inputs
//! where only some Gaussians are the person's.
//!
//! Both priors are smooth (sums of exponentials and of the binary entropy of a logistic), so with
//! h = 1e-6 on inputs of order 1 the central differences are exact to ~1e-10 (truncation h²·f'''
//! ≈ 1e-12 at these scales, rounding ε·|f|/h ≈ 1e-10 for losses of order 1); the tolerance
//! |num − ana| ≤ 1e-8 + 1e-6·max(|num|, |ana|) leaves a margin of 100 over that. Each check also
//! asserts that a negated gradient and one without the entries of the Gaussians outside the
//! person (which must be exactly zero) fail it.

use gradient_checks::{central_differences, compare, GradientChecker, Tolerance};
use proptest::prelude::*;
use train::loss::sharpness::{opacity_entropy, size_prior};

const TOL: Tolerance = Tolerance::new(1e-8, 1e-6);
const H: f64 = 1e-6;

/// The person's Gaussians: every index whose flag is set (at least one).
fn person(flags: &[bool]) -> Vec<usize> {
    let mut index: Vec<usize> = (0..flags.len()).filter(|&i| flags[i]).collect();
    if index.is_empty() {
        index.push(0);
    }
    index
}

/// Compares `analytic` with `numeric`, and asserts that the two injected errors fail.
fn check(name: &str, numeric: &[f64], analytic: &[f64], per_gaussian: usize, index: &[usize]) {
    let mut checker = GradientChecker::new();
    checker.check(name, numeric, analytic, TOL);
    let negated: Vec<f64> = analytic.iter().map(|a| -a).collect();
    assert!(
        !compare(name, numeric, &negated, TOL).passed(),
        "{name}: the negated gradient passes"
    );
    // A gradient that also reaches the Gaussians outside the person must fail too (when there
    // are some): give each of them the first person Gaussian's gradient.
    if index.len() * per_gaussian < analytic.len() {
        let first = index[0] * per_gaussian;
        let leaked: Vec<f64> = (0..analytic.len())
            .map(|j| match index.contains(&(j / per_gaussian)) {
                true => analytic[j],
                false => analytic[first + j % per_gaussian],
            })
            .collect();
        assert!(
            !compare(name, numeric, &leaked, TOL).passed(),
            "{name}: a gradient on Gaussians outside the person passes"
        );
    }
    checker.finish();
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn size_prior_gradients_match(
        scales in prop::collection::vec(prop::array::uniform3(-6.0f64..-1.0), 2..24),
        flags in prop::collection::vec(any::<bool>(), 24),
        weight in 0.001f64..3.0,
    ) {
        let index = person(&flags[..scales.len()]);
        let mut d = vec![[0.0f64; 3]; scales.len()];
        size_prior(&scales, &index, weight, Some(&mut d));
        let flat: Vec<f64> = scales.iter().flatten().copied().collect();
        let numeric = central_differences(
            |p| {
                let s: Vec<[f64; 3]> = p.chunks(3).map(|c| [c[0], c[1], c[2]]).collect();
                size_prior(&s, &index, weight, None)
            },
            &flat,
            H,
        );
        let analytic: Vec<f64> = d.iter().flatten().copied().collect();
        check("size prior d log scales", &numeric, &analytic, 3, &index);
    }

    #[test]
    fn opacity_entropy_gradients_match(
        logits in prop::collection::vec(-8.0f64..8.0, 2..24),
        flags in prop::collection::vec(any::<bool>(), 24),
        weight in 0.001f64..3.0,
    ) {
        let index = person(&flags[..logits.len()]);
        // A logit at 0 has a zero gradient (the entropy's maximum): keep the person's away from it
        // so that the negated gradient is told apart.
        prop_assume!(index.iter().all(|&i| logits[i].abs() > 1e-3));
        let mut d = vec![0.0f64; logits.len()];
        opacity_entropy(&logits, &index, weight, Some(&mut d));
        let numeric =
            central_differences(|p| opacity_entropy(p, &index, weight, None), &logits, H);
        check("opacity entropy d logits", &numeric, &d, 1, &index);
    }
}
