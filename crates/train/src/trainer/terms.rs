//! The loss terms of one training step, each returning its value and its cotangents: frame k's
//! image terms (`frame_losses`: the photometric and in-exposure event terms of
//! `crate::loss::photometric`, and the optional LPIPS term), the pair losses (flow, events) between the passes of frames k and k+1,
//! the AIAP regulariser on the human Gaussians and the skinning loss on canonical surface samples.

use super::StageTimes;
use crate::config::{BlurModel, EventPairs, FlowGradient, FlowMeasure, TrainConfig};
use crate::data::{EventPair, FlowPair, TrainingData};
use crate::loss::aiap::{aiap_loss, upper_triangle, upper_triangle_backward, AIAP_NEIGHBOURS};
use crate::loss::event::pair_event_loss_with;
use crate::loss::image::ImageShape;
use crate::loss::optical_flow::{pair_flow_loss, pair_warp_loss};
use crate::loss::perceptual::perceptual_term;
use crate::loss::photometric::{add_scaled, exposure_loss, ExposureEvents, PhotometricWeights};
use crate::loss::sharpness::{opacity_entropy, size_prior};
use crate::model::{FramePass, Model, PosedGradients, RENDER_CHANNELS};
use crate::pose::posing::{ModelGradients, PosedFrame};
use crate::TrainError;
use flow::SpyNet;
use gaussians::covariance::{covariance_3d, covariance_3d_backward};
use smpl_deform::deform_net::{skinning_loss, SkinningField};
use std::time::Instant;

/// Frame k's image losses: the photometric loss of the passes' mean (with the events between its
/// renders) and the optional LPIPS term, and the cotangent of every pass's render.
pub(super) struct FrameLosses {
    pub photometric: f32,
    pub l1: f32,
    pub ssim: f32,
    /// The weighted event-generation loss inside the exposure.
    pub exposure_events: f32,
    pub lpips: f32,
    /// The mean of the renders (the frame's prediction).
    pub prediction: Vec<f32>,
    pub d_images: Vec<Vec<f32>>,
}

/// The photometric loss of the passes' mean (its cotangent reaches every pass scaled by 1/S) with
/// the events between consecutive sub-exposure renders, and the perceptual loss of the same
/// prediction (its cotangent scaled likewise).
pub(super) fn frame_losses(
    data: &TrainingData,
    config: &TrainConfig,
    slot: usize,
    target: &[f32],
    passes: &[FramePass<'_>],
    times: &mut StageTimes,
) -> Result<FrameLosses, TrainError> {
    let (height, width) = (data.camera.height as usize, data.camera.width as usize);
    let t0 = Instant::now();
    let shape = ImageShape {
        channels: 3,
        height,
        width,
    };
    let renders: Vec<&[f32]> = passes.iter().map(FramePass::rgb).collect();
    let exposure_events =
        config.event_loss && config.event_pairs == EventPairs::Exposure && passes.len() > 1;
    let modulated = config.event_modulation && config.blur_model == BlurModel::Exposure;
    let events = if exposure_events || modulated {
        Some(ExposureEvents {
            expected: if exposure_events {
                data.exposure_event_counts(slot)?
            } else {
                &[]
            },
            weight: config.event_weight,
            penalty: config.event_penalty(),
            log_eps: config.event_log_eps,
            pairs: config.exposure_pairs.render_pairs(),
            pool: config.event_pool as usize,
            reach: config.event_reach as usize,
            modulation: if modulated {
                data.exposure_modulation(slot)?
            } else {
                &[]
            },
        })
    } else {
        None
    };
    let photo = exposure_loss(
        &renders,
        target,
        shape,
        PhotometricWeights {
            ssim: config.ssim_weight,
            image_gradient: config.image_gradient_weight,
        },
        events,
        passes
            .first()
            .map_or(RENDER_CHANNELS, FramePass::render_channels),
        data.grey,
    );
    let mut d_images = photo.d_renders;
    times.loss = t0.elapsed().as_secs_f64();
    let t0 = Instant::now();
    let lpips = if config.lpips_weight > 0.0 {
        perceptual_term(
            data.lpips_network()?,
            &photo.prediction,
            target,
            height,
            width,
            config.lpips_weight,
            &mut d_images,
            data.grey,
        )?
    } else {
        0.0
    };
    times.lpips = t0.elapsed().as_secs_f64();
    Ok(FrameLosses {
        photometric: photo.photometric,
        l1: photo.l1,
        ssim: photo.ssim,
        exposure_events: photo.events,
        lpips,
        prediction: photo.prediction,
        d_images,
    })
}

/// The supervision of the pair (k, k+1) that a step uses, if any.
pub(super) struct PairSupervision<'a> {
    /// Slot of frame k+1.
    pub next_slot: usize,
    /// The flow loss's frozen network and target.
    pub flow: Option<(&'a SpyNet<f32>, &'a FlowPair)>,
    /// The event-generation loss's expected log-intensity change.
    pub events: Option<&'a EventPair>,
}

