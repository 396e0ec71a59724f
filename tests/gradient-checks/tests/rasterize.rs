//! Checks of the `rasterize-cpu` backward pass and of its hard (non-differentiable) rules.
//!
//! Three independent lines of evidence, all in f64:
//! 1. A naive per-pixel oracle renderer written here (its own projection, a `std` sort of every
//!    Gaussian whose tile rectangle covers the pixel's tile, INRIA blending) must match the crate's
//!    forward to 1e-12, including the 0.99 clamp, the 1/255 cut and the early stop.
//! 2. The oracle's own backward (per pixel, back to front with T recovered by division, chained
//!    through a central-difference Jacobian of the oracle projection) must match the crate's backward
//!    for a random cotangent on image, alpha and depth — on the hard path, whatever the thresholds do.
//! 3. Central finite differences of the crate's forward must match the crate's backward. Finite
//!    differences are meaningless across the hard steps (1/255 cut, 0.99 clamp, early stop, tile
//!    rectangle, Jacobian clamp, near plane), so every probe is validated: the oracle records every
//!    discrete decision (per pixel and splat: power > 0, α < 1/255, clamped, stop; per Gaussian:
//!    visibility, tile rectangle, Jacobian clamp) and a probe whose x ± h decisions differ from x's is
//!    discarded (counted; at least 90% of a run's probes must be valid, `ProbeTally`).
//!
//! Tolerances. FD (h = 1e-6): the loss L = Σ cot·output is O(10); rounding error ε·|L|/h ≈ 1e-9, and
//! truncation error h²·|L'''|/6 where L''' w.r.t. a world-space mean scales like (f/z)³/σ³ ≈ 1e7 for
//! our smallest splats, i.e. ≈ 2e-6. Hence |num − ana| ≤ 1e-5 + 1e-5·max(|num|, |ana|). Oracle
//! backward: both sides analytic in the blending, the projection Jacobian by central differences
//! (relative error ≈ 1e-9), so 1e-7 + 1e-6·max.
//!
//! Proptest case counts (dev profile, ~seconds each): 48 oracle scenes, 24 FD scenes, 12 SH scenes.

mod raster_support;

use proptest::prelude::*;
use rand::Rng;
use raster_support::*;

// ---------------------------------------------------------------------------------------------
// Oracle comparisons (hard path).

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    #[test]
    fn forward_and_backward_match_the_naive_oracle(
        seed in any::<u64>(),
        kinds in kinds_strategy(10),
        c in 0usize..4,
    ) {
        let s = random_scene(seed, &kinds, c);
        let cot = random_cotangent(&s, seed);
        let (out, g) = crate_backward(&s, &cot);
        let o = oracle(&s, Some((&cot.0, &cot.1, &cot.2)));
        let mut checker = GradientChecker::new();
        // Forward: same sums in the same order up to the pixel-box restriction ⇒ ~1e-15; allow 1e-12.
        let fwd_tol = Tolerance::new(1e-12, 1e-12);
        checker.check("image vs oracle", &o.image, &out.image, fwd_tol);
        checker.check("alpha vs oracle", &o.alpha, &out.alpha, fwd_tol);
        checker.check("depth vs oracle", &o.depth, &out.depth, fwd_tol);
        for i in 0..s.n() {
            let mut want = oracle_param_grad(&s, i, &o.d_proj[i]);
            want.extend_from_slice(&o.d_channels[i * c..(i + 1) * c]);
            checker.check(&format!("gaussian {i} (kind {}) vs oracle", kind_of(&kinds, i)), &want, &crate_param_grad(&g, i, c), ORACLE_TOL);
            checker.check(&format!("gaussian {i} mean2d vs oracle"), &o.d_proj[i][..2], &g.means_2d[i], ORACLE_TOL);
        }
        checker.finish();
    }
}

