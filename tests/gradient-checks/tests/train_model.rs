//! End-to-end finite-difference check of the per-frame model (`train::pose::posing`): non-rigid network →
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
//!
//! The second check is the exposure model's shared-network composition (`train::pose::reposing`): the
//! frame posed at its reference bones plus two re-posings at other bones, each output paired with its
//! own cotangent, differentiated by one reference backward that receives the re-posings' summed
//! cotangents — w.r.t. the same quantities and every pass's bones (same tolerance and argument).
//!
//! Both checks run with one person and with two and three people (K = 1 + P one-hot classes, each
//! Gaussian deformed by its most probable person's bones and pose code, each person's probability
//! an output of its own; probes that change a Gaussian's most probable person need two logits
//! within 1e-6 of each other, probability ~1e-6).
//!
//! The third is learned pose correction end to end: a frame's correction → its corrected
//! sub-exposure poses → bones and pose code → the same composition → outputs, plus the prior.

use gradient_checks::{central_differences, rng, symmetric_from_seed, GradientChecker, Tolerance};
use proptest::prelude::*;
use rand::Rng;
use smpl_deform::deform_net::{NonRigidNet, SkinningField, NR_FEATURE_DIM};
use train::blend::SemanticMode;
use train::colour::{ColourNet, ColourNetConfig};
use train::pose::posing::{
    pose_frame_backward, pose_frame_backward_with, pose_frame_gated, FrameCotangents, FrameInputs,
    GaussianParams, ModelNets, PosedFrame, ViewRotation,
};
use train::pose::reposing::{repose_frame, repose_frame_backward, ReposeCotangents};

const TOL: Tolerance = Tolerance::new(1e-7, 1e-6);
const H: f64 = 1e-6;
const N: usize = 3;
/// Gaussians of a case with several people (enough for every person to have some, mostly).
const N_PEOPLE: usize = 6;
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
    view_rotation: ViewRotation,
}

fn case(seed: u64, scalar: bool, gate: f64) -> Case {
    case_of(seed, scalar, gate, 1)
}

/// A case of `people` people (one-hot semantics when more than one).
fn case_of(seed: u64, scalar: bool, gate: f64, people: usize) -> Case {
    let n = if people > 1 { N_PEOPLE } else { N };
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
    let bones = (0..24 * people)
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
    let mode = if scalar && people == 1 {
        SemanticMode::Scalar
    } else {
        SemanticMode::OneHot
    };
    Case {
        nets,
        means: (0..n).map(|_| [0.5 * r(), 0.5 * r(), 0.5 * r()]).collect(),
        log_scales: (0..n)
            .map(|_| [-2.0 + 0.3 * r(), -2.0 + 0.3 * r(), -2.0 + 0.3 * r()])
            .collect(),
        quats: (0..n)
            .map(|_| [1.0, 0.3 * r(), 0.3 * r(), 0.3 * r()])
            .collect(),
        features: (0..n * F).map(|_| r()).collect(),
        logits: (0..n * mode.logits_for(people))
            .map(|_| 2.0 * r())
            .collect(),
        pose_code: (0..207 * people).map(|_| 0.2 * r()).collect(),
        bones,
        latent: vec![r(), r()],
        centre: [0.2 * r(), 0.1 * r(), -3.0],
        mode,
        gate,
        view_rotation: ViewRotation::Canonical,
    }
}

fn outputs(
    c: &Case,
) -> (
    train::pose::posing::PosedFrame<f64>,
    train::pose::posing::FrameCache<f64>,
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
        view_rotation: c.view_rotation,
    };
    pose_frame_gated(&c.nets, c.mode, c.gate, &g, &f).expect("forward")
}

impl Case {
    fn n(&self) -> usize {
        self.means.len()
    }

    fn people(&self) -> usize {
        self.bones.len() / 24
    }

    /// The length of the flattened outputs (means, covariances, colours, probability, and each
    /// person's probability with several people).
    fn outputs_len(&self) -> usize {
        let extra = if self.people() > 1 { self.people() } else { 0 };
        self.n() * (3 + 9 + 3 + 1 + extra)
    }
}

