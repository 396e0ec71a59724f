//! One optimisation step, in the order it runs: frame k's passes (one at mid exposure, or one per
//! sub-exposure pose) and the losses of their mean; frame k+1 when a pair loss applies; the backward
//! of every pass into one set of gradients (the AIAP regulariser on the mid pass, the pose
//! corrections' share of each pass); then the update and density control.

use super::camera::{CameraGradient, CorrectedCameras};
use super::correction::{self, CorrectedPoses};
use super::terms::{
    add_aiap_canonical, aiap_terms, frame_losses, pair_terms, skinning_term, PairSupervision,
    PairTerms,
};
use super::{add_to, all_finite, StageTimes, StepReport, Trainer};
use crate::config::{BlurModel, DensityGradient, ExposureNetworks, FlowGradient, TrainConfig};
use crate::data::TrainingData;
use crate::density::{add_ndc_norms, StepStatistics};
use crate::eval::psnr;
use crate::model::{ExposurePasses, FramePass, Model, PassCamera, PassPlan, PosedGradients};
use crate::pose::posing::ModelGradients;
use crate::schedule::{event_weight_at, ssim_weight_at};
use crate::TrainError;
use rasterize_cpu::TileSharing;
use smpl_deform::math::Affine;
use std::time::Instant;

/// The configuration step `step` trains with: `config` itself, except during the EDI warm-up
/// (`step < edi_warmup`), which renders once at mid exposure with no event term (its target is
/// the frame's EDI deblurring, [`TrainingData::target_image`]), and the event weight, which
/// decays from `event_weight_decay_from` on when `event_weight_final_fraction` is below 1, as
/// the D-SSIM weight does when `ssim_weight_final_fraction` is.
fn step_config(config: &TrainConfig, step: usize) -> TrainConfig {
    let mut config = config.clone();
    config.event_weight = event_weight_at(&config, step);
    config.ssim_weight = ssim_weight_at(&config, step);
    if step < config.edi_warmup {
        config.blur_model = BlurModel::None;
        config.event_loss = false;
        config.event_modulation = false;
    }
    config
}

/// Frame k's passes: one at mid exposure, or one per sub-exposure pose.
struct FramePasses<'a> {
    passes: Vec<FramePass<'a>>,
    /// The pass at mid exposure (the middle one).
    mid: usize,
    /// The other passes re-pose the mid pass's networks (`exposure_networks = once`).
    reposed: bool,
    /// The tiles the passes share, blended once by the mid pass (`share_static_tiles`).
    sharing: Option<TileSharing>,
}

/// Frame k+1's pass and the pair losses between it and frame k's mid pass.
struct NextFrame<'a> {
    slot: usize,
    pass: FramePass<'a>,
    terms: PairTerms,
}

/// Every gradient of one step, and the values of the terms taken during the backward.
struct StepGradients {
    grads: ModelGradients<f32>,
    opacity: Vec<f32>,
    means_2d: Vec<[f32; 2]>,
    pass_norms: Option<Vec<f32>>,
    /// ∂L/∂pose corrections, and the knots the step's frames are interpolated from.
    corrections: Option<(Vec<f32>, Vec<usize>)>,
    /// ∂L/∂camera corrections of the step's frames (with camera correction).
    cameras: Option<CameraGradient>,
    /// Frame k+1's slot and ∂L/∂ its latent code.
    next_latent: Option<(usize, Vec<f32>)>,
    aiap: f32,
    skinning: f32,
    pose_prior: f32,
}