#[test]
fn oracle_scenes_exercise_every_hard_rule() {
    // Across a fixed sweep of scenes the decisions must include every rule, so the proptest above
    // really covers the clamp, the cut, the early stop and invisible Gaussians.
    // power > 0 is not on the list: the conic is positive definite, so only rounding could make it
    // positive. Index 1 records a Jacobian clamp on a visible Gaussian instead.
    let mut seen = [false; 6];
    for seed in 0..40u64 {
        let kinds: Vec<usize> = (0..10)
            .map(|k| ((seed as usize) * 7 + k * 3) % KINDS)
            .collect();
        let s = random_scene(seed, &kinds, 3);
        let o = oracle(&s, None);
        for &d in &o.decisions[s.n() * 6..] {
            if (2..=5).contains(&d) {
                seen[d as usize] = true;
            }
        }
        for g in o.decisions.chunks(6).take(s.n()) {
            seen[0] |= g[0] == 0;
            seen[1] |= g[0] == 1 && g[5] != 0;
        }
    }
    assert_eq!(
        seen, [true; 6],
        "rules seen: [invisible, Jacobian clamp, α<1/255, stop, blend, 0.99 clamp]"
    );
}

// ---------------------------------------------------------------------------------------------
// Finite differences of the crate's own forward.

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    #[test]
    fn gradients_match_finite_differences(
        seed in any::<u64>(),
        kinds in kinds_strategy(6),
        c in 1usize..4,
    ) {
        let s = random_scene(seed, &kinds, c);
        let cot = random_cotangent(&s, seed);
        let (_, g) = crate_backward(&s, &cot);
        let base = oracle(&s, None).decisions;
        let mut checker = GradientChecker::new();
        let (mut probes, mut valid) = (0usize, 0usize);
        for i in 0..s.n() {
            let x = s.params(i);
            let ana = crate_param_grad(&g, i, c);
            let mut num = Vec::new();
            let mut ana_kept = Vec::new();
            for k in 0..x.len() {
                probes += 1;
                let mut same = true;
                for sign in [-1.0, 1.0] {
                    let mut p = x.clone();
                    p[k] += sign * FD_H;
                    let mut s2 = s.clone();
                    s2.set_params(i, &p);
                    same &= oracle(&s2, None).decisions == base;
                }
                if !same {
                    continue;
                }
                valid += 1;
                let d = central_differences(
                    |p| {
                        let mut s2 = s.clone();
                        let mut full = x.clone();
                        full[k] = p[0];
                        s2.set_params(i, &full);
                        loss(&s2, &cot)
                    },
                    &[x[k]],
                    FD_H,
                );
                num.push(d[0]);
                ana_kept.push(ana[k]);
            }
            checker.check(&format!("gaussian {i} (kind {}) vs FD", kind_of(&kinds, i)), &num, &ana_kept, FD_TOL);
        }
        static TALLY: ProbeTally = ProbeTally::new(200);
        let tally = TALLY.add(probes, valid);
        prop_assert!(tally.is_ok(), "{}", tally.unwrap_err());
        checker.finish();
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(12))]

    #[test]
    fn sh_render_gradients_match_finite_differences(
        seed in any::<u64>(),
        kinds in prop::collection::vec(0usize..6, 1..=5),
        degree in 0usize..=3,
    ) {
        // Colours from SH (view dependent): the means also get the view-direction gradient.
        let s = random_scene(seed, &kinds, 0);
        let k = gaussians::sh::num_sh_coeffs(degree);
        let mut rng = rng(seed ^ 0x5151);
        // DC keeps colours near 0.5 and higher bands small, away from the clamp at 0.
        let sh: Vec<f64> = (0..s.n() * k * 3)
            .map(|j| if (j / 3) % k == 0 { rng.gen_range(-0.3..0.3) } else { rng.gen_range(-0.1..0.1) })
            .collect();
        let (ci, _, _) = random_cotangent(&s, seed);
        let hw = (s.cam.width * s.cam.height) as usize;
        let ci: Vec<f64> = ci.into_iter().chain(std::iter::repeat(0.5)).take(3 * hw).collect();
        let settings = RenderSettings { near_plane: NEAR, background: vec![0.1, 0.2, 0.3] };
        let sh_loss = |means: &[[f64; 3]], sh: &[f64]| -> f64 {
            let splats = ShSplats { means, log_scales: &s.log_scales, quats: &s.quats, opacity_logits: &s.logits, sh, sh_degree: degree };
            let r = render_sh(&s.cam, &splats, &settings).unwrap_or_else(|e| panic!("render_sh: {e}"));
            dot(&r.output.image, &ci)
        };
        let splats = ShSplats { means: &s.means, log_scales: &s.log_scales, quats: &s.quats, opacity_logits: &s.logits, sh: &sh, sh_degree: degree };
        let fwd = render_sh(&s.cam, &splats, &settings).unwrap_or_else(|e| panic!("render_sh: {e}"));
        let g = render_sh_backward(&s.cam, &splats, &settings, &fwd, &Cotangents { image: &ci, alpha: None, depth: None })
            .unwrap_or_else(|e| panic!("render_sh_backward: {e}"));
        let base = oracle(&s, None).decisions;
        let mut checker = GradientChecker::new();
        let (mut probes, mut valid) = (0usize, 0usize);
        for i in 0..s.n() {
            // Means: probe validity as above (counted; at least 90% of the run's must be valid).
            let mut num = Vec::new();
            let mut ana = Vec::new();
            for a in 0..3 {
                probes += 1;
                let mut ok = true;
                for sign in [-1.0, 1.0] {
                    let mut s2 = s.clone();
                    s2.means[i][a] += sign * FD_H;
                    ok &= oracle(&s2, None).decisions == base;
                }
                if ok {
                    valid += 1;
                    let d = central_differences(|p| { let mut m = s.means.clone(); m[i][a] = p[0]; sh_loss(&m, &sh) }, &[s.means[i][a]], FD_H);
                    num.push(d[0]);
                    ana.push(g.means[i][a]);
                }
            }
            checker.check(&format!("gaussian {i} means (SH deg {degree})"), &num, &ana, FD_TOL);
            // SH coefficients never change a discrete decision (colours stay positive).
            let range = i * k * 3..(i + 1) * k * 3;
            let num_sh = central_differences(|p| { let mut c = sh.clone(); c[range.clone()].copy_from_slice(p); sh_loss(&s.means, &c) }, &sh[range.clone()], FD_H);
            checker.check(&format!("gaussian {i} sh (deg {degree})"), &num_sh, &g.sh[range.clone()], FD_TOL);
        }
        static TALLY: ProbeTally = ProbeTally::new(25);
        let tally = TALLY.add(probes, valid);
        prop_assert!(tally.is_ok(), "{}", tally.unwrap_err());
        checker.finish();
    }
}