/// ⟨cot, outputs⟩ over the flattened outputs (means, covariances, colours, probability, people).
fn pairing(o: &PosedFrame<f64>, cot: &[f64]) -> f64 {
    let flat: Vec<f64> = o
        .means
        .iter()
        .flatten()
        .chain(o.covariances.iter().flatten().flatten())
        .chain(&o.colours)
        .chain(&o.human_probability)
        .chain(&o.person_probability)
        .copied()
        .collect();
    assert_eq!(flat.len(), cot.len());
    flat.iter().zip(cot).map(|(a, b)| a * b).sum()
}

fn loss(c: &Case, cot: &[f64]) -> f64 {
    pairing(&outputs(c).0, cot)
}

/// The frame's outputs paired with `cots[0]` plus each re-posing's paired with `cots[1 + s]`.
fn reposed_loss(c: &Case, reposings: &[Vec<[f64; 12]>], cots: &[Vec<f64>]) -> f64 {
    let (reference, cache) = outputs(c);
    let mut total = pairing(&reference, &cots[0]);
    for (bones, cot) in reposings.iter().zip(&cots[1..]) {
        let (o, _) = repose_frame(&reference, &cache, bones).expect("repose");
        total += pairing(&o, cot);
    }
    total
}

/// The means' and covariances' cotangents of a flat cotangent vector of `n` Gaussians.
fn frame_cotangents(cot: &[f64], n: usize) -> (Vec<[f64; 3]>, Vec<[[f64; 3]; 3]>) {
    let means = rows::<3>(&cot[..n * 3]);
    let covariances = cot[n * 3..n * 12]
        .chunks(9)
        .map(|m| [[m[0], m[1], m[2]], [m[3], m[4], m[5]], [m[6], m[7], m[8]]])
        .collect();
    (means, covariances)
}

/// The posing's cotangents of a flat cotangent vector (see [`pairing`]).
fn cotangents<'a>(
    cot: &'a [f64],
    n: usize,
    rows: &'a (Vec<[f64; 3]>, Vec<[[f64; 3]; 3]>),
) -> FrameCotangents<'a, f64> {
    FrameCotangents {
        means: &rows.0,
        covariances: &rows.1,
        colours: &cot[n * 12..n * 15],
        human_probability: &cot[n * 15..n * 16],
        person_probability: &cot[n * 16..],
    }
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

