//! The event-flow loss of E-Sem3DGS (paper §4.4), minus the network: preparing the event-flow target
//! at the flow network's resolution, and the masked L1 between predicted and event flow.
//!
//! L_flow = (1/|M|) Σ_{p∈M} ‖F_pred(p) − F_evt(p)‖₁ with M = {p : ‖F_evt(p)‖₂ > τ and p valid}, where
//! F_evt is the event flow bilinearly resized (`align_corners = true`) to the network's resolution with
//! its vectors scaled by the same factor (x by w_out/W, y by h_out/H; 1/4 in the paper). The renders
//! themselves are resized by the same operator inside the training step (`nn::resize_bilinear_*`).
//! Flows are planar (2, H, W) in pixels, forward k → k+1 (DESIGN.md §3).

use crate::TrainError;
use flow::SpyNet;
use nn::{resize_bilinear_backward, resize_bilinear_forward, NnError, Real};

/// Event flow at the network's resolution, with the supervision mask.
#[derive(Clone, Debug, PartialEq)]
pub struct FlowTarget<T> {
    /// Height of the resized flow (pixels).
    pub height: usize,
    /// Width of the resized flow (pixels).
    pub width: usize,
    /// Resized flow (2, h, w), vectors in resized pixels.
    pub flow: Vec<T>,
    /// Supervised pixels (h × w): magnitude above τ and valid.
    pub mask: Vec<bool>,
}

impl<T: Real> FlowTarget<T> {
    /// Number of supervised pixels |M|.
    pub fn supervised(&self) -> usize {
        self.mask.iter().filter(|&&m| m).count()
    }
}

/// Resizes an event flow (2, H, W) and its validity (H × W, `None` = all valid) to (h_out, w_out) and
/// builds the mask with threshold `tau` (pixels at the *resized* scale). A resized pixel is valid when
/// its bilinear validity weight is above 0.5 (i.e. it is mostly made of valid source pixels).
pub fn prepare_target<T: Real>(
    flow: &[T],
    valid: Option<&[bool]>,
    height: usize,
    width: usize,
    h_out: usize,
    w_out: usize,
    tau: T,
) -> Result<FlowTarget<T>, NnError> {
    let mut resized = vec![T::zero(); 2 * h_out * w_out];
    resize_bilinear_forward(2, height, width, flow, h_out, w_out, true, &mut resized)?;
    let (sx, sy) = (
        T::of(w_out as f64 / width.max(1) as f64),
        T::of(h_out as f64 / height.max(1) as f64),
    );
    let plane = h_out * w_out;
    for v in &mut resized[..plane] {
        *v = *v * sx;
    }
    for v in &mut resized[plane..] {
        *v = *v * sy;
    }
    let valid_resized = match valid {
        Some(valid) => {
            let as_float: Vec<T> = valid
                .iter()
                .map(|&b| if b { T::one() } else { T::zero() })
                .collect();
            let mut out = vec![T::zero(); plane];
            resize_bilinear_forward(1, height, width, &as_float, h_out, w_out, true, &mut out)?;
            out.iter().map(|&v| v > T::of(0.5)).collect()
        }
        None => vec![true; plane],
    };
    let mask = (0..plane)
        .map(|p| {
            let (u, v) = (resized[p], resized[plane + p]);
            valid_resized[p] && (u * u + v * v).sqrt() > tau
        })
        .collect();
    Ok(FlowTarget {
        height: h_out,
        width: w_out,
        flow: resized,
        mask,
    })
}

/// A target made by the frozen network itself: frames k and k+1 (planar (3, H, W) RGB, normally the
/// sharp references) are resized to (h_out, w_out) exactly as [`pair_flow_loss`] resizes renders,
/// the network predicts the flow between them, and the mask keeps pixels whose predicted flow is
/// longer than `tau` (resized pixels); every pixel counts as valid. This is the paper's protocol for
/// ZJU-MoCap-Blur (target flow inferred from the sharp frames by a pretrained network, RAFT there),
/// with the frozen network in RAFT's place; [`pair_flow_loss`] of the same two frames against it is
/// exactly zero, so the sharp frames are a global minimum of the loss.
#[allow(clippy::too_many_arguments)]
pub fn network_target<T: Real>(
    net: &SpyNet<T>,
    first: &[T],
    second: &[T],
    height: usize,
    width: usize,
    h_out: usize,
    w_out: usize,
    tau: T,
) -> Result<FlowTarget<T>, TrainError> {
    let small = resize_pair(first, second, height, width, h_out, w_out)?;
    let flow = net.forward(&small[0], &small[1], h_out, w_out)?.flow;
    let plane = h_out * w_out;
    let mask = (0..plane)
        .map(|p| (flow[p] * flow[p] + flow[plane + p] * flow[plane + p]).sqrt() > tau)
        .collect();
    Ok(FlowTarget {
        height: h_out,
        width: w_out,
        flow,
        mask,
    })
}

