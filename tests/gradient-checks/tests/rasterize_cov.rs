//! Checks of the rasterizer's precomputed-covariance path (`render_cov`): its backward against
//! central differences, and that it equals the scale-rotation path bit for bit; typed errors for
//! bad covariances. Tolerances and probe validation as in `rasterize.rs`.

mod raster_support;

use proptest::prelude::*;
use raster_support::*;

// ---------------------------------------------------------------------------------------------
// Precomputed-covariance path (`render_cov`).
proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    /// dL/dΣ of `render_cov_backward` against central differences of `render_cov`, every one of the
    /// nine entries perturbed on its own (so Σ is briefly non-symmetric, which `render_cov` accepts up
    /// to 1e-4 relative). The step is relative: Σ_kl ± h·s with s = max_k Σ_kk and h = FD_H, and the
    /// compared quantity is s·dL/dΣ_kl, which has the units and size of L; the FD_TOL argument above
    /// then holds unchanged (the log-scales spread by ±0.7, so Σ's eigenvalues differ from s by at
    /// most e^2.8 ≈ 16 and a probe moves cov2d by ≤ 16·h relative: truncation ≈ (16h)², rounding
    /// ε·|L|/h ≈ 1e-9). Means, opacity logits and channels are checked on the same path too. Probes
    /// whose ± steps flip any discrete decision of the oracle (run on the same covariances) are
    /// discarded; at least 90% must remain.
    #[test]
    fn cov_gradients_match_finite_differences(
        seed in any::<u64>(),
        kinds in kinds_strategy(6),
        c in 1usize..4,
    ) {
        let (s, covs, cot, g) = cov_scene_and_gradients(seed, &kinds, c);
        prop_assert_eq!(g.covariances.len(), s.n());
        prop_assert!(g.log_scales.is_empty() && g.quats.is_empty());
        let base = oracle(&s, None).decisions;
        let mut checker = GradientChecker::new();
        let (mut probes, mut valid) = (0usize, 0usize);
        for i in 0..s.n() {
            let scale = covs[i][0][0].max(covs[i][1][1]).max(covs[i][2][2]);
            // Σ entries (relative step), then mean, logit, channels (the Scene::params layout).
            let mut num = Vec::new();
            let mut ana = Vec::new();
            for kl in 0..9 {
                let (k, l) = (kl / 3, kl % 3);
                probes += 1;
                let perturbed = |t: f64| {
                    let mut s2 = s.clone();
                    if let Some(cv) = s2.covs.as_mut() {
                        cv[i][k][l] = covs[i][k][l] + t * scale;
                    }
                    s2
                };
                if oracle(&perturbed(FD_H), None).decisions != base
                    || oracle(&perturbed(-FD_H), None).decisions != base
                {
                    continue;
                }
                valid += 1;
                let d = central_differences(|t| cov_loss(&perturbed(t[0]), &cot), &[0.0], FD_H);
                num.push(d[0]);
                ana.push(scale * g.covariances[i][k][l]);
            }
            checker.check(&format!("gaussian {i} (kind {}) s*dL/dSigma vs FD", kind_of(&kinds, i)), &num, &ana, FD_TOL);
            let x = s.params(i);
            let mut num = Vec::new();
            let mut ana = Vec::new();
            let others = [0usize, 1, 2, 10].into_iter().chain(11..11 + c);
            for k in others {
                probes += 1;
                let perturbed = |v: f64| {
                    let mut p = x.clone();
                    p[k] = v;
                    let mut s2 = s.clone();
                    s2.set_params(i, &p);
                    s2
                };
                if oracle(&perturbed(x[k] + FD_H), None).decisions != base
                    || oracle(&perturbed(x[k] - FD_H), None).decisions != base
                {
                    continue;
                }
                valid += 1;
                let d = central_differences(|v| cov_loss(&perturbed(v[0]), &cot), &[x[k]], FD_H);
                num.push(d[0]);
                ana.push(match k {
                    0..=2 => g.means[i][k],
                    10 => g.opacity_logits[i],
                    _ => g.channels[i * c + k - 11],
                });
            }
            checker.check(&format!("gaussian {i} (kind {}) cov path mean/logit/channels vs FD", kind_of(&kinds, i)), &num, &ana, FD_TOL);
        }
        static TALLY: ProbeTally = ProbeTally::new(200);
        let tally = TALLY.add(probes, valid);
        prop_assert!(tally.is_ok(), "{}", tally.unwrap_err());
        checker.finish();
    }
}

