//! Whole-network f64 finite-difference check of the SPyNet input gradients (both images), and of the
//! weight gradients of a few convolutions, on small random images with 2- and 3-level networks.
//!
//! Kinks: the network is piecewise smooth (ReLUs, bilinear cells of the warp, border clamping). Each
//! probe evaluates the forward pass at `x ± h·e_i` and compares [`flow::Tape::region_signature`] with the
//! centre's; a probe whose three signatures differ straddles a kink, where a difference quotient means
//! nothing, and is dropped from the comparison (the test asserts that at most 2% are dropped and
//! reports how many). Inside one region the network is smooth.
//!
//! Tolerance: `abs 1e-6, rel 1e-5`, step `h = 1e-6`. `L = ⟨g, flow⟩` is O(10); rounding in the
//! difference quotient is `≈ ε·|L|/h ≈ 1e-16·10/1e-6 = 1e-9`, and the truncation error `h²·|L'''|/6`
//! is below 1e-10 for the O(1)–O(100) third derivatives of these O(1)-scaled networks; the tolerance
//! leaves a ≥100× margin, yet a wrong sign, a missing term (e.g. the warp's flow path, the pyramid
//! pooling path, the skip connection) or a zero gradient changes entries by O(0.01–1) and fails.

use flow::SpyNet;
use gradient_checks::{central_differences, compare, rng, symmetric, GradientChecker, Tolerance};
use proptest::prelude::*;
use rand::Rng;
use std::cell::RefCell;

const H: f64 = 1e-6;
const TOL: Tolerance = Tolerance::new(1e-6, 1e-5);

/// A random f64 network whose last layers are scaled so the predicted flow is O(1) px (so the warp,
/// its flow path and border clamping are all exercised).
fn network(levels: usize, seed: u64) -> SpyNet<f64> {
    let mut net = SpyNet::<f64>::random(levels, seed);
    for level in &mut net.levels {
        for v in &mut level[4].weight {
            *v *= 30.0;
        }
    }
    net
}

/// Numeric gradient of `x ↦ ⟨g, f(x)⟩` at the probe coordinates `probe`, where `x` is the
/// concatenation of the probed vector; drops probes that straddle a kink. Returns (kept indices,
/// numeric values).
fn probe_numeric(
    x: &[f64],
    probe: &[usize],
    eval: impl Fn(&[f64]) -> (f64, u64),
) -> (Vec<usize>, Vec<f64>, usize) {
    let (_, centre) = eval(x);
    let mut kept = Vec::new();
    let mut num = Vec::new();
    let mut dropped = 0;
    for &i in probe {
        let sigs = RefCell::new(Vec::new());
        let d = central_differences(
            |p| {
                let mut full = x.to_vec();
                full[i] = p[0];
                let (l, s) = eval(&full);
                sigs.borrow_mut().push(s);
                l
            },
            &[x[i]],
            H,
        );
        if sigs.borrow().iter().all(|&s| s == centre) {
            kept.push(i);
            num.push(d[0]);
        } else {
            dropped += 1;
        }
    }
    (kept, num, dropped)
}

/// Weights (`bias = false`) or bias of convolution `i` of level `level`.
fn conv_param(n: &SpyNet<f64>, level: usize, i: usize, bias: bool) -> Vec<f64> {
    let c = &n.levels[level][i];
    if bias {
        c.bias.clone()
    } else {
        c.weight.clone()
    }
}

/// `n` with the weights (or bias) of convolution `i` of level `level` replaced by `p`.
fn with_conv_param(n: &SpyNet<f64>, level: usize, i: usize, bias: bool, p: &[f64]) -> SpyNet<f64> {
    let mut m = n.clone();
    let c = &mut m.levels[level][i];
    if bias {
        c.bias.copy_from_slice(p);
    } else {
        c.weight.copy_from_slice(p);
    }
    m
}