/// Masked L1 between a predicted flow (2, h, w) and the target; writes dL/dpred into `grad` when given.
/// Returns 0 (and a zero gradient) when no pixel is supervised.
pub fn masked_l1<T: Real>(pred: &[T], target: &FlowTarget<T>, grad: Option<&mut [T]>) -> T {
    let plane = target.height * target.width;
    let count = target.supervised();
    let mut grad = grad;
    if let Some(g) = grad.as_deref_mut() {
        g.iter_mut().for_each(|v| *v = T::zero());
    }
    if count == 0 {
        return T::zero();
    }
    let inv = T::one() / T::of(count as f64);
    let mut total = T::zero();
    for p in 0..plane {
        if !target.mask[p] {
            continue;
        }
        for c in 0..2 {
            let i = c * plane + p;
            let d = pred[i] - target.flow[i];
            total = total + d.abs();
            if let Some(g) = grad.as_deref_mut() {
                g[i] = super::l1_slope(d, inv);
            }
        }
    }
    total * inv
}

/// [`pair_flow_loss`]'s result: the loss, the network's prediction, and the loss gradient w.r.t. both
/// full-resolution renders.
#[derive(Clone, Debug)]
pub struct PairFlowLoss<T> {
    /// L_flow (pixels at the network's resolution).
    pub loss: T,
    /// Predicted flow (2, h, w) at the target's resolution.
    pub predicted: Vec<T>,
    /// ∂L_flow/∂(render of frame k), planar (3, H, W).
    pub d_first: Vec<T>,
    /// ∂L_flow/∂(render of frame k+1), planar (3, H, W).
    pub d_second: Vec<T>,
    /// Identifies the smooth piece of the loss the inputs fall in (the network's ReLU and warp-cell
    /// pattern and the signs of the L1 residuals): finite-difference probes whose signatures differ
    /// straddle a kink.
    pub region_signature: u64,
}

/// L_flow of two renders (planar (3, H, W) RGB, frames k and k+1): both are resized to the target's
/// resolution (bilinear, `align_corners = true`), the frozen network predicts the flow between them,
/// [`masked_l1`] compares it with the target, and the gradient goes back through the network's input
/// gradient and the resize into both renders. The network's weights are not differentiated.
pub fn pair_flow_loss<T: Real>(
    net: &SpyNet<T>,
    first: &[T],
    second: &[T],
    height: usize,
    width: usize,
    target: &FlowTarget<T>,
) -> Result<PairFlowLoss<T>, TrainError> {
    let (h, w) = (target.height, target.width);
    let small = resize_pair(first, second, height, width, h, w)?;
    let tape = net.forward(&small[0], &small[1], h, w)?;
    let mut d_flow = vec![T::zero(); 2 * h * w];
    let loss = masked_l1(&tape.flow, target, Some(&mut d_flow));
    let (d_small_first, d_small_second) = net.backward(&tape, &d_flow, None)?;
    let (d_first, d_second) =
        resize_pair_backward(&d_small_first, &d_small_second, height, width, h, w)?;
    // Fold the L1 residual signs of supervised pixels into the network's region signature.
    let plane = h * w;
    let mut signature = tape.region_signature();
    for (i, &g) in d_flow.iter().enumerate() {
        if target.mask[i % plane] {
            signature = fold_sign(signature, g > T::zero(), i);
        }
    }
    Ok(PairFlowLoss {
        loss,
        predicted: tape.flow,
        d_first,
        d_second,
        region_signature: signature,
    })
}