impl Trainer {
    /// One optimisation step on the next training frame of the seeded order, then
    /// [`Trainer::refine`]. On a non-finite loss or gradient nothing is updated and
    /// [`TrainError::NonFinite`] is returned.
    pub fn step(&mut self, data: &TrainingData) -> Result<StepReport, TrainError> {
        let step = self.step;
        let config = step_config(&self.config, step);
        let warmup = step < self.config.edi_warmup;
        let slot = self.next_slot(data.frames.len());
        let frame = &data.frames[slot];
        let target = data.target_image(slot, warmup);
        let mut times = StageTimes::default();
        let model = &self.model;

        // Frame k: its passes (poses corrected by the frame's pose correction once it learns) and
        // the losses of their mean.
        let correcting = config.carries_pose_rows() && step >= config.pose_correction_from;
        let corrected = if correcting {
            let exposure = config.blur_model == BlurModel::Exposure;
            Some(CorrectedPoses::of(model, data, slot, exposure)?)
        } else {
            None
        };
        let exposure = config.blur_model == BlurModel::Exposure;
        let correcting_cameras = config.camera_correction && step >= config.camera_correction_from;
        let cameras = correcting_cameras
            .then(|| data.cameras(slot, exposure))
            .transpose()?
            .map(|given| CorrectedCameras::of(model, &given, slot));
        let frame_k = frame_passes(
            model,
            data,
            &config,
            slot,
            (corrected.as_ref(), cameras.as_ref()),
            &mut times,
        )?;
        let mut losses = frame_losses(data, &config, slot, target, &frame_k.passes, &mut times)?;

        // Frame k+1 when a pair loss applies.
        let t_pair = Instant::now();
        let pair = PairSupervision::of(data, &config, slot);
        let next_corrected = match &pair {
            Some(pair) if correcting => {
                Some(CorrectedPoses::of(model, data, pair.next_slot, false)?)
            }
            _ => None,
        };
        let next_cameras = match &pair {
            Some(pair) if correcting_cameras => Some(CorrectedCameras::of(
                model,
                &[&data.frames[pair.next_slot].camera],
                pair.next_slot,
            )),
            _ => None,
        };
        let next = match &pair {
            Some(pair) => Some(next_frame(
                model,
                data,
                &config,
                pair,
                (next_corrected.as_ref(), next_cameras.as_ref()),
                &frame_k.passes[frame_k.mid],
                &mut losses.d_images[frame_k.mid],
                &mut times,
            )?),
            None => None,
        };
        times.flow = t_pair.elapsed().as_secs_f64();

        let mut back = self.backward(
            data,
            &config,
            &frame_k,
            &losses.d_images,
            next.as_ref(),
            (corrected.as_ref(), next_corrected.as_ref()),
            (cameras.as_ref(), next_cameras.as_ref()),
            &mut times,
        )?;
        let (flow, event) = next
            .as_ref()
            .map_or((0.0, 0.0), |n| (n.terms.flow, n.terms.event));
        let event = event + losses.exposure_events;
        let sharpness = self.sharpness_priors(&config, &mut back.grads, &mut back.opacity);
        let loss = losses.photometric
            + sharpness
            + losses.lpips
            + back.aiap
            + back.skinning
            + flow
            + event
            + back.pose_prior
            + back.cameras.as_ref().map_or(0.0, |c| c.prior);
        if !(loss.is_finite() && back.all_finite()) {
            return Err(TrainError::NonFinite { step });
        }
        let first = &frame_k.passes[frame_k.mid];
        let active = first.active().len();
        let (shared_tiles, layered_tiles) = frame_k
            .sharing
            .as_ref()
            .map_or((0.0, 0.0), |s| (s.shared_fraction(), s.layered_fraction()));
        let statistics = StepStatistics {
            means_2d: back.means_2d,
            radii: first.out.radii.clone(),
            pass_norms: back.pass_norms,
        };
        drop(next);
        drop(frame_k);

        let t0 = Instant::now();
        let people_before = self.people_of_gaussians();
        self.apply_gradients(
            slot,
            back.grads,
            back.opacity,
            back.next_latent,
            back.corrections,
            back.cameras,
        )?;
        let person_changes = self.count_person_changes(&people_before);
        times.adam = t0.elapsed().as_secs_f64();
        let t0 = Instant::now();
        self.refine(data, &statistics);
        self.step += 1;
        times.density = t0.elapsed().as_secs_f64();
        let human = self.model.human_count();
        Ok(StepReport {
            step,
            frame: frame.index,
            loss,
            l1: losses.l1,
            ssim: losses.ssim,
            lpips: losses.lpips,
            skinning: back.skinning,
            aiap: back.aiap,
            sharpness,
            flow,
            event,
            pose_prior: back.pose_prior,
            psnr: psnr(&losses.prediction, target),
            gaussians_human: human,
            gaussians_scene: self.model.set.len() - human,
            active,
            shared_tiles,
            layered_tiles,
            person_changes,
            times,
        })
    }

