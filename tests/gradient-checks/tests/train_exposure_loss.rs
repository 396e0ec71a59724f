//! Finite-difference check of the exposure model's image terms (`train::loss::photometric`): the
//! photometric loss — (1 − λ)·L1 + λ·(1 − SSIM) — of the mean of S sub-exposure renders against the
//! observed frame, plus the weighted event-generation loss between consecutive renders, between
//! every pair of renders (some intervals without events), or consecutive and silent spans, w.r.t. every render, for S = 1, 2, 3 and 5. Each render carries a fourth plane
//! (the trainer's human probability) that the terms ignore: its cotangent must be exactly zero.
//! With a grey frame (three equal planes) the photometric terms compare the mean render's Rec. 601
//! luminance; the colour cotangent (without the luminance's adjoint) fails that case.
//!
//! Tolerance in f64 with h = 1e-6: the loss is O(1), so rounding is ≈ ε·|L|/h ≈ 2e-10; the terms are
//! smooth (SSIM, log of luma ≥ 0.05) except at L1's kinks where the mean equals the observed value;
//! a probe of 1e-6 moves the mean by at most 2e-6 (modulation factors ≤ 2), so cases with a mean
//! within 1e-5 of the observed value somewhere are rejected (`clear_of_l1_kinks`: about 1 % of
//! them; a random case once landed 5e-7 from a kink and failed);
//! truncation h²·|L'''| is ≤ 1e-8 at luma ≥ 0.05. |num − ana| ≤ 1e-9 + 1e-6·max(|num|, |ana|) keeps
//! more than an order of magnitude of margin. Dropping the 1/S of the mean, or the weight of the
//! event pairs, fails it (asserted below). The event terms run with the squared or the bound
//! penalty (`train::loss::event::EventPenalty`).

use gradient_checks::{central_differences, compare, rng, GradientChecker, Tolerance};
use proptest::prelude::*;
use rand::Rng;
use train::loss::event::EventPenalty;
use train::loss::image::ImageShape;
use train::loss::photometric::{exposure_loss, ExposureEvents, PhotometricWeights, RenderPairs};

/// λ = 0.2, μ = 0 (the image-gradient term has its own check, `train_image_gradient.rs`).
const WEIGHTS: PhotometricWeights<f64> = PhotometricWeights {
    ssim: 0.2,
    image_gradient: 0.0,
};

const TOL: Tolerance = Tolerance::new(1e-9, 1e-6);
const H: f64 = 1e-6;
const SIDE: usize = 12;
const HW: usize = SIDE * SIDE;
const PLANES: usize = 4;
/// The bound penalty of `train::loss::event` (its kinks: see `train_event_loss.rs`).
const BOUND: EventPenalty = EventPenalty::Bound {
    c_pos: 0.2,
    c_neg: 0.2,
    margin: 0.5,
    dead_zone: 1.0,
    overshoot: 0.3,
    cap: f64::INFINITY,
    huber: false,
};

/// The terms' value for S renders laid out one after the other in `x` (PLANES × HW each).
fn value(
    x: &[f64],
    observed: &[f64],
    expected: &[Option<Vec<f64>>],
    event_weight: f64,
    pairs: RenderPairs,
    grey: bool,
    penalty: EventPenalty,
    modulation: &[Option<Vec<f64>>],
) -> (f64, Vec<Vec<f64>>) {
    let renders: Vec<&[f64]> = x.chunks(PLANES * HW).collect();
    let shape = ImageShape {
        channels: 3,
        height: SIDE,
        width: SIDE,
    };
    let out = exposure_loss(
        &renders,
        observed,
        shape,
        WEIGHTS,
        Some(ExposureEvents {
            expected,
            weight: event_weight,
            penalty,
            log_eps: 1e-3,
            pairs,
            pool: 1,
            reach: 0,
            modulation,
        }),
        PLANES,
        grey,
    );
    (out.photometric + out.events, out.d_renders)
}

