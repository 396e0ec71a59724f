//! End-to-end finite-difference check of `train::step::photometric_step`: scene-colour network →
//! rasterizer → L1 + λ·D-SSIM, differentiated w.r.t. the colour features and the network weights.
//!
//! This proves the composition (loss cotangent → image → channels → colour network). The geometric
//! gradients of the rasterizer are proven in `rasterize.rs` against an oracle and validated FD probes;
//! colour inputs change no discrete rasterizer decision (visibility, tiles, α cut and clamp, early stop
//! depend on geometry and opacity only), so these probes are smooth except for L1's kink at
//! render = target, which a random target places within h of a pixel with probability ~1e-6 per probe.
//! Tolerance in f64 with h = 1e-6: |num − ana| ≤ 1e-9 + 1e-6·max(|num|, |ana|) (loss O(1), rounding
//! ε·|L|/h ≈ 1e-10, truncation ≈ h²·|L'''| ≪ 1e-9 for these smooth compositions).

use gradient_checks::{central_differences, GradientChecker, Tolerance};
use proptest::prelude::*;
use rasterize_cpu::{Camera, RenderSettings};
use train::colour::{ColourNet, ColourNetConfig};
use train::step::{photometric_step, StaticGaussians};

const TOL: Tolerance = Tolerance::new(1e-9, 1e-6);
const H: f64 = 1e-6;
const N: usize = 6;
const FEATURES: usize = 4;

struct Scene {
    means: Vec<[f64; 3]>,
    log_scales: Vec<[f64; 3]>,
    quats: Vec<[f64; 4]>,
    opacity_logits: Vec<f64>,
}

fn scene(values: &[f64]) -> Scene {
    let v = |i: usize| values[i % values.len()];
    Scene {
        means: (0..N)
            .map(|i| [v(i) * 0.4, v(i + 7) * 0.3, 2.0 + v(i + 13).abs()])
            .collect(),
        log_scales: (0..N)
            .map(|i| [-2.0 + 0.3 * v(i + 3), -2.0 + 0.3 * v(i + 5), -2.2])
            .collect(),
        quats: (0..N)
            .map(|i| [1.0, 0.3 * v(i + 1), 0.3 * v(i + 2), 0.3 * v(i + 4)])
            .collect(),
        opacity_logits: (0..N).map(|i| v(i + 11)).collect(),
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(12))]

    #[test]
    fn photometric_step_colour_gradients_match(
        geometry in prop::collection::vec(-1.0f64..1.0, 17),
        features in prop::collection::vec(-1.0f64..1.0, N * FEATURES),
        target in prop::collection::vec(0.0f64..1.0, 3 * 20 * 24),
        seed in any::<u64>(),
        ssim_weight in 0.0f64..1.0,
    ) {
        let camera = Camera::looking_down_z(24, 20, 30.0, 30.0).expect("valid camera");
        let s = scene(&geometry);
        let mut config = ColourNetConfig::scene();
        config.feature_dim = FEATURES;
        config.hidden = vec![5];
        let net = ColourNet::<f64>::new(config, seed).expect("valid config");
        let settings = RenderSettings { near_plane: 0.2, background: vec![0.1, 0.2, 0.3] };
        let run = |net: &ColourNet<f64>, f: &[f64], grads: bool| {
            let g = StaticGaussians {
                means: &s.means,
                log_scales: &s.log_scales,
                quats: &s.quats,
                opacity_logits: &s.opacity_logits,
                features: f,
            };
            photometric_step(&camera, &g, net, &target, ssim_weight, &settings, grads).expect("step")
        };
        let out = run(&net, &features, true);
        let grads = out.grads.expect("gradients requested");
        prop_assert!(out.radii.iter().any(|&r| r > 0), "no Gaussian visible");
        let num_features = central_differences(|f| run(&net, f, false).loss, &features, H);
        let num_params = central_differences(
            |p| {
                let mut m = net.clone();
                m.mlp.params = p.to_vec();
                run(&m, &features, false).loss
            },
            &net.mlp.params,
            H,
        );
        let mut checker = GradientChecker::new();
        checker.check("step d features", &num_features, &grads.features, TOL);
        checker.check("step d colour params", &num_params, &grads.colour_params, TOL);
        checker.finish();
        // Geometry gradients are reported and not all zero (their values are proven in rasterize.rs).
        prop_assert!(grads.means.iter().flatten().any(|&g| g != 0.0));
    }
}
