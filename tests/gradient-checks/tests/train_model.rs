//! End-to-end finite-difference check of the per-frame model (`train::posing`): non-rigid network →
//! learned skinning → LBS → deformed covariance, static covariance, both colour networks, semantic
//! blend — w.r.t. every learnable quantity (Gaussian parameters, logits, the four networks, the frame
//! latent and the bone transforms), for the one-hot and scalar semantics, with the exact blend
//! (gate 0) and with a semantic gate of 0.5 (some Gaussians then skip the human branch: the gated
//! function is what is differentiated; probes crossing the gate have probability ~1e-6).
//!
//! Tolerance: the loss L = Σ cot·outputs is O(10); in f64 with h = 1e-6 the rounding error of a central
//! difference is ≈ ε·|L|/h ≈ 2e-9 and the truncation error ≈ h²·|L'''| ≪ 1e-9, so
//! |num − ana| ≤ 1e-7 + 1e-6·max(|num|, |ana|) has two orders of magnitude of margin. The networks
//! are smooth except at LeakyReLU kinks, which a 1e-6 probe crosses with probability ~1e-6 per unit.
//! The non-rigid network's zero-initialised last layer is randomised so its gradients are exercised.

use gradient_checks::{central_differences, rng, symmetric_from_seed, GradientChecker, Tolerance};
use proptest::prelude::*;
use rand::Rng;
use smpl_deform::deform_net::{NonRigidNet, SkinningField, NR_FEATURE_DIM};
use train::blend::SemanticMode;
use train::colour::{ColourNet, ColourNetConfig};
use train::posing::{
    pose_frame_backward, pose_frame_gated, FrameCotangents, FrameInputs, GaussianParams, ModelNets,
};

const TOL: Tolerance = Tolerance::new(1e-7, 1e-6);
const H: f64 = 1e-6;
const N: usize = 3;
const F: usize = 3;

struct Case {
    nets: ModelNets<f64>,
    means: Vec<[f64; 3]>,
    log_scales: Vec<[f64; 3]>,
    quats: Vec<[f64; 4]>,
    features: Vec<f64>,
    logits: Vec<f64>,
    pose_code: Vec<f64>,
    bones: Vec<[f64; 12]>,
    latent: Vec<f64>,
    centre: [f64; 3],
    mode: SemanticMode,
    gate: f64,
}

fn case(seed: u64, scalar: bool, gate: f64) -> Case {
    // Not `seed` itself: the networks below draw their initial weights from a generator seeded so.
    let mut rng = rng(seed ^ 0xca5e);
    let mut r = || rng.gen_range(-1.0..1.0);
    let verts: Vec<[f32; 3]> = (0..20)
        .map(|_| [r() as f32, r() as f32, r() as f32])
        .collect();
    let mut nonrigid = NonRigidNet::<f64>::new(&verts, 5, seed).expect("net");
    for p in nonrigid.mlp.params.iter_mut() {
        *p += 0.05 * r();
    }
    let skinning = SkinningField::<f64>::new(&verts, 5, seed ^ 1).expect("field");
    let mut human = ColourNetConfig::human();
    human.feature_dim = F;
    human.latent_dim = 2;
    human.hidden = vec![4];
    assert_eq!(human.extra_dim, NR_FEATURE_DIM);
    let mut scene = ColourNetConfig::scene();
    scene.feature_dim = F;
    scene.hidden = vec![4];
    let nets = ModelNets {
        nonrigid,
        skinning,
        human_colour: ColourNet::new(human, seed ^ 2).expect("net"),
        scene_colour: ColourNet::new(scene, seed ^ 3).expect("net"),
    };
    let bones = (0..24)
        .map(|_| {
            // A rotation from a random axis-angle (Rodrigues) and a translation.
            let w = [0.5 * r(), 0.5 * r(), 0.5 * r()];
            let th = (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]).sqrt();
            let k = [w[0] / th, w[1] / th, w[2] / th];
            let (c, sn) = (th.cos(), th.sin());
            let kx = [[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]];
            let mut m = [0.0; 12];
            for i in 0..3 {
                for j in 0..3 {
                    let kk = (0..3).map(|l| kx[i][l] * kx[l][j]).sum::<f64>();
                    m[i * 4 + j] = f64::from(u8::from(i == j)) + sn * kx[i][j] + (1.0 - c) * kk;
                }
                m[i * 4 + 3] = 0.3 * r();
            }
            m
        })
        .collect();
    let mode = if scalar {
        SemanticMode::Scalar
    } else {
        SemanticMode::OneHot
    };
    Case {
        nets,
        means: (0..N).map(|_| [0.5 * r(), 0.5 * r(), 0.5 * r()]).collect(),
        log_scales: (0..N)
            .map(|_| [-2.0 + 0.3 * r(), -2.0 + 0.3 * r(), -2.0 + 0.3 * r()])
            .collect(),
        quats: (0..N)
            .map(|_| [1.0, 0.3 * r(), 0.3 * r(), 0.3 * r()])
            .collect(),
        features: (0..N * F).map(|_| r()).collect(),
        logits: (0..N * mode.logits_per_gaussian())
            .map(|_| 2.0 * r())
            .collect(),
        pose_code: (0..207).map(|_| 0.2 * r()).collect(),
        bones,
        latent: vec![r(), r()],
        centre: [0.2 * r(), 0.1 * r(), -3.0],
        mode,
        gate,
    }
}