/// `c` with the view directions canonicalised by the deformation's own weights at the moved
/// means when `moved`, else by the field at the canonical means.
fn with_view_rotation(c: Case, moved: bool) -> Case {
    let view_rotation = if moved {
        ViewRotation::Moved
    } else {
        ViewRotation::Canonical
    };
    Case { view_rotation, ..c }
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
        view_rotation: c.view_rotation,
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
    fn model_gradients_match_finite_differences(seed in any::<u64>(), scalar in any::<bool>(), gated in any::<bool>(), people in 1usize..=3, moved in any::<bool>()) {
        let c = with_view_rotation(case_of(seed, scalar, if gated { 0.5 } else { 0.0 }, people), moved);
        let n = c.n();
        let cot = symmetric_from_seed(seed ^ 0xabc, c.outputs_len());
        let (_, cache) = outputs(&c);
        let split = frame_cotangents(&cot, n);
        let g = GaussianParams { means: &c.means, log_scales: &c.log_scales, quats: &c.quats, features: &c.features, semantic_logits: &c.logits };
        let f = FrameInputs { pose_code: &c.pose_code, bones: &c.bones, camera_centre: c.centre, latent: &c.latent, view_rotation: c.view_rotation };
        let grads = pose_frame_backward(&c.nets, c.mode, &g, &f, &cache, &cotangents(&cot, n, &split)).expect("backward");
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
        let num = fd(&c, &cot, c.pose_code.clone(), |w, p| w.pose_code = p.to_vec());
        checker.check("pose code", &num, &grads.pose_code, TOL);
        checker.finish();
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(6))]

    #[test]
    fn reposed_frame_gradients_match_finite_differences(seed in any::<u64>(), scalar in any::<bool>(), gated in any::<bool>(), people in 1usize..=3, moved in any::<bool>()) {
        let c = with_view_rotation(case_of(seed, scalar, if gated { 0.5 } else { 0.0 }, people), moved);
        let n = c.n();
        let mut rng = rng(seed ^ 0x5eb);
        let reposings: Vec<Vec<[f64; 12]>> = (0..2)
            .map(|_| c.bones.iter().map(|b| b.map(|v| v + 0.05 * rng.gen_range(-1.0..1.0))).collect())
            .collect();
        let cots: Vec<Vec<f64>> = (0..3).map(|s| symmetric_from_seed(seed ^ (0xabc + s), c.outputs_len())).collect();
        let (reference, cache) = outputs(&c);
        // At the reference's own bones a re-posing is the reference, bit for bit.
        let (same, _) = repose_frame(&reference, &cache, &c.bones).expect("repose");
        prop_assert_eq!(&same, &reference);
        let g = GaussianParams { means: &c.means, log_scales: &c.log_scales, quats: &c.quats, features: &c.features, semantic_logits: &c.logits };
        let mut summed = ReposeCotangents::zeros(n, cache.active().len());
        let mut sub_bones = Vec::new();
        for (bones, cot) in reposings.iter().zip(&cots[1..]) {
            let (_, sub) = repose_frame(&reference, &cache, bones).expect("repose");
            let split = frame_cotangents(cot, n);
            let (d, d_bones) = repose_frame_backward(c.mode, &g, &cache, bones, &sub, &cotangents(cot, n, &split)).expect("re-posing backward");
            summed.add(&d);
            sub_bones.push(d_bones);
        }
        let f = FrameInputs { pose_code: &c.pose_code, bones: &c.bones, camera_centre: c.centre, latent: &c.latent, view_rotation: c.view_rotation };
        let split = frame_cotangents(&cots[0], n);
        let grads = pose_frame_backward_with(&c.nets, c.mode, &g, &f, &cache, &cotangents(&cots[0], n, &split), Some(&summed)).expect("backward");
        let flat = |v: &[[f64; 3]]| v.iter().flatten().copied().collect::<Vec<_>>();
        let fd = |x: Vec<f64>, set: &dyn Fn(&mut Case, &[f64])| {
            let mut work = clone_case(&c);
            central_differences(|p| { set(&mut work, p); reposed_loss(&work, &reposings, &cots) }, &x, H)
        };
        let mut checker = GradientChecker::new();
        checker.check("means", &fd(flat(&c.means), &|w, p| w.means = rows(p)), &flat(&grads.means), TOL);
        checker.check("log_scales", &fd(flat(&c.log_scales), &|w, p| w.log_scales = rows(p)), &flat(&grads.log_scales), TOL);
        checker.check("quats", &fd(c.quats.iter().flatten().copied().collect(), &|w, p| w.quats = rows(p)), &grads.quats.iter().flatten().copied().collect::<Vec<_>>(), TOL);
        checker.check("features", &fd(c.features.clone(), &|w, p| w.features = p.to_vec()), &grads.features, TOL);
        checker.check("semantic logits", &fd(c.logits.clone(), &|w, p| w.logits = p.to_vec()), &grads.semantic_logits, TOL);
        checker.check("latent", &fd(c.latent.clone(), &|w, p| w.latent = p.to_vec()), &grads.latent, TOL);
        checker.check("reference bones", &fd(c.bones.iter().flatten().copied().collect(), &|w, p| w.bones = rows(p)), &grads.bones.iter().flatten().copied().collect::<Vec<_>>(), TOL);
        checker.check("non-rigid net", &fd(c.nets.nonrigid.mlp.params.clone(), &|w, p| w.nets.nonrigid.mlp.params = p.to_vec()), &grads.nonrigid, TOL);
        checker.check("skinning field", &fd(c.nets.skinning.mlp.params.clone(), &|w, p| w.nets.skinning.mlp.params = p.to_vec()), &grads.skinning, TOL);
        checker.check("human colour net", &fd(c.nets.human_colour.mlp.params.clone(), &|w, p| w.nets.human_colour.mlp.params = p.to_vec()), &grads.human_colour, TOL);
        checker.check("scene colour net", &fd(c.nets.scene_colour.mlp.params.clone(), &|w, p| w.nets.scene_colour.mlp.params = p.to_vec()), &grads.scene_colour, TOL);
        for (s, d_bones) in sub_bones.iter().enumerate() {
            let x: Vec<f64> = reposings[s].iter().flatten().copied().collect();
            let num = central_differences(|p| {
                let mut moved = reposings.clone();
                moved[s] = rows(p);
                reposed_loss(&c, &moved, &cots)
            }, &x, H);
            checker.check("re-posing bones", &num, &d_bones.iter().flatten().copied().collect::<Vec<_>>(), TOL);
        }
        checker.finish();
    }
}