/// [`probe_numeric`] at `count` random coordinates of one convolution's weights or bias, `eval`
/// giving `(L, region signature)` of a whole network.
fn probe_conv(
    net: &SpyNet<f64>,
    (level, i, bias): (usize, usize, bool),
    count: usize,
    rng: &mut impl Rng,
    eval: impl Fn(&SpyNet<f64>) -> (f64, u64),
) -> (Vec<usize>, Vec<f64>, usize) {
    let x = conv_param(net, level, i, bias);
    let probe: Vec<usize> = (0..count).map(|_| rng.gen_range(0..x.len())).collect();
    probe_numeric(&x, &probe, |p| {
        eval(&with_conv_param(net, level, i, bias, p))
    })
}

fn check_case(levels: usize, h: usize, w: usize, seed: u64, probes: Option<usize>) {
    check_case_with(network(levels, seed), h, w, seed, probes);
}

fn check_case_with(net: SpyNet<f64>, h: usize, w: usize, seed: u64, probes: Option<usize>) {
    let levels = net.num_levels();
    let mut rng = rng(seed ^ 0xF10);
    let n = 3 * h * w;
    let imgs: Vec<f64> = (0..2 * n).map(|_| rng.gen::<f64>()).collect();
    let g = symmetric(&mut rng, 2 * h * w);
    let eval = |x: &[f64]| {
        let tape = net.forward(&x[..n], &x[n..], h, w).expect("forward");
        let l: f64 = tape.flow.iter().zip(&g).map(|(a, b)| a * b).sum();
        (l, tape.region_signature())
    };
    let tape = net.forward(&imgs[..n], &imgs[n..], h, w).expect("forward");
    let max_flow = tape.flow.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    assert!(
        max_flow > 0.3,
        "test network predicts too little flow ({max_flow}) to exercise the warp"
    );
    let (d1, d2) = net.backward(&tape, &g, None).expect("backward");
    let analytic: Vec<f64> = d1.iter().chain(&d2).copied().collect();
    let probe: Vec<usize> = match probes {
        None => (0..2 * n).collect(),
        Some(k) => (0..k).map(|_| rng.gen_range(0..2 * n)).collect(),
    };
    let (kept, numeric, dropped) = probe_numeric(&imgs, &probe, eval);
    assert!(
        dropped * 50 <= probe.len(),
        "{dropped} of {} probes straddled a kink",
        probe.len()
    );
    let ana: Vec<f64> = kept.iter().map(|&i| analytic[i]).collect();
    let name =
        format!("spynet L={levels} {h}x{w} seed {seed} d(img1,img2) ({dropped} probes dropped)");
    let mut checker = GradientChecker::new();
    checker.check(&name, &numeric, &ana, TOL);
    // The check must be able to fail: wrong sign and a zeroed image-2 gradient (the warp path).
    let neg: Vec<f64> = ana.iter().map(|a| -a).collect();
    assert!(
        !compare(&name, &numeric, &neg, TOL).passed(),
        "{name}: negated gradient passes"
    );
    let no_img2: Vec<f64> = kept
        .iter()
        .map(|&i| if i >= n { 0.0 } else { analytic[i] })
        .collect();
    if kept.iter().any(|&i| i >= n) {
        assert!(
            !compare(&name, &numeric, &no_img2, TOL).passed(),
            "{name}: zero d img2 passes"
        );
    }
    checker.finish();
}

#[test]
fn two_level_network_all_input_coordinates() {
    check_case(2, 6, 8, 11, None);
}

#[test]
fn three_level_network_resized_input_sampled_coordinates() {
    // 7x10 is not a multiple of 4: exercises the resize-in / resize-back path.
    check_case(3, 7, 10, 23, Some(120));
}

#[test]
fn reference_pyramid_rule_running_two_of_three_levels() {
    // Halving while a side exceeds 6: 7x10 is resized to 8x12, pooled once to 4x6, and stops, so
    // the finest weights are unused; the resize-in / resize-back path and the shorter pyramid's
    // pooling backward are both exercised.
    let net = network(3, 31).with_depth(flow::PyramidDepth::HalveWhileAbove(6));
    assert_eq!(net.levels_run(7, 10), 2);
    check_case_with(net, 7, 10, 31, Some(120));
}

