//! f64 finite-difference checks of the LPIPS gradient with respect to the first image
//! (`lpips::Lpips::distance_and_gradient`) — the one generic code path the training loss runs in f32.
//!
//! Two networks with the LPIPS structure (strided 11×11 stem, two 3/2 max-pools, five ReLU taps,
//! channel normalisation, 1×1 heads, spatial means): a reduced one with random weights
//! (`Lpips::random`, 6–10 channels per tap) on every input value of 64 × 64 and 35 × 41 images, and
//! the shipped AlexNet weights cast to f64 on a 31 × 40 image (the smallest height), on 120 random
//! input values (the full network in f64 costs ≈ 5 ms per evaluation, so every value would take
//! minutes).
//!
//! Tolerance `abs 1e-9, rel 1e-6` with step `h = 1e-6`. Around the probe point the distance is smooth:
//! every ReLU pre-activation is at least 1e-4 from 0 and every max-pool window's maximum at least 1e-4
//! above its runner-up (`Lpips::kink_margin`, asserted), while one probe moves an activation by h times
//! its derivative with respect to one input value, O(1) here (inputs scaled by 2/0.45, He-scaled
//! weights): two orders of magnitude from any kink. The distance is ≈ 1, so rounding gives
//! ≈ ε·|d|/h ≈ 1e-10 and truncation h²·|d'''| a few 1e-12 (measured: relative L2 error ≈ 1e-8);
//! gradient entries are 1e-5–1e-1, and a wrong term (the normalisation's `f fᵀ` part, the 2/scale
//! factor, a pool's routing) is off by far more. Each case also proves the comparison would fail for
//! the negated, halved and all-zero gradient.

use gradient_checks::{central_differences, compare, rng, GradientChecker, Tolerance};
use lpips::Lpips;
use rand::Rng;

const H: f64 = 1e-6;
const TOL: Tolerance = Tolerance::new(1e-9, 1e-6);
/// Smallest distance from a kink the test points must keep (see the module docs).
const MARGIN: f64 = 1e-4;

/// `n` values uniform in [0, 1) (an image as LPIPS takes it).
fn uniform(r: &mut impl Rng, n: usize) -> Vec<f64> {
    (0..n).map(|_| r.gen_range(0.0..1.0)).collect()
}

/// Draws image pairs from `seed` on until the first image's forward pass keeps [`MARGIN`] from every
/// kink; returns (first image, reference image).
fn images_away_from_kinks(
    net: &Lpips<f64>,
    seed: u64,
    height: usize,
    width: usize,
) -> (Vec<f64>, Vec<f64>) {
    for attempt in 0..20 {
        let mut r = rng(seed + 1000 * attempt);
        let a = uniform(&mut r, 3 * height * width);
        let b = uniform(&mut r, 3 * height * width);
        let margin = net.kink_margin(&a, height, width).expect("size");
        if margin >= MARGIN {
            return (a, b);
        }
    }
    panic!("no test point {MARGIN} away from every kink in 20 draws");
}

/// Checks `analytic` against `numeric` and that a negated, halved or zeroed gradient would fail.
fn check(checker: &mut GradientChecker, name: &str, numeric: &[f64], analytic: &[f64]) {
    checker.check(name, numeric, analytic, TOL);
    let neg: Vec<f64> = analytic.iter().map(|a| -a).collect();
    let half: Vec<f64> = analytic.iter().map(|a| 0.5 * a).collect();
    let zero = vec![0.0; analytic.len()];
    for (what, bad) in [("negated", neg), ("halved", half), ("zeroed", zero)] {
        assert!(
            !compare(name, numeric, &bad, TOL).passed(),
            "{name}: a {what} gradient would pass this check"
        );
    }
}

#[test]
fn lpips_gradient_of_a_reduced_network_matches_finite_differences_everywhere() {
    let mut checker = GradientChecker::new();
    for (seed, height, width) in [(1u64, 64usize, 64usize), (2, 35, 41)] {
        let net = Lpips::<f64>::random([6, 8, 10, 8, 6], seed);
        let (a, b) = images_away_from_kinks(&net, seed, height, width);
        let reference = net.features(&b, height, width).expect("size");
        let (value, gradient) = net
            .distance_and_gradient(&a, height, width, &reference)
            .expect("size");
        assert_eq!(
            value,
            net.distance_to(&a, height, width, &reference)
                .expect("size")
        );
        let numeric = central_differences(
            |p| net.distance_to(p, height, width, &reference).expect("size"),
            &a,
            H,
        );
        check(
            &mut checker,
            &format!("reduced LPIPS {height}x{width} seed {seed}"),
            &numeric,
            &gradient,
        );
    }
    checker.finish();
}

#[test]
fn lpips_gradient_of_the_shipped_network_matches_finite_differences_on_sampled_values() {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../data-fixtures/lpips/alexnet-lpips-v0.1.safetensors"
    );
    let net = lpips::load_safetensors(std::path::Path::new(path))
        .expect("the shipped LPIPS weights")
        .cast::<f64>();
    let (height, width) = (lpips::MIN_SIZE, 40);
    let (a, b) = images_away_from_kinks(&net, 7, height, width);
    let reference = net.features(&b, height, width).expect("size");
    let (_, gradient) = net
        .distance_and_gradient(&a, height, width, &reference)
        .expect("size");
    let mut r = rng(11);
    let picks: Vec<usize> = (0..120).map(|_| r.gen_range(0..a.len())).collect();
    let mut probe = a.clone();
    let numeric: Vec<f64> = picks
        .iter()
        .map(|&i| {
            let mut at = |v: f64| {
                probe[i] = v;
                net.distance_to(&probe, height, width, &reference)
                    .expect("size")
            };
            let slope = (at(a[i] + H) - at(a[i] - H)) / (2.0 * H);
            probe[i] = a[i];
            slope
        })
        .collect();
    let analytic: Vec<f64> = picks.iter().map(|&i| gradient[i]).collect();
    let mut checker = GradientChecker::new();
    check(
        &mut checker,
        "AlexNet LPIPS 31x40, 120 sampled values",
        &numeric,
        &analytic,
    );
    checker.finish();
}