/// The pose-correction check's passes: sub-exposure offsets of S = 3 renders.
const OFFSETS: [f64; 3] = [-1.0 / 3.0, 0.0, 1.0 / 3.0];

/// The body of the pose-correction check: random rest joints on the SMPL tree and random
/// canonical inverses (rigid-ish, like real ones).
struct CorrectionBody {
    joints: Vec<[f64; 3]>,
    inverses: Vec<[f64; 12]>,
    base_poses: Vec<Vec<f64>>,
    base_transl: Vec<[f64; 3]>,
}

fn correction_body(seed: u64) -> CorrectionBody {
    let mut rng = rng(seed ^ 0xb0d1);
    let mut r = || rng.gen_range(-1.0..1.0);
    CorrectionBody {
        joints: (0..24).map(|_| [0.5 * r(), r(), 0.3 * r()]).collect(),
        inverses: (0..24)
            .map(|_| {
                let mut m = [0.0; 12];
                for i in 0..3 {
                    for j in 0..3 {
                        m[4 * i + j] = f64::from(u8::from(i == j)) + 0.1 * r();
                    }
                    m[4 * i + 3] = 0.2 * r();
                }
                m
            })
            .collect(),
        base_poses: (0..3)
            .map(|_| (0..72).map(|_| 0.4 * r()).collect())
            .collect(),
        base_transl: (0..3).map(|_| [0.1 * r(), 0.1 * r(), 0.1 * r()]).collect(),
    }
}

