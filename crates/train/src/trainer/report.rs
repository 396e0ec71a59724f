//! What a training step reports: its loss terms, figures and the wall-clock time of each stage.

/// Wall-clock seconds per stage of one step (for the cost breakdown; not deterministic).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct StageTimes {
    /// Deformation, colour networks and blend.
    pub pose: f64,
    /// Rasterization forward.
    pub render: f64,
    /// Photometric loss and its gradient.
    pub loss: f64,
    /// The perceptual (LPIPS) loss and its gradient: the network's forward on the observed frame,
    /// forward and backward on the prediction (0 with `lpips_weight = 0`).
    pub lpips: f64,
    /// Rasterization backward.
    pub render_backward: f64,
    /// Model backward (networks, blend, deformation) plus skinning and AIAP losses.
    pub model_backward: f64,
    /// Optimiser updates.
    pub adam: f64,
    /// Density control and opacity reset.
    pub density: f64,
    /// The pair losses (flow, events): posing and rendering frame k+1, the flow network forward and
    /// backward, the event loss, frame k+1's rasterizer and model backward (0 without a pair).
    pub flow: f64,
    /// The part of `flow` spent in the flow loss proper: resizing both renders, the frozen network's
    /// forward and input gradient, the masked L1 (0 without a flow pair).
    pub flow_network: f64,
}

/// What one step did.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct StepReport {
    /// 0-based step index.
    pub step: usize,
    /// Frame number trained on.
    pub frame: u32,
    /// Total loss.
    pub loss: f32,
    /// The L1 term.
    pub l1: f32,
    /// SSIM (not 1 − SSIM).
    pub ssim: f32,
    /// The weighted perceptual loss λ_lpips·LPIPS (0 with `lpips_weight = 0`).
    pub lpips: f32,
    /// The weighted skinning loss.
    pub skinning: f32,
    /// The weighted AIAP loss (positions + covariances).
    pub aiap: f32,
    /// The weighted priors on the person's size and opacity (0 with both weights 0).
    pub sharpness: f32,
    /// The weighted flow loss λ_flow·L_flow (0 on steps without a flow pair).
    pub flow: f32,
    /// The weighted event-generation loss (0 on steps without an event pair).
    pub event: f32,
    /// The pose-correction prior's terms of the step's frame (0 without pose correction).
    pub pose_prior: f32,
    /// PSNR (dB) of the render against the (blurred) training frame.
    pub psnr: f64,
    /// Gaussians with human probability ≥ 0.5 after the step.
    pub gaussians_human: usize,
    /// Other Gaussians after the step.
    pub gaussians_scene: usize,
    /// Gaussians whose human branch was evaluated.
    pub active: usize,
    /// Fraction of the tiles the step's sub-exposure renders shared (blended once;
    /// `share_static_tiles`), 0 when they shared none.
    pub shared_tiles: f64,
    /// Fraction of the tiles whose static Gaussians behind every moving one were blended once,
    /// as a layer behind the renders' own lists (`static_layer`), 0 without a layer.
    pub layered_tiles: f64,
    /// With several people: Gaussians whose most probable person changed in this step's update
    /// (0 with one person).
    pub person_changes: usize,
    /// Stage timings.
    pub times: StageTimes,
}

impl StageTimes {
    /// The step's wall time: every stage (`flow_network` is part of `flow`).
    pub fn total(&self) -> f64 {
        self.pose
            + self.render
            + self.loss
            + self.lpips
            + self.render_backward
            + self.model_backward
            + self.adam
            + self.density
            + self.flow
    }
}
