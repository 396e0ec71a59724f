//! f64 central-finite-difference checks of every backward pass in `nn`.
//!
//! Each check draws random inputs and a random cotangent `g`, forms the scalar `L(x) = ⟨g, f(x)⟩` and
//! compares the analytic `∂L/∂x` from the op's backward pass with central differences of `L`.
//!
//! Tolerance (all checks): `abs 1e-7, rel 1e-6` with step `h = 1e-6`. Justification: every op here is,
//! around the probe point, either linear in the checked argument (dense, conv2d, pooling, resize, warp
//! w.r.t. the image), a polynomial of degree ≤ 2 in it (warp w.r.t. the flow is bilinear inside one
//! pixel cell), or smooth with |f'''| ≲ 1 (sigmoid, softplus). Central differences are exact on
//! quadratics, so the error is rounding, `≈ ε·|L|/h ≈ 1e-16·1e2/1e-6 = 1e-8`, plus `h²·|f'''|/6 ≈ 2e-13`
//! for the smooth ones: `1e-7` absolute leaves a 10× margin while a wrong sign, a missing term or a
//! zeroed gradient (all O(0.1–10) here) is off by many orders of magnitude. Each op additionally proves
//! the check is sensitive: the same comparison must fail for the negated, halved and all-zero analytic
//! gradient.
//!
//! Kinks: ReLU/LeakyReLU inputs are drawn with `|x| ≥ 0.05 ≫ h`; warp sample positions are kept at least
//! 0.1 px (≫ h) away from integer coordinates (bilinear cell edges) and from the clamping borders 0 and
//! `n − 1` (positions outside the image are kept ≥ 0.1 px outside, where the gradient is exactly 0 on
//! both sides).

use gradient_checks::{central_differences, compare, rng, symmetric, GradientChecker, Tolerance};
use nn::*;
use proptest::prelude::*;
use rand::Rng;

const H: f64 = 1e-6;
const TOL: Tolerance = Tolerance::new(1e-7, 1e-6);

