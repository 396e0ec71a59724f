//! The backward of one rendered pass ([`FramePass`]): through the rasterizer to the posed
//! Gaussians, then through the posing to the model's parameters; and what a pass reports.

use super::*;

impl FramePass<'_> {
    fn pixels(&self) -> usize {
        self.camera.width as usize * self.camera.height as usize
    }

    /// The rendered linear RGB, planar (3, H, W).
    pub fn rgb(&self) -> &[f32] {
        &self.out.image[..3 * self.pixels()]
    }

    /// The rendered human probability, (H, W).
    pub fn human(&self) -> &[f32] {
        let hw = self.pixels();
        &self.out.image[3 * hw..4 * hw]
    }

    /// Each Gaussian's smear over the pass's time slice (m²; `crate::pose::smear`), or `None`.
    pub fn smears(&self) -> Option<&[Mat3<f32>]> {
        self.smears.as_deref()
    }

    /// The number of rendered channels ([`Model::render_channels`]).
    pub fn render_channels(&self) -> usize {
        self.model.render_channels()
    }

    /// With several people, each person's rendered probability, (H, W) each (empty with one).
    pub fn people_planes(&self) -> Vec<Vec<f32>> {
        let hw = self.pixels();
        let extra = self.model.render_channels() - RENDER_CHANNELS;
        (0..extra)
            .map(|j| self.out.image[(4 + j) * hw..(5 + j) * hw].to_vec())
            .collect()
    }

    /// This pass's posed Gaussians rasterized from `camera` instead of its own (colours as posed,
    /// i.e. viewed from this pass's view centre; [`PassCamera`]): the render output, (C, H, W).
    pub fn render_from(&self, camera: &Camera) -> Result<RenderOutput<f32>, TrainError> {
        let splats = splats(
            self.model,
            &self.posed,
            &self.channels,
            self.smears.as_deref(),
        );
        Ok(render_cov(camera, &splats, &self.model.render_settings())?)
    }

    /// dL/dξ of `camera` for a further left twist ξ = (ω, v) (radians, metres;
    /// `rasterize_cpu::camera_pose_gradient`), for the image cotangent `d_image` ((C, H, W)) of
    /// `out`, [`FramePass::render_from`]'s render from that camera.
    pub fn camera_twist_gradient(
        &self,
        camera: &Camera,
        out: &RenderOutput<f32>,
        d_image: &[f32],
    ) -> Result<[f64; 6], TrainError> {
        let splats = splats(
            self.model,
            &self.posed,
            &self.channels,
            self.smears.as_deref(),
        );
        let cotangents = Cotangents {
            image: d_image,
            alpha: None,
            depth: None,
        };
        let g = render_cov_backward(
            camera,
            &splats,
            &self.model.render_settings(),
            out,
            &cotangents,
        )?;
        let mut twist = camera_pose_gradient(
            camera,
            &self.posed.means,
            &self.posed.covariances,
            &g.means,
            &g.covariances,
        )?;
        // A smear turns with the world like a covariance: its share, with no mean gradient.
        if let Some(smears) = &self.smears {
            let still = vec![[0.0f32; 3]; smears.len()];
            let share = camera_pose_gradient(camera, &self.posed.means, smears, &still, &g.smears)?;
            twist.iter_mut().zip(share).for_each(|(t, s)| *t += s);
        }
        Ok(twist)
    }

    /// Rasterizer backward of the image cotangent `d_image` ((C, H, W), C =
    /// [`Model::render_channels`]) plus,
    /// when given, a cotangent `d_geometric` of the RGB planes of which only the geometric share is
    /// kept: its gradients w.r.t. the means, covariances and screen-space means. The backward is
    /// linear in the cotangent, so this is exactly the gradient of all losses with `d_geometric`'s
    /// colour, opacity and semantic terms removed (the flow loss's `geometry` ablation).
    pub fn render_backward(
        &self,
        d_image: &[f32],
        d_geometric: Option<&[f32]>,
    ) -> Result<PosedGradients, TrainError> {
        let g = self.rasterizer_backward(d_image, d_geometric)?;
        Ok(PosedGradients::from_raster(g, self.model.render_channels()))
    }

    fn rasterizer_backward(
        &self,
        d_image: &[f32],
        d_geometric: Option<&[f32]>,
    ) -> Result<Gradients<f32>, TrainError> {
        let splats = splats(
            self.model,
            &self.posed,
            &self.channels,
            self.smears.as_deref(),
        );
        let settings = self.model.render_settings();
        let backward = |image: &[f32]| {
            render_cov_backward(
                self.camera,
                &splats,
                &settings,
                &self.out,
                &Cotangents {
                    image,
                    alpha: None,
                    depth: None,
                },
            )
        };
        let Some(d_geometric) = d_geometric else {
            return Ok(backward(d_image)?);
        };
        let mut padded = vec![0.0f32; d_image.len()];
        padded[..d_geometric.len()].copy_from_slice(d_geometric);
        let geometric = backward(&padded)?;
        if d_image.iter().all(|&v| v == 0.0) {
            // Only the geometric cotangent reaches this frame: one backward.
            return Ok(Gradients {
                opacity_logits: vec![0.0; geometric.opacity_logits.len()],
                channels: vec![0.0; geometric.channels.len()],
                background: vec![0.0; geometric.background.len()],
                ..geometric
            });
        }
        let mut grads = backward(d_image)?;
        let add = |a: &mut [f32], b: &[f32]| a.iter_mut().zip(b).for_each(|(x, &y)| *x += y);
        add(
            grads.means.as_flattened_mut(),
            geometric.means.as_flattened(),
        );
        add(
            grads.means_2d.as_flattened_mut(),
            geometric.means_2d.as_flattened(),
        );
        for (a, b) in grads.covariances.iter_mut().zip(&geometric.covariances) {
            add(a.as_flattened_mut(), b.as_flattened());
        }
        Ok(grads)
    }

    /// Backward through the posing (networks, blend, deformation) of the rasterizer-input gradients
    /// `posed`: gradients of every learnable quantity of the model and of this frame's latent.
    /// A re-posed pass ([`Model::forward_passes`]) is differentiated with its frame's passes by
    /// [`Model::reposed_backward`] and is refused here.
    pub fn model_backward(
        &self,
        posed: &PosedGradients,
    ) -> Result<ModelGradients<f32>, TrainError> {
        let model = self.model;
        let PassCache::Frame(cache) = &self.cache else {
            return Err(TrainError::Config(
                "a re-posed pass is differentiated with its frame's passes (Model::reposed_backward)"
                    .into(),
            ));
        };
        pose_frame_backward_with(
            &model.nets,
            model.config.semantic,
            &model.params(),
            &frame_inputs(
                self.view_centre,
                self.pose,
                self.latent,
                model.config.view_rotation,
            ),
            cache,
            &posed.cotangents(),
            None,
        )
    }

    /// The full backward of an image cotangent `d_image` ((C, H, W)): the model's gradients and the
    /// rasterizer-input gradients (for the opacities and density statistics).
    pub fn backward(
        &self,
        d_image: &[f32],
    ) -> Result<(ModelGradients<f32>, PosedGradients), TrainError> {
        let posed = self.render_backward(d_image, None)?;
        Ok((self.model_backward(&posed)?, posed))
    }

    /// Indices of the Gaussians whose human branch was evaluated (human probability ≥ the gate).
    pub fn active(&self) -> &[usize] {
        self.cache.active()
    }
}

