//! Posing the E-Sem3DGS Gaussians for one frame, up to rasterization: every Gaussian is read twice — deformed as a
//! human Gaussian (non-rigid network, learned skinning weights, LBS with the frame's bones) and static
//! as a scene Gaussian — coloured by the human and the scene colour networks, and blended by its human
//! probability (see [`crate::blend`]) into one position, covariance and colour. The human probability
//! itself is an output too (rendered as the semantic mask).
//!
//! The backward pass takes cotangents of those four outputs and returns gradients for every learnable
//! quantity: the stored Gaussian parameters, the semantic logits, the four networks, the per-frame
//! latent and the bone transforms (for pose refinement).
//!
//! Semantic gate: a Gaussian whose human probability is below `gate` is read as a scene Gaussian only
//! (its human branch — deformation, skinning, human colour — is not evaluated, and the blend's human
//! term, weighted by p < gate, is dropped together with its contribution to dL/dp through the blend).
//! The rendered probability and its gradient are kept exactly. With `gate = 0` the function is the
//! exact blend of every Gaussian; the trainer uses a small gate (default 0.01) because deforming the
//! scene Gaussians, whose p stays ≈ 0.0025 from the ±3 initial logits, would dominate the step's cost
//! while changing its result by less than 1% of one Gaussian's displacement.
//!
//! View directions: `x − camera centre` (world) for the scene network; for the human network the
//! direction to the deformed mean rotated back into canonical space by the transpose of the
//! skinning-blended bone rotation R = Σ_b w_b R_b ([`ViewRotation`]): with `moved`, w are the
//! deformation's own weights at the non-rigidly moved mean x + Δx (the rotation that posed the
//! Gaussian, as 3DGS-Avatar's `fwd_transform`, which it detaches); with `canonical`, a second pass
//! of the skinning field at the canonical mean x. Both are differentiated (into the means, the
//! skinning field, the non-rigid network and the bones), so the gradients are those of the
//! function computed; `moved` hands its weights' cotangent to the deformation's own backward. With
//! `canonical`, while the non-rigid offsets are exactly zero (before the non-rigid network is
//! switched on) the deformation has already evaluated the field at the canonical means, and that
//! pass is reused, forward and backward (`DeformCache::skinning_at`: bit for bit what a second
//! evaluation would give).

mod active_blend;
mod people;
mod repose_cotangents;
mod views;

pub(crate) use active_blend::{
    blend_backward_active, deformed_covariance, ActiveBlendGrads, StaticCotangents,
};
pub(crate) use people::PeopleRepose;
pub use repose_cotangents::ReposeCotangents;

use crate::blend::{
    blend, most_probable_person, person_probabilities, person_probabilities_backward, BlendInputs,
    SemanticMode,
};
use crate::colour::{ColourInputs, ColourNet};
use crate::TrainError;
use gaussians::covariance::{covariance_3d, covariance_3d_backward};
use nn::Real;
use people::{DeformCotangents, DeformNets, PeopleDeform};
use rayon::prelude::*;
use smpl_deform::deform_net::{
    CanonicalGaussians, MovedCotangents, NonRigidNet, SkinningCache, SkinningField, NR_FEATURE_DIM,
};
use smpl_deform::math::{Affine, Mat3};
use smpl_deform::{NUM_JOINTS, NUM_POSE_FEATURES};
use views::CanonicalViews;

pub use crate::config::ViewRotation;

/// The four networks of the model.
#[derive(Clone, Debug)]
pub struct ModelNets<T: Real> {
    /// Pose-conditioned non-rigid deformation.
    pub nonrigid: NonRigidNet<T>,
    /// Learned skinning weights.
    pub skinning: SkinningField<T>,
    /// Human colour network (feature ⊕ canonical-direction SH ⊕ non-rigid feature ⊕ frame latent).
    pub human_colour: ColourNet<T>,
    /// Scene colour network (feature ⊕ world-direction SH).
    pub scene_colour: ColourNet<T>,
}