#[test]
fn weight_gradients_of_selected_convolutions() {
    let (levels, h, w) = (2, 6, 8);
    let net = network(levels, 5);
    let mut rng = rng(77);
    let n = 3 * h * w;
    let img1: Vec<f64> = (0..n).map(|_| rng.gen::<f64>()).collect();
    let img2: Vec<f64> = (0..n).map(|_| rng.gen::<f64>()).collect();
    let g = symmetric(&mut rng, 2 * h * w);
    let tape = net.forward(&img1, &img2, h, w).expect("forward");
    let mut grads = net.zeros_like();
    net.backward(&tape, &g, Some(&mut grads)).expect("backward");
    let mut checker = GradientChecker::new();
    for (l, i, bias) in [
        (0, 0, false),
        (0, 4, true),
        (1, 1, false),
        (1, 3, true),
        (1, 4, false),
    ] {
        let len = if bias {
            net.levels[l][i].bias.len()
        } else {
            net.levels[l][i].weight.len()
        };
        let probe: Vec<usize> = (0..24.min(len)).map(|_| rng.gen_range(0..len)).collect();
        let params = conv_param(&net, l, i, bias);
        let eval = |p: &[f64]| {
            let m = with_conv_param(&net, l, i, bias, p);
            let t = m.forward(&img1, &img2, h, w).expect("forward");
            (
                t.flow.iter().zip(&g).map(|(a, b)| a * b).sum::<f64>(),
                t.region_signature(),
            )
        };
        let (kept, numeric, dropped) = probe_numeric(&params, &probe, eval);
        assert!(
            dropped * 10 <= probe.len(),
            "level {l} conv {i}: {dropped} probes on kinks"
        );
        let all = conv_param(&grads, l, i, bias);
        let ana: Vec<f64> = kept.iter().map(|&k| all[k]).collect();
        checker.check(
            &format!("level{l}.conv{i} {}", if bias { "bias" } else { "weight" }),
            &numeric,
            &ana,
            TOL,
        );
    }
    checker.finish();
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(3))]
    #[test]
    fn random_two_level_networks_sampled_coordinates(seed in any::<u64>(), h in 4usize..7, w in 4usize..7) {
        check_case(2, 2 * (h / 2), 2 * (w / 2), seed, Some(60));
    }
}

/// The trainer's loss ([`flow::train::level_epe_loss`]: partial forward to the trained level,
/// smoothed EPE against the level's ground truth, last-level weight backward) against central
/// differences of the same function, for weights and biases of all five convolutions of the trained
/// level on a 2-level network (level 0 frozen, so its weight gradient must stay zero).
///
/// Tolerance `abs 1e-6, rel 1e-5`, step `h = 1e-6`: the loss is an O(1) mean of smoothed EPEs,
/// smooth inside one region (probes straddling a ReLU or warp-cell kink are dropped as above; the
/// smoothed norm `√(|d|² + 1e-6)` has curvature ≤ 1/√ε = 1e3, so its truncation error at `h = 1e-6`
/// is ≤ 1e3·h² ≈ 1e-9 for unit-scale weight sensitivities); rounding `≈ 1e-16/1e-6 = 1e-10`.
fn check_trainer_loss(seed: u64) {
    use flow::synthetic::{generate_pair, PairConfig};
    use flow::train::{flow_at_level, level_epe_loss};
    let levels = 2;
    let size = 8;
    let net = network(levels, seed);
    let pair = generate_pair(
        seed,
        0,
        &PairConfig {
            size,
            ..PairConfig::default()
        },
    );
    let f64v = |v: &[f32]| v.iter().map(|&x| f64::from(x)).collect::<Vec<f64>>();
    let (i1, i2) = (f64v(&pair.img1), f64v(&pair.img2));
    let truth = f64v(&flow_at_level(&pair.flow, size, size, levels, 1));
    let mut grads = net.zeros_like();
    let loss =
        level_epe_loss(&net, &i1, &i2, size, size, 1, &truth, Some(&mut grads), 1.0).expect("loss");
    assert!(loss > 0.1, "degenerate loss {loss}");
    let eval = |n: &SpyNet<f64>| {
        let l = level_epe_loss(n, &i1, &i2, size, size, 1, &truth, None, 1.0).expect("loss");
        let sig = n
            .forward_to_level(&i1, &i2, size, size, 1)
            .expect("forward")
            .region_signature();
        (l, sig)
    };
    let mut rng = rng(seed ^ 0x7a1);
    let mut checker = GradientChecker::new();
    for i in 0..5 {
        for bias in [false, true] {
            let (kept, numeric, dropped) = probe_conv(&net, (1, i, bias), 12, &mut rng, eval);
            assert!(dropped <= 3, "conv{i}: {dropped} of 12 probes on a kink");
            let g = conv_param(&grads, 1, i, bias);
            let ana: Vec<f64> = kept.iter().map(|&k| g[k]).collect();
            let name = format!("trainer loss seed {seed} level1.conv{i} bias={bias}");
            checker.check(&name, &numeric, &ana, TOL);
            let scaled: Vec<f64> = ana.iter().map(|a| 1.5 * a).collect();
            if numeric.iter().any(|v| v.abs() > 1e-4) {
                assert!(
                    !compare(&name, &numeric, &scaled, TOL).passed(),
                    "{name}: a 1.5x gradient passes"
                );
            }
        }
    }
    checker.finish();
    assert!(
        grads.levels[0]
            .iter()
            .all(|c| c.weight.iter().chain(&c.bias).all(|&v| v == 0.0)),
        "the frozen level 0 received a weight gradient"
    );
}

