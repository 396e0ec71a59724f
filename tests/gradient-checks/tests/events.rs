//! f64 finite-difference check of the contrast-maximisation objective's analytic gradient
//! (`events::CmaxProblem`): IWE bilinear voting, Gaussian blur, variance, tile interpolation, and the
//! smoothness, curvature and divergence penalties; and the affine level 0 through its 6 parameters.
//!
//! The bilinear vote has kinks where a warped event crosses a pixel boundary; events are generated
//! with dithering (non-integer positions) and times away from the reference so that a ±h probe
//! (h = 1e-6 px) crosses a boundary with negligible probability.

use events::cmax::{affine_pullback, affine_tiles};
use events::{CmaxConfig, CmaxProblem, Event, EventStream, SensorSize};
use gradient_checks::{central_differences, rng, symmetric_from_seed, GradientChecker, Tolerance};
use rand::Rng;

/// `n` events at uniformly random pixels and polarities, 1 to 20 µs apart.
fn stream(n: usize, w: u16, h: u16, seed: u64) -> EventStream {
    let mut s = EventStream::new();
    let mut rng = rng(seed);
    let mut t = 0i64;
    for _ in 0..n {
        t += rng.gen_range(1..=20);
        s.push(Event {
            t,
            x: rng.gen_range(0..w),
            y: rng.gen_range(0..h),
            p: if rng.gen::<bool>() { 1 } else { -1 },
        });
    }
    s
}

#[test]
fn cmax_objective_gradient_matches_finite_differences() {
    let mut checker = GradientChecker::new();
    let (w, h) = (24u16, 20u16);
    for (case, (tx, ty, smooth, curv, div)) in [
        (1, 1, 0.0, 0.0, 0.0),
        (2, 2, 0.01, 0.0, 5.0),
        (3, 2, 0.001, 0.3, 50.0),
        (4, 3, 0.0, 1.0, 50.0),
    ]
    .into_iter()
    .enumerate()
    {
        let ev = stream(600, w, h, 11 + case as u64);
        let t_b = ev.t[ev.len() - 1] + 1;
        let cfg = CmaxConfig {
            smoothness: smooth,
            curvature: curv,
            divergence: div,
            ..CmaxConfig::default()
        };
        let p = CmaxProblem::new(
            &ev.as_slice(),
            SensorSize::new(w as u32, h as u32),
            0,
            t_b,
            tx,
            ty,
            &cfg,
        )
        .expect("problem");
        let v: Vec<f64> = symmetric_from_seed(99 + case as u64, p.num_params())
            .iter()
            .map(|x| 1.5 * x)
            .collect();
        let (f, ana) = p.objective_and_gradient(&v);
        assert!((f - p.objective(&v)).abs() <= 1e-12 * f.abs().max(1.0));
        let num = central_differences(|x| p.objective(x), &v, 1e-6);
        // Objective ~1, smooth except at measure-zero kinks: truncation O(h²) ~ 1e-12, rounding
        // O(ε·f/h) ~ 1e-10. abs 1e-7 / rel 1e-5 leaves room for both and nothing more.
        checker.check(
            &format!("cmax {tx}x{ty} tiles"),
            &num,
            &ana,
            Tolerance::new(1e-7, 1e-5),
        );
    }
    checker.finish();
}

/// Level 0 of `flow_from_events`: the objective as a function of the 6 affine parameters through
/// `affine_tiles` on a 2×2 problem, with the gradient pulled back by `affine_pullback`, with the
/// curvature penalty of the default configuration on.
#[test]
fn cmax_affine_objective_gradient_matches_finite_differences() {
    let mut checker = GradientChecker::new();
    let (w, h) = (24u16, 20u16);
    for case in 0..4u64 {
        let ev = stream(600, w, h, 40 + case);
        let t_b = ev.t[ev.len() - 1] + 1;
        let cfg = CmaxConfig::default();
        assert!(
            cfg.curvature > 0.0,
            "the default level 0 uses the curvature penalty"
        );
        let p = CmaxProblem::new(
            &ev.as_slice(),
            SensorSize::new(w as u32, h as u32),
            0,
            t_b,
            2,
            2,
            &cfg,
        )
        .expect("problem");
        let theta: Vec<f64> = symmetric_from_seed(7 + case, 6)
            .iter()
            .map(|x| 1.5 * x)
            .collect();
        let (_, g_tiles) = p.objective_and_gradient(&affine_tiles(&theta));
        let ana = affine_pullback(&g_tiles);
        let num = central_differences(|th| p.objective(&affine_tiles(th)), &theta, 1e-6);
        // Same scale and tolerance argument as the tile test above.
        checker.check(
            &format!("cmax affine case {case}"),
            &num,
            &ana,
            Tolerance::new(1e-7, 1e-5),
        );
    }
    checker.finish();
}
