//! Checks of the rasterizer's smears (`CovSplats::smears`: each Gaussian blurred by its motion
//! within the render's time slice): the forward against the naive oracle (which adds the smear to
//! Σ and rescales the opacity by its own plain code), the backward of every smear entry, Σ entry,
//! mean and opacity logit against central differences, and a zero smear giving the bits of none.
//! Tolerances and probe validation as in `rasterize.rs` and `rasterize_cov.rs`.

mod raster_support;

use proptest::prelude::*;
use rand::Rng;
use raster_support::*;

/// A random scene with covariances and, for every Gaussian, a smear u uᵀ/12 of a displacement of
/// 0–8 pixels' worth at its depth in a random direction (half of the Gaussians also moving in
/// depth), a random cotangent and `render_cov_backward`'s gradients.
fn smeared_case(seed: u64, kinds: &[usize], c: usize) -> CovCase {
    let (mut s, covs, _, _) = cov_scene_and_gradients(seed, kinds, c);
    let mut rng = rng(seed ^ 0x5EA5);
    let smears = s
        .means
        .iter()
        .map(|m| {
            let depth = m[2].abs().max(0.3);
            // One Gaussian in four does not move (the rasterizer's zero-smear branch).
            let pixels: f64 = if rng.gen_bool(0.25) {
                0.0
            } else {
                rng.gen_range(0.0..8.0)
            };
            let along_depth = if rng.gen_bool(0.5) { 1.0 } else { 0.0 };
            let dir = [
                rng.gen_range(-1.0..1.0),
                rng.gen_range(-1.0..1.0),
                along_depth * rng.gen_range(-1.0..1.0),
            ];
            let norm = dir
                .iter()
                .map(|v: &f64| v * v)
                .sum::<f64>()
                .sqrt()
                .max(1e-3);
            let u = dir.map(|v| v / norm * pixels * depth / s.cam.fx);
            [0, 1, 2].map(|k| [0, 1, 2].map(|l| u[k] * u[l] / 12.0))
        })
        .collect();
    s.smears = Some(smears);
    let cot = random_cotangent(&s, seed);
    let g = cov_gradients(&s, &covs, &cot);
    (s, covs, cot, g)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    /// The smeared forward equals the oracle's (same sums in the same order up to the pixel-box
    /// restriction ⇒ ~1e-15; allowed 1e-12, as `rasterize.rs`), and a smear changes the image.
    #[test]
    fn smeared_forward_matches_the_oracle(
        seed in any::<u64>(),
        kinds in kinds_strategy(6),
        c in 1usize..4,
    ) {
        let (s, covs, _, _) = smeared_case(seed, &kinds, c);
        let out = render_cov(&s.cam, &cov_splats(&s, &covs), &s.settings())
            .unwrap_or_else(|e| panic!("{e}"));
        let o = oracle(&s, None);
        let mut checker = GradientChecker::new();
        let fwd_tol = Tolerance::new(1e-12, 1e-12);
        checker.check("smeared image vs oracle", &o.image, &out.image, fwd_tol);
        checker.check("smeared alpha vs oracle", &o.alpha, &out.alpha, fwd_tol);
        checker.check("smeared depth vs oracle", &o.depth, &out.depth, fwd_tol);
        checker.finish();
    }

    /// dL/d smear, dL/dΣ, dL/d mean and dL/d opacity logit of `render_cov_backward` with smears
    /// against central differences of `render_cov`. Matrix entries are perturbed one at a time by
    /// a step relative to their own matrix (h times its largest diagonal entry, so the smear stays
    /// within the symmetry tolerance), and the compared quantity is that scale times the gradient
    /// (the units of L), so `rasterize_cov.rs`'s FD_TOL argument holds unchanged. Probes whose
    /// ± steps flip a discrete decision of the oracle (which smears the same way) are discarded;
    /// at least 90 % must remain.
    #[test]
    fn smear_gradients_match_finite_differences(
        seed in any::<u64>(),
        kinds in kinds_strategy(6),
        c in 1usize..4,
    ) {
        let (s, covs, cot, g) = smeared_case(seed, &kinds, c);
        prop_assert_eq!(g.smears.len(), s.n());
        let smears = s.smears.clone().unwrap_or_default();
        let base = oracle(&s, None).decisions;
        let mut checker = GradientChecker::new();
        let (mut probes, mut valid) = (0usize, 0usize);
        let mut keep = |perturbed: &dyn Fn(f64) -> Scene| {
            probes += 1;
            let valid_probe = oracle(&perturbed(FD_H), None).decisions == base
                && oracle(&perturbed(-FD_H), None).decisions == base;
            valid += usize::from(valid_probe);
            valid_probe
        };
        for i in 0..s.n() {
            let diag = |m: &Mat3<f64>| m[0][0].max(m[1][1]).max(m[2][2]);
            let (mut num, mut ana) = (Vec::new(), Vec::new());
            // A zero smear has no scale of its own and no room for asymmetry: its entries are
            // stepped relative to Σ, (k, l) and (l, k) together, against the pair's summed gradient.
            let still = diag(&smears[i]) == 0.0;
            for kl in 0..18 {
                let (smear, k, l) = (kl >= 9, (kl % 9) / 3, kl % 3);
                if smear && still && l < k {
                    continue;
                }
                let scale = if smear && !still { diag(&smears[i]) } else { diag(&covs[i]) };
                let perturbed = |t: f64| {
                    let mut s2 = s.clone();
                    let m = if smear { s2.smears.as_mut() } else { s2.covs.as_mut() };
                    if let Some(m) = m {
                        m[i][k][l] += t * scale;
                        if smear && still && k != l {
                            m[i][l][k] += t * scale;
                        }
                    }
                    s2
                };
                if !keep(&perturbed) {
                    continue;
                }
                num.push(central_differences(|t| cov_loss(&perturbed(t[0]), &cot), &[0.0], FD_H)[0]);
                let grads = if smear { &g.smears } else { &g.covariances };
                let pair = if smear && still && k != l { grads[i][l][k] } else { 0.0 };
                ana.push(scale * (grads[i][k][l] + pair));
            }
            for k in [0usize, 1, 2, 10] {
                let x = s.params(i);
                let perturbed = |t: f64| {
                    let mut p = x.clone();
                    p[k] += t;
                    let mut s2 = s.clone();
                    s2.set_params(i, &p);
                    s2
                };
                if !keep(&perturbed) {
                    continue;
                }
                num.push(central_differences(|t| cov_loss(&perturbed(t[0]), &cot), &[0.0], FD_H)[0]);
                ana.push(if k == 10 { g.opacity_logits[i] } else { g.means[i][k] });
            }
            checker.check(&format!("gaussian {i} (kind {}) smeared path vs FD", kind_of(&kinds, i)), &num, &ana, FD_TOL);
        }
        static TALLY: ProbeTally = ProbeTally::new(200);
        let tally = TALLY.add(probes, valid);
        prop_assert!(tally.is_ok(), "{}", tally.unwrap_err());
        checker.finish();
    }
}

