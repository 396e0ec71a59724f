//! End-to-end finite-difference check of `photometric_step` (below): scene-colour network →
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
use static_step::{photometric_step, StaticGaussians};
use train::colour::{ColourNet, ColourNetConfig};

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

/// One differentiable photometric step for statically coloured Gaussians: per-Gaussian colour from
/// the scene-colour network, rasterization, L1 + λ·D-SSIM against a target frame, and the backward
/// pass to every Gaussian parameter, the features and the network weights — the scene branch of the
/// training step composed from the library's pieces, generic over the float type so that the chain
/// is finite-difference checked in f64.
mod static_step {
    use rasterize_cpu::{render, render_backward, Camera, Cotangents, RenderSettings, Splats};
    use train::colour::{ColourInputs, ColourNet};
    use train::loss::image::{l1, ssim, ImageShape};
    use train::TrainError;

    /// Stored parameters of N statically coloured Gaussians (same conventions as `gaussians::GaussianSet`).
    #[derive(Clone, Copy, Debug)]
    pub struct StaticGaussians<'a, T> {
        /// Means in world space (m).
        pub means: &'a [[T; 3]],
        /// Log-scales (ln m).
        pub log_scales: &'a [[T; 3]],
        /// Unnormalised (w, x, y, z) quaternions.
        pub quats: &'a [[T; 4]],
        /// Opacity logits.
        pub opacity_logits: &'a [T],
        /// Colour features, N × `feature_dim` of the colour network.
        pub features: &'a [T],
    }

    /// Gradients of a step w.r.t. the Gaussians and the colour network.
    #[derive(Clone, Debug, PartialEq)]
    pub struct StaticGradients<T> {
        /// dL/d means.
        pub means: Vec<[T; 3]>,
        /// dL/d log-scales.
        pub log_scales: Vec<[T; 3]>,
        /// dL/d quaternions.
        pub quats: Vec<[T; 4]>,
        /// dL/d opacity logits.
        pub opacity_logits: Vec<T>,
        /// dL/d features.
        pub features: Vec<T>,
        /// dL/d colour-network parameters.
        pub colour_params: Vec<T>,
        /// dL/d screen-space means in pixels (density-control statistic).
        pub means_2d: Vec<[T; 2]>,
    }

    /// Result of [`photometric_step`].
    #[derive(Clone, Debug)]
    pub struct StepOutput<T> {
        /// Total loss (1 − λ)·L1 + λ·(1 − SSIM).
        pub loss: T,
        /// Screen radius per Gaussian (pixels, 0 = culled).
        pub radii: Vec<u32>,
        /// Gradients (None when not requested).
        pub grads: Option<StaticGradients<T>>,
    }

    /// Renders the Gaussians coloured by `net` (view direction = mean − camera centre, differentiated) from
    /// `camera` and compares with `target` (3, H, W) using (1 − `ssim_weight`)·L1 + `ssim_weight`·(1 − SSIM).
    /// With `with_grads` the backward runs through SSIM/L1, the rasterizer and the colour network.
    pub fn photometric_step<T>(
        camera: &Camera,
        gaussians: &StaticGaussians<'_, T>,
        net: &ColourNet<T>,
        target: &[T],
        ssim_weight: T,
        settings: &RenderSettings,
        with_grads: bool,
    ) -> Result<StepOutput<T>, TrainError>
    where
        T: nn::Real + rasterize_cpu::Real,
    {
        let n = gaussians.means.len();
        let centre = camera.center_world();
        let centre: [T; 3] = centre.map(<T as nn::Real>::of);
        let directions: Vec<[T; 3]> = gaussians
            .means
            .iter()
            .map(|m| [m[0] - centre[0], m[1] - centre[1], m[2] - centre[2]])
            .collect();
        let inputs = ColourInputs {
            features: gaussians.features,
            directions: &directions,
            extra: &[],
            latent: &[],
        };
        let (rgb, colour_cache) = net.forward(&inputs)?;
        let splats = Splats {
            means: gaussians.means,
            log_scales: gaussians.log_scales,
            quats: gaussians.quats,
            opacity_logits: gaussians.opacity_logits,
            channels: &rgb,
            num_channels: 3,
        };
        let out = render(camera, &splats, settings)?;
        let shape = ImageShape {
            channels: 3,
            height: camera.height as usize,
            width: camera.width as usize,
        };
        if target.len() != shape.len() {
            return Err(TrainError::Shape {
                what: "target image".into(),
                expected: shape.len(),
                found: target.len(),
            });
        }
        let one = T::one();
        let mut d_l1 = if with_grads {
            vec![T::zero(); shape.len()]
        } else {
            Vec::new()
        };
        let mut d_ssim = if with_grads {
            vec![T::zero(); shape.len()]
        } else {
            Vec::new()
        };
        let l1_value = l1(&out.image, target, with_grads.then_some(&mut d_l1[..]));
        let ssim_value = ssim(
            &out.image,
            target,
            shape,
            with_grads.then_some(&mut d_ssim[..]),
        );
        let loss = (one - ssim_weight) * l1_value + ssim_weight * (one - ssim_value);
        let grads = if with_grads {
            let d_image: Vec<T> = d_l1
                .iter()
                .zip(&d_ssim)
                .map(|(&a, &b)| (one - ssim_weight) * a - ssim_weight * b)
                .collect();
            let cot = Cotangents {
                image: &d_image,
                alpha: None,
                depth: None,
            };
            let g = render_backward(camera, &splats, settings, &out, &cot)?;
            let cg = net.backward(&colour_cache, &g.channels)?;
            debug_assert_eq!(g.means.len(), n);
            // The view direction is mean − camera centre, so its gradient adds to the means'.
            let mut means = g.means;
            for (m, d) in means.iter_mut().zip(&cg.directions) {
                for a in 0..3 {
                    m[a] = m[a] + d[a];
                }
            }
            Some(StaticGradients {
                means,
                log_scales: g.log_scales,
                quats: g.quats,
                opacity_logits: g.opacity_logits,
                features: cg.features,
                colour_params: cg.params,
                means_2d: g.means_2d,
            })
        } else {
            None
        };
        Ok(StepOutput {
            loss,
            radii: out.radii,
            grads,
        })
    }
}