impl<'a> PairSupervision<'a> {
    /// The pair supervision of slot `slot` under `config`; `None` when no pair loss applies.
    pub fn of(data: &'a TrainingData, config: &TrainConfig, slot: usize) -> Option<Self> {
        let flow = match (config.flow_loss, data.flow_net.as_ref()) {
            (true, Some(net)) => data
                .flow_pairs
                .get(slot)
                .and_then(Option::as_ref)
                .map(|p| (net, p)),
            _ => None,
        };
        let events = if config.event_loss && config.event_pairs == EventPairs::Frames {
            data.event_pairs.get(slot).and_then(Option::as_ref)
        } else {
            None
        };
        let next_slot = flow
            .map(|(_, p)| p.next_slot)
            .or(events.map(|p| p.next_slot))?;
        Some(Self {
            next_slot,
            flow,
            events,
        })
    }
}

/// Values and cotangents of the pair losses.
pub(super) struct PairTerms {
    /// λ_flow·L_flow.
    pub flow: f32,
    /// The weighted event-generation loss.
    pub event: f32,
    /// Cotangent of frame k+1's image (C, H, W).
    pub d_second: Vec<f32>,
    /// With `FlowGradient::Geometry`, the flow loss's RGB cotangents of frames k and k+1, kept apart
    /// so that only their geometric share is used.
    pub d_flow_geometric: Option<(Vec<f32>, Vec<f32>)>,
    /// Seconds in the flow loss proper (resize, network, masked L1).
    pub flow_network_seconds: f64,
}

/// The pair losses between the renders `rgb` (frame k) and `rgb2` (frame k+1), both (3, H, W); frame
/// k's share of their cotangent is added to `d_first`.
pub(super) fn pair_terms(
    pair: &PairSupervision<'_>,
    config: &TrainConfig,
    rgb: &[f32],
    rgb2: &[f32],
    (height, width): (usize, usize),
    d_first: &mut [f32],
) -> Result<PairTerms, TrainError> {
    let hw = height * width;
    let mut terms = PairTerms {
        flow: 0.0,
        event: 0.0,
        d_second: vec![0.0f32; d_first.len()],
        d_flow_geometric: None,
        flow_network_seconds: 0.0,
    };
    if let Some((net, flow_pair)) = pair.flow {
        let t_network = Instant::now();
        let (fl_loss, fl_d_first, fl_d_second) = match config.flow_measure {
            FlowMeasure::Network => {
                let fl = pair_flow_loss(net, rgb, rgb2, height, width, &flow_pair.target)?;
                (fl.loss, fl.d_first, fl.d_second)
            }
            FlowMeasure::Warp => {
                let wl = pair_warp_loss(rgb, rgb2, height, width, &flow_pair.target)?;
                (wl.loss, wl.d_first, wl.d_second)
            }
        };
        terms.flow_network_seconds = t_network.elapsed().as_secs_f64();
        let lambda = config.flow_weight;
        terms.flow = lambda * fl_loss;
        match config.flow_gradient {
            FlowGradient::All => {
                add_scaled(&mut d_first[..3 * hw], &fl_d_first, lambda);
                add_scaled(&mut terms.d_second[..3 * hw], &fl_d_second, lambda);
            }
            FlowGradient::Geometry => {
                let scaled = |g: &[f32]| g.iter().map(|&v| lambda * v).collect::<Vec<f32>>();
                terms.d_flow_geometric = Some((scaled(&fl_d_first), scaled(&fl_d_second)));
            }
        }
    }
    if let Some(event_pair) = pair.events {
        let el = pair_event_loss_with(
            rgb,
            rgb2,
            &event_pair.expected,
            config.event_log_eps,
            config.event_penalty(),
        );
        let lambda = config.event_weight;
        terms.event = lambda * el.loss;
        add_scaled(&mut d_first[..3 * hw], &el.d_first, lambda);
        add_scaled(&mut terms.d_second[..3 * hw], &el.d_second, lambda);
    }
    Ok(terms)
}