/// Stored per-Gaussian parameters (conventions of `gaussians::GaussianSet`).
#[derive(Clone, Copy, Debug)]
pub struct GaussianParams<'a, T> {
    /// Means: canonical position when read as human, world position when read as scene (m).
    pub means: &'a [[T; 3]],
    /// Log-scales (ln m).
    pub log_scales: &'a [[T; 3]],
    /// Unnormalised (w, x, y, z) quaternions.
    pub quats: &'a [[T; 4]],
    /// Colour features, N × feature_dim (shared by both colour networks).
    pub features: &'a [T],
    /// Semantic logits, N × `SemanticMode::logits_for` the frame's people.
    pub semantic_logits: &'a [T],
}

impl<T> GaussianParams<'_, T> {
    /// The number of semantic logits per Gaussian (0 without Gaussians).
    fn logits_per_gaussian(&self) -> usize {
        self.semantic_logits
            .len()
            .checked_div(self.means.len())
            .unwrap_or(0)
    }
}

/// What a frame contributes. With several people, each one's pose code and bones follow the
/// previous one's (person order of the model's semantic classes).
#[derive(Clone, Copy, Debug)]
pub struct FrameInputs<'a, T> {
    /// The 207-value pose feature of the frame, per person.
    pub pose_code: &'a [T],
    /// `frame_from_canonical` transform per bone (24 per person).
    pub bones: &'a [Affine<T>],
    /// Camera centre in world coordinates (m).
    pub camera_centre: [T; 3],
    /// Per-frame latent of the human colour network.
    pub latent: &'a [T],
    /// Whose skinning weights canonicalise the human colour network's view directions.
    pub view_rotation: ViewRotation,
}

impl<T> FrameInputs<'_, T> {
    /// The number of people the frame poses (its bones / 24).
    pub fn people(&self) -> usize {
        self.bones.len() / NUM_JOINTS
    }

    /// Checks that the bones and the pose code are those of whole people (at least one).
    fn check(&self) -> Result<(), TrainError> {
        let people = self.people().max(1);
        for (what, expected, found) in [
            ("frame bones", people * NUM_JOINTS, self.bones.len()),
            (
                "frame pose code",
                people * NUM_POSE_FEATURES,
                self.pose_code.len(),
            ),
        ] {
            if expected != found {
                return Err(TrainError::Shape {
                    what: what.into(),
                    expected,
                    found,
                });
            }
        }
        Ok(())
    }
}

/// Blended attributes of every Gaussian in the frame.
#[derive(Clone, Debug, PartialEq)]
pub struct PosedFrame<T> {
    /// World positions (m).
    pub means: Vec<[T; 3]>,
    /// World covariances (m²).
    pub covariances: Vec<[[T; 3]; 3]>,
    /// Linear RGB, N × 3.
    pub colours: Vec<T>,
    /// Human probability per Gaussian.
    pub human_probability: Vec<T>,
    /// With several people: each person's probability per Gaussian, N × P (empty with one).
    pub person_probability: Vec<T>,
}

/// Forward state kept for the backward pass.
#[derive(Clone, Debug)]
pub struct FrameCache<T: Real> {
    /// Indices of the Gaussians whose human branch was evaluated (p ≥ gate), ascending.
    pub(crate) active: Vec<usize>,
    pub(crate) deform: PeopleDeform<T>,
    posed_mats: Vec<Mat3<T>>,
    pub(crate) posed_log_scales: Vec<[T; 3]>,
    human_colour: crate::colour::ColourCache<T>,
    scene_colour: crate::colour::ColourCache<T>,
    pub(crate) inputs: Vec<BlendInputs<T>>,
    /// The skinning weights of the canonicalised directions' rotation, and where they came from.
    direction_weights: Vec<T>,
    direction_skinning: DirectionSkinning<T>,
    /// The human Gaussians' canonical view directions, with the world direction x_def − c and the
    /// blended rotation R (row-major) of each.
    views: CanonicalViews<T>,
}