#[test]
fn zero_smears_render_the_bits_of_none_and_a_smear_blurs() {
    let scene = F32Renders::new();
    let plain = scene.splats().swap_remove(0);
    let zeros = vec![[[0.0f32; 3]; 3]; plain.means.len()];
    let zero = CovSplats {
        smears: Some(&zeros),
        ..plain
    };
    let settings = scene.settings();
    let o1 = render_cov(&scene.cam, &plain, &settings).unwrap_or_else(|e| panic!("{e}"));
    let o2 = render_cov(&scene.cam, &zero, &settings).unwrap_or_else(|e| panic!("{e}"));
    let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert!(o1.num_pairs > 1000, "scene too sparse: {}", o1.num_pairs);
    assert_eq!(bits(&o1.image), bits(&o2.image));
    assert_eq!(o1.radii, o2.radii);
    let (ci, ca) = f32_cotangents(&scene.cam);
    let cot = Cotangents {
        image: &ci,
        alpha: Some(&ca),
        depth: None,
    };
    let g1 = render_cov_backward(&scene.cam, &plain, &settings, &o1, &cot)
        .unwrap_or_else(|e| panic!("{e}"));
    let g2 = render_cov_backward(&scene.cam, &zero, &settings, &o2, &cot)
        .unwrap_or_else(|e| panic!("{e}"));
    assert!(g1.smears.is_empty() && g2.smears.len() == plain.means.len());
    let fmt = |g: &rasterize_cpu::Gradients<f32>| {
        format!(
            "{:?}",
            (
                &g.means,
                &g.covariances,
                &g.opacity_logits,
                &g.channels,
                &g.means_2d
            )
        )
    };
    assert_eq!(fmt(&g1), fmt(&g2));
    // A smear along x keeps each splat's screen mass but spreads it: the image changes, and the
    // smears' gradients are not all zero.
    let along_x: Vec<_> = plain
        .means
        .iter()
        .map(|m| {
            let u = 4.0 * m[2].abs() / scene.cam.fx as f32;
            [[u * u / 12.0, 0.0, 0.0], [0.0; 3], [0.0; 3]]
        })
        .collect();
    let smeared = CovSplats {
        smears: Some(&along_x),
        ..plain
    };
    let o3 = render_cov(&scene.cam, &smeared, &settings).unwrap_or_else(|e| panic!("{e}"));
    assert_ne!(bits(&o1.image), bits(&o3.image));
    let g3 = render_cov_backward(&scene.cam, &smeared, &settings, &o3, &cot)
        .unwrap_or_else(|e| panic!("{e}"));
    assert!(g3.smears.iter().any(|m| m[0][0] != 0.0));
}