/// `n` values with |x| uniform in [0.05, 1) and a random sign (away from the ReLU kink).
fn away_from_zero(rng: &mut impl Rng, n: usize) -> Vec<f64> {
    symmetric(rng, n)
        .into_iter()
        .map(|v| v.signum() * (0.05 + 0.95 * v.abs()))
        .collect()
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// Compares `analytic` with central differences of `x ↦ ⟨g, f(x)⟩`, and asserts that the comparison
/// would catch a wrong sign, a factor-2 error and an all-zero gradient.
fn check(
    checker: &mut GradientChecker,
    name: &str,
    x: &[f64],
    g: &[f64],
    f: impl Fn(&[f64]) -> Vec<f64>,
    analytic: &[f64],
) {
    let numeric = central_differences(|p| dot(g, &f(p)), x, H);
    checker.check(name, &numeric, analytic, TOL);
    if analytic.iter().any(|&a| a.abs() > 1e-3) {
        let neg: Vec<f64> = analytic.iter().map(|a| -a).collect();
        let half: Vec<f64> = analytic.iter().map(|a| 0.5 * a).collect();
        let zero = vec![0.0; analytic.len()];
        for (what, bad) in [("negated", neg), ("halved", half), ("zeroed", zero)] {
            assert!(
                !compare(name, &numeric, &bad, TOL).passed(),
                "{name}: a {what} gradient would pass this check"
            );
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(12))]

    #[test]
    fn dense_gradients(seed in any::<u64>(), batch in 1usize..4, inputs in 1usize..6, outputs in 1usize..5) {
        let mut r = rng(seed);
        let s = DenseShape { batch, inputs, outputs };
        let (x, w, b) = (symmetric(&mut r, batch * inputs), symmetric(&mut r, outputs * inputs), symmetric(&mut r, outputs));
        let g = symmetric(&mut r, batch * outputs);
        let fwd = |x: &[f64], w: &[f64], b: &[f64]| {
            let mut y = vec![0.0; batch * outputs];
            dense_forward(s, x, w, Some(b), &mut y).expect("shape");
            y
        };
        let mut dx = vec![f64::NAN; x.len()];
        let mut dw = vec![0.0; w.len()];
        let mut db = vec![0.0; b.len()];
        dense_backward(s, &x, &w, &g, Some(&mut dx), Some(&mut dw), Some(&mut db)).expect("shape");
        let mut c = GradientChecker::new();
        check(&mut c, "dense dx", &x, &g, |p| fwd(p, &w, &b), &dx);
        check(&mut c, "dense dw", &w, &g, |p| fwd(&x, p, &b), &dw);
        check(&mut c, "dense db", &b, &g, |p| fwd(&x, &w, p), &db);
        c.finish();
    }

    #[test]
    fn activation_gradients(seed in any::<u64>(), n in 1usize..40, slope in 0.01f64..0.3) {
        let mut r = rng(seed);
        let x = away_from_zero(&mut r, n);
        let xs: Vec<f64> = symmetric(&mut r, n).iter().map(|v| 6.0 * v).collect();
        let g = symmetric(&mut r, n);
        let mut c = GradientChecker::new();
        let run = |f: &dyn Fn(&[f64], &mut [f64]), p: &[f64]| {
            let mut y = vec![0.0; p.len()];
            f(p, &mut y);
            y
        };
        let mut d = vec![f64::NAN; n];
        relu_backward(&x, &g, &mut d);
        check(&mut c, "relu", &x, &g, |p| run(&|a, b| relu_forward(a, b), p), &d);
        leaky_relu_backward(&x, &g, &mut d, slope);
        check(&mut c, "leaky_relu", &x, &g, |p| run(&|a, b| leaky_relu_forward(a, b, slope), p), &d);
        let y = run(&|a, b| sigmoid_forward(a, b), &xs);
        sigmoid_backward(&y, &g, &mut d);
        check(&mut c, "sigmoid", &xs, &g, |p| run(&|a, b| sigmoid_forward(a, b), p), &d);
        softplus_backward(&xs, &g, &mut d);
        check(&mut c, "softplus", &xs, &g, |p| run(&|a, b| softplus_forward(a, b), p), &d);
        c.finish();
    }

    #[test]
    fn conv2d_gradients(
        seed in any::<u64>(),
        batch in 1usize..3,
        c_in in 1usize..3,
        c_out in 1usize..4,
        height in 1usize..7,
        width in 1usize..8,
        kp in prop::sample::select(vec![(1usize, 0usize), (3, 0), (3, 1), (3, 2), (5, 2), (7, 3)]),
    ) {
        let (kernel, pad) = kp;
        prop_assume!(height + 2 * pad >= kernel && width + 2 * pad >= kernel);
        let mut r = rng(seed);
        let s = Conv2dShape { batch, c_in, c_out, height, width, kernel, stride: 1, pad };
        let (x, w, b) = (symmetric(&mut r, s.input_len()), symmetric(&mut r, s.weight_len()), symmetric(&mut r, c_out));
        let g = symmetric(&mut r, s.output_len());
        let fwd = |x: &[f64], w: &[f64], b: &[f64]| {
            let mut y = vec![0.0; s.output_len()];
            conv2d_forward(s, x, w, Some(b), &mut y).expect("shape");
            y
        };
        let mut dx = vec![f64::NAN; x.len()];
        conv2d_backward_input(s, &g, &w, &mut dx).expect("shape");
        let mut dw = vec![0.0; w.len()];
        let mut db = vec![0.0; c_out];
        conv2d_backward_weight(s, &x, &g, &mut dw, Some(&mut db)).expect("shape");
        let mut c = GradientChecker::new();
        check(&mut c, "conv2d dx", &x, &g, |p| fwd(p, &w, &b), &dx);
        check(&mut c, "conv2d dw", &w, &g, |p| fwd(&x, p, &b), &dw);
        check(&mut c, "conv2d db", &b, &g, |p| fwd(&x, &w, p), &db);
        c.finish();
    }

    #[test]
    fn avg_pool_gradients(seed in any::<u64>(), planes in 1usize..4, h in 1usize..8, w in 1usize..8) {
        let mut r = rng(seed);
        let x = symmetric(&mut r, planes * h * w);
        let g = symmetric(&mut r, planes * pooled_size(h) * pooled_size(w));
        let mut dx = vec![f64::NAN; x.len()];
        avg_pool2x2_backward(planes, h, w, &g, &mut dx).expect("shape");
        let mut c = GradientChecker::new();
        check(&mut c, "avg_pool", &x, &g, |p| {
            let mut y = vec![0.0; g.len()];
            avg_pool2x2_forward(planes, h, w, p, &mut y).expect("shape");
            y
        }, &dx);
        c.finish();
    }

    #[test]
    fn resize_gradients(
        seed in any::<u64>(),
        planes in 1usize..3,
        h in 1usize..7,
        w in 1usize..7,
        ho in 1usize..12,
        wo in 1usize..12,
        align_corners in any::<bool>(),
    ) {
        let mut r = rng(seed);
        let x = symmetric(&mut r, planes * h * w);
        let g = symmetric(&mut r, planes * ho * wo);
        let mut dx = vec![f64::NAN; x.len()];
        resize_bilinear_backward(planes, h, w, ho, wo, align_corners, &g, &mut dx).expect("shape");
        let mut c = GradientChecker::new();
        check(&mut c, "resize", &x, &g, |p| {
            let mut y = vec![0.0; g.len()];
            resize_bilinear_forward(planes, h, w, p, ho, wo, align_corners, &mut y).expect("shape");
            y
        }, &dx);
        c.finish();
    }

    #[test]
    fn warp_gradients(seed in any::<u64>(), batch in 1usize..3, channels in 1usize..4, h in 2usize..7, w in 2usize..7) {
        let mut r = rng(seed);
        let img = symmetric(&mut r, batch * channels * h * w);
        let g = symmetric(&mut r, img.len());
        // Sample positions in [-1.5, n + 0.5], then moved ≥ 0.1 px away from integers (cell edges and
        // the clamping borders 0 and n-1 are integers).
        let mut flow = vec![0.0; batch * 2 * h * w];
        for b in 0..batch {
            for (axis, n) in [(0usize, w), (1, h)] {
                for y in 0..h {
                    for x in 0..w {
                        let mut pos = -1.5 + r.gen::<f64>() * (n as f64 + 2.0);
                        let frac = pos - pos.floor();
                        if frac < 0.1 {
                            pos += 0.1;
                        } else if frac > 0.9 {
                            pos -= 0.1;
                        }
                        let base = if axis == 0 { x } else { y } as f64;
                        flow[((b * 2 + axis) * h + y) * w + x] = pos - base;
                    }
                }
            }
        }
        let fwd = |img: &[f64], flow: &[f64]| {
            let mut y = vec![0.0; img.len()];
            warp_forward(batch, channels, h, w, img, flow, &mut y).expect("shape");
            y
        };
        let mut di = vec![f64::NAN; img.len()];
        let mut df = vec![f64::NAN; flow.len()];
        warp_backward(batch, channels, h, w, &img, &flow, &g, Some(&mut di), Some(&mut df)).expect("shape");
        let mut c = GradientChecker::new();
        check(&mut c, "warp d img", &img, &g, |p| fwd(p, &flow), &di);
        check(&mut c, "warp d flow", &flow, &g, |p| fwd(&img, p), &df);
        c.finish();
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(12))]

    #[test]
    fn strided_conv2d_gradients(
        seed in any::<u64>(),
        batch in 1usize..3,
        c_in in 1usize..3,
        c_out in 1usize..4,
        height in 1usize..14,
        width in 1usize..14,
        ksp in prop::sample::select(vec![(11usize, 4usize, 2usize), (3, 2, 1), (5, 2, 0), (2, 3, 1), (3, 1, 1)]),
    ) {
        let (kernel, stride, pad) = ksp;
        prop_assume!(height + 2 * pad >= kernel && width + 2 * pad >= kernel);
        let mut r = rng(seed);
        let s = Conv2dShape { batch, c_in, c_out, height, width, kernel, stride, pad };
        let (x, w, b) = (symmetric(&mut r, s.input_len()), symmetric(&mut r, s.weight_len()), symmetric(&mut r, c_out));
        let g = symmetric(&mut r, s.output_len());
        let fwd = |x: &[f64], w: &[f64], b: &[f64]| {
            let mut y = vec![0.0; s.output_len()];
            conv2d_forward(s, x, w, Some(b), &mut y).expect("shape");
            y
        };
        let mut dx = vec![f64::NAN; x.len()];
        conv2d_backward_input(s, &g, &w, &mut dx).expect("shape");
        let mut dw = vec![0.0; w.len()];
        let mut db = vec![0.0; c_out];
        conv2d_backward_weight(s, &x, &g, &mut dw, Some(&mut db)).expect("shape");
        let mut c = GradientChecker::new();
        check(&mut c, "strided conv2d dx", &x, &g, |p| fwd(p, &w, &b), &dx);
        check(&mut c, "strided conv2d dw", &w, &g, |p| fwd(&x, p, &b), &dw);
        check(&mut c, "strided conv2d db", &b, &g, |p| fwd(&x, &w, p), &db);
        c.finish();
    }

    /// Inputs are a random permutation of values 0.01 apart (≫ h), so no window's maximum changes
    /// under the probe: max pooling is linear around the test point.
    #[test]
    fn max_pool_gradients(
        seed in any::<u64>(),
        planes in 1usize..4,
        h in 3usize..9,
        w in 3usize..9,
        ks in prop::sample::select(vec![(3usize, 2usize), (2, 2), (3, 1)]),
    ) {
        let (kernel, stride) = ks;
        let mut r = rng(seed);
        let s = MaxPool2dShape { planes, height: h, width: w, kernel, stride };
        let n = s.input_len();
        let mut x: Vec<f64> = (0..n).map(|i| 0.01 * i as f64 - 0.005 * n as f64).collect();
        for i in (1..n).rev() {
            x.swap(i, r.gen_range(0..=i));
        }
        let g = symmetric(&mut r, s.output_len());
        let mut y = vec![0.0; s.output_len()];
        let mut arg = vec![0u32; s.output_len()];
        max_pool2d_forward(s, &x, &mut y, &mut arg).expect("shape");
        let mut dx = vec![f64::NAN; n];
        max_pool2d_backward(s, &arg, &g, &mut dx).expect("shape");
        let mut c = GradientChecker::new();
        check(&mut c, "max_pool", &x, &g, |p| {
            let mut y = vec![0.0; g.len()];
            let mut a = vec![0u32; g.len()];
            max_pool2d_forward(s, p, &mut y, &mut a).expect("shape");
            y
        }, &dx);
        c.finish();
    }
}
