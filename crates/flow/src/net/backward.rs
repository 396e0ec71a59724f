//! The backward pass of the SPyNet pyramid: the exact adjoint of [`SpyNet::forward`], from
//! `∂L/∂flow` to both images and (optionally) the weights.

use super::*;

/// Adjoint of [`upsample_flow`].
fn upsample_flow_backward<T: Real>(
    grad: &[T],
    (h, w): (usize, usize),
    (ht, wt): (usize, usize),
) -> Result<Vec<T>, FlowError> {
    let (h2, w2) = (2 * h, 2 * w);
    let mut g_up = vec![T::zero(); 2 * h2 * w2];
    let two = T::of(2.0);
    for c in 0..2 {
        for y in 0..ht {
            let sy = y.min(h2 - 1);
            for x in 0..wt {
                let i = (c * h2 + sy) * w2 + x.min(w2 - 1);
                g_up[i] = g_up[i] + two * grad[(c * ht + y) * wt + x];
            }
        }
    }
    let mut g = vec![T::zero(); 2 * h * w];
    resize_bilinear_backward(2, h, w, h2, w2, true, &g_up, &mut g)?;
    Ok(g)
}

impl<T: Real> SpyNet<T> {
    /// Backward pass of a full [`SpyNet::forward`]: returns `(∂L/∂img1, ∂L/∂img2)` (each `(3, H, W)`)
    /// given `grad_flow = ∂L/∂flow` (`(2, H, W)`). If `weight_grads` is given (same structure as the
    /// network, e.g. from [`SpyNet::zeros_like`]), the weight and bias gradients are **accumulated**
    /// into it.
    pub fn backward(
        &self,
        tape: &Tape<T>,
        grad_flow: &[T],
        weight_grads: Option<&mut SpyNet<T>>,
    ) -> Result<(Vec<T>, Vec<T>), FlowError> {
        if tape.levels.len() != tape.level_sizes.len() {
            return Err(FlowError::Size(
                "backward needs the tape of a full forward pass".into(),
            ));
        }
        let (h, w) = tape.size;
        let (hp, wp) = tape.work_size;
        if grad_flow.len() != 2 * h * w {
            return Err(FlowError::Size(format!(
                "flow gradient has {} values, expected 2x{h}x{w}",
                grad_flow.len()
            )));
        }
        let g_work = if (hp, wp) != (h, w) {
            let (su, sv) = (T::of(w as f64 / wp as f64), T::of(h as f64 / hp as f64));
            let mut g = grad_flow.to_vec();
            let (u, v) = g.split_at_mut(h * w);
            u.iter_mut().for_each(|x| *x = *x * su);
            v.iter_mut().for_each(|x| *x = *x * sv);
            let mut gw = vec![T::zero(); 2 * hp * wp];
            resize_bilinear_backward(2, hp, wp, h, w, false, &g, &mut gw)?;
            gw
        } else {
            grad_flow.to_vec()
        };
        let (mut g1, mut g2) = self
            .backward_impl(tape, g_work, weight_grads, true, 0, None)?
            .ok_or_else(|| FlowError::Size("internal: no input gradient".into()))?;
        // Pyramids: level l−1 = pool(level l).
        let sizes = &tape.level_sizes;
        for l in 1..sizes.len() {
            let (lh, lw) = sizes[l];
            for g in [&mut g1, &mut g2] {
                let mut gi = vec![T::zero(); 3 * lh * lw];
                avg_pool2x2_backward(3, lh, lw, &g[l - 1], &mut gi)?;
                add_into(&mut g[l], &gi);
            }
        }
        let mut out = Vec::with_capacity(2);
        for g in [g1, g2] {
            let mut g = g.into_iter().next_back().unwrap_or_default();
            for (c, plane) in g.chunks_exact_mut(hp * wp).enumerate() {
                let inv_std = T::of(1.0 / IMAGENET_STD[c]);
                plane.iter_mut().for_each(|v| *v = *v * inv_std);
            }
            if (hp, wp) != (h, w) {
                let mut gi = vec![T::zero(); 3 * h * w];
                resize_bilinear_backward(3, h, w, hp, wp, false, &g, &mut gi)?;
                g = gi;
            }
            out.push(g);
        }
        let g2 = out.pop().unwrap_or_default();
        let g1 = out.pop().unwrap_or_default();
        Ok((g1, g2))
    }

    /// Weight gradients of the last level of a partial pass ([`SpyNet::forward_to_level`]) given
    /// `∂L/∂flow_l` (`(2, h_l, w_l)`), **accumulated** into `weight_grads`. Lower levels are treated
    /// as frozen (no gradient flows into them), as in SPyNet's coarse-to-fine training.
    pub fn backward_last_level_weights(
        &self,
        tape: &Tape<T>,
        grad_flow: &[T],
        weight_grads: &mut SpyNet<T>,
    ) -> Result<(), FlowError> {
        let last = tape.levels.len().saturating_sub(1);
        let (lh, lw) = tape.level_sizes[last];
        if grad_flow.len() != 2 * lh * lw {
            return Err(FlowError::Size(format!(
                "level {last} flow gradient has {} values, expected 2x{lh}x{lw}",
                grad_flow.len()
            )));
        }
        self.backward_impl(
            tape,
            grad_flow.to_vec(),
            Some(weight_grads),
            false,
            last,
            None,
        )?;
        Ok(())
    }

