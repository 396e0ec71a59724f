//! One exposure's passes: posed by the networks once and re-posed for the other sub-exposure
//! poses, rasterized together (the static tiles blended once), and differentiated together (one
//! network backward for every re-posed pass). Each pass's work is a parallel task; results are
//! collected and summed in pass order, so the bits do not depend on the threads.

use super::*;
use crate::pose::smear::{exposure_smears, exposure_smears_backward};

/// One re-posed pass's backward: the reference's internal cotangents and ∂L/∂bones.
type ReposedBackward = (ReposeCotangents<f32>, Vec<Affine<f32>>);

impl Model {
    /// Renders one frame at each of `poses` (its sub-exposure poses), pass s from `cameras[s]` (the
    /// same camera for every pass unless the camera moves within the exposure or is corrected). With
    /// `plan.reposed` the networks are evaluated once, at `poses[reference]`, and that pass is
    /// re-posed for the others by linear blend skinning alone (`train::pose::reposing`; differentiate the
    /// passes together with [`Model::reposed_backward`]); else every pass is posed by the networks.
    /// With `plan.share_static_tiles` the tiles only static Gaussians (human probability below the
    /// gate, the same in every pass) reach are blended once, by the reference pass, when every pass
    /// has the same camera
    /// (`rasterize_cpu::render_cov_shared`; differentiate with [`Model::shared_render_backward`]).
    pub fn forward_passes<'a>(
        &'a self,
        cameras: &[PassCamera<'a>],
        poses: &[&'a PreparedPose],
        reference: usize,
        latent: &'a [f32],
        plan: PassPlan,
    ) -> Result<ExposurePasses<'a>, TrainError> {
        let (Some(&reference_pose), Some(&camera)) = (poses.get(reference), cameras.get(reference))
        else {
            return Err(TrainError::Config(format!(
                "passes: reference {reference} of {} poses",
                poses.len()
            )));
        };
        if cameras.len() != poses.len() {
            return Err(TrainError::Shape {
                what: "cameras of an exposure's passes".into(),
                expected: poses.len(),
                found: cameras.len(),
            });
        }
        let first = self.posed_pass(camera.view_centre, reference_pose, latent)?;
        let others: Vec<usize> = (0..poses.len()).filter(|&s| s != reference).collect();
        let mut posed = if plan.reposed {
            let PassCache::Frame(reference_cache) = &first.cache else {
                unreachable!("Model::posed_pass poses with the networks");
            };
            // The re-posings are independent, and each is mostly serial work (the copy of the
            // reference frame, the blend): one task per pass, collected in pass order. Each
            // pass's share of the wall time is its `pose_seconds`, so that they sum to it.
            let t0 = Instant::now();
            let mut passes = others
                .par_iter()
                .map(|&s| {
                    let (frame, cache) =
                        repose_frame(&first.posed, reference_cache, &poses[s].bones)?;
                    Ok(PosedPass {
                        view_centre: cameras[s].view_centre,
                        pose: poses[s],
                        latent,
                        cache: PassCache::Reposed(cache),
                        channels: interleave_channels(&frame),
                        smears: None,
                        posed: frame,
                        pose_seconds: 0.0,
                    })
                })
                .collect::<Result<Vec<_>, TrainError>>()?;
            let share = t0.elapsed().as_secs_f64() / passes.len().max(1) as f64;
            for p in &mut passes {
                p.pose_seconds = share;
            }
            passes
        } else {
            let mut passes = Vec::with_capacity(poses.len());
            for &s in &others {
                passes.push(self.posed_pass(cameras[s].view_centre, poses[s], latent)?);
            }
            passes
        };
        posed.insert(reference, first);
        // Tiles are shared only between renders from one camera (a moving camera moves every
        // Gaussian on the image).
        let one_camera = cameras.iter().all(|c| c.raster == camera.raster);
        // Smears follow the Gaussians' world motion: with one camera that is their motion on the
        // image.
        if plan.smear && one_camera {
            let means: Vec<_> = posed.iter().map(|p| &p.posed.means[..]).collect();
            let smears = exposure_smears(&means);
            for (pass, smears) in posed.iter_mut().zip(smears) {
                pass.smears = Some(smears);
            }
        }
        if plan.share_static_tiles && posed.len() > 1 && one_camera {
            let outputs = if plan.joint_backward_only && plan.static_layer {
                SharedOutputs::Layered
            } else if plan.joint_backward_only {
                SharedOutputs::OwnerLists
            } else {
                SharedOutputs::Complete
            };
            return self.rasterize_shared(camera.raster, posed, reference, outputs);
        }
        let passes = posed
            .into_iter()
            .zip(cameras)
            .map(|(p, c)| self.rasterize(c.raster, p))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(ExposurePasses {
            passes,
            sharing: None,
        })
    }