    /// The backward of the step's passes into one set of gradients: frame k's passes (the AIAP
    /// regulariser on the mid pass), frame k+1's, the skinning regulariser, and the pose
    /// corrections' share with their prior.
    #[allow(clippy::too_many_arguments)]
    fn backward(
        &self,
        data: &TrainingData,
        config: &TrainConfig,
        frame_k: &FramePasses<'_>,
        d_images: &[Vec<f32>],
        next: Option<&NextFrame<'_>>,
        (corrected, next_corrected): (Option<&CorrectedPoses>, Option<&CorrectedPoses>),
        (cameras, next_cameras): (Option<&CorrectedCameras>, Option<&CorrectedCameras>),
        times: &mut StageTimes,
    ) -> Result<StepGradients, TrainError> {
        let model = &self.model;
        let d_geometric = next.and_then(|n| n.terms.d_flow_geometric.as_ref());
        let mut k = self.passes_backward(
            config,
            &data.camera,
            frame_k,
            d_images,
            d_geometric.map(|(a, _)| a.as_slice()),
            cameras,
            times,
        )?;
        let mut camera_frames: Vec<(usize, Vec<f64>)> = cameras
            .zip(k.camera_grad.take())
            .map(|(c, g)| (c.slot, g))
            .into_iter()
            .collect();
        // The pose corrections' gradient: frame k's passes, frame k+1's below, and the prior.
        let mut corrections = corrected.map(|c| {
            let mut g = vec![0.0f32; model.pose_corrections.len()];
            let bones: Vec<&[_]> = k.bones.iter().map(Vec::as_slice).collect();
            let codes: Vec<&[f32]> = k.codes.iter().map(Vec::as_slice).collect();
            c.add_gradient(
                &data.body,
                config.pose_correction_root,
                &bones,
                &codes,
                &mut g,
            );
            g
        });

        // Frame k+1: backward, accumulated into the shared gradients (counted under `flow`).
        let mut next_latent = None;
        let mut next_backward_seconds = 0.0;
        if let Some(next) = next {
            let t = Instant::now();
            let d_geometric_second = d_geometric.map(|(_, b)| b.as_slice());
            let posed = next
                .pass
                .render_backward(&next.terms.d_second, d_geometric_second)?;
            let grads = next.pass.model_backward(&posed)?;
            k.grads.add_shared(&grads);
            if let Some(c) = next_cameras {
                let mut g = vec![0.0; c.gradient_len()];
                c.add_gradient(0, &next.pass, &posed, &mut g)?;
                camera_frames.push((c.slot, g));
            }
            if let (Some(c), Some(g)) = (next_corrected, corrections.as_mut()) {
                c.add_gradient(
                    &data.body,
                    config.pose_correction_root,
                    &[&grads.bones],
                    &[&grads.pose_code],
                    g,
                );
            }
            for (o, &g) in k.opacity.iter_mut().zip(&posed.opacity_logits) {
                *o += g;
            }
            next_latent = Some((next.slot, grads.latent));
            next_backward_seconds = t.elapsed().as_secs_f64();
            times.flow += next_backward_seconds;
        }
        let skinning = skinning_term(
            &model.nets.skinning,
            data,
            config,
            self.step,
            &mut k.grads.skinning,
        )?;
        times.model_backward =
            k.started.elapsed().as_secs_f64() - next_backward_seconds - k.sub_render_seconds;

        // The knots the step's frames are interpolated from: frame k's (which the prior's step
        // covers), and k + 1's when rendered.
        let mut knots = corrected.map(CorrectedPoses::knots).unwrap_or_default();
        let pose_prior = match corrections.as_mut() {
            Some(g) => correction::add_prior(model, config, &knots, g),
            None => 0.0,
        };
        if let (Some(_), Some(c)) = (next, next_corrected) {
            for knot in c.knots() {
                if !knots.contains(&knot) {
                    knots.push(knot);
                }
            }
        }
        Ok(StepGradients {
            grads: k.grads,
            opacity: k.opacity,
            means_2d: k.means_2d,
            pass_norms: k.pass_norms,
            corrections: corrections.map(|g| (g, knots)),
            cameras: cameras.map(|_| CameraGradient::of(model, config, data, &camera_frames)),
            next_latent,
            aiap: k.aiap,
            skinning,
            pose_prior,
        })
    }