/// Where the view directions' skinning weights came from, for the backward.
#[derive(Clone, Debug)]
enum DirectionSkinning<T: Real> {
    /// A pass of the field at the canonical means of its own.
    Own(SkinningCache<T>),
    /// The deformation's pass, bit for bit the field at the canonical means (`skinning_at`).
    Reused,
    /// The deformation's weights at the moved means ([`ViewRotation::Moved`]): their cotangent
    /// joins the deformation's own.
    Moved,
}

/// Cotangents of the four outputs.
#[derive(Clone, Copy, Debug)]
pub struct FrameCotangents<'a, T> {
    /// dL/d means.
    pub means: &'a [[T; 3]],
    /// dL/d covariances (nine independent entries).
    pub covariances: &'a [[[T; 3]; 3]],
    /// dL/d colours, N × 3.
    pub colours: &'a [T],
    /// dL/d human probability.
    pub human_probability: &'a [T],
    /// dL/d each person's probability, N × P with several people (else empty).
    pub person_probability: &'a [T],
}

/// Gradients of one frame.
#[derive(Clone, Debug, PartialEq)]
pub struct ModelGradients<T> {
    /// dL/d means.
    pub means: Vec<[T; 3]>,
    /// dL/d log-scales.
    pub log_scales: Vec<[T; 3]>,
    /// dL/d quaternions.
    pub quats: Vec<[T; 4]>,
    /// dL/d features.
    pub features: Vec<T>,
    /// dL/d semantic logits.
    pub semantic_logits: Vec<T>,
    /// dL/d non-rigid network parameters.
    pub nonrigid: Vec<T>,
    /// dL/d skinning-field parameters.
    pub skinning: Vec<T>,
    /// dL/d human colour network parameters.
    pub human_colour: Vec<T>,
    /// dL/d scene colour network parameters.
    pub scene_colour: Vec<T>,
    /// dL/d frame latent.
    pub latent: Vec<T>,
    /// dL/d bone transforms (24 per person).
    pub bones: Vec<Affine<T>>,
    /// dL/d pose code (207 values per person; for pose correction).
    pub pose_code: Vec<T>,
}

impl<T: Real> ModelGradients<T> {
    /// Adds `other`'s gradients of the parameters shared by every frame (Gaussians and networks) to
    /// these; `latent` and `bones` belong to one frame each and are left alone.
    pub fn add_shared(&mut self, other: &ModelGradients<T>) {
        fn add<T: Real>(a: &mut [T], b: &[T]) {
            for (x, &y) in a.iter_mut().zip(b) {
                *x = *x + y;
            }
        }
        add(self.means.as_flattened_mut(), other.means.as_flattened());
        add(
            self.log_scales.as_flattened_mut(),
            other.log_scales.as_flattened(),
        );
        add(self.quats.as_flattened_mut(), other.quats.as_flattened());
        add(&mut self.features, &other.features);
        add(&mut self.semantic_logits, &other.semantic_logits);
        add(&mut self.nonrigid, &other.nonrigid);
        add(&mut self.skinning, &other.skinning);
        add(&mut self.human_colour, &other.human_colour);
        add(&mut self.scene_colour, &other.scene_colour);
    }
}

/// The model's per-Gaussian attributes for one frame (every Gaussian blended exactly: `gate = 0`).
pub fn pose_frame<T: Real>(
    nets: &ModelNets<T>,
    mode: SemanticMode,
    g: &GaussianParams<'_, T>,
    frame: &FrameInputs<'_, T>,
) -> Result<(PosedFrame<T>, FrameCache<T>), TrainError> {
    pose_frame_gated(nets, mode, T::zero(), g, frame)
}

/// Copies the rows `idx` of `v` (row length `stride`).
fn gather<T: Copy>(v: &[T], stride: usize, idx: &[usize]) -> Vec<T> {
    let mut out = Vec::with_capacity(idx.len() * stride);
    for &i in idx {
        out.extend_from_slice(&v[i * stride..(i + 1) * stride]);
    }
    out
}

