//! Checks of the camera's gradients through the rasterizer: `camera_pose_gradient` (a left twist
//! of the camera) and the learned camera correction chained through it, against central
//! differences of `render_cov`. Tolerances and probe validation as in `rasterize.rs`.
//!
//! Each check must be able to fail: the negated gradient fails every case with a numeric
//! derivative above twice the tolerance, and one injected error per check (a missing term) fails
//! at least 90 % of the cases over the run (a case can hold Gaussians for which that term is
//! below the tolerance).

mod raster_support;

use gradient_checks::compare;
use proptest::prelude::*;
use proptest::test_runner::TestCaseError;
use rand::Rng;
use raster_support::*;

/// True unless every kept probe's analytic derivative is zero and every numeric one within the
/// check's absolute tolerance of zero (a scene, or subset, the camera does not see).
fn seen(num: &[f64], kept: &[f64]) -> bool {
    kept.iter().any(|&a| a != 0.0) || num.iter().any(|&n| n.abs() > FD_TOL.abs)
}

/// Whether the comparison rejects `analytic` against `numeric` under `FD_TOL`.
fn rejected(numeric: &[f64], analytic: &[f64]) -> bool {
    !compare("injected", numeric, analytic, FD_TOL).passed()
}

/// Asserts that the negated `analytic` fails against `numeric` when some numeric derivative is
/// beyond twice the tolerance (a wrong sign cannot pass).
fn negation_fails(name: &str, numeric: &[f64], analytic: &[f64]) -> Result<(), TestCaseError> {
    let negated: Vec<f64> = analytic.iter().map(|a| -a).collect();
    let visible = numeric.iter().any(|n| n.abs() > 2.0 * FD_TOL.abs);
    prop_assert!(
        !visible || rejected(numeric, &negated),
        "{name}: the negated gradient passes"
    );
    Ok(())
}