#[test]
fn render_cov_of_scale_rotation_covariances_equals_render_bit_for_bit() {
    // Same covariance_3d, same projection and raster code ⇒ identical bits, forward and backward; the
    // cov-path dΣ chained through covariance_3d_backward gives render_backward's log-scale and
    // quaternion gradients bit for bit (render_backward does exactly that chaining).
    let (cam, m, ls, q, op, ch) = f32_scene(3000, 100, 76, 7);
    let (o1, g1) = render_f32(&cam, &m, &ls, &q, &op, &ch);
    let covs: Vec<Mat3<f32>> = ls
        .iter()
        .zip(&q)
        .map(|(l, r)| covariance_3d(*l, *r))
        .collect();
    let splats = CovSplats {
        means: &m,
        covariances: &covs,
        opacity_logits: &op,
        channels: &ch,
        num_channels: 3,
        smears: None,
    };
    let settings = RenderSettings {
        near_plane: 0.2,
        background: vec![0.2, 0.3, 0.4],
    };
    let o2 = render_cov(&cam, &splats, &settings).unwrap_or_else(|e| panic!("{e}"));
    let (ci, ca) = f32_cotangents(&cam);
    let g2 = render_cov_backward(
        &cam,
        &splats,
        &settings,
        &o2,
        &Cotangents {
            image: &ci,
            alpha: Some(&ca),
            depth: Some(&ca),
        },
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert!(
        o1.num_pairs > 3000,
        "scene too sparse: {} pairs",
        o1.num_pairs
    );
    assert_eq!(o1.radii, o2.radii);
    assert_eq!(bits(&o1.image), bits(&o2.image));
    assert_eq!(bits(&o1.alpha), bits(&o2.alpha));
    assert_eq!(bits(&o1.depth), bits(&o2.depth));
    assert!(g1.covariances.is_empty());
    assert!(g2.log_scales.is_empty() && g2.quats.is_empty());
    assert_eq!(g2.covariances.len(), m.len());
    assert!(g2.covariances.iter().any(|s| s[0][1] != 0.0));
    let fmt = |g: &rasterize_cpu::Gradients<f32>| {
        format!(
            "{:?}",
            (
                &g.means,
                &g.opacity_logits,
                &g.channels,
                &g.means_2d,
                &g.background
            )
        )
    };
    assert_eq!(fmt(&g1), fmt(&g2));
    for i in 0..m.len() {
        let (dls, dq) = if o2.radii[i] == 0 {
            ([0.0; 3], [0.0; 4])
        } else {
            covariance_3d_backward(ls[i], q[i], &g2.covariances[i])
        };
        assert_eq!(
            dls.map(f32::to_bits),
            g1.log_scales[i].map(f32::to_bits),
            "gaussian {i}"
        );
        assert_eq!(
            dq.map(f32::to_bits),
            g1.quats[i].map(f32::to_bits),
            "gaussian {i}"
        );
    }
}

#[test]
fn bad_covariances_give_typed_errors() {
    let cam = Camera::looking_down_z(32, 24, 30.0, 30.0).unwrap_or_else(|e| panic!("{e}"));
    let good: Mat3<f32> = [
        [0.01, 0.002, 0.0],
        [0.002, 0.02, 0.001],
        [0.0, 0.001, 0.015],
    ];
    let means = [[0.0f32, 0.0, 2.0], [0.1, 0.0, 2.0]];
    let settings = RenderSettings::default();
    let with = |bad: Mat3<f32>| {
        let covs = [good, bad];
        let splats = CovSplats {
            means: &means,
            covariances: &covs,
            opacity_logits: &[0.0, 0.0],
            channels: &[],
            num_channels: 0,
            smears: None,
        };
        render_cov(&cam, &splats, &settings).map(|o| o.alpha)
    };
    let mut nan = good;
    nan[2][1] = f32::NAN;
    assert!(matches!(
        with(nan),
        Err(RasterError::NonFiniteParameter {
            index: 1,
            field: "covariances"
        })
    ));
    let mut inf = good;
    inf[0][0] = f32::INFINITY;
    assert!(matches!(
        with(inf),
        Err(RasterError::NonFiniteParameter {
            index: 1,
            field: "covariances"
        })
    ));
    let mut skew = good;
    skew[0][2] = 0.005;
    assert!(matches!(
        with(skew),
        Err(RasterError::NonSymmetricCovariance {
            index: 1,
            row: 0,
            col: 2,
            ..
        })
    ));
    // Rounding-level asymmetry (far below 1e-4 relative) is accepted and renders finitely.
    let mut rounded = good;
    rounded[1][0] = 0.002 * (1.0 + 4.0 * f32::EPSILON);
    let alpha = with(rounded).unwrap_or_else(|e| panic!("{e}"));
    assert!(alpha.iter().all(|a| a.is_finite()) && alpha.iter().any(|&a| a > 0.0));
    let covs = [good];
    let short = CovSplats {
        means: &means,
        covariances: &covs,
        opacity_logits: &[0.0, 0.0],
        channels: &[],
        num_channels: 0,
        smears: None,
    };
    assert!(matches!(
        render_cov(&cam, &short, &settings),
        Err(RasterError::LengthMismatch {
            field: "covariances",
            got: 1,
            expected: 2
        })
    ));
}