/// The model's per-Gaussian attributes for one frame, evaluating the human branch only for Gaussians
/// with human probability ≥ `gate` (see the module documentation).
pub fn pose_frame_gated<T: Real>(
    nets: &ModelNets<T>,
    mode: SemanticMode,
    gate: T,
    g: &GaussianParams<'_, T>,
    frame: &FrameInputs<'_, T>,
) -> Result<(PosedFrame<T>, FrameCache<T>), TrainError> {
    let n = g.means.len();
    frame.check()?;
    let people = frame.people();
    if people > 1 && mode != SemanticMode::OneHot {
        return Err(TrainError::Config(format!(
            "{people} people need one-hot semantics (one class per person), not {mode:?}"
        )));
    }
    let k = mode.logits_for(people);
    if g.semantic_logits.len() != n * k {
        return Err(TrainError::Shape {
            what: "semantic logits".into(),
            expected: n * k,
            found: g.semantic_logits.len(),
        });
    }
    let fd = nets.scene_colour.config.feature_dim;
    if g.features.len() != n * fd {
        return Err(TrainError::Shape {
            what: "Gaussian features".into(),
            expected: n * fd,
            found: g.features.len(),
        });
    }
    let probability: Vec<T> = (0..n)
        .map(|i| mode.probability(&g.semantic_logits[i * k..(i + 1) * k]))
        .collect();
    let person_probability = if people > 1 {
        let mut q = vec![T::zero(); n * people];
        for (i, out) in q.chunks_exact_mut(people).enumerate() {
            person_probabilities(&g.semantic_logits[i * k..(i + 1) * k], out);
        }
        q
    } else {
        Vec::new()
    };
    let active: Vec<usize> = (0..n).filter(|&i| probability[i] >= gate).collect();
    let owners: Option<Vec<usize>> = (people > 1).then(|| {
        active
            .iter()
            .map(|&i| most_probable_person(&g.semantic_logits[i * k..(i + 1) * k]))
            .collect()
    });
    let a_means = gather(g.means, 1, &active);
    let a_log_scales = gather(g.log_scales, 1, &active);
    let a_quats = gather(g.quats, 1, &active);
    let a_features = gather(g.features, fd, &active);
    let canonical = CanonicalGaussians {
        positions: &a_means,
        log_scales: &a_log_scales,
        quats: &a_quats,
    };
    let (posed, deform) = PeopleDeform::forward(
        nets.deform_nets(),
        &canonical,
        owners.as_deref(),
        frame.pose_code,
        frame.bones,
    )?;
    // Canonicalised view directions for the human colour network: Rᵀ (x_def − c), R = Σ_b w_b R_b.
    let (direction_weights, direction_skinning) = match frame.view_rotation {
        ViewRotation::Moved => (deform.weights(), DirectionSkinning::Moved),
        ViewRotation::Canonical => match deform.skinning_at(&a_means) {
            Some(reused) => (reused.weights(), DirectionSkinning::Reused),
            None => {
                let (weights, skinning) = nets.skinning.forward(&a_means)?;
                (weights, DirectionSkinning::Own(skinning))
            }
        },
    };
    let c = frame.camera_centre;
    let views = deform.views(frame.bones, c, &posed.positions, &direction_weights);
    let scene_dirs: Vec<[T; 3]> = g
        .means
        .iter()
        .map(|m| [m[0] - c[0], m[1] - c[1], m[2] - c[2]])
        .collect();
    let (human_rgb, human_colour) = nets.human_colour.forward(&ColourInputs {
        features: &a_features,
        directions: &views.directions,
        extra: &posed.features,
        latent: frame.latent,
    })?;
    let (scene_rgb, scene_colour) = nets.scene_colour.forward(&ColourInputs {
        features: g.features,
        directions: &scene_dirs,
        extra: &[],
        latent: &[],
    })?;
    let mut out = PosedFrame {
        means: g.means.to_vec(),
        covariances: (0..n)
            .into_par_iter()
            .map(|i| covariance_3d(g.log_scales[i], g.quats[i]))
            .collect(),
        colours: scene_rgb.clone(),
        human_probability: probability,
        person_probability,
    };
    // The active Gaussians' blends in parallel, then written to their slots.
    let (inputs, blended): (Vec<_>, Vec<_>) = active
        .par_iter()
        .enumerate()
        .map(|(a, &i)| {
            let input = BlendInputs {
                x_def: posed.positions[a],
                x_static: g.means[i],
                cov_def: deformed_covariance(&posed.mats[a], &posed.log_scales[a]),
                cov_static: out.covariances[i],
                c_human: [human_rgb[a * 3], human_rgb[a * 3 + 1], human_rgb[a * 3 + 2]],
                c_scene: [scene_rgb[i * 3], scene_rgb[i * 3 + 1], scene_rgb[i * 3 + 2]],
            };
            let b = blend(out.human_probability[i], &input);
            (input, b)
        })
        .unzip();
    for (&i, b) in active.iter().zip(&blended) {
        out.means[i] = b.x;
        out.covariances[i] = b.cov;
        out.colours[i * 3..i * 3 + 3].copy_from_slice(&b.c);
    }
    Ok((
        out,
        FrameCache {
            active,
            deform,
            posed_mats: posed.mats,
            posed_log_scales: posed.log_scales,
            human_colour,
            scene_colour,
            inputs,
            direction_weights,
            direction_skinning,
            views,
        },
    ))
}