/// Loss of the exposure passes of one frame posed from the corrected poses: the mid pass through the
/// networks (its pose code from its own pose), the others re-posed at their bones, each paired with
/// its own cotangent; plus the correction prior's terms of slot 1 of `all` (three slots).
fn corrected_loss(
    c: &Case,
    b: &CorrectionBody,
    all: &[f64],
    cots: &[Vec<f64>],
    prior: train::pose::correction::CorrectionPrior<f64>,
) -> f64 {
    use smpl_deform::frame_pose::frame_pose;
    use train::pose::correction::{correct_pose, prior_terms, CORRECTION_VALUES};
    let correction = &all[CORRECTION_VALUES..2 * CORRECTION_VALUES];
    let frames: Vec<_> = (0..3)
        .map(|s| {
            let (pose, transl) =
                correct_pose(&b.base_poses[s], b.base_transl[s], correction, OFFSETS[s]);
            frame_pose(
                &pose,
                transl,
                &b.joints,
                &smpl_deform::SMPL_PARENTS,
                &b.inverses,
            )
        })
        .collect();
    let mut mid = clone_case(c);
    mid.bones = frames[1].bones.clone();
    mid.pose_code = frames[1].pose_code.clone();
    let (reference, cache) = outputs(&mid);
    let mut total = pairing(&reference, &cots[1]);
    for s in [0, 2] {
        let (o, _) = repose_frame(&reference, &cache, &frames[s].bones).expect("repose");
        total += pairing(&o, &cots[s]);
    }
    let mut unused = vec![0.0; CORRECTION_VALUES];
    total + prior_terms(all, 1, prior, &mut unused)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(4))]

    /// Pose correction end to end: a slot's correction (mid-exposure values and their change over
    /// the exposure) → corrected sub-exposure poses → bones and pose code
    /// (`smpl_deform::frame_pose`) → the networks at the mid pose and LBS re-posings at the others →
    /// outputs, plus the correction prior. Same tolerance and argument as above (the added maps are
    /// polynomials in sines and cosines of the pose). The mid-exposure values and their change are
    /// reported separately, so a wrong offset weight shows on its own.
    #[test]
    fn pose_correction_gradients_match_finite_differences(seed in any::<u64>(), scalar in any::<bool>()) {
        use smpl_deform::frame_pose::{frame_pose, frame_pose_backward};
        use train::pose::correction::{correct_pose, correct_pose_backward, prior_terms, CorrectionPrior, CORRECTION_VALUES, POSE_VALUES};
        let c = case(seed, scalar, 0.0);
        let b = correction_body(seed);
        let all: Vec<f64> = symmetric_from_seed(seed ^ 0xc0, 3 * CORRECTION_VALUES).iter().map(|v| 0.1 * v).collect();
        let prior = CorrectionPrior { zero: 0.3, smooth: 0.7 };
        let cots: Vec<Vec<f64>> = (0..3).map(|s| symmetric_from_seed(seed ^ (0xdef + s), c.outputs_len())).collect();

        // Analytic: the forward, then the backward of every stage.
        let correction = &all[CORRECTION_VALUES..2 * CORRECTION_VALUES];
        let corrected: Vec<(Vec<f64>, [f64; 3])> = (0..3).map(|s| correct_pose(&b.base_poses[s], b.base_transl[s], correction, OFFSETS[s])).collect();
        let frames: Vec<_> = corrected.iter().map(|(p, t)| frame_pose(p, *t, &b.joints, &smpl_deform::SMPL_PARENTS, &b.inverses)).collect();
        let mut mid = clone_case(&c);
        mid.bones = frames[1].bones.clone();
        mid.pose_code = frames[1].pose_code.clone();
        let (reference, cache) = outputs(&mid);
        let g = GaussianParams { means: &mid.means, log_scales: &mid.log_scales, quats: &mid.quats, features: &mid.features, semantic_logits: &mid.logits };
        let mut summed = ReposeCotangents::zeros(N, cache.active().len());
        let mut d_bones = vec![Vec::new(); 3];
        for s in [0, 2] {
            let (_, sub) = repose_frame(&reference, &cache, &frames[s].bones).expect("repose");
            let split = frame_cotangents(&cots[s], N);
            let (d, bones) = repose_frame_backward(mid.mode, &g, &cache, &frames[s].bones, &sub, &cotangents(&cots[s], N, &split)).expect("re-posing backward");
            summed.add(&d);
            d_bones[s] = bones;
        }
        let f = FrameInputs { pose_code: &mid.pose_code, bones: &mid.bones, camera_centre: mid.centre, latent: &mid.latent, view_rotation: mid.view_rotation };
        let split = frame_cotangents(&cots[1], N);
        let grads = pose_frame_backward_with(&mid.nets, mid.mode, &g, &f, &cache, &cotangents(&cots[1], N, &split), Some(&summed)).expect("backward");
        d_bones[1] = grads.bones.clone();
        let mut ana = vec![0.0; CORRECTION_VALUES];
        for s in 0..3 {
            let code: &[f64] = if s == 1 { &grads.pose_code } else { &[] };
            let fk = frame_pose_backward(&corrected[s].0, &b.joints, &smpl_deform::SMPL_PARENTS, &b.inverses, &frames[s], &d_bones[s], code);
            correct_pose_backward(&fk.pose, fk.transl, OFFSETS[s], &mut ana);
        }
        prior_terms(&all, 1, prior, &mut ana);

        let num = central_differences(|x| {
            let mut moved = all.clone();
            moved[CORRECTION_VALUES..2 * CORRECTION_VALUES].copy_from_slice(x);
            corrected_loss(&c, &b, &moved, &cots, prior)
        }, correction, H);
        let mut checker = GradientChecker::new();
        checker.check("correction, mid exposure", &num[..POSE_VALUES], &ana[..POSE_VALUES], TOL);
        checker.check("correction, change over the exposure", &num[POSE_VALUES..], &ana[POSE_VALUES..], TOL);
        checker.finish();
        // The pose code's path is exercised (its gradient is part of what was checked).
        prop_assert!(grads.pose_code.iter().any(|&v| v != 0.0));
    }
}