/// Both renders of a pair (planar (3, height, width)) resized to (3, h, w), bilinear with
/// `align_corners = true`: the inputs of [`network_target`], [`pair_flow_loss`] and
/// [`pair_warp_loss`].
fn resize_pair<T: Real>(
    first: &[T],
    second: &[T],
    height: usize,
    width: usize,
    h: usize,
    w: usize,
) -> Result<[Vec<T>; 2], TrainError> {
    let mut small = [vec![T::zero(); 3 * h * w], vec![T::zero(); 3 * h * w]];
    for (img, out) in [first, second].into_iter().zip(small.iter_mut()) {
        resize_bilinear_forward(3, height, width, img, h, w, true, out)?;
    }
    Ok(small)
}

/// The backward of [`resize_pair`]: gradients w.r.t. the resized pair, (3, h, w) each, taken back
/// to the renders' (3, height, width).
fn resize_pair_backward<T: Real>(
    d_small_first: &[T],
    d_small_second: &[T],
    height: usize,
    width: usize,
    h: usize,
    w: usize,
) -> Result<(Vec<T>, Vec<T>), TrainError> {
    let mut d_first = vec![T::zero(); 3 * height * width];
    let mut d_second = vec![T::zero(); 3 * height * width];
    resize_bilinear_backward(3, height, width, h, w, true, d_small_first, &mut d_first)?;
    resize_bilinear_backward(3, height, width, h, w, true, d_small_second, &mut d_second)?;
    Ok((d_first, d_second))
}

/// Mixes the sign of L1 residual `index` (positive or not) into a region signature, so that
/// finite-difference probes can tell when they cross a kink of the loss.
fn fold_sign(signature: u64, positive: bool, index: usize) -> u64 {
    let sign = if positive { 1u64 } else { 2 };
    (signature ^ sign.wrapping_add(index as u64))
        .wrapping_mul(0x1000_0000_01B3)
        .rotate_left(5)
}

/// [`pair_warp_loss`]'s result: the loss and its gradient w.r.t. both full-resolution renders.
#[derive(Clone, Debug)]
pub struct PairWarpLoss<T> {
    /// L_warp (intensity units: mean over M of the L1 over the three colour channels).
    pub loss: T,
    /// ∂L_warp/∂(render of frame k), planar (3, H, W).
    pub d_first: Vec<T>,
    /// ∂L_warp/∂(render of frame k+1), planar (3, H, W).
    pub d_second: Vec<T>,
    /// Identifies the smooth piece of the loss the inputs fall in (the signs of the L1 residuals):
    /// finite-difference probes whose signatures differ straddle a kink.
    pub region_signature: u64,
}