// ---------------------------------------------------------------------------------------------
// Invariances and determinism.
#[test]
fn one_and_two_threads_are_bit_identical() {
    let (cam, m, ls, q, op, ch) = f32_scene(3000, 100, 76, 7);
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap_or_else(|e| panic!("{e}"));
        pool.install(|| render_f32(&cam, &m, &ls, &q, &op, &ch))
    };
    let (o1, g1) = run(1);
    let (o2, g2) = run(2);
    let (o3, g3) = run(2);
    assert!(
        o1.num_pairs > 3000,
        "scene too sparse: {} pairs",
        o1.num_pairs
    );
    assert!(g1.means.iter().any(|v| v[0] != 0.0));
    let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&o1.image), bits(&o2.image));
    assert_eq!(bits(&o1.alpha), bits(&o2.alpha));
    assert_eq!(bits(&o1.depth), bits(&o2.depth));
    assert_eq!(bits(&o2.image), bits(&o3.image));
    assert_eq!(format!("{g1:?}"), format!("{g2:?}"));
    assert_eq!(format!("{g2:?}"), format!("{g3:?}"));
}

#[test]
fn permuting_inputs_permutes_gradients_and_keeps_the_image() {
    let (cam, m, ls, q, op, ch) = f32_scene(800, 64, 48, 11);
    let (o1, g1) = render_f32(&cam, &m, &ls, &q, &op, &ch);
    let n = m.len();
    let perm: Vec<usize> = (0..n).map(|i| (i * 389 + 17) % n).collect();
    let pm: Vec<_> = perm.iter().map(|&i| m[i]).collect();
    let pls: Vec<_> = perm.iter().map(|&i| ls[i]).collect();
    let pq: Vec<_> = perm.iter().map(|&i| q[i]).collect();
    let pop: Vec<_> = perm.iter().map(|&i| op[i]).collect();
    let pch: Vec<_> = perm
        .iter()
        .flat_map(|&i| ch[i * 3..i * 3 + 3].to_vec())
        .collect();
    let (o2, g2) = render_f32(&cam, &pm, &pls, &pq, &pop, &pch);
    assert_eq!(o1.image, o2.image);
    assert_eq!(o1.alpha, o2.alpha);
    assert_eq!(o1.depth, o2.depth);
    for (j, &i) in perm.iter().enumerate() {
        assert_eq!(g1.means[i], g2.means[j]);
        assert_eq!(g1.quats[i], g2.quats[j]);
        assert_eq!(g1.opacity_logits[i], g2.opacity_logits[j]);
    }
}