    /// Frame k's backward: the mid pass with the AIAP regulariser on its posed human Gaussians,
    /// then every other sub-exposure pass, accumulated — through the networks once for all
    /// re-posed passes, else once per pass.
    fn passes_backward(
        &self,
        config: &TrainConfig,
        camera: &rasterize_cpu::Camera,
        frame_k: &FramePasses<'_>,
        d_images: &[Vec<f32>],
        d_geometric: Option<&[f32]>,
        cameras: Option<&CorrectedCameras>,
        times: &mut StageTimes,
    ) -> Result<PassesBackward, TrainError> {
        let model = &self.model;
        let FramePasses {
            passes,
            mid,
            reposed,
            sharing,
        } = frame_k;
        let (mid, reposed) = (*mid, *reposed);
        let first = &passes[mid];
        let mut pass_norms = (config.density_gradient == DensityGradient::PerPass
            && passes.len() > 1)
            .then(|| vec![0.0f32; first.out.radii.len()]);
        // Every pass's rasterizer backward at once when they shared tiles and each pass's own
        // gradients are not needed; else each pass's below.
        let t0 = Instant::now();
        let mut shared: Vec<Option<PosedGradients>> = match sharing {
            Some(sharing) if d_geometric.is_none() && pass_norms.is_none() => model
                .shared_render_backward(passes, sharing, d_images)?
                .into_iter()
                .map(Some)
                .collect(),
            _ => passes.iter().map(|_| None).collect(),
        };
        // Smears read the neighbouring passes' means: every pass's rasterizer backward first, so
        // that each pass's mean gradients are complete before its model backward.
        if passes.iter().any(|p| p.smears().is_some()) {
            let mut all = Vec::with_capacity(passes.len());
            for (s, (pass, done)) in passes.iter().zip(shared).enumerate() {
                all.push(match done {
                    Some(g) => g,
                    None => pass.render_backward(&d_images[s], d_geometric.filter(|_| s == mid))?,
                });
            }
            model.add_smear_gradients(passes, &mut all)?;
            shared = all.into_iter().map(Some).collect();
        }
        let mut posed = match shared[mid].take() {
            Some(posed) => posed,
            None => first.render_backward(&d_images[mid], d_geometric)?,
        };
        times.render_backward = t0.elapsed().as_secs_f64();
        let started = Instant::now();
        // The camera corrections' gradient, from the renders' own gradients (before the AIAP
        // regulariser adds to the mid pass's).
        let mut camera_grad = cameras.map(|c| vec![0.0f64; c.gradient_len()]);
        let mut camera_gradient = |s: usize, pass: &FramePass<'_>, g: &PosedGradients| match (
            cameras,
            camera_grad.as_mut(),
        ) {
            (Some(c), Some(grad)) => c.add_gradient(s, pass, g, grad),
            _ => Ok(()),
        };
        camera_gradient(mid, first, &posed)?;
        let (aiap, aiap_canonical) =
            aiap_terms(&self.aiap, model, &first.posed, config, &mut posed);
        // Per pass, ∂L/∂bones and ∂L/∂pose code (for the pose correction).
        let mut bones = vec![Vec::new(); passes.len()];
        let mut codes = vec![Vec::new(); passes.len()];
        // Passes of their own networks: the mid pass's model backward first.
        let mut own = if reposed {
            None
        } else {
            let mut grads = first.model_backward(&posed)?;
            bones[mid] = grads.bones.clone();
            codes[mid] = grads.pose_code.clone();
            add_aiap_canonical(&self.aiap, model, &aiap_canonical, &mut grads);
            Some(grads)
        };
        let mut opacity = std::mem::take(&mut posed.opacity_logits);
        let mut means_2d = std::mem::take(&mut posed.means_2d);
        if let Some(norms) = pass_norms.as_mut() {
            add_ndc_norms(norms, &means_2d, camera);
        }
        let mut sub_render_seconds = 0.0;
        let mut reposed_subs = Vec::new();
        for (s, pass) in passes.iter().enumerate().filter(|&(s, _)| s != mid) {
            let sub = match shared[s].take() {
                Some(sub) => sub,
                None => {
                    let t = Instant::now();
                    let sub = pass.render_backward(&d_images[s], None)?;
                    sub_render_seconds += t.elapsed().as_secs_f64();
                    sub
                }
            };
            if let Some(norms) = pass_norms.as_mut() {
                add_ndc_norms(norms, &sub.means_2d, camera);
            }
            camera_gradient(s, pass, &sub)?;
            if let Some(grads) = own.as_mut() {
                let g = pass.model_backward(&sub)?;
                grads.add_shared(&g);
                add_to(&mut grads.latent, &g.latent);
                bones[s] = g.bones;
                codes[s] = g.pose_code;
            }
            add_to(&mut opacity, &sub.opacity_logits);
            add_to(means_2d.as_flattened_mut(), sub.means_2d.as_flattened());
            if reposed {
                reposed_subs.push(sub);
            }
        }
        let grads = match own {
            Some(grads) => grads,
            None => {
                // One backward through the networks for every sub-exposure pass.
                let mut all: Vec<&PosedGradients> = reposed_subs.iter().collect();
                all.insert(mid, &posed);
                let (mut grads, pass_bones) = model.reposed_backward(passes, mid, &all)?;
                bones = pass_bones;
                codes[mid] = grads.pose_code.clone();
                add_aiap_canonical(&self.aiap, model, &aiap_canonical, &mut grads);
                grads
            }
        };
        times.render_backward += sub_render_seconds;
        Ok(PassesBackward {
            grads,
            opacity,
            means_2d,
            pass_norms,
            bones,
            codes,
            camera_grad,
            aiap,
            started,
            sub_render_seconds,
        })
    }
}