#[test]
fn trainer_loss_weight_gradient_matches_finite_differences() {
    check_trainer_loss(3);
}

/// Weight gradients of a multi-scale loss (`SpyNet::backward_multiscale_weights`, the joint
/// training of all levels): `L = Σ_l ⟨g_l, flow_l⟩` with random cotangents `g_l` on every level's
/// output of a 3-level network, against central differences, for weights and biases of every
/// convolution of every level. Level 0's weights reach `L` both directly (its own output) and
/// through the upsampling and the warps of the finer levels, so a missing path changes them.
/// Tolerance and kink handling as above (`L` is an O(10) linear functional of the flows).
fn check_multiscale(seed: u64) {
    let (levels, size) = (3, 8);
    let net = network(levels, seed);
    let mut rng = rng(seed ^ 0x3c5);
    let mut img = || {
        (0..3 * size * size)
            .map(|_| rng.gen::<f64>())
            .collect::<Vec<f64>>()
    };
    let (i1, i2) = (img(), img());
    let tape = net
        .forward_to_level(&i1, &i2, size, size, levels - 1)
        .expect("forward");
    let cot: Vec<Vec<f64>> = (0..levels)
        .map(|l| {
            let n = tape.level_flow(l).expect("level").len();
            symmetric(&mut rng, n)
        })
        .collect();
    let mut grads = net.zeros_like();
    net.backward_multiscale_weights(&tape, &cot, &mut grads)
        .expect("backward");
    let eval = |n: &SpyNet<f64>| {
        let t = n
            .forward_to_level(&i1, &i2, size, size, levels - 1)
            .expect("forward");
        let l: f64 = (0..levels)
            .map(|l| {
                let f = t.level_flow(l).expect("level");
                f.iter().zip(&cot[l]).map(|(a, b)| a * b).sum::<f64>()
            })
            .sum();
        (l, t.region_signature())
    };
    let mut checker = GradientChecker::new();
    for level in 0..levels {
        for i in 0..5 {
            for bias in [false, true] {
                let (kept, numeric, dropped) =
                    probe_conv(&net, (level, i, bias), 6, &mut rng, eval);
                assert!(
                    dropped <= 2,
                    "level{level}.conv{i}: {dropped} of 6 probes on a kink"
                );
                let g = conv_param(&grads, level, i, bias);
                let ana: Vec<f64> = kept.iter().map(|&k| g[k]).collect();
                let name = format!("multiscale seed {seed} level{level}.conv{i} bias={bias}");
                checker.check(&name, &numeric, &ana, TOL);
            }
        }
    }
    checker.finish();
    // Level 0 without the finer levels' paths: only its own cotangent. Must differ from the full
    // gradient (the upsampling/warp paths carry signal), so a backward that dropped them fails.
    let mut own = net.zeros_like();
    let only0: Vec<Vec<f64>> = cot
        .iter()
        .enumerate()
        .map(|(l, c)| {
            if l == 0 {
                c.clone()
            } else {
                vec![0.0; c.len()]
            }
        })
        .collect();
    net.backward_multiscale_weights(&tape, &only0, &mut own)
        .expect("backward");
    let differs = own.levels[0][4]
        .weight
        .iter()
        .zip(&grads.levels[0][4].weight)
        .any(|(a, b)| (a - b).abs() > 1e-6 * (1.0 + b.abs()));
    assert!(
        differs,
        "finer levels contribute nothing to level 0's gradient"
    );
    let nonzero = grads
        .levels
        .iter()
        .all(|l| l.iter().all(|c| c.weight.iter().any(|&v| v != 0.0)));
    assert!(nonzero, "a level received an all-zero weight gradient");
}