impl<T: Real> ModelNets<T> {
    /// The two networks of the deformation.
    fn deform_nets(&self) -> DeformNets<'_, T> {
        DeformNets {
            nonrigid: &self.nonrigid,
            skinning: &self.skinning,
        }
    }
}

impl<T: Real> FrameCache<T> {
    /// Indices of the Gaussians whose human branch was evaluated (ascending).
    pub fn active(&self) -> &[usize] {
        &self.active
    }
}

/// Backward of [`pose_frame`] / [`pose_frame_gated`] (the gate is read from the cache).
pub fn pose_frame_backward<T: Real>(
    nets: &ModelNets<T>,
    mode: SemanticMode,
    g: &GaussianParams<'_, T>,
    frame: &FrameInputs<'_, T>,
    cache: &FrameCache<T>,
    cot: &FrameCotangents<'_, T>,
) -> Result<ModelGradients<T>, TrainError> {
    pose_frame_backward_with(nets, mode, g, frame, cache, cot, None)
}

/// [`pose_frame_backward`] with, when given, the summed cotangents `reposings` of the frame's
/// re-posings ([`crate::pose::reposing::repose_frame_backward`]): one network backward for the frame and
/// every re-posing of it. `bones` gradients are those of this pass's own bones.
pub fn pose_frame_backward_with<T: Real>(
    nets: &ModelNets<T>,
    mode: SemanticMode,
    g: &GaussianParams<'_, T>,
    frame: &FrameInputs<'_, T>,
    cache: &FrameCache<T>,
    cot: &FrameCotangents<'_, T>,
    reposings: Option<&ReposeCotangents<T>>,
) -> Result<ModelGradients<T>, TrainError> {
    let n = g.means.len();
    let k = g.logits_per_gaussian();
    let active = &cache.active;
    let na = active.len();
    if let Some(r) = reposings {
        r.check(n, na)?;
    }
    let mut d_semantic = vec![T::zero(); n * k];
    let BlendCotangents {
        mut d_means,
        d_cov_static,
        d_scene_rgb,
        d_p,
        d_q,
        active:
            ActiveBlendGrads {
                x_def: mut d_x_def,
                mats: d_mats,
                log_scales: d_s_def,
                human_rgb: d_human_rgb,
            },
    } = blend_cotangents(mode, g, cache, cot, reposings);
    let (mut d_log_scales, mut d_quats) =
        static_backward(mode, g, &d_p, &d_q, &d_cov_static, &mut d_semantic);
    let human = nets
        .human_colour
        .backward(&cache.human_colour, &d_human_rgb)?;
    let scene = nets
        .scene_colour
        .backward(&cache.scene_colour, &d_scene_rgb)?;
    // Scene direction x − c: its gradient is the means'.
    for (dm, dd) in d_means.iter_mut().zip(&scene.directions) {
        for a in 0..3 {
            dm[a] = dm[a] + dd[a];
        }
    }
    let (d_direction_weights, d_bone_rotations) = cache.deform.views_backward(
        frame.bones,
        &cache.views,
        &cache.direction_weights,
        &human.directions,
        &mut d_x_def,
    );
    let mut d_nonrigid = vec![T::zero(); nets.nonrigid.mlp.num_params()];
    let mut d_skinning = vec![T::zero(); nets.skinning.mlp.num_params()];
    let direction_skinning = match &cache.direction_skinning {
        DirectionSkinning::Own(skinning) => Some(skinning),
        DirectionSkinning::Reused => Some(cache.deform.reused_skinning().ok_or_else(|| {
            TrainError::Config("the view directions' skinning pass was not kept".into())
        })?),
        DirectionSkinning::Moved => None,
    };
    let d_means_from_weights = match direction_skinning {
        Some(skinning) => {
            nets.skinning
                .backward(skinning, &d_direction_weights, &mut d_skinning)?
        }
        None => vec![[T::zero(); 3]; na],
    };
    // With the moved means' weights, their cotangent joins the re-posings' on the deformation's
    // own weights: one backward of the field for both.
    let moved_with_views =
        matches!(cache.direction_skinning, DirectionSkinning::Moved).then(|| {
            let mut moved =
                reposings.map_or_else(|| MovedCotangents::zeros(na), |r| r.moved.clone());
            for (w, &d) in moved.weights.iter_mut().zip(&d_direction_weights) {
                *w = *w + d;
            }
            moved
        });
    debug_assert_eq!(human.extra.len(), na * NR_FEATURE_DIM);
    let deform = cache.deform.backward(
        nets.deform_nets(),
        frame.bones,
        &DeformCotangents {
            positions: &d_x_def,
            log_scales: &d_s_def,
            mats: &d_mats,
            features: &human.extra,
        },
        moved_with_views.as_ref().or(reposings.map(|r| &r.moved)),
        &mut d_nonrigid,
        &mut d_skinning,
    )?;
    // The human branch's share of each active Gaussian's canonical parameters.
    let fd = nets.scene_colour.config.feature_dim;
    let mut features = scene.features;
    for (a, &i) in active.iter().enumerate() {
        let (dp, dw) = (deform.positions[a], d_means_from_weights[a]);
        d_means[i] = std::array::from_fn(|ax| d_means[i][ax] + dp[ax] + dw[ax]);
        let ds = deform.log_scales[a];
        d_log_scales[i] = std::array::from_fn(|ax| d_log_scales[i][ax] + ds[ax]);
        let dq = deform.quats[a];
        d_quats[i] = std::array::from_fn(|ax| d_quats[i][ax] + dq[ax]);
        for f in 0..fd {
            features[i * fd + f] = features[i * fd + f] + human.features[a * fd + f];
        }
    }
    let pose_code = deform.pose_code;
    let d_bones = with_rotations(deform.bones, &d_bone_rotations);
    Ok(ModelGradients {
        means: d_means,
        log_scales: d_log_scales,
        quats: d_quats,
        features,
        semantic_logits: d_semantic,
        nonrigid: d_nonrigid,
        skinning: d_skinning,
        human_colour: human.params,
        scene_colour: scene.params,
        latent: human.latent,
        bones: d_bones,
        pose_code,
    })
}