#[test]
fn off_screen_and_behind_camera_gaussians_change_nothing() {
    let (cam, mut m, mut ls, mut q, mut op, mut ch) = f32_scene(500, 64, 48, 5);
    let (o1, g1) = render_f32(&cam, &m, &ls, &q, &op, &ch);
    // Behind the camera, at the near plane, far off to the side, and transparent.
    for p in [
        [0.0f32, 0.0, -1.0],
        [0.0, 0.0, 0.1],
        [60.0, 0.0, 2.0],
        [0.0, -80.0, 3.0],
    ] {
        m.push(p);
        ls.push([-1.0; 3]);
        q.push([1.0, 0.0, 0.0, 0.0]);
        op.push(5.0);
        ch.extend_from_slice(&[1.0, 1.0, 1.0]);
    }
    let (o2, g2) = render_f32(&cam, &m, &ls, &q, &op, &ch);
    assert_eq!(o1.image, o2.image);
    assert_eq!(o1.alpha, o2.alpha);
    assert_eq!(o1.depth, o2.depth);
    assert_eq!(g1.means[..], g2.means[..500]);
    assert_eq!(g1.log_scales[..], g2.log_scales[..500]);
    assert!(g2.means[500..].iter().all(|v| *v == [0.0; 3]));
    assert!(g2.opacity_logits[500..].iter().all(|v| *v == 0.0));
    assert!(o2.radii[500..].iter().all(|&r| r == 0));
}

#[test]
fn f32_render_agrees_with_f64() {
    let (cam, m, ls, q, op, ch) = f32_scene(400, 48, 40, 3);
    let (o32, _) = render_f32(&cam, &m, &ls, &q, &op, &ch);
    let w = |v: &[f32]| v.iter().map(|&x| f64::from(x)).collect::<Vec<_>>();
    let (m64, ls64, q64, op64, ch64) = (
        m.iter().map(|p| p.map(f64::from)).collect::<Vec<_>>(),
        ls.iter().map(|p| p.map(f64::from)).collect::<Vec<_>>(),
        q.iter().map(|p| p.map(f64::from)).collect::<Vec<_>>(),
        w(&op),
        w(&ch),
    );
    let splats = Splats {
        means: &m64,
        log_scales: &ls64,
        quats: &q64,
        opacity_logits: &op64,
        channels: &ch64,
        num_channels: 3,
    };
    let settings = RenderSettings {
        near_plane: 0.2,
        background: vec![0.2, 0.3, 0.4],
    };
    let o64 = render(&cam, &splats, &settings).unwrap_or_else(|e| panic!("{e}"));
    // f32 rounding moves a handful of pixel/splat pairs across the 1/255 cut or the stop; the rest
    // agree to f32 precision.
    let far = o32
        .image
        .iter()
        .zip(&o64.image)
        .filter(|(a, b)| (f64::from(**a) - **b).abs() > 1e-4)
        .count();
    assert!(
        far * 100 <= o64.image.len(),
        "{far} of {} pixels differ by > 1e-4",
        o64.image.len()
    );
}