    /// Weight gradients of a multi-scale loss on the per-level outputs of a pass (full or partial):
    /// `level_grads[l] = ∂L/∂flow_l` (`(2, h_l, w_l)`, see [`Tape::level_flow`]) for every level
    /// `l` of the tape, gradients flowing through the whole pyramid (warps and upsampling included),
    /// **accumulated** into `weight_grads`. End-to-end training of all levels at once, as later
    /// pyramid networks (PWC-Net, LiteFlowNet) are trained; an empty level gradient counts as zero.
    pub fn backward_multiscale_weights(
        &self,
        tape: &Tape<T>,
        level_grads: &[Vec<T>],
        weight_grads: &mut SpyNet<T>,
    ) -> Result<(), FlowError> {
        let run = tape.levels.len();
        if level_grads.len() != run {
            return Err(FlowError::Size(format!(
                "{} level gradients for a pass of {run} levels",
                level_grads.len()
            )));
        }
        for (l, g) in level_grads.iter().enumerate() {
            let (lh, lw) = tape.level_sizes[l];
            if !g.is_empty() && g.len() != 2 * lh * lw {
                return Err(FlowError::Size(format!(
                    "level {l} flow gradient has {} values, expected 2x{lh}x{lw}",
                    g.len()
                )));
            }
        }
        let (lh, lw) = tape.level_sizes[run.saturating_sub(1)];
        let mut top = vec![T::zero(); 2 * lh * lw];
        if let Some(g) = level_grads.last() {
            add_into(&mut top, g);
        }
        self.backward_impl(tape, top, Some(weight_grads), false, 0, Some(level_grads))?;
        Ok(())
    }

    /// Backward through levels `tape.levels.len()−1` down to `min_level`. Returns the per-level
    /// gradients w.r.t. the normalised pyramids when `inputs` is set. `extra[l]` (levels below the
    /// top; the top level's is already in `gflow`) is added to the gradient of level `l`'s output.
    #[allow(clippy::type_complexity)]
    fn backward_impl(
        &self,
        tape: &Tape<T>,
        mut gflow: Vec<T>,
        mut weight_grads: Option<&mut SpyNet<T>>,
        inputs: bool,
        min_level: usize,
        extra: Option<&[Vec<T>]>,
    ) -> Result<Option<(Vec<Vec<T>>, Vec<Vec<T>>)>, FlowError> {
        if let Some(g) = &weight_grads {
            if g.num_levels() != self.num_levels() {
                return Err(FlowError::Size(
                    "weight-gradient container has a different number of levels".into(),
                ));
            }
        }
        let sizes = &tape.level_sizes;
        let mut gp1: Vec<Vec<T>> = sizes
            .iter()
            .map(|&(a, b)| vec![T::zero(); 3 * a * b])
            .collect();
        let mut gp2 = gp1.clone();
        for l in (min_level..tape.levels.len()).rev() {
            let (lh, lw) = sizes[l];
            let hw = lh * lw;
            let lt = &tape.levels[l];
            if l + 1 < tape.levels.len() {
                if let Some(e) = extra.and_then(|e| e.get(l)).filter(|e| !e.is_empty()) {
                    add_into(&mut gflow, e);
                }
            }
            let mut g_up = gflow.clone();
            let mut g = gflow;
            for i in (0..5).rev() {
                let s = conv_shape(i, lh, lw);
                let conv = &self.levels[l][i];
                if let Some(wg) = weight_grads.as_deref_mut() {
                    let gc = &mut wg.levels[l][i];
                    conv2d_backward_weight(s, &lt.acts[i], &g, &mut gc.weight, Some(&mut gc.bias))?;
                }
                if i == 0 && (!inputs && l == min_level) {
                    g = Vec::new();
                    break;
                }
                let mut gin = vec![T::zero(); s.input_len()];
                conv2d_backward_input(s, &g, &conv.weight, &mut gin)?;
                if i > 0 {
                    for (gv, &a) in gin.iter_mut().zip(&lt.acts[i]) {
                        if a <= T::zero() {
                            *gv = T::zero();
                        }
                    }
                }
                g = gin;
            }
            if l == min_level && !inputs {
                break;
            }
            // g = ∂L/∂[img1_l, warp(img2_l, U_l), U_l].
            add_into(&mut gp1[l], &g[..3 * hw]);
            let mut gi2 = vec![T::zero(); 3 * hw];
            let mut gfw = vec![T::zero(); 2 * hw];
            warp_backward(
                1,
                3,
                lh,
                lw,
                &tape.pyr2[l],
                &lt.up,
                &g[3 * hw..6 * hw],
                Some(&mut gi2),
                Some(&mut gfw),
            )?;
            add_into(&mut gp2[l], &gi2);
            add_into(&mut g_up, &gfw);
            add_into(&mut g_up, &g[6 * hw..]);
            gflow = if l > 0 {
                upsample_flow_backward(&g_up, sizes[l - 1], sizes[l])?
            } else {
                Vec::new()
            };
        }
        Ok(if inputs { Some((gp1, gp2)) } else { None })
    }
}