    /// Rasterizes the posed passes of one frame together, the tiles only the Gaussians outside
    /// every pass's active set reach blended once, by pass `owner`.
    fn rasterize_shared<'a>(
        &'a self,
        camera: &'a Camera,
        posed: Vec<PosedPass<'a>>,
        owner: usize,
        outputs: SharedOutputs,
    ) -> Result<ExposurePasses<'a>, TrainError> {
        let t0 = Instant::now();
        let mut moving = vec![false; self.set.len()];
        for pass in &posed {
            for &i in pass.cache.active() {
                moving[i] = true;
            }
        }
        let splats: Vec<_> = posed
            .iter()
            .map(|p| splats(self, &p.posed, &p.channels, p.smears.as_deref()))
            .collect();
        let settings = self.render_settings();
        let renders = render_cov_shared(camera, &splats, &moving, owner, &settings, outputs)?;
        let seconds = t0.elapsed().as_secs_f64() / posed.len() as f64;
        let passes = posed
            .into_iter()
            .zip(renders.outputs)
            .map(|(p, out)| p.rendered(self, camera, out, seconds))
            .collect();
        Ok(ExposurePasses {
            passes,
            sharing: Some(renders.sharing),
        })
    }

    /// The model's gradients of passes made by [`Model::forward_passes`] with `reposed` (same `reference`), from
    /// each pass's rasterizer-input gradients `posed` (same order): one backward through the
    /// networks, into which every re-posed pass's cotangents are summed. The returned model gradients'
    /// `bones` and `pose_code` are the reference pass's; the list holds ∂L/∂bones of every pass (same
    /// order), for pose correction.
    pub fn reposed_backward(
        &self,
        passes: &[FramePass<'_>],
        reference: usize,
        posed: &[&PosedGradients],
    ) -> Result<(ModelGradients<f32>, Vec<BoneGradients>), TrainError> {
        let reference_pass = passes
            .get(reference)
            .filter(|_| posed.len() == passes.len());
        let Some(FramePass {
            cache: PassCache::Frame(reference_cache),
            ..
        }) = reference_pass
        else {
            return Err(TrainError::Config(format!(
                "re-posed backward: {} passes, {} gradients, reference {reference} not a posed pass",
                passes.len(),
                posed.len()
            )));
        };
        let params = self.params();
        // The re-posed passes' backwards are independent (one task each); their cotangents are
        // summed in pass order, as one after the other would.
        let reposed: Vec<Option<ReposedBackward>> = passes
            .par_iter()
            .zip(posed)
            .map(|(pass, grads)| {
                let PassCache::Reposed(cache) = &pass.cache else {
                    return Ok(None);
                };
                repose_frame_backward(
                    self.config.semantic,
                    &params,
                    reference_cache,
                    &pass.pose.bones,
                    cache,
                    &grads.cotangents(),
                )
                .map(Some)
            })
            .collect::<Result<_, TrainError>>()?;
        let mut summed = ReposeCotangents::zeros(self.set.len(), reference_cache.active.len());
        let mut pass_bones = vec![Vec::new(); passes.len()];
        for (result, bones) in reposed.into_iter().zip(&mut pass_bones) {
            if let Some((d, d_bones)) = result {
                summed.add(&d);
                *bones = d_bones;
            }
        }
        let reference_pass = &passes[reference];
        let grads = pose_frame_backward_with(
            &self.nets,
            self.config.semantic,
            &params,
            &frame_inputs(
                reference_pass.view_centre,
                reference_pass.pose,
                reference_pass.latent,
                self.config.view_rotation,
            ),
            reference_cache,
            &posed[reference].cotangents(),
            Some(&summed),
        )?;
        pass_bones[reference] = grads.bones.clone();
        Ok((grads, pass_bones))
    }

    /// Adds to the passes' mean gradients `grads` (one per pass of `passes`, same order) the share
    /// of their smears' gradients (`crate::pose::smear`): each smear is read from the neighbouring
    /// passes' means. Nothing to do for passes rendered without smears; gradients without a smear
    /// gradient per Gaussian are refused.
    pub fn add_smear_gradients(
        &self,
        passes: &[FramePass<'_>],
        grads: &mut [PosedGradients],
    ) -> Result<(), TrainError> {
        if passes.iter().any(|p| p.smears.is_none()) {
            return Ok(());
        }
        if passes.len() != grads.len() {
            return Err(TrainError::Shape {
                what: "smear gradients of an exposure's passes".into(),
                expected: passes.len(),
                found: grads.len(),
            });
        }
        if let Some(g) = grads.iter().find(|g| g.smears.len() != g.means.len()) {
            return Err(TrainError::Shape {
                what: "smear gradients of a pass's Gaussians".into(),
                expected: g.means.len(),
                found: g.smears.len(),
            });
        }
        let means: Vec<_> = passes.iter().map(|p| &p.posed.means[..]).collect();
        let d_smears: Vec<Vec<Mat3<f32>>> = grads
            .iter_mut()
            .map(|g| std::mem::take(&mut g.smears))
            .collect();
        let d_smears: Vec<_> = d_smears.iter().map(|d| &d[..]).collect();
        let mut d_means: Vec<_> = grads.iter_mut().map(|g| &mut g.means[..]).collect();
        exposure_smears_backward(&means, &d_smears, &mut d_means);
        Ok(())
    }
}