#[test]
fn multiscale_weight_gradients_match_finite_differences() {
    check_multiscale(5);
    check_multiscale(11);
}

/// The training steps' per-pixel loss with per-pixel weights ([`flow::train::pixel_loss`]):
/// its gradient w.r.t. the predicted flow against central differences, for both losses, random
/// flows, truths and weights (a quarter of them zero). Tolerance as above: the loss is an O(1)
/// weighted mean; away from `d = 0` (differences here are O(0.1–1) px) the smoothed norm's
/// curvature is O(1/|d|) ≤ O(100), so truncation at `h = 1e-6` is ≤ 1e-10. A gradient without the
/// weights (uniform), without the `1/Σw` normalisation or with a wrong sign changes entries by
/// O(0.01–1) and fails; a 1.5× gradient is checked to fail too.
fn check_weighted_pixel_loss(seed: u64, hw: usize, kind: flow::train::Loss) {
    let mut rng = rng(seed);
    let mut vec_of = |n: usize, lo: f64, hi: f64| -> Vec<f64> {
        (0..n).map(|_| rng.gen_range(lo..hi)).collect()
    };
    let flow = vec_of(2 * hw, -2.0, 2.0);
    let truth: Vec<f64> = flow
        .iter()
        .zip(vec_of(2 * hw, 0.1, 1.0))
        .enumerate()
        .map(|(i, (f, d))| if i % 3 == 0 { f - d } else { f + d })
        .collect();
    let mut weight: Vec<f32> = vec_of(hw, -0.33, 1.0)
        .iter()
        .map(|&v| v.max(0.0) as f32)
        .collect();
    weight[0] = weight[0].max(0.5); // not all zero

    let name = format!("weighted pixel loss seed {seed} {kind:?}");
    let (_, _, grad) =
        flow::train::pixel_loss(&flow, &truth, Some(&weight), kind, 1.0).expect("loss");
    let numeric = central_differences(
        |f| {
            flow::train::pixel_loss(f, &truth, Some(&weight), kind, 1.0)
                .expect("loss")
                .0
        },
        &flow,
        H,
    );
    let mut checker = GradientChecker::new();
    checker.check(&name, &numeric, &grad, TOL);
    checker.finish();
    let scaled: Vec<f64> = grad.iter().map(|g| 1.5 * g).collect();
    assert!(
        !compare(&name, &numeric, &scaled, TOL).passed(),
        "{name}: a 1.5x gradient passes"
    );
    let (_, _, uniform) = flow::train::pixel_loss(&flow, &truth, None, kind, 1.0).expect("loss");
    assert!(
        !compare(&name, &numeric, &uniform, TOL).passed(),
        "{name}: the unweighted gradient passes"
    );
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(16))]
    #[test]
    fn weighted_pixel_loss_gradient_matches_finite_differences(seed in any::<u64>(), hw in 2usize..40) {
        check_weighted_pixel_loss(seed, hw, flow::train::Loss::Epe);
        check_weighted_pixel_loss(seed, hw, flow::train::Loss::Mse);
    }
}