/// [`Trainer::passes_backward`]'s result.
struct PassesBackward {
    grads: ModelGradients<f32>,
    opacity: Vec<f32>,
    means_2d: Vec<[f32; 2]>,
    pass_norms: Option<Vec<f32>>,
    bones: Vec<Vec<Affine<f32>>>,
    codes: Vec<Vec<f32>>,
    /// ∂L/∂ the frame's camera correction (with camera correction).
    camera_grad: Option<Vec<f64>>,
    aiap: f32,
    /// When the model backward started (after the mid pass's render backward), and the seconds
    /// of the other passes' render backward since: the stage times subtract them.
    started: Instant,
    sub_render_seconds: f64,
}

impl StepGradients {
    /// True when every gradient is finite.
    fn all_finite(&self) -> bool {
        self.corrections
            .as_ref()
            .is_none_or(|(g, _)| g.iter().all(|v| v.is_finite()))
            && self.cameras.as_ref().is_none_or(CameraGradient::all_finite)
            && self.opacity.iter().all(|v| v.is_finite())
            && self
                .next_latent
                .as_ref()
                .is_none_or(|(_, g)| g.iter().all(|v| v.is_finite()))
            && all_finite(&self.grads)
    }
}

/// Frame k's passes: one at mid exposure, or with the exposure model one per sub-exposure pose
/// (`corrected`: the poses as the frame's pose correction moves them; `cameras`: the cameras as its
/// camera correction moves them).
fn frame_passes<'a>(
    model: &'a Model,
    data: &'a TrainingData,
    config: &TrainConfig,
    slot: usize,
    (corrected, cameras): (Option<&'a CorrectedPoses>, Option<&'a CorrectedCameras>),
    times: &mut StageTimes,
) -> Result<FramePasses<'a>, TrainError> {
    let exposure = config.blur_model == BlurModel::Exposure;
    let poses: Vec<_> = match corrected {
        Some(c) => c.prepared.iter().collect(),
        None => data
            .poses(slot, exposure)?
            .iter()
            .map(|p| &p.prepared)
            .collect(),
    };
    let cameras = match cameras {
        Some(c) => c.pass_cameras(),
        None => data
            .cameras(slot, exposure)?
            .into_iter()
            .map(PassCamera::of)
            .collect(),
    };
    let mid = poses.len() / 2;
    // Corrected cameras differ between passes once the correction's change does; their gradient
    // needs each pass's own, so no tiles are shared.
    let plan = PassPlan {
        reposed: poses.len() > 1 && config.exposure_networks == ExposureNetworks::Once,
        share_static_tiles: config.share_static_tiles && !config.camera_correction,
        joint_backward_only: joint_backward_only(config),
        static_layer: config.static_layer,
        smear: config.exposure_smear && !config.camera_correction,
    };
    let ExposurePasses { passes, sharing } =
        model.forward_passes(&cameras, &poses, mid, model.latent(slot), plan)?;
    for pass in &passes {
        times.pose += pass.timing.pose;
        times.render += pass.timing.render;
    }
    Ok(FramePasses {
        passes,
        mid,
        reposed: plan.reposed,
        sharing,
    })
}

