//! Fast kernels against slow, obviously-correct oracles (forward and with a random cotangent backward).

use nn::*;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// `n` values uniform in [-1, 1) from `rng`.
fn symmetric(rng: &mut impl Rng, n: usize) -> Vec<f64> {
    (0..n).map(|_| rng.gen_range(-1.0..1.0)).collect()
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

fn max_diff(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

#[test]
fn conv2d_matches_direct_oracle_forward_and_adjoint() {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    for &(batch, c_in, c_out, h, w, k, pad) in &[
        (1, 3, 4, 9, 7, 3, 1),
        (2, 2, 3, 6, 11, 7, 3),
        (1, 1, 2, 5, 5, 1, 0),
        (2, 3, 2, 8, 40, 5, 0),
        (1, 2, 2, 30, 33, 7, 3),
        (1, 2, 3, 1, 2, 7, 3),
        (2, 2, 3, 2, 1, 5, 2),
    ] {
        let s = Conv2dShape {
            batch,
            c_in,
            c_out,
            height: h,
            width: w,
            kernel: k,
            stride: 1,
            pad,
        };
        let x = symmetric(&mut rng, s.input_len());
        let wt = symmetric(&mut rng, s.weight_len());
        let b = symmetric(&mut rng, c_out);
        let mut fast = vec![0.0; s.output_len()];
        let mut slow = vec![0.0; s.output_len()];
        conv2d_forward(s, &x, &wt, Some(&b), &mut fast).expect("shape");
        conv2d_reference(s, &x, &wt, Some(&b), &mut slow).expect("shape");
        assert!(max_diff(&fast, &slow) < 1e-12, "{s:?} forward");
        // Adjoint identities: <g, conv(x)> = <conv_x^T g, x> = <conv_w^T g, w> (+ bias term).
        let g = symmetric(&mut rng, s.output_len());
        let mut dx = vec![0.0; s.input_len()];
        conv2d_backward_input(s, &g, &wt, &mut dx).expect("shape");
        let mut nobias = vec![0.0; s.output_len()];
        conv2d_reference(s, &x, &wt, None, &mut nobias).expect("shape");
        let lhs = dot(&g, &nobias);
        assert!(
            (lhs - dot(&dx, &x)).abs() < 1e-9 * (1.0 + lhs.abs()),
            "{s:?} dx"
        );
        let mut dw = vec![0.0; s.weight_len()];
        let mut db = vec![0.0; c_out];
        conv2d_backward_weight(s, &x, &g, &mut dw, Some(&mut db)).expect("shape");
        assert!(
            (lhs - dot(&dw, &wt)).abs() < 1e-9 * (1.0 + lhs.abs()),
            "{s:?} dw"
        );
        let gsum: f64 = dot(&db, &b);
        assert!(
            (dot(&g, &slow) - lhs - gsum).abs() < 1e-9 * (1.0 + lhs.abs()),
            "{s:?} db"
        );
    }
}

#[test]
fn conv2d_f32_is_identical_for_one_and_two_threads() {
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let s = Conv2dShape {
        batch: 1,
        c_in: 8,
        c_out: 16,
        height: 40,
        width: 36,
        kernel: 7,
        stride: 1,
        pad: 3,
    };
    let x: Vec<f32> = symmetric(&mut rng, s.input_len())
        .iter()
        .map(|&v| v as f32)
        .collect();
    let w: Vec<f32> = symmetric(&mut rng, s.weight_len())
        .iter()
        .map(|&v| v as f32)
        .collect();
    let g: Vec<f32> = symmetric(&mut rng, s.output_len())
        .iter()
        .map(|&v| v as f32)
        .collect();
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("pool");
        pool.install(|| {
            let mut y = vec![0.0f32; s.output_len()];
            conv2d_forward(s, &x, &w, None, &mut y).expect("shape");
            let mut dx = vec![0.0f32; s.input_len()];
            conv2d_backward_input(s, &g, &w, &mut dx).expect("shape");
            let mut dw = vec![0.0f32; s.weight_len()];
            conv2d_backward_weight(s, &x, &g, &mut dw, None).expect("shape");
            (y, dx, dw)
        })
    };
    assert_eq!(run(1), run(2));
}

#[test]
fn dense_matches_naive_loops() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let s = DenseShape {
        batch: 5,
        inputs: 7,
        outputs: 3,
    };
    let x = symmetric(&mut rng, 35);
    let w = symmetric(&mut rng, 21);
    let b = symmetric(&mut rng, 3);
    let mut y = vec![0.0; 15];
    dense_forward(s, &x, &w, Some(&b), &mut y).expect("shape");
    for r in 0..5 {
        for o in 0..3 {
            let want: f64 = b[o] + (0..7).map(|i| x[r * 7 + i] * w[o * 7 + i]).sum::<f64>();
            assert!((y[r * 3 + o] - want).abs() < 1e-12);
        }
    }
    assert_eq!(
        dense_forward(s, &x[..34], &w, None, &mut y),
        Err(NnError::Length {
            name: "dense x",
            expected: 35,
            actual: 34
        })
    );
}