/// The AIAP neighbourhoods: the human Gaussians (probability ≥ 0.5) and their K nearest human
/// neighbours in canonical space, refreshed after density control. With several people, whose
/// canonical spaces overlap, a Gaussian's neighbours are of its own person.
#[derive(Clone, Debug, Default)]
pub(super) struct AiapNeighbours {
    /// Set indices of the human Gaussians.
    pub index: Vec<usize>,
    /// K neighbours per entry of `index` (positions in `index`), empty with too few Gaussians.
    pub neighbours: Vec<u32>,
}

impl AiapNeighbours {
    /// The neighbourhoods of `model`'s current human Gaussians.
    pub fn of(model: &Model) -> Self {
        let human: Vec<usize> = (0..model.set.len())
            .filter(|&i| model.probability(i) >= 0.5)
            .collect();
        let neighbours_of = |index: &[usize]| {
            let points: Vec<[f32; 3]> = index.iter().map(|&i| model.set.means[i]).collect();
            gaussians::init::knn_indices(&points, AIAP_NEIGHBOURS)
        };
        if model.people() == 1 {
            let neighbours = if human.len() > AIAP_NEIGHBOURS {
                neighbours_of(&human)
            } else {
                Vec::new()
            };
            return Self {
                index: human,
                neighbours,
            };
        }
        // Person by person; a person with too few Gaussians has no neighbourhoods.
        let mut out = Self::default();
        for person in 0..model.people() {
            let own: Vec<usize> = human
                .iter()
                .copied()
                .filter(|&i| model.person_of(i) == person)
                .collect();
            if own.len() <= AIAP_NEIGHBOURS {
                continue;
            }
            let offset = out.index.len() as u32;
            out.neighbours
                .extend(neighbours_of(&own).into_iter().map(|k| k + offset));
            out.index.extend(own);
        }
        out
    }
}

/// The AIAP loss's canonical-side cotangents (per human Gaussian of the neighbourhoods).
pub(super) struct AiapCanonical {
    means: Vec<[f32; 3]>,
    covariances: Vec<[f32; 6]>,
}

/// The AIAP losses of the posed frame `posed` (positions and covariances of the human Gaussians
/// against their canonical ones): adds the posed-side cotangents to `d_posed`, returns the weighted
/// value and the canonical-side cotangents for [`add_aiap_canonical`].
pub(super) fn aiap_terms(
    aiap: &AiapNeighbours,
    model: &Model,
    posed: &PosedFrame<f32>,
    config: &TrainConfig,
    d_posed: &mut PosedGradients,
) -> (f32, AiapCanonical) {
    let mut canonical = AiapCanonical {
        means: vec![[0.0f32; 3]; aiap.index.len()],
        covariances: vec![[0.0f32; 6]; aiap.index.len()],
    };
    let mut value = 0.0f32;
    if aiap.neighbours.is_empty()
        || (config.aiap_position_weight <= 0.0 && config.aiap_covariance_weight <= 0.0)
    {
        return (value, canonical);
    }
    let set = &model.set;
    let idx = &aiap.index;
    let canon_x: Vec<[f32; 3]> = idx.iter().map(|&i| set.means[i]).collect();
    let posed_x: Vec<[f32; 3]> = idx.iter().map(|&i| posed.means[i]).collect();
    let mut d_posed_x = vec![[0.0f32; 3]; idx.len()];
    value += aiap_loss(
        &canon_x,
        &posed_x,
        &aiap.neighbours,
        AIAP_NEIGHBOURS,
        config.aiap_position_weight,
        Some(&mut canonical.means),
        Some(&mut d_posed_x),
    );
    let canon_c: Vec<[f32; 6]> = idx
        .iter()
        .map(|&i| upper_triangle(&covariance_3d(set.log_scales[i], set.quats[i])))
        .collect();
    let posed_c: Vec<[f32; 6]> = idx
        .iter()
        .map(|&i| upper_triangle(&posed.covariances[i]))
        .collect();
    let mut d_posed_c = vec![[0.0f32; 6]; idx.len()];
    value += aiap_loss(
        &canon_c,
        &posed_c,
        &aiap.neighbours,
        AIAP_NEIGHBOURS,
        config.aiap_covariance_weight,
        Some(&mut canonical.covariances),
        Some(&mut d_posed_c),
    );
    for (a, &i) in idx.iter().enumerate() {
        for ax in 0..3 {
            d_posed.means[i][ax] += d_posed_x[a][ax];
        }
        let g = upper_triangle_backward(&d_posed_c[a]);
        for r in 0..3 {
            for c in 0..3 {
                d_posed.covariances[i][r][c] += g[r][c];
            }
        }
    }
    (value, canonical)
}