fn outputs(
    c: &Case,
) -> (
    train::posing::PosedFrame<f64>,
    train::posing::FrameCache<f64>,
) {
    let g = GaussianParams {
        means: &c.means,
        log_scales: &c.log_scales,
        quats: &c.quats,
        features: &c.features,
        semantic_logits: &c.logits,
    };
    let f = FrameInputs {
        pose_code: &c.pose_code,
        bones: &c.bones,
        camera_centre: c.centre,
        latent: &c.latent,
    };
    pose_frame_gated(&c.nets, c.mode, c.gate, &g, &f).expect("forward")
}

fn loss(c: &Case, cot: &[f64]) -> f64 {
    let (o, _) = outputs(c);
    let flat: Vec<f64> = o
        .means
        .iter()
        .flatten()
        .chain(o.covariances.iter().flatten().flatten())
        .chain(&o.colours)
        .chain(&o.human_probability)
        .copied()
        .collect();
    flat.iter().zip(cot).map(|(a, b)| a * b).sum()
}

/// FD over one parameter block, read and written through `get`/`set` closures.
fn fd(c: &Case, cot: &[f64], x: Vec<f64>, set: impl Fn(&mut Case, &[f64])) -> Vec<f64> {
    let mut work = Case { ..clone_case(c) };
    central_differences(
        |p| {
            set(&mut work, p);
            loss(&work, cot)
        },
        &x,
        H,
    )
}

fn clone_case(c: &Case) -> Case {
    Case {
        nets: c.nets.clone(),
        means: c.means.clone(),
        log_scales: c.log_scales.clone(),
        quats: c.quats.clone(),
        features: c.features.clone(),
        logits: c.logits.clone(),
        pose_code: c.pose_code.clone(),
        bones: c.bones.clone(),
        latent: c.latent.clone(),
        centre: c.centre,
        mode: c.mode,
        gate: c.gate,
    }
}

fn rows<const D: usize>(p: &[f64]) -> Vec<[f64; D]> {
    p.chunks(D)
        .map(|ch| std::array::from_fn(|k| ch[k]))
        .collect()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(8))]

    #[test]
    fn model_gradients_match_finite_differences(seed in any::<u64>(), scalar in any::<bool>(), gated in any::<bool>()) {
        let c = case(seed, scalar, if gated { 0.5 } else { 0.0 });
        let outputs_len = N * (3 + 9 + 3 + 1);
        let cot = symmetric_from_seed(seed ^ 0xabc, outputs_len);
        let (_, cache) = outputs(&c);
        let means_cot = rows::<3>(&cot[..N * 3]);
        let cov_cot: Vec<[[f64; 3]; 3]> = cot[N * 3..N * 12].chunks(9).map(|m| [[m[0], m[1], m[2]], [m[3], m[4], m[5]], [m[6], m[7], m[8]]]).collect();
        let g = GaussianParams { means: &c.means, log_scales: &c.log_scales, quats: &c.quats, features: &c.features, semantic_logits: &c.logits };
        let f = FrameInputs { pose_code: &c.pose_code, bones: &c.bones, camera_centre: c.centre, latent: &c.latent };
        let grads = pose_frame_backward(&c.nets, c.mode, &g, &f, &cache, &FrameCotangents {
            means: &means_cot,
            covariances: &cov_cot,
            colours: &cot[N * 12..N * 15],
            human_probability: &cot[N * 15..],
        }).expect("backward");
        let flat = |v: &[[f64; 3]]| v.iter().flatten().copied().collect::<Vec<_>>();
        let mut checker = GradientChecker::new();
        let num = fd(&c, &cot, flat(&c.means), |w, p| w.means = rows(p));
        checker.check("means", &num, &flat(&grads.means), TOL);
        let num = fd(&c, &cot, flat(&c.log_scales), |w, p| w.log_scales = rows(p));
        checker.check("log_scales", &num, &flat(&grads.log_scales), TOL);
        let num = fd(&c, &cot, c.quats.iter().flatten().copied().collect(), |w, p| w.quats = rows(p));
        checker.check("quats", &num, &grads.quats.iter().flatten().copied().collect::<Vec<_>>(), TOL);
        let num = fd(&c, &cot, c.features.clone(), |w, p| w.features = p.to_vec());
        checker.check("features", &num, &grads.features, TOL);
        let num = fd(&c, &cot, c.logits.clone(), |w, p| w.logits = p.to_vec());
        checker.check("semantic logits", &num, &grads.semantic_logits, TOL);
        let num = fd(&c, &cot, c.latent.clone(), |w, p| w.latent = p.to_vec());
        checker.check("latent", &num, &grads.latent, TOL);
        let num = fd(&c, &cot, c.bones.iter().flatten().copied().collect(), |w, p| w.bones = rows(p));
        checker.check("bones", &num, &grads.bones.iter().flatten().copied().collect::<Vec<_>>(), TOL);
        let num = fd(&c, &cot, c.nets.nonrigid.mlp.params.clone(), |w, p| w.nets.nonrigid.mlp.params = p.to_vec());
        checker.check("non-rigid net", &num, &grads.nonrigid, TOL);
        let num = fd(&c, &cot, c.nets.skinning.mlp.params.clone(), |w, p| w.nets.skinning.mlp.params = p.to_vec());
        checker.check("skinning field", &num, &grads.skinning, TOL);
        let num = fd(&c, &cot, c.nets.human_colour.mlp.params.clone(), |w, p| w.nets.human_colour.mlp.params = p.to_vec());
        checker.check("human colour net", &num, &grads.human_colour, TOL);
        let num = fd(&c, &cot, c.nets.scene_colour.mlp.params.clone(), |w, p| w.nets.scene_colour.mlp.params = p.to_vec());
        checker.check("scene colour net", &num, &grads.scene_colour, TOL);
        checker.finish();
    }
}