/// Counts one case of an injected error in `tally` (one per check, judged from 10 cases on):
/// fails the case when, over the run so far, fewer than 90 % of the cases caught it.
fn tally_catch(tally: &ProbeTally, name: &str, caught: bool) -> Result<(), TestCaseError> {
    match tally.add_counts(1, usize::from(caught)) {
        Ok(()) => Ok(()),
        Err((hits, all)) => Err(TestCaseError::fail(format!(
            "{name}: the check caught the injected error in only {hits} of {all} cases"
        ))),
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    /// `camera_pose_gradient` (dL/dξ of the camera, from `render_cov_backward`'s world gradients)
    /// against central differences of `render_cov` from the camera moved by ±h along each of the
    /// six twist components (h = FD_H in radians or metres; the scene is 1-6 m away, so a probe
    /// moves a splat by ≤ 6·h relative, as a mean probe does: the FD_TOL argument above holds).
    /// Probes whose ± steps flip any discrete decision of the oracle are discarded.
    #[test]
    fn camera_pose_gradient_matches_finite_differences(
        seed in any::<u64>(),
        kinds in kinds_strategy(6),
        c in 1usize..4,
    ) {
        let (s, covs, cot, g) = cov_scene_and_gradients(seed, &kinds, c);
        let ana = camera_pose_gradient(&s.cam, &s.means, &covs, &g.means, &g.covariances)
            .unwrap_or_else(|e| panic!("camera_pose_gradient: {e}"));
        let base = oracle(&s, None).decisions;
        let (mut probes, mut valid) = (0usize, 0usize);
        let (mut num, mut kept, mut valid_axes) = (Vec::new(), Vec::new(), Vec::new());
        for k in 0..6 {
            probes += 1;
            let moved = |t: f64| {
                let mut xi = [0.0; 6];
                xi[k] = t;
                let mut s2 = s.clone();
                s2.cam = moved_camera(&s.cam, xi);
                s2
            };
            if oracle(&moved(FD_H), None).decisions != base
                || oracle(&moved(-FD_H), None).decisions != base
            {
                continue;
            }
            valid += 1;
            valid_axes.push(k);
            num.push(central_differences(|t| cov_loss(&moved(t[0]), &cot), &[0.0], FD_H)[0]);
            kept.push(ana[k]);
        }
        // A scene the camera does not see (no gradient, analytic or numeric) has nothing to
        // check; a zero analytic gradient against a difference beyond the tolerance still fails.
        prop_assume!(seen(&num, &kept));
        let mut checker = GradientChecker::new();
        checker.check("camera twist (ω, v) vs FD", &num, &kept, FD_TOL);
        negation_fails("camera twist", &num, &kept)?;
        // Injected: the covariances' share dropped (a rotating camera turns every footprint).
        let no_cov_terms = vec![[[0.0; 3]; 3]; s.n()];
        let without = camera_pose_gradient(&s.cam, &s.means, &covs, &g.means, &no_cov_terms)
            .unwrap_or_else(|e| panic!("camera_pose_gradient: {e}"));
        let injected: Vec<f64> = valid_axes.iter().map(|&k| without[k]).collect();
        static CAUGHT: ProbeTally = ProbeTally::new(10);
        let caught = rejected(&num, &injected);
        tally_catch(&CAUGHT, "camera twist without the covariance term", caught)?;
        static TALLY: ProbeTally = ProbeTally::new(30);
        let tally = TALLY.add(probes, valid);
        prop_assert!(tally.is_ok(), "{}", tally.unwrap_err());
        checker.finish();
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    /// A frame's learned camera correction (`train::pose::camera_correction`: twist
    /// ξ = mid + o·change, camera [Exp(ω) | v]·T) through the render: `camera_pose_gradient`
    /// chained by `twist_backward` and `correction_backward`, against central differences of
    /// `render_cov` over the 12 correction values. The corrections are large (ω up to 0.3 rad,
    /// v up to 0.2 m) so that the left Jacobian and the v × g_v term matter; the base camera is
    /// chosen so that the corrected one is the scene's (its Gaussians stay in view). A probe
    /// moves the camera by at most h (radians, metres), as in the twist check above: FD_TOL holds.
    /// Probes whose ± steps flip any discrete decision of the oracle are discarded.
    #[test]
    fn camera_correction_gradient_matches_finite_differences(
        seed in any::<u64>(),
        kinds in kinds_strategy(6),
        c in 1usize..4,
    ) {
        let (s, covs, cot, _) = cov_scene_and_gradients(seed, &kinds, c);
        let mut r = rng(seed ^ 0x00ca_3e7a);
        let limits = [0.3, 0.3, 0.3, 0.2, 0.2, 0.2, 0.2, 0.2, 0.2, 0.1, 0.1, 0.1];
        let correction: Vec<f64> = limits.iter().map(|&l| r.gen_range(-l..l)).collect();
        let offset = f64::from(r.gen_range(-0.5f32..0.5));
        let twist = |c: &[f64]| -> [f64; 6] { std::array::from_fn(|k| c[k] + offset * c[6 + k]) };
        let base = uncorrected(&s.cam.world_to_camera, &twist(&correction));
        let scene_at = |c: &[f64]| {
            let mut s2 = s.clone();
            s2.cam.world_to_camera = corrected_world_to_camera(&base, &twist(c));
            s2
        };
        let s0 = scene_at(&correction);
        let g = cov_gradients(&s0, &covs, &cot);
        let d_left = camera_pose_gradient(&s0.cam, &s0.means, &covs, &g.means, &g.covariances)
            .unwrap_or_else(|e| panic!("camera_pose_gradient: {e}"));
        let mut ana = vec![0.0; 12];
        correction_backward(&twist_backward(&d_left, &twist(&correction)), offset as f32, &mut ana);
        let base_decisions = oracle(&s0, None).decisions;
        let (mut probes, mut valid) = (0usize, 0usize);
        let (mut num, mut kept, mut valid_values) = (Vec::new(), Vec::new(), Vec::new());
        for k in 0..12 {
            probes += 1;
            let moved = |t: f64| {
                let mut c = correction.clone();
                c[k] += t;
                scene_at(&c)
            };
            if oracle(&moved(FD_H), None).decisions != base_decisions
                || oracle(&moved(-FD_H), None).decisions != base_decisions
            {
                continue;
            }
            valid += 1;
            valid_values.push(k);
            num.push(central_differences(|t| cov_loss(&moved(t[0]), &cot), &[0.0], FD_H)[0]);
            kept.push(ana[k]);
        }
        // A scene the camera does not see (no gradient, analytic or numeric) has nothing to
        // check; a zero analytic gradient against a difference beyond the tolerance still fails.
        prop_assume!(seen(&num, &kept));
        let mut checker = GradientChecker::new();
        checker.check("camera correction (mid ω, v; change ω, v) vs FD", &num, &kept, FD_TOL);
        negation_fails("camera correction", &num, &kept)?;
        // Injected: the twist's backward skipped (the left Jacobian and the v × g_v term lost).
        let mut without = vec![0.0; 12];
        correction_backward(&d_left, offset as f32, &mut without);
        let injected: Vec<f64> = valid_values.iter().map(|&k| without[k]).collect();
        static CAUGHT: ProbeTally = ProbeTally::new(10);
        let caught = rejected(&num, &injected);
        tally_catch(&CAUGHT, "camera correction without the twist's Jacobian", caught)?;
        static TALLY: ProbeTally = ProbeTally::new(60);
        let tally = TALLY.add(probes, valid);
        prop_assert!(tally.is_ok(), "{}", tally.unwrap_err());
        checker.finish();
    }
}

/// `world_to_camera⁻¹ · other`: the rigid map that carries a world point seen by `other` to the
/// point the camera `world_to_camera` sees at the same camera coordinates.
fn carried_along(world_to_camera: &[[f64; 4]; 4], other: &[[f64; 4]; 4]) -> [[f64; 4]; 4] {
    let r = world_to_camera;
    let mut out = [[0.0; 4]; 4];
    out[3][3] = 1.0;
    for i in 0..3 {
        for j in 0..4 {
            // Rᵀ (other_j − t) for the translation column, Rᵀ other_j for the rotation's.
            let column = |k: usize| other[k][j] - if j == 3 { r[k][3] } else { 0.0 };
            out[i][j] = (0..3).map(|k| r[k][i] * column(k)).sum();
        }
    }
    out
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    /// The camera gradient of a subset of the Gaussians (the person's, for the clip-wide camera
    /// twist of `train::pose::camera_correction`'s person gauge): `camera_pose_gradient` over the
    /// subset alone against central differences of `render_cov` with the camera moved by ±h and
    /// every other Gaussian carried along with it (its camera coordinates, mean and covariance,
    /// unchanged), so that only the subset moves on the image. The subset is a random non-empty
    /// proper one: the whole set's gradient fails the check wherever the others are seen.
    /// Probe size and tolerance as in the twist check above; probes whose ± steps flip any
    /// discrete decision of the oracle are discarded.
    #[test]
    fn a_subsets_camera_gradient_leaves_the_others_with_the_camera(
        seed in any::<u64>(),
        kinds in kinds_strategy(6),
        c in 1usize..4,
    ) {
        let (s, covs, cot, g) = cov_scene_and_gradients(seed, &kinds, c);
        let mut r = rng(seed ^ 0x005a_b5e7);
        let n = s.n();
        let mut subset: Vec<usize> = (0..n).filter(|_| r.gen_bool(0.5)).collect();
        if subset.is_empty() {
            subset.push(0);
        }
        if subset.len() == n && n > 1 {
            subset.pop();
        }
        let pick = |v: &[[f64; 3]]| subset.iter().map(|&i| v[i]).collect::<Vec<_>>();
        let pick_cov = |v: &[Mat3<f64>]| subset.iter().map(|&i| v[i]).collect::<Vec<_>>();
        let ana = camera_pose_gradient(
            &s.cam,
            &pick(&s.means),
            &pick_cov(&covs),
            &pick(&g.means),
            &pick_cov(&g.covariances),
        )
        .unwrap_or_else(|e| panic!("camera_pose_gradient: {e}"));
        let moved = |k: usize, t: f64| {
            let mut xi = [0.0; 6];
            xi[k] = t;
            let mut s2 = s.clone();
            s2.cam = moved_camera(&s.cam, xi);
            let m = carried_along(&s2.cam.world_to_camera, &s.cam.world_to_camera);
            let mut moved_covs = covs.clone();
            for i in (0..n).filter(|i| !subset.contains(i)) {
                let p = s.means[i];
                s2.means[i] = std::array::from_fn(|a| {
                    (0..3).map(|b| m[a][b] * p[b]).sum::<f64>() + m[a][3]
                });
                let cov = &covs[i];
                moved_covs[i] = std::array::from_fn(|a| {
                    std::array::from_fn(|b| {
                        (0..3)
                            .flat_map(|x| (0..3).map(move |y| (x, y)))
                            .map(|(x, y)| m[a][x] * cov[x][y] * m[b][y])
                            .sum()
                    })
                });
            }
            s2.covs = Some(moved_covs);
            s2
        };
        let base = oracle(&s, None).decisions;
        let (mut probes, mut valid) = (0usize, 0usize);
        let (mut num, mut kept, mut valid_axes) = (Vec::new(), Vec::new(), Vec::new());
        for k in 0..6 {
            probes += 1;
            if oracle(&moved(k, FD_H), None).decisions != base
                || oracle(&moved(k, -FD_H), None).decisions != base
            {
                continue;
            }
            valid += 1;
            valid_axes.push(k);
            num.push(central_differences(|t| cov_loss(&moved(k, t[0]), &cot), &[0.0], FD_H)[0]);
            kept.push(ana[k]);
        }
        // A scene the camera does not see (no gradient, analytic or numeric) has nothing to
        // check; a zero analytic gradient against a difference beyond the tolerance still fails.
        prop_assume!(seen(&num, &kept));
        let mut checker = GradientChecker::new();
        checker.check("a subset's camera twist (ω, v) vs FD", &num, &kept, FD_TOL);
        negation_fails("a subset's camera twist", &num, &kept)?;
        // Injected: every Gaussian's share (the others moved with the camera instead of staying).
        let whole = camera_pose_gradient(&s.cam, &s.means, &covs, &g.means, &g.covariances)
            .unwrap_or_else(|e| panic!("camera_pose_gradient: {e}"));
        if subset.len() < n {
            let injected: Vec<f64> = valid_axes.iter().map(|&k| whole[k]).collect();
            static CAUGHT: ProbeTally = ProbeTally::new(10);
            let caught = rejected(&num, &injected);
            tally_catch(&CAUGHT, "a subset's camera twist from the whole set", caught)?;
        }
        static TALLY: ProbeTally = ProbeTally::new(30);
        let tally = TALLY.add(probes, valid);
        prop_assert!(tally.is_ok(), "{}", tally.unwrap_err());
        checker.finish();
    }
}