/// The flow loss with an *ideal* flow estimator in place of the network — an ablation outside the
/// paper. A perfect estimator reports the target flow F between two renders exactly when they obey
/// brightness constancy along it, `R_{k+1}(p + F(p)) = R_k(p)`; so instead of comparing a network's
/// flow with F, this compares render k with render k+1 warped back by F:
///
/// L_warp = (1/|M|) Σ_{p∈M} Σ_c |R_k(c, p) − warp(R_{k+1}, F)(c, p)|
///
/// at the target's resolution (both renders resized as in [`pair_flow_loss`], bilinear
/// `align_corners = true`; `warp` is [`nn::warp_forward`]: bilinear, border padding). The target
/// flow is fixed, so the gradient reaches the renders only: frame k directly, frame k+1 through the
/// warp's image gradient. It measures what the flow constraint itself can tell the renders, free of
/// any network's error; it is zero for renders that move exactly as F says (up to occlusion and the
/// warp's interpolation).
pub fn pair_warp_loss<T: Real>(
    first: &[T],
    second: &[T],
    height: usize,
    width: usize,
    target: &FlowTarget<T>,
) -> Result<PairWarpLoss<T>, TrainError> {
    let (h, w) = (target.height, target.width);
    let plane = h * w;
    let small = resize_pair(first, second, height, width, h, w)?;
    let mut warped = vec![T::zero(); 3 * plane];
    nn::warp_forward(1, 3, h, w, &small[1], &target.flow, &mut warped)?;
    let count = target.supervised();
    let mut d_small_first = vec![T::zero(); 3 * plane];
    let mut d_warped = vec![T::zero(); 3 * plane];
    let mut loss = T::zero();
    let mut signature = 0xCBF2_9CE4_8422_2325u64;
    if count > 0 {
        let inv = T::one() / T::of(count as f64);
        for p in (0..plane).filter(|&p| target.mask[p]) {
            for c in 0..3 {
                let i = c * plane + p;
                let r = small[0][i] - warped[i];
                loss = loss + r.abs();
                let g = super::l1_slope(r, inv);
                d_small_first[i] = g;
                d_warped[i] = -g;
                signature = fold_sign(signature, r > T::zero(), i);
            }
        }
        loss = loss * inv;
    }
    let mut d_small_second = vec![T::zero(); 3 * plane];
    nn::warp_backward(
        1,
        3,
        h,
        w,
        &small[1],
        &target.flow,
        &d_warped,
        Some(&mut d_small_second),
        None,
    )?;
    let (d_first, d_second) =
        resize_pair_backward(&d_small_first, &d_small_second, height, width, h, w)?;
    Ok(PairWarpLoss {
        loss,
        d_first,
        d_second,
        region_signature: signature,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uniform_flow_is_scaled_with_the_resolution() {
        let (h, w) = (16, 24);
        let mut flow = vec![8.0f32; h * w];
        flow.extend(vec![-4.0f32; h * w]);
        let t = prepare_target(&flow, None, h, w, 4, 6, 0.5).unwrap();
        assert!(t.flow[..24].iter().all(|&u| (u - 2.0).abs() < 1e-6));
        assert!(t.flow[24..].iter().all(|&v| (v + 1.0).abs() < 1e-6));
        assert_eq!(t.supervised(), 24);
        let still = prepare_target(&vec![0.1f32; 2 * h * w], None, h, w, 4, 6, 0.5).unwrap();
        assert_eq!(still.supervised(), 0);
        assert_eq!(masked_l1(&[1.0; 48], &still, None), 0.0);
    }

    #[test]
    fn warp_loss_is_zero_exactly_for_frames_that_move_as_the_flow_says() {
        // Frame k+1 is frame k shifted one pixel right; the flow says u = 1 everywhere. The last
        // column's correspondent leaves the image (the warp clamps it), so it is marked invalid.
        let (h, w) = (6, 8);
        let plane = h * w;
        let first: Vec<f32> = (0..3 * plane)
            .map(|i| ((i * 37 % 11) as f32) / 10.0)
            .collect();
        let mut second = vec![0.5f32; 3 * plane];
        for c in 0..3 {
            for y in 0..h {
                for x in 1..w {
                    second[c * plane + y * w + x] = first[c * plane + y * w + x - 1];
                }
            }
        }
        let mut flow = vec![1.0f32; plane];
        flow.extend(vec![0.0f32; plane]);
        let valid: Vec<bool> = (0..plane).map(|p| p % w != w - 1).collect();
        let target = prepare_target(&flow, Some(&valid), h, w, h, w, 0.5).unwrap();
        assert_eq!(target.supervised(), h * (w - 1));
        let exact = pair_warp_loss(&first, &second, h, w, &target).unwrap();
        assert_eq!(exact.loss, 0.0);
        // Frame k+1 not moved at all: the constraint is violated and the loss says so.
        let still = pair_warp_loss(&first, &first, h, w, &target).unwrap();
        assert!(still.loss > 0.1, "{}", still.loss);
        assert!(still.d_second.iter().any(|&g| g != 0.0));
    }

    #[test]
    fn invalid_source_pixels_are_not_supervised() {
        let (h, w) = (8, 8);
        let flow = vec![8.0f32; 2 * h * w];
        let valid: Vec<bool> = (0..h * w).map(|i| i % w < 4).collect();
        let t = prepare_target(&flow, Some(&valid), h, w, 2, 2, 0.5).unwrap();
        assert_eq!(t.mask, vec![true, false, true, false]);
        let pred = vec![0.0f32; 8];
        let mut g = vec![9.0f32; 8];
        let l = masked_l1(&pred, &t, Some(&mut g));
        assert!((l - 4.0).abs() < 1e-6, "{l}");
        assert_eq!(g, vec![-0.5, 0.0, -0.5, 0.0, -0.5, 0.0, -0.5, 0.0]);
    }
}