#[test]
fn resize_identity_and_known_values() {
    let img: Vec<f64> = (0..12).map(f64::from).collect(); // 3 x 4
    for ac in [true, false] {
        let mut out = vec![0.0; 12];
        resize_bilinear_forward(1, 3, 4, &img, 3, 4, ac, &mut out).expect("shape");
        assert!(max_diff(&out, &img) < 1e-12);
    }
    // 1-D 2 -> 3 with align_corners: [0, 0.5, 1]·(a, b).
    let mut out = vec![0.0; 3];
    resize_bilinear_forward(1, 1, 2, &[2.0, 4.0], 1, 3, true, &mut out).expect("shape");
    assert_eq!(out, vec![2.0, 3.0, 4.0]);
    // align_corners=false 2 -> 4: sources max(-0.25,0)=0, 0.25, 0.75, 1.25->clamped to last pixel.
    let mut out = vec![0.0; 4];
    resize_bilinear_forward(1, 1, 2, &[2.0, 4.0], 1, 4, false, &mut out).expect("shape");
    assert_eq!(out, vec![2.0, 2.5, 3.5, 4.0]);
}

#[test]
fn pool_averages_only_covered_pixels() {
    let img: Vec<f64> = (0..15).map(f64::from).collect(); // 3 x 5
    let mut out = vec![0.0; 2 * 3];
    avg_pool2x2_forward(1, 3, 5, &img, &mut out).expect("shape");
    assert_eq!(out, vec![3.0, 5.0, 6.5, 10.5, 12.5, 14.0]);
}

#[test]
fn warp_by_integer_flow_shifts_and_clamps() {
    let img: Vec<f64> = (0..12).map(f64::from).collect(); // 1 channel, 3 x 4
    let mut flow = vec![0.0; 24];
    flow[..12].fill(1.0); // u = +1: out(x) = img(x + 1), last column clamped
    let mut out = vec![0.0; 12];
    warp_forward(1, 1, 3, 4, &img, &flow, &mut out).expect("shape");
    assert_eq!(&out[..4], &[1.0, 2.0, 3.0, 3.0]);
}

#[test]
fn adam_matches_hand_computed_steps() {
    let mut p = vec![1.0f64, -2.0];
    let mut opt = Adam::new(
        2,
        AdamConfig {
            lr: 0.1,
            ..AdamConfig::default()
        },
    );
    opt.step(&mut p, &[0.5, -3.0]).expect("len");
    // First step: m̂ = g, v̂ = g², update = lr·g/(|g| + eps) ≈ ±lr.
    assert!((p[0] - 0.9).abs() < 1e-7 && (p[1] + 1.9).abs() < 1e-7);
    opt.step(&mut p, &[0.5, 1.0]).expect("len");
    let (m, v) = (
        0.9 * 0.1 * -3.0 + 0.1 * 1.0,
        0.999 * 0.001 * 9.0 + 0.001 * 1.0,
    );
    let upd = 0.1 * (m / (1.0 - 0.81)) / ((v / (1.0 - 0.999f64.powi(2))).sqrt() + 1e-8);
    let p1 = -2.0 + 0.1 * 3.0 / (3.0 + 1e-8);
    assert!((p[1] - (p1 - upd)).abs() < 1e-12);
    assert_eq!(opt.steps(), 2);
}