/// Whether every value of the terms' prediction (the mean render, or its luminance) lies at least
/// 1e-5 from the observed frame's, i.e. no finite-difference probe crosses one of L1's kinks.
#[allow(clippy::too_many_arguments)]
fn clear_of_l1_kinks(
    x: &[f64],
    observed: &[f64],
    expected: &[Option<Vec<f64>>],
    pairs: RenderPairs,
    grey: bool,
    penalty: EventPenalty,
    modulation: &[Option<Vec<f64>>],
) -> bool {
    let renders: Vec<&[f64]> = x.chunks(PLANES * HW).collect();
    let shape = ImageShape {
        channels: 3,
        height: SIDE,
        width: SIDE,
    };
    let events = ExposureEvents {
        expected,
        weight: 0.7,
        penalty,
        log_eps: 1e-3,
        pairs,
        pool: 1,
        reach: 0,
        modulation,
    };
    let out = exposure_loss(
        &renders,
        observed,
        shape,
        WEIGHTS,
        Some(events),
        PLANES,
        grey,
    );
    out.prediction
        .iter()
        .zip(observed)
        .all(|(p, o)| (p - o).abs() >= 1e-5)
}

/// S random renders (PLANES planes each, one after the other) and a random observed frame (three
/// equal planes when `grey`), values in [0.05, 1).
fn renders_and_frame(rng: &mut impl Rng, subframes: usize, grey: bool) -> (Vec<f64>, Vec<f64>) {
    let x: Vec<f64> = (0..subframes * PLANES * HW)
        .map(|_| rng.gen_range(0.05..1.0))
        .collect();
    let mut observed: Vec<f64> = (0..3 * HW).map(|_| rng.gen_range(0.05..1.0)).collect();
    if grey {
        let (first, rest) = observed.split_at_mut(HW);
        rest[..HW].copy_from_slice(first);
        rest[HW..].copy_from_slice(first);
    }
    (x, observed)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(8))]

    #[test]
    fn exposure_terms_gradient_matches(seed in any::<u64>(), which in 0usize..4, which_pairs in 0usize..3, grey in any::<bool>(), bound in any::<bool>()) {
        let penalty = if bound { BOUND } else { EventPenalty::Squared };
        let subframes = [1, 2, 3, 5][which];
        let pairs = [RenderPairs::Consecutive, RenderPairs::All, RenderPairs::SilentSpans][which_pairs];
        let mut rng = rng(seed);
        let (x, observed) = renders_and_frame(&mut rng, subframes, grey);
        // Every other pair has events (C·E with C = 0.2); the first pair has none.
        let expected: Vec<Option<Vec<f64>>> = (0..subframes.saturating_sub(1))
            .map(|s| (s % 2 == 1 || subframes == 2).then(|| (0..HW).map(|_| 0.2 * f64::from(rng.gen_range(-3i32..4))).collect()))
            .collect();
        prop_assume!(clear_of_l1_kinks(&x, &observed, &expected, pairs, grey, penalty, &[]));
        let (_, d) = value(&x, &observed, &expected, 0.7, pairs, grey, penalty, &[]);
        let analytic: Vec<f64> = d.concat();
        let numeric = central_differences(|p| value(p, &observed, &expected, 0.7, pairs, grey, penalty, &[]).0, &x, H);
        let mut checker = GradientChecker::new();
        checker.check(&format!("exposure terms, S = {subframes}, {pairs:?}, grey {grey}"), &numeric, &analytic, TOL);
        if grey {
            // The luminance's adjoint is needed: the colour cotangent fails a grey frame.
            let (_, colour) = value(&x, &observed, &expected, 0.7, pairs, false, penalty, &[]);
            prop_assert!(!compare("colour cotangent on a grey frame", &numeric, &colour.concat(), TOL).passed());
        }
        // The probability plane is not part of the terms.
        for render in &d {
            prop_assert!(render[3 * HW..].iter().all(|&v| v == 0.0));
        }
        if subframes > 1 {
            // The mean's 1/S is needed: the unscaled photometric cotangent fails.
            let (_, d_no_events) = value(&x, &observed, &expected, 0.0, pairs, grey, penalty, &[]);
            let unscaled: Vec<f64> = d.iter().zip(&d_no_events).flat_map(|(with, without)| {
                with.iter().zip(without).map(move |(&a, &b)| a + (subframes as f64 - 1.0) * b)
            }).collect();
            prop_assert!(!compare("unscaled mean", &numeric, &unscaled, TOL).passed());
            // And so is every event pair's weight.
            let unweighted: Vec<f64> = d.iter().zip(&d_no_events).flat_map(|(with, without)| {
                with.iter().zip(without).map(|(&a, &b)| b + (a - b) / 0.7)
            }).collect();
            if expected.iter().any(Option::is_some) {
                prop_assert!(!compare("unweighted events", &numeric, &unweighted, TOL).passed());
            }
        }
        checker.finish();
    }

    /// Every interval covered, most pixels silent in each (counts of −1, 0, 0, 0 or +1
    /// thresholds): the silent spans' longer pairs add terms on the pixels silent across them, with
    /// the exact gradient; the consecutive pairs' gradient alone fails (the longer pairs count).
    #[test]
    fn silent_span_terms_gradient_matches(seed in any::<u64>(), which in 0usize..2) {
        let subframes = [3, 5][which];
        let mut rng = rng(seed);
        let (x, observed) = renders_and_frame(&mut rng, subframes, false);
        let expected: Vec<Option<Vec<f64>>> = (0..subframes - 1)
            .map(|_| Some((0..HW).map(|_| 0.2 * f64::from([-1, 0, 0, 0, 1][rng.gen_range(0..5)])).collect()))
            .collect();
        prop_assume!(clear_of_l1_kinks(&x, &observed, &expected, RenderPairs::SilentSpans, false, BOUND, &[]));
        let f = |p: &[f64], pairs| value(p, &observed, &expected, 0.7, pairs, false, BOUND, &[]);
        let (_, d) = f(&x, RenderPairs::SilentSpans);
        let numeric = central_differences(|p| f(p, RenderPairs::SilentSpans).0, &x, H);
        let mut checker = GradientChecker::new();
        checker.check(&format!("silent spans, S = {subframes}"), &numeric, &d.concat(), TOL);
        let (_, consecutive) = f(&x, RenderPairs::Consecutive);
        prop_assert!(!compare("consecutive pairs only", &numeric, &consecutive.concat(), TOL).passed());
        checker.finish();
    }

    /// With the events' modulation of each render's slice (`ExposureEvents::modulation`: random
    /// factors in [0.5, 2], the first render unmodulated), the prediction is the mean of
    /// (r + ε)·M − ε; its cotangent reaches a render multiplied by M, which the cotangent without
    /// the factor fails.
    #[test]
    fn modulated_exposure_terms_gradient_matches(seed in any::<u64>(), which in 0usize..3, grey in any::<bool>()) {
        let subframes = [2, 3, 5][which];
        let mut rng = rng(seed);
        let (x, observed) = renders_and_frame(&mut rng, subframes, grey);
        let expected: Vec<Option<Vec<f64>>> = (0..subframes - 1)
            .map(|_| Some((0..HW).map(|_| 0.2 * f64::from(rng.gen_range(-3i32..4))).collect()))
            .collect();
        let modulation: Vec<Option<Vec<f64>>> = (0..subframes)
            .map(|s| (s > 0).then(|| (0..HW).map(|_| rng.gen_range(0.5..2.0)).collect()))
            .collect();
        prop_assume!(clear_of_l1_kinks(&x, &observed, &expected, RenderPairs::Consecutive, grey, BOUND, &modulation));
        let f = |p: &[f64]| value(p, &observed, &expected, 0.7, RenderPairs::Consecutive, grey, BOUND, &modulation);
        let (_, d) = f(&x);
        let numeric = central_differences(|p| f(p).0, &x, H);
        let mut checker = GradientChecker::new();
        checker.check(&format!("modulated exposure terms, S = {subframes}, grey {grey}"), &numeric, &d.concat(), TOL);
        // The factor M is needed in the cotangent: without it the check fails.
        let (_, d_events_only) = value(&x, &observed, &expected, 0.7, RenderPairs::Consecutive, grey, BOUND, &[]);
        let unfactored: Vec<f64> = d.iter().zip(&modulation).flat_map(|(render, m)| {
            render.iter().enumerate().map(move |(i, &v)| match m {
                Some(m) if i < 3 * HW => v / m[i % HW],
                _ => v,
            })
        }).collect();
        prop_assert!(!compare("cotangent without M", &numeric, &unfactored, TOL).passed());
        // And the modulation changes the loss: the unmodulated gradient fails too.
        prop_assert!(!compare("unmodulated", &numeric, &d_events_only.concat(), TOL).passed());
        checker.finish();
    }
}