/// The cotangents of the blend's two branches: the static path of every Gaussian (means,
/// covariances, scene colours, the human probability) and the human branch of the active ones,
/// with the frame's re-posings' cotangents added when given.
struct BlendCotangents<T> {
    d_means: Vec<[T; 3]>,
    d_cov_static: Vec<[[T; 3]; 3]>,
    d_scene_rgb: Vec<T>,
    d_p: Vec<T>,
    /// Of each person's probability, N × P (empty with one person).
    d_q: Vec<T>,
    active: ActiveBlendGrads<T>,
}

/// [`BlendCotangents`] of the frame's cotangents `cot` (and `reposings`').
fn blend_cotangents<T: Real>(
    mode: SemanticMode,
    g: &GaussianParams<'_, T>,
    cache: &FrameCache<T>,
    cot: &FrameCotangents<'_, T>,
    reposings: Option<&ReposeCotangents<T>>,
) -> BlendCotangents<T> {
    // Static path of every Gaussian (inactive ones are exactly static; active ones get the blend's
    // (1 − p) share below, so start from the direct cotangents and correct).
    let mut d_means: Vec<[T; 3]> = cot.means.to_vec();
    let mut d_cov_static: Vec<[[T; 3]; 3]> = cot.covariances.to_vec();
    let mut d_scene_rgb: Vec<T> = cot.colours.to_vec();
    let mut d_p: Vec<T> = cot.human_probability.to_vec();
    let mut d_q: Vec<T> = cot.person_probability.to_vec();
    let mut active = blend_backward_active(
        mode,
        g.semantic_logits,
        &cache.active,
        &cache.inputs,
        &cache.posed_mats,
        &cache.posed_log_scales,
        cot,
        StaticCotangents {
            means: &mut d_means,
            covariances: &mut d_cov_static,
            scene_rgb: &mut d_scene_rgb,
            probability: &mut d_p,
        },
    );
    if let Some(r) = reposings {
        let add = |a: &mut [T], b: &[T]| a.iter_mut().zip(b).for_each(|(x, &y)| *x = *x + y);
        add(d_means.as_flattened_mut(), r.means.as_flattened());
        let covariances = r.covariances.as_flattened().as_flattened();
        add(
            d_cov_static.as_flattened_mut().as_flattened_mut(),
            covariances,
        );
        add(&mut d_scene_rgb, &r.scene_colours);
        add(&mut d_p, &r.human_probability);
        add(&mut d_q, &r.person_probability);
        add(&mut active.human_rgb, &r.human_colours);
        add(
            active.log_scales.as_flattened_mut(),
            r.log_scales.as_flattened(),
        );
    }
    BlendCotangents {
        d_means,
        d_cov_static,
        d_scene_rgb,
        d_p,
        d_q,
        active,
    }
}

