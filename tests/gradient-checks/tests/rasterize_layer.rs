//! Checks of the static layer of shared renders (`SharedOutputs::Layered`): the backward against
//! central differences of the layered forward itself, and the layered outputs against separate
//! renders. Tolerances and probe validation as in `rasterize.rs`.

mod raster_support;

use proptest::prelude::*;
use raster_support::*;

/// Three renders of `s` in which every third Gaussian moves (`moving_renders`), the moving ones
/// first brought halfway to the camera along their rays (same pixel, half the depth), so that
/// most tiles hold static Gaussians behind every moving one: the layer's case.
fn layered_renders(s: &Scene) -> (Vec<Scene>, Vec<bool>) {
    let mut front = s.clone();
    let m = &s.cam.world_to_camera;
    for (i, mean) in front.means.iter_mut().enumerate() {
        if i % 3 != 1 {
            continue;
        }
        let cam: Vec<f64> = (0..3)
            .map(|r| (0..3).map(|k| m[r][k] * mean[k]).sum::<f64>() + m[r][3])
            .collect();
        // Halve the camera-space point, then back to the world: x = Rᵀ (c − t).
        let half: Vec<f64> = (0..3).map(|r| 0.5 * cam[r] - m[r][3]).collect();
        *mean = std::array::from_fn(|k| (0..3).map(|r| m[r][k] * half[r]).sum());
    }
    moving_renders(&front, 3)
}

/// The layered renders' outputs of `scenes` (one camera, `moving` flags, covariances `covs`).
fn layered_outputs(
    scenes: &[Scene],
    covs: &[Mat3<f64>],
    moving: &[bool],
) -> rasterize_cpu::SharedRenders<f64> {
    let splats: Vec<CovSplats<'_, f64>> = scenes.iter().map(|sc| cov_splats(sc, covs)).collect();
    let settings = scenes[0].settings();
    render_cov_shared(
        &scenes[0].cam,
        &splats,
        moving,
        1,
        &settings,
        SharedOutputs::Layered,
    )
    .unwrap_or_else(|e| panic!("render_cov_shared: {e}"))
}

type Cot = (Vec<f64>, Vec<f64>, Vec<f64>);

/// L = Σ_r cot_r · (image, alpha, depth)_r of the layered renders.
fn layered_loss(scenes: &[Scene], covs: &[Mat3<f64>], moving: &[bool], cots: &[Cot]) -> f64 {
    let fwd = layered_outputs(scenes, covs, moving);
    fwd.outputs
        .iter()
        .zip(cots)
        .map(|(o, c)| dot(&o.image, &c.0) + dot(&o.alpha, &c.1) + dot(&o.depth, &c.2))
        .sum()
}