// ---------------------------------------------------------------------------------------------
// Bad input.

#[test]
fn bad_cameras_and_requests_give_typed_errors() {
    let eye = [
        [1.0, 0.0, 0.0, 0.0],
        [0.0, 1.0, 0.0, 0.0],
        [0.0, 0.0, 1.0, 0.0],
        [0.0, 0.0, 0.0, 1.0],
    ];
    let mut singular = eye;
    singular[2][2] = 0.0;
    assert!(matches!(
        Camera::new(64, 48, 50.0, 50.0, 32.0, 24.0, singular),
        Err(CameraError::SingularMatrix { .. })
    ));
    assert!(matches!(
        Camera::new(0, 48, 50.0, 50.0, 32.0, 24.0, eye),
        Err(CameraError::InvalidImageSize { .. })
    ));
    assert!(matches!(
        Camera::new(64, 48, f64::NAN, 50.0, 32.0, 24.0, eye),
        Err(CameraError::NonFinite { .. })
    ));
    let mut nan_m = eye;
    nan_m[1][3] = f64::NAN;
    assert!(matches!(
        Camera::new(64, 48, 50.0, 50.0, 32.0, 24.0, nan_m),
        Err(CameraError::NonFinite { .. })
    ));
    assert!(matches!(
        Camera::new(20000, 48, 50.0, 50.0, 32.0, 24.0, eye),
        Err(CameraError::InvalidImageSize { .. })
    ));
    assert!(matches!(
        Camera::new(16385, 16385, 50.0, 50.0, 32.0, 24.0, eye),
        Err(CameraError::InvalidImageSize { .. })
    ));
    let mut too_big = match Camera::new(64, 48, 50.0, 50.0, 32.0, 24.0, eye) {
        Ok(c) => c,
        Err(e) => panic!("{e}"),
    };
    too_big.width = 16385;
    too_big.height = 16385;
    let splats = Splats::<f32> {
        means: &[[0.0, 0.0, 2.0]],
        log_scales: &[[-3.0; 3]],
        quats: &[[1.0, 0.0, 0.0, 0.0]],
        opacity_logits: &[0.0],
        channels: &[],
        num_channels: 0,
    };
    assert!(matches!(
        render(&too_big, &splats, &RenderSettings::default()),
        Err(RasterError::Camera(CameraError::InvalidImageSize { .. }))
    ));
    let cam = match Camera::new(64, 48, 50.0, 50.0, 32.0, 24.0, eye) {
        Ok(c) => c,
        Err(e) => panic!("{e}"),
    };
    let zero_q = Splats::<f32> {
        quats: &[[0.0; 4]],
        ..splats
    };
    assert!(matches!(
        render(&cam, &zero_q, &RenderSettings::default()),
        Err(RasterError::ZeroQuaternion { index: 0 })
    ));
    let nan_mean = Splats::<f32> {
        means: &[[f32::NAN, 0.0, 2.0]],
        ..splats
    };
    assert!(matches!(
        render(&cam, &nan_mean, &RenderSettings::default()),
        Err(RasterError::NonFiniteParameter {
            index: 0,
            field: "means"
        })
    ));
    let short = Splats::<f32> {
        opacity_logits: &[],
        ..splats
    };
    assert!(matches!(
        render(&cam, &short, &RenderSettings::default()),
        Err(RasterError::LengthMismatch {
            field: "opacity_logits",
            ..
        })
    ));
    let ok = render(&cam, &splats, &RenderSettings::default()).unwrap_or_else(|e| panic!("{e}"));
    assert!(ok.alpha.iter().all(|a| a.is_finite()) && ok.alpha.iter().any(|&a| a > 0.0));
}