#[test]
fn strided_conv2d_matches_direct_oracle_forward_and_adjoint() {
    let mut rng = ChaCha8Rng::seed_from_u64(17);
    for &(batch, c_in, c_out, h, w, k, stride, pad) in &[
        (1, 3, 4, 35, 31, 11, 4, 2), // AlexNet's stem at its smallest input
        (2, 2, 3, 13, 17, 11, 4, 2),
        (1, 2, 3, 9, 8, 3, 2, 1),
        (1, 1, 2, 7, 6, 1, 3, 0),
        (2, 3, 2, 10, 12, 5, 1, 2),
        (1, 2, 2, 6, 9, 4, 3, 0),
    ] {
        let s = Conv2dShape {
            batch,
            c_in,
            c_out,
            height: h,
            width: w,
            kernel: k,
            stride,
            pad,
        };
        let x = symmetric(&mut rng, s.input_len());
        let wt = symmetric(&mut rng, s.weight_len());
        let b = symmetric(&mut rng, c_out);
        let mut fast = vec![0.0; s.output_len()];
        let mut slow = vec![0.0; s.output_len()];
        conv2d_forward(s, &x, &wt, Some(&b), &mut fast).expect("shape");
        conv2d_reference(s, &x, &wt, Some(&b), &mut slow).expect("shape");
        assert!(max_diff(&fast, &slow) < 1e-12, "{s:?} forward");
        let g = symmetric(&mut rng, s.output_len());
        let mut nobias = vec![0.0; s.output_len()];
        conv2d_reference(s, &x, &wt, None, &mut nobias).expect("shape");
        let lhs = dot(&g, &nobias);
        let mut dx = vec![f64::NAN; s.input_len()];
        conv2d_backward_input(s, &g, &wt, &mut dx).expect("shape");
        assert!(
            (lhs - dot(&dx, &x)).abs() < 1e-9 * (1.0 + lhs.abs()),
            "{s:?} dx"
        );
        let mut dw = vec![0.0; s.weight_len()];
        let mut db = vec![0.0; c_out];
        conv2d_backward_weight(s, &x, &g, &mut dw, Some(&mut db)).expect("shape");
        assert!(
            (lhs - dot(&dw, &wt)).abs() < 1e-9 * (1.0 + lhs.abs()),
            "{s:?} dw"
        );
        assert!(
            (dot(&g, &slow) - lhs - dot(&db, &b)).abs() < 1e-9 * (1.0 + lhs.abs()),
            "{s:?} db"
        );
    }
}

#[test]
fn strided_conv2d_f32_is_identical_for_one_and_two_threads() {
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let s = Conv2dShape {
        batch: 1,
        c_in: 3,
        c_out: 16,
        height: 67,
        width: 70,
        kernel: 11,
        stride: 4,
        pad: 2,
    };
    let f32s = |v: Vec<f64>| v.iter().map(|&x| x as f32).collect::<Vec<f32>>();
    let x = f32s(symmetric(&mut rng, s.input_len()));
    let w = f32s(symmetric(&mut rng, s.weight_len()));
    let g = f32s(symmetric(&mut rng, s.output_len()));
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("pool");
        pool.install(|| {
            let mut y = vec![0.0f32; s.output_len()];
            conv2d_forward(s, &x, &w, None, &mut y).expect("shape");
            let mut dx = vec![0.0f32; s.input_len()];
            conv2d_backward_input(s, &g, &w, &mut dx).expect("shape");
            let mut dw = vec![0.0f32; s.weight_len()];
            conv2d_backward_weight(s, &x, &g, &mut dw, None).expect("shape");
            (y, dx, dw)
        })
    };
    assert_eq!(run(1), run(2));
}

#[test]
fn max_pool_matches_naive_windows_and_routes_gradients_to_the_first_maximum() {
    let mut rng = ChaCha8Rng::seed_from_u64(23);
    for &(planes, h, w, k, stride) in &[(2, 7, 9, 3, 2), (1, 8, 8, 2, 2), (3, 5, 4, 3, 1)] {
        let s = MaxPool2dShape {
            planes,
            height: h,
            width: w,
            kernel: k,
            stride,
        };
        // Values on a coarse grid, so that windows hold ties.
        let x: Vec<f64> = symmetric(&mut rng, s.input_len())
            .iter()
            .map(|v| (v * 3.0).round())
            .collect();
        let mut y = vec![0.0; s.output_len()];
        let mut arg = vec![0u32; s.output_len()];
        max_pool2d_forward(s, &x, &mut y, &mut arg).expect("shape");
        let (ho, wo) = (s.out_height(), s.out_width());
        assert_eq!((ho, wo), ((h - k) / stride + 1, (w - k) / stride + 1));
        let mut want_dx = vec![0.0; s.input_len()];
        let g = symmetric(&mut rng, s.output_len());
        for p in 0..planes {
            for oy in 0..ho {
                for ox in 0..wo {
                    let mut best = (f64::NEG_INFINITY, 0);
                    for iy in oy * stride..oy * stride + k {
                        for ix in ox * stride..ox * stride + k {
                            let v = x[(p * h + iy) * w + ix];
                            if v > best.0 {
                                best = (v, iy * w + ix);
                            }
                        }
                    }
                    let o = (p * ho + oy) * wo + ox;
                    assert_eq!((y[o], arg[o] as usize), best, "{s:?} ({p}, {oy}, {ox})");
                    want_dx[p * h * w + best.1] += g[o];
                }
            }
        }
        let mut dx = vec![f64::NAN; s.input_len()];
        max_pool2d_backward(s, &arg, &g, &mut dx).expect("shape");
        assert!(max_diff(&dx, &want_dx) < 1e-12, "{s:?} backward");
    }
    let s = MaxPool2dShape {
        planes: 1,
        height: 2,
        width: 5,
        kernel: 3,
        stride: 2,
    };
    let err = max_pool2d_forward(s, &[0.0; 10], &mut [], &mut []).expect_err("too small");
    assert!(matches!(err, NnError::Shape(_)), "{err:?}");
}
