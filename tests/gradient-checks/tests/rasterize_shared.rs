//! Checks of renders that share their static Gaussians (`render_cov_shared`): the backward
//! against central differences, and the outputs against separate renders. Tolerances and probe
//! validation as in `rasterize.rs`.

mod raster_support;

use proptest::prelude::*;
use raster_support::*;

// ---------------------------------------------------------------------------------------------
// Renders that share their static Gaussians (`render_cov_shared`).
proptest! {
    #![proptest_config(ProptestConfig::with_cases(12))]

    /// `render_cov_shared_backward` against central differences of L = Σ_r cot_r · render_r over
    /// three renders from one camera: a static Gaussian's parameter is perturbed in every render at
    /// once and compared with the sum of the renders' gradients (its shared tiles' share reaches
    /// only the owner's); a moving Gaussian's in one render, against that render's gradient.
    /// Probes flipping a discrete decision of the oracle in any render are discarded (≥ 90% must
    /// remain); tolerance FD_TOL, as for one render (the loss is a sum of three such losses).
    #[test]
    fn shared_render_gradients_match_finite_differences(
        seed in any::<u64>(),
        kinds in kinds_strategy(6),
        c in 1usize..4,
    ) {
        let mut s = random_scene(seed, &kinds, c);
        s.covs = Some((0..s.n()).map(|i| covariance_3d(s.log_scales[i], s.quats[i])).collect());
        let (scenes, moving) = moving_renders(&s, 3);
        let cots: Vec<_> = (0..3).map(|r| random_cotangent(&s, seed ^ (r as u64 + 1))).collect();
        let settings = s.settings();
        let covs = s.covs.clone().unwrap_or_default();
        let splats: Vec<CovSplats<'_, f64>> = scenes.iter().map(|sc| cov_splats(sc, &covs)).collect();
        let fwd = render_cov_shared(&s.cam, &splats, &moving, 1, &settings, SharedOutputs::OwnerLists)
            .unwrap_or_else(|e| panic!("render_cov_shared: {e}"));
        let cot_refs: Vec<Cotangents<'_, f64>> = cots
            .iter()
            .map(|c| Cotangents { image: &c.0, alpha: Some(&c.1), depth: Some(&c.2) })
            .collect();
        let outs: Vec<_> = fwd.outputs.iter().collect();
        let g = render_cov_shared_backward(&s.cam, &splats, &settings, &outs, &fwd.sharing, &cot_refs)
            .unwrap_or_else(|e| panic!("render_cov_shared_backward: {e}"));
        let base: Vec<_> = scenes.iter().map(|sc| oracle(sc, None).decisions).collect();
        let total = |sc: &[Scene]| -> f64 { sc.iter().zip(&cots).map(|(x, c)| cov_loss(x, c)).sum() };
        let mut checker = GradientChecker::new();
        let (mut probes, mut valid) = (0usize, 0usize);
        for i in 0..s.n() {
            // Σ (one slice for every render, so every render's gradient counts), relative step.
            let scale = covs[i][0][0].max(covs[i][1][1]).max(covs[i][2][2]);
            let (mut num, mut ana) = (Vec::new(), Vec::new());
            for kl in 0..9 {
                let (k, l) = (kl / 3, kl % 3);
                probes += 1;
                let perturbed = |t: f64| -> Vec<Scene> {
                    let mut sc = scenes.clone();
                    for x2 in &mut sc {
                        if let Some(cv) = x2.covs.as_mut() {
                            cv[i][k][l] = covs[i][k][l] + t * scale;
                        }
                    }
                    sc
                };
                let flips = |t: f64| {
                    perturbed(t).iter().zip(&base).any(|(sc, b)| &oracle(sc, None).decisions != b)
                };
                if flips(FD_H) || flips(-FD_H) {
                    continue;
                }
                valid += 1;
                num.push(central_differences(|t| total(&perturbed(t[0])), &[0.0], FD_H)[0]);
                ana.push(scale * g.iter().map(|gr| gr.covariances[i][k][l]).sum::<f64>());
            }
            checker.check(&format!("gaussian {i} (kind {}) s*dL/dSigma", kind_of(&kinds, i)), &num, &ana, FD_TOL);
            for r in 0..3 {
                if !moving[i] && r > 0 {
                    continue;
                }
                let flips = |perturbed: &dyn Fn(f64) -> Vec<Scene>, x: f64| {
                    [x + FD_H, x - FD_H].into_iter().any(|v| {
                        perturbed(v).iter().zip(&base).any(|(sc, b)| &oracle(sc, None).decisions != b)
                    })
                };
                let (num, ana, p, v) =
                    shared_render_probes(&scenes, &moving, i, r, c, &g, &|sc| total(sc), &flips);
                probes += p;
                valid += v;
                checker.check(
                    &format!("gaussian {i} (kind {}, moving {}) render {r}", kind_of(&kinds, i), moving[i]),
                    &num,
                    &ana,
                    FD_TOL,
                );
            }
        }
        static TALLY: ProbeTally = ProbeTally::new(200);
        let tally = TALLY.add(probes, valid);
        prop_assert!(tally.is_ok(), "{}", tally.unwrap_err());
        checker.finish();
    }
}