/// Whether an exposure's passes are differentiated only together ([`Model::shared_render_backward`]
/// in `passes_backward`): not when each pass's own screen-space gradients are kept (per-pass
/// density statistics) or the flow loss's geometric cotangent needs the mid pass's own backward.
fn joint_backward_only(config: &TrainConfig) -> bool {
    config.density_gradient != DensityGradient::PerPass
        && !(config.flow_loss && config.flow_gradient == FlowGradient::Geometry)
}

/// Frame k+1's pass (at its corrected pose and camera when `corrected` and `camera` are given)
/// and the pair losses between it and frame k's mid pass `first`, whose share of their cotangent
/// is added to `d_first`.
#[allow(clippy::too_many_arguments)]
fn next_frame<'a>(
    model: &'a Model,
    data: &'a TrainingData,
    config: &TrainConfig,
    pair: &PairSupervision<'_>,
    (corrected, camera): (Option<&'a CorrectedPoses>, Option<&'a CorrectedCameras>),
    first: &FramePass<'_>,
    d_first: &mut [f32],
    times: &mut StageTimes,
) -> Result<NextFrame<'a>, TrainError> {
    let next = &data.frames[pair.next_slot];
    let pose = corrected.map_or(&next.pose.prepared, |c| &c.prepared[0]);
    let camera = match camera {
        Some(c) => c.pass_cameras()[0],
        None => PassCamera::of(&next.camera),
    };
    let pass = model.forward_from(camera, pose, model.latent(pair.next_slot))?;
    let size = (data.camera.height as usize, data.camera.width as usize);
    let terms = pair_terms(pair, config, first.rgb(), pass.rgb(), size, d_first)?;
    times.flow_network = terms.flow_network_seconds;
    Ok(NextFrame {
        slot: pair.next_slot,
        pass,
        terms,
    })
}
