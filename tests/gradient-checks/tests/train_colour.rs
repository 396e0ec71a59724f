//! Finite-difference check of the colour networks (`train::colour`): gradients w.r.t. the MLP
//! parameters, the per-Gaussian features, the extra inputs, the per-frame latent and the unnormalised
//! view directions (through the SH encoding and the normalisation), for both the scene
//! and the human layouts (shrunk widths so the check is fast; the code paths are the same).
//!
//! The network is smooth away from LeakyReLU kinks; random weights and inputs put a hidden
//! pre-activation within h = 1e-6 of 0 with probability ~1e-5 per unit, so a kink is crossed in well
//! under one case in a thousand over the 32 cases run. The tolerance
//! |num − ana| ≤ 1e-9 + 1e-6·max(|num|, |ana|) in f64 leaves orders of magnitude of margin otherwise.

use gradient_checks::{central_differences, GradientChecker, Tolerance};
use proptest::prelude::*;
use train::colour::{ColourInputs, ColourNet, ColourNetConfig};

const TOL: Tolerance = Tolerance::new(1e-9, 1e-6);
const H: f64 = 1e-6;

proptest! {
    #![proptest_config(ProptestConfig::with_cases(32))]

    #[test]
    fn colour_net_gradients_match(
        human in any::<bool>(),
        n in 1usize..5,
        seed in any::<u64>(),
        values in prop::collection::vec(-1.0f64..1.0, 200),
        dirs in prop::collection::vec(prop::array::uniform3(-1.0f64..1.0), 5),
    ) {
        let mut config = if human { ColourNetConfig::human() } else { ColourNetConfig::scene() };
        config.feature_dim = 4;
        config.extra_dim = if human { 3 } else { 0 };
        config.latent_dim = if human { 2 } else { 0 };
        config.hidden = vec![6; config.hidden.len()];
        let net = ColourNet::<f64>::new(config.clone(), seed).expect("valid config");
        let features = values[..n * 4].to_vec();
        let extra = values[40..40 + n * config.extra_dim].to_vec();
        let latent = values[80..80 + config.latent_dim].to_vec();
        let cot = values[100..100 + n * 3].to_vec();
        let dirs = dirs[..n].to_vec();
        prop_assume!(dirs.iter().all(|d| d.iter().map(|v| v * v).sum::<f64>() > 0.01));
        let loss_dirs = |net: &ColourNet<f64>, f: &[f64], e: &[f64], l: &[f64], dirs: &[[f64; 3]]| {
            let x = ColourInputs { features: f, directions: dirs, extra: e, latent: l };
            let (rgb, _) = net.forward(&x).expect("forward");
            rgb.iter().zip(&cot).map(|(a, b)| a * b).sum::<f64>()
        };
        let loss = |net: &ColourNet<f64>, f: &[f64], e: &[f64], l: &[f64]| loss_dirs(net, f, e, l, &dirs);
        let x = ColourInputs { features: &features, directions: &dirs, extra: &extra, latent: &latent };
        let (_, cache) = net.forward(&x).expect("forward");
        let g = net.backward(&cache, &cot).expect("backward");
        let num_params = central_differences(
            |p| {
                let mut m = net.clone();
                m.mlp.params = p.to_vec();
                loss(&m, &features, &extra, &latent)
            },
            &net.mlp.params,
            H,
        );
        let num_f = central_differences(|f| loss(&net, f, &extra, &latent), &features, H);
        let num_e = central_differences(|e| loss(&net, &features, e, &latent), &extra, H);
        let num_l = central_differences(|l| loss(&net, &features, &extra, l), &latent, H);
        let flat_dirs: Vec<f64> = dirs.iter().flatten().copied().collect();
        let num_d = central_differences(
            |d| {
                let d: Vec<[f64; 3]> = d.chunks(3).map(|c| [c[0], c[1], c[2]]).collect();
                loss_dirs(&net, &features, &extra, &latent, &d)
            },
            &flat_dirs,
            H,
        );
        let mut checker = GradientChecker::new();
        checker.check("colour params", &num_params, &g.params, TOL);
        checker.check("colour features", &num_f, &g.features, TOL);
        checker.check("colour extra", &num_e, &g.extra, TOL);
        checker.check("colour latent", &num_l, &g.latent, TOL);
        let ana_d: Vec<f64> = g.directions.iter().flatten().copied().collect();
        checker.check("colour directions", &num_d, &ana_d, TOL);
        checker.finish();
    }
}