/// Bone gradients `d_bones` with each bone's rotation gradient (row-major 3×3) added to its
/// rotation block.
fn with_rotations<T: Real>(mut d_bones: Vec<Affine<T>>, d_rotations: &[[T; 9]]) -> Vec<Affine<T>> {
    for (db, dr) in d_bones.iter_mut().zip(d_rotations) {
        for e in 0..9 {
            db[(e / 3) * 4 + e % 3] = db[(e / 3) * 4 + e % 3] + dr[e];
        }
    }
    d_bones
}

/// The semantic logits' and static covariances' share of the backward of every Gaussian: the
/// human probability's cotangent `d_p` (and with several people each person's, `d_q`, N × P) into
/// `d_semantic`, and ∂L/∂(log-scales, quaternions) of the static covariances' cotangents.
#[allow(clippy::type_complexity)]
fn static_backward<T: Real>(
    mode: SemanticMode,
    g: &GaussianParams<'_, T>,
    d_p: &[T],
    d_q: &[T],
    d_cov_static: &[[[T; 3]; 3]],
    d_semantic: &mut [T],
) -> (Vec<[T; 3]>, Vec<[T; 4]>) {
    let n = g.means.len();
    let k = g.logits_per_gaussian();
    let people = d_q.len().checked_div(n).unwrap_or(0);
    let semantic_backward = |i: usize, d_semantic: &mut [T]| {
        let logits = &g.semantic_logits[i * k..(i + 1) * k];
        mode.probability_backward(logits, d_p[i], d_semantic);
        if people > 1 {
            person_probabilities_backward(logits, &d_q[i * people..(i + 1) * people], d_semantic);
        }
        covariance_3d_backward(g.log_scales[i], g.quats[i], &d_cov_static[i])
    };
    // Per Gaussian, in parallel (each writes only its own logits' slots).
    if k == 0 {
        (0..n)
            .into_par_iter()
            .map(|i| semantic_backward(i, &mut []))
            .unzip()
    } else {
        d_semantic[..n * k]
            .par_chunks_mut(k)
            .enumerate()
            .map(|(i, d)| semantic_backward(i, d))
            .unzip()
    }
}
