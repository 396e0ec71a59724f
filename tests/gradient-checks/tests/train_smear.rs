//! Finite-difference check of `train::pose::smear`'s backward: the smears u uᵀ/12 of an exposure's
//! passes as functions of every pass's means, each read through its neighbours' (central inside,
//! one-sided at the ends). L = Σ_s Σ_i ⟨W_si, S_si⟩ for random, non-symmetric W (the rasterizer's
//! gradients treat the nine entries as independent), some Gaussians static in every pass.
//! L is a quadratic polynomial of the means, so central differences are exact up to rounding:
//! with h = 1e-6 and |L| ≲ 1, rounding ε·|L|/h ≈ 1e-10; tolerance 1e-8 + 1e-6 relative.

use gradient_checks::{central_differences, rng, GradientChecker, Tolerance};
use proptest::prelude::*;
use rand::Rng;
use train::pose::smear::{exposure_smears, exposure_smears_backward};

const TOL: Tolerance = Tolerance::new(1e-8, 1e-6);
const H: f64 = 1e-6;

type Mat3 = [[f64; 3]; 3];

fn loss(means: &[Vec<[f64; 3]>], weights: &[Vec<Mat3>]) -> f64 {
    let views: Vec<_> = means.iter().map(|m| &m[..]).collect();
    let smears = exposure_smears(&views);
    smears
        .iter()
        .zip(weights)
        .flat_map(|(s, w)| s.iter().zip(w))
        .map(|(s, w)| {
            (0..9)
                .map(|kl| s[kl / 3][kl % 3] * w[kl / 3][kl % 3])
                .sum::<f64>()
        })
        .sum()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    #[test]
    fn smear_mean_gradients_match_finite_differences(seed in any::<u64>(), passes in 2usize..7) {
        let mut rng = rng(seed);
        let n = 5;
        let still: Vec<bool> = (0..n).map(|i| i > 0 && rng.gen_bool(0.3)).collect();
        let start: Vec<[f64; 3]> = (0..n).map(|_| [0, 1, 2].map(|_| rng.gen_range(-1.0..1.0))).collect();
        let means: Vec<Vec<[f64; 3]>> = (0..passes)
            .map(|_| {
                start
                    .iter()
                    .zip(&still)
                    .map(|(p, &s)| if s { *p } else { p.map(|v| v + rng.gen_range(-0.2..0.2)) })
                    .collect()
            })
            .collect();
        let weights: Vec<Vec<Mat3>> = (0..passes)
            .map(|_| (0..n).map(|_| [0, 1, 2].map(|_| [0, 1, 2].map(|_| rng.gen_range(-1.0..1.0)))).collect())
            .collect();
        let mut d_means = vec![vec![[0.0; 3]; n]; passes];
        {
            let views: Vec<_> = means.iter().map(|m| &m[..]).collect();
            let w: Vec<_> = weights.iter().map(|w| &w[..]).collect();
            let mut d: Vec<_> = d_means.iter_mut().map(|d| &mut d[..]).collect();
            exposure_smears_backward(&views, &w, &mut d);
        }
        let mut checker = GradientChecker::new();
        let mut any = false;
        for s in 0..passes {
            for i in 0..n {
                let num: Vec<f64> = (0..3)
                    .map(|k| {
                        central_differences(
                            |x| {
                                let mut m = means.clone();
                                m[s][i][k] = x[0];
                                loss(&m, &weights)
                            },
                            &[means[s][i][k]],
                            H,
                        )[0]
                    })
                    .collect();
                any |= d_means[s][i].iter().any(|&v| v != 0.0);
                checker.check(&format!("pass {s} gaussian {i} dL/dmean"), &num, &d_means[s][i], TOL);
            }
        }
        prop_assert!(any, "all-zero gradients");
        checker.finish();
    }
}