/// Adds the AIAP loss's canonical-side cotangents to the stored parameters' gradients.
pub(super) fn add_aiap_canonical(
    aiap: &AiapNeighbours,
    model: &Model,
    canonical: &AiapCanonical,
    grads: &mut ModelGradients<f32>,
) {
    let set = &model.set;
    for (a, &i) in aiap.index.iter().enumerate() {
        for ax in 0..3 {
            grads.means[i][ax] += canonical.means[a][ax];
        }
        let g = upper_triangle_backward(&canonical.covariances[a]);
        let (ds, dq) = covariance_3d_backward(set.log_scales[i], set.quats[i], &g);
        for ax in 0..3 {
            grads.log_scales[i][ax] += ds[ax];
        }
        for ax in 0..4 {
            grads.quats[i][ax] += dq[ax];
        }
    }
}

impl super::Trainer {
    /// The priors on the human Gaussians' size and opacity (`train::loss::sharpness`, over the
    /// Gaussians AIAP holds together): adds their gradients to the stored parameters' and
    /// returns their weighted value.
    pub(super) fn sharpness_priors(
        &self,
        config: &TrainConfig,
        grads: &mut ModelGradients<f32>,
        d_opacity_logits: &mut [f32],
    ) -> f32 {
        let (set, index) = (&self.model.set, &self.aiap.index);
        let mut value = 0.0;
        if config.size_prior_weight > 0.0 {
            let d = Some(&mut grads.log_scales[..]);
            value += size_prior(&set.log_scales, index, config.size_prior_weight, d);
        }
        if config.opacity_entropy_weight > 0.0 {
            let (logits, weight) = (&set.opacity_logits, config.opacity_entropy_weight);
            value += opacity_entropy(logits, index, weight, Some(d_opacity_logits));
        }
        value
    }
}

/// The canonical surface samples of step `step`'s skinning-loss window: `m` consecutive samples of
/// the pool (wrapping), and their body weights (m × bones).
fn skinning_window(data: &TrainingData, step: usize, m: usize) -> (Vec<[f32; 3]>, Vec<f32>) {
    let pool = data.skin_points.len();
    let start = (step * m) % pool;
    let nb = data.skin_weights.len() / pool;
    let idx: Vec<usize> = (0..m).map(|j| (start + j) % pool).collect();
    let pts = idx.iter().map(|&j| data.skin_points[j]).collect();
    let target = idx
        .iter()
        .flat_map(|&j| data.skin_weights[j * nb..(j + 1) * nb].iter().copied())
        .collect();
    (pts, target)
}

/// The weighted skinning loss of step `step` (learned weights vs the body's on a window of surface
/// samples that moves every step); its gradient is added to `d_field`. Zero after
/// `config.skinning_until`.
pub(super) fn skinning_term(
    field: &SkinningField<f32>,
    data: &TrainingData,
    config: &TrainConfig,
    step: usize,
    d_field: &mut [f32],
) -> Result<f32, TrainError> {
    if step >= config.skinning_until || config.skinning_weight <= 0.0 || data.skin_points.is_empty()
    {
        return Ok(0.0);
    }
    let m = config.skinning_samples.min(data.skin_points.len()).max(1);
    let (pts, target) = skinning_window(data, step, m);
    let (pred, cache) = field.forward(&pts)?;
    let (value, mut d_pred) = skinning_loss(&pred, &target);
    for g in &mut d_pred {
        *g *= config.skinning_weight;
    }
    field.backward(&cache, &d_pred, d_field)?;
    Ok(value * config.skinning_weight)
}

/// Fits the skinning field to the body's skinning weights on the data's canonical surface samples
/// (`config.skinning_warmup_steps` Adam steps of the skinning loss, 2048 samples each, its own
/// optimiser state, deterministic).
pub fn warm_up_skinning(
    field: &mut SkinningField<f32>,
    data: &TrainingData,
    config: &TrainConfig,
) -> Result<(), TrainError> {
    let pool = data.skin_points.len();
    if config.skinning_warmup_steps == 0 || pool == 0 {
        return Ok(());
    }
    let m = 2048.min(pool);
    let mut adam = nn::Adam::new(
        field.mlp.num_params(),
        crate::optimisers::adam_config(config.lr_skinning.max(1e-3) * 5.0),
    );
    for step in 0..config.skinning_warmup_steps {
        let (pts, target) = skinning_window(data, step, m);
        let (pred, cache) = field.forward(&pts)?;
        let (_, d_pred) = skinning_loss(&pred, &target);
        let mut grads = vec![0.0f32; field.mlp.num_params()];
        field.backward(&cache, &d_pred, &mut grads)?;
        adam.step(&mut field.mlp.params, &grads)?;
    }
    Ok(())
}