#[test]
fn shared_renders_equal_separate_renders_and_share_tiles() {
    // f32 scene large enough for static tiles and moving tiles: the outputs are bit-identical to
    // rendering each alone, the moving Gaussians' gradients bit-identical per render, and the
    // static ones' summed gradients equal the separate sum up to rounding.
    let scene = F32Renders::new();
    let (cam, moving, means) = (&scene.cam, &scene.moving, &scene.means);
    let splats = scene.splats();
    let settings = scene.settings();
    let shared = render_cov_shared(cam, &splats, moving, 1, &settings, SharedOutputs::Complete)
        .unwrap_or_else(|e| panic!("render_cov_shared: {e}"));
    let fraction = shared.sharing.shared_fraction();
    assert!(
        fraction > 0.1 && fraction < 0.9,
        "shared fraction {fraction}"
    );
    let hw = (cam.width * cam.height) as usize;
    let cots: Vec<Vec<f32>> = (0..3)
        .map(|r| {
            (0..3 * hw)
                .map(|p| ((p * 7 + r * 13) % 17) as f32 / 17.0 - 0.5)
                .collect()
        })
        .collect();
    let cot_refs: Vec<Cotangents<'_, f32>> = cots
        .iter()
        .map(|c| Cotangents {
            image: c,
            alpha: None,
            depth: None,
        })
        .collect();
    let outs: Vec<_> = shared.outputs.iter().collect();
    let g = render_cov_shared_backward(cam, &splats, &settings, &outs, &shared.sharing, &cot_refs)
        .unwrap_or_else(|e| panic!("render_cov_shared_backward: {e}"));
    // Binning the shared tiles only in the owner gives the same images and gradients, bit for bit,
    // from fewer pairs.
    let lean = render_cov_shared(
        cam,
        &splats,
        moving,
        1,
        &settings,
        SharedOutputs::OwnerLists,
    )
    .unwrap_or_else(|e| panic!("render_cov_shared: {e}"));
    assert_eq!(lean.sharing, shared.sharing);
    let lean_outs: Vec<_> = lean.outputs.iter().collect();
    let g_lean = render_cov_shared_backward(
        cam,
        &splats,
        &settings,
        &lean_outs,
        &lean.sharing,
        &cot_refs,
    )
    .unwrap_or_else(|e| panic!("render_cov_shared_backward: {e}"));
    for r in 0..3 {
        assert_eq!(lean.outputs[r].image, shared.outputs[r].image, "render {r}");
        let bits = |g: &rasterize_cpu::Gradients<f32>| {
            let mut v: Vec<u32> = g.means.as_flattened().iter().map(|x| x.to_bits()).collect();
            v.extend(g.opacity_logits.iter().map(|x| x.to_bits()));
            v.extend(g.channels.iter().map(|x| x.to_bits()));
            v.extend(g.means_2d.as_flattened().iter().map(|x| x.to_bits()));
            v.extend(
                g.covariances
                    .iter()
                    .flat_map(|c| c.as_flattened())
                    .map(|x| x.to_bits()),
            );
            v
        };
        assert_eq!(bits(&g_lean[r]), bits(&g[r]), "render {r}'s gradients");
        if r != 1 {
            assert!(
                lean.outputs[r].num_pairs < shared.outputs[r].num_pairs,
                "render {r}"
            );
            // A render without the shared tiles' lists cannot be differentiated alone.
            let alone =
                render_cov_backward(cam, &splats[r], &settings, &lean.outputs[r], &cot_refs[r]);
            assert!(
                matches!(alone, Err(RasterError::ForwardMismatch(_))),
                "render {r}"
            );
        }
    }
    let mut sum_shared = vec![0.0f64; moving.len()];
    let mut sum_separate = vec![0.0f64; moving.len()];
    for r in 0..3 {
        let alone = render_cov(cam, &splats[r], &settings).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(alone.image, shared.outputs[r].image, "render {r} image");
        assert_eq!(alone.alpha, shared.outputs[r].alpha, "render {r} alpha");
        let ga = render_cov_backward(cam, &splats[r], &settings, &alone, &cot_refs[r])
            .unwrap_or_else(|e| panic!("{e}"));
        for i in 0..moving.len() {
            if moving[i] {
                assert_eq!(
                    ga.means[i], g[r].means[i],
                    "moving Gaussian {i}, render {r}"
                );
            }
            sum_shared[i] += f64::from(g[r].means[i][0]);
            sum_separate[i] += f64::from(ga.means[i][0]);
        }
    }
    let scale = sum_separate.iter().fold(0.0f64, |a, v| a.max(v.abs()));
    for i in 0..moving.len() {
        let err = (sum_shared[i] - sum_separate[i]).abs();
        assert!(
            err <= 1e-4 * scale,
            "Gaussian {i}: {} vs {}",
            sum_shared[i],
            sum_separate[i]
        );
    }
    // A static Gaussian whose inputs change between renders is refused, naming it.
    let mut bad = means[2].clone();
    let victim = moving.iter().position(|&mv| !mv).unwrap_or(0);
    bad[victim][2] += 0.5;
    let mut splats_bad = splats.clone();
    splats_bad[2].means = &bad;
    let err = render_cov_shared(
        cam,
        &splats_bad,
        moving,
        1,
        &settings,
        SharedOutputs::OwnerLists,
    )
    .map(|_| ());
    assert!(
        matches!(&err, Err(RasterError::InvalidSettings(m)) if m.contains(&format!("Gaussian {victim} "))),
        "{err:?}"
    );
}