/// Whether `f` bends at 0 (the one-sided slopes differ beyond what smooth curvature gives at
/// step `h`): a discrete decision of the layered blend (a head/layer split or a layer's stop)
/// flips within the probe, which the separate renders' decisions do not see.
fn kinked(f: &dyn Fn(f64) -> f64, h: f64) -> bool {
    let (lo, mid, hi) = (f(-h), f(0.0), f(h));
    let (left, right) = ((mid - lo) / h, (hi - mid) / h);
    (right - left).abs() > 1e-3 * (1.0 + left.abs().max(right.abs()))
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(12))]

    /// `render_cov_shared_backward` of layered renders against central differences of the
    /// layered forward's L = Σ_r cot_r · render_r, over three renders from one camera: a static
    /// Gaussian's parameter is perturbed in every render at once against the sum of the renders'
    /// gradients (its layer's share reaches only the owner's), a moving Gaussian's in one render
    /// against that render's. Probes flipping a decision of the separate renders' oracle or bending
    /// the layered loss (`kinked`) are discarded (≥ 90% must remain); tolerance FD_TOL.
    #[test]
    fn layered_render_gradients_match_finite_differences(
        seed in any::<u64>(),
        kinds in kinds_strategy(10),
        c in 1usize..4,
    ) {
        let s = random_scene(seed, &kinds, c);
        let (mut scenes, moving) = layered_renders(&s);
        let covs: Vec<Mat3<f64>> =
            (0..s.n()).map(|i| covariance_3d(s.log_scales[i], s.quats[i])).collect();
        for sc in &mut scenes {
            sc.covs = Some(covs.clone());
        }
        let cots: Vec<Cot> = (0..3).map(|r| random_cotangent(&s, seed ^ (r as u64 + 1))).collect();
        let settings = s.settings();
        let splats: Vec<CovSplats<'_, f64>> = scenes.iter().map(|sc| cov_splats(sc, &covs)).collect();
        let fwd = layered_outputs(&scenes, &covs, &moving);
        let cot_refs: Vec<Cotangents<'_, f64>> = cots
            .iter()
            .map(|c| Cotangents { image: &c.0, alpha: Some(&c.1), depth: Some(&c.2) })
            .collect();
        let outs: Vec<_> = fwd.outputs.iter().collect();
        let g = render_cov_shared_backward(&s.cam, &splats, &settings, &outs, &fwd.sharing, &cot_refs)
            .unwrap_or_else(|e| panic!("render_cov_shared_backward: {e}"));
        let layered = fwd.sharing.layer.as_ref().map_or(0.0, |l| l.layered_fraction());
        static LAYERED: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
        if layered > 0.0 {
            LAYERED.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        }
        let base: Vec<_> = scenes.iter().map(|sc| oracle(sc, None).decisions).collect();
        let mut checker = GradientChecker::new();
        let (mut probes, mut valid) = (0usize, 0usize);
        for i in 0..s.n() {
            for r in 0..3 {
                if !moving[i] && r > 0 {
                    continue;
                }
                let loss = |sc: &[Scene]| layered_loss(sc, &covs, &moving, &cots);
                let discard = |perturbed: &dyn Fn(f64) -> Vec<Scene>, x: f64| {
                    let flips = [x + FD_H, x - FD_H].into_iter().any(|v| {
                        perturbed(v).iter().zip(&base).any(|(sc, b)| &oracle(sc, None).decisions != b)
                    });
                    flips || kinked(&|t| loss(&perturbed(x + t)), FD_H)
                };
                let (num, ana, p, v) =
                    shared_render_probes(&scenes, &moving, i, r, c, &g, &loss, &discard);
                probes += p;
                valid += v;
                checker.check(
                    &format!("gaussian {i} (kind {}, moving {}) render {r}, layered {layered:.2}", kind_of(&kinds, i), moving[i]),
                    &num,
                    &ana,
                    FD_TOL,
                );
            }
        }
        static TALLY: ProbeTally = ProbeTally::new(300);
        let tally = TALLY.add(probes, valid);
        prop_assert!(tally.is_ok(), "{}", tally.unwrap_err());
        // The check is not vacuous: after a few cases, some had layers.
        prop_assert!(
            probes < 300 || LAYERED.load(std::sync::atomic::Ordering::Relaxed) > 0,
            "no case had a layered tile"
        );
        checker.finish();
    }

    /// Where no pixel's transmittance falls below 1e-4 (faint Gaussians), the layered renders are
    /// the separate renders, to f64 rounding: the composite C_h + T_h C_s, T_h T_s, D_h + T_h D_s
    /// is the blend of the whole list.
    #[test]
    fn faint_layered_renders_equal_separate_renders(
        seed in any::<u64>(),
        kinds in kinds_strategy(10),
        c in 1usize..4,
    ) {
        let mut s = random_scene(seed, &kinds, c);
        for l in &mut s.logits {
            *l = l.min(-1.0);
        }
        let (scenes, moving) = layered_renders(&s);
        let covs: Vec<Mat3<f64>> =
            (0..s.n()).map(|i| covariance_3d(s.log_scales[i], s.quats[i])).collect();
        let fwd = layered_outputs(&scenes, &covs, &moving);
        for (r, sc) in scenes.iter().enumerate() {
            let alone = render_cov(&sc.cam, &cov_splats(sc, &covs), &sc.settings())
                .unwrap_or_else(|e| panic!("render_cov: {e}"));
            let out = &fwd.outputs[r];
            for (name, a, b) in [
                ("image", &alone.image, &out.image),
                ("alpha", &alone.alpha, &out.alpha),
                ("depth", &alone.depth, &out.depth),
            ] {
                let worst = a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0f64, f64::max);
                prop_assert!(worst <= 1e-12, "render {r} {name}: {worst:e}");
            }
        }
    }
}

#[test]
fn layered_renders_stay_within_the_stop_rule_of_separate_renders() {
    // f32, many opaque Gaussians: the layer exists, and a pixel differs from its separate render
    // only by what the 1e-4 stop leaves out of the layer, at most T·(max |channel| + max |bg|)
    // with T < 1e-4 / (1 − 0.99) at the stop. Every output refuses its own backward.
    let scene = F32Renders::new();
    let (cam, moving) = (&scene.cam, &scene.moving);
    let splats = scene.splats();
    let settings = scene.settings();
    let layered = render_cov_shared(cam, &splats, moving, 1, &settings, SharedOutputs::Layered)
        .unwrap_or_else(|e| panic!("render_cov_shared: {e}"));
    let fraction = layered
        .sharing
        .layer
        .as_ref()
        .map_or(0.0, |l| l.layered_fraction());
    assert!(fraction > 0.05, "layered fraction {fraction}");
    let max_channel = scene.channels.iter().fold(0.0f32, |a, v| a.max(v.abs()));
    let bound = 1e-2 * (max_channel + 0.3) + 1e-5;
    let hw = (cam.width * cam.height) as usize;
    let cot: Vec<f32> = vec![0.1; 3 * hw];
    for r in 0..3 {
        let alone = render_cov(cam, &splats[r], &settings).unwrap_or_else(|e| panic!("{e}"));
        let out = &layered.outputs[r];
        let worst = alone
            .image
            .iter()
            .zip(&out.image)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0f32, f32::max);
        assert!(worst <= bound, "render {r}: {worst} > {bound}");
        let same = alone
            .image
            .iter()
            .zip(&out.image)
            .filter(|(a, b)| (*a - *b).abs() <= 1e-6)
            .count();
        assert!(
            same * 10 >= 9 * alone.image.len(),
            "render {r}: {same} of {}",
            alone.image.len()
        );
        let own = Cotangents {
            image: &cot,
            alpha: None,
            depth: None,
        };
        let alone_backward = render_cov_backward(cam, &splats[r], &settings, out, &own);
        assert!(
            matches!(alone_backward, Err(RasterError::ForwardMismatch(_))),
            "render {r}"
        );
    }
}