impl Model {
    /// The rasterizer backward of passes rendered together ([`Model::forward_passes`] with
    /// `share_static_tiles`; `sharing` is theirs), one image cotangent per pass: each pass's
    /// rasterizer-input gradients, the shared tiles' share (replayed once with the passes' summed
    /// cotangent) in the owner's.
    pub fn shared_render_backward(
        &self,
        passes: &[FramePass<'_>],
        sharing: &TileSharing,
        d_images: &[Vec<f32>],
    ) -> Result<Vec<PosedGradients>, TrainError> {
        let Some(camera) = passes.first().map(|p| p.camera) else {
            return Ok(Vec::new());
        };
        let splats: Vec<_> = passes
            .iter()
            .map(|p| splats(self, &p.posed, &p.channels, p.smears.as_deref()))
            .collect();
        let outputs: Vec<_> = passes.iter().map(|p| &p.out).collect();
        let cotangents: Vec<_> = d_images
            .iter()
            .map(|image| Cotangents {
                image,
                alpha: None,
                depth: None,
            })
            .collect();
        let grads = render_cov_shared_backward(
            camera,
            &splats,
            &self.render_settings(),
            &outputs,
            sharing,
            &cotangents,
        )?;
        let channels = self.render_channels();
        Ok(grads
            .into_iter()
            .map(|g| PosedGradients::from_raster(g, channels))
            .collect())
    }
}

impl PosedGradients {
    /// The rasterizer's gradients, the `channels` render channels split into RGB, human
    /// probability and (with several people) each person's.
    fn from_raster(g: Gradients<f32>, channels: usize) -> Self {
        let per = g.channels.chunks_exact(channels);
        let colours = per.clone().flat_map(|c| c[..3].iter().copied()).collect();
        let human_probability = per.clone().map(|c| c[3]).collect();
        let person_probability = per
            .flat_map(|c| c[RENDER_CHANNELS..].iter().copied())
            .collect();
        PosedGradients {
            means: g.means,
            covariances: g.covariances,
            colours,
            human_probability,
            person_probability,
            opacity_logits: g.opacity_logits,
            means_2d: g.means_2d,
            smears: g.smears,
        }
    }

    /// The posing backward's view of these gradients.
    pub(super) fn cotangents(&self) -> FrameCotangents<'_, f32> {
        FrameCotangents {
            means: &self.means,
            covariances: &self.covariances,
            colours: &self.colours,
            human_probability: &self.human_probability,
            person_probability: &self.person_probability,
        }
    }
}
