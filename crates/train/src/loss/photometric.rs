//! The exposure model's image terms on one training frame, generic over f32 / f64 (the trainer runs
//! f32; the gradient checks run f64): the photometric loss — (1 − λ)·L1 + λ·(1 − SSIM) + μ·G, G the
//! L1 of the image gradients' residual (`train::loss::image_gradient`; μ = 0 by default) — of the mean
//! of the frame's S sub-exposure renders against the observed frame, and the event-generation loss
//! between consecutive renders against the events between their times (`train::loss::event`).
//!
//! With the events' modulation (`ExposureEvents::modulation`, `--event-modulation`), render s
//! stands for its slice of the exposure as the event double integral over that slice says:
//! (r_s + ε)·M_s − ε, M_s = mean over the slice of exp(E(t_s → t)) per pixel — what the pixel's
//! events say happened between the renders (a thin stripe that passes between two renders leaves
//! no net count, but a dip in its slice's mean). M_s is data, so its cotangent is M_s times the
//! mean's.
//!
//! Backward: the photometric cotangent of the mean reaches every render scaled by 1/S (unscaled for
//! one render, so the single-render model is the S = 1 case bit for bit); each event pair —
//! consecutive renders, every pair, or every pair on its silent pixels ([`RenderPairs`]) — adds its
//! weighted cotangents to its two renders.

use crate::loss::event::{pair_event_loss_pooled, pair_event_loss_reach, EventPenalty};
use crate::loss::image::{l1, ssim, ImageShape};
use crate::loss::image_gradient::image_gradient_l1;
use nn::Real;
use rayon::prelude::*;

/// The events between consecutive sub-exposure renders of a frame.
#[derive(Clone, Copy, Debug)]
pub struct ExposureEvents<'a, T> {
    /// Per consecutive pair (s, s+1): C·E per pixel (H × W), or `None` where no events file covers
    /// the interval.
    pub expected: &'a [Option<Vec<T>>],
    /// Weight of the event-generation loss.
    pub weight: T,
    /// How a change is held to its events.
    pub penalty: EventPenalty,
    /// ε of log(Y + ε).
    pub log_eps: T,
    /// Which pairs of renders the event term compares.
    pub pairs: RenderPairs,
    /// Side of the pixel blocks the squared penalty pools (`train::loss::event::
    /// pair_event_loss_pooled`); 1: per pixel, with any penalty.
    pub pool: usize,
    /// The spatial reach of a count, in pixels (`train::loss::event::pair_event_loss_reach`; 0:
    /// per pixel). Ignored when `pool` > 1.
    pub reach: usize,
    /// Per render s, the events' modulation M_s of its slice of the exposure (H × W: the mean over
    /// the slice of exp(E(t_s → t))), or `None` (M_s = 1, e.g. a slice no events file covers);
    /// empty: no modulation. The prediction is then the mean of (r_s + ε)·M_s − ε, every channel
    /// modulated by the luma's events (EDI's assumption: the colour's ratios hold over the slice).
    pub modulation: &'a [Option<Vec<T>>],
}

/// Which pairs (s, s′ > s) of an exposure's renders the event term compares, each against the
/// events of [t_s, t_s′) when every consecutive interval between them is covered.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RenderPairs {
    /// Consecutive renders (s′ = s + 1).
    Consecutive,
    /// Every pair, against the summed counts of the consecutive intervals between them.
    All,
    /// Consecutive renders, and every longer pair on the pixels that fired no event between them
    /// (the others free there): a pixel that stays silent keeps its log intensity within one
    /// threshold of a reference level it does not move, so its change over the whole silent span
    /// is bounded as over one interval, not by the sum of the intervals' bounds.
    SilentSpans,
}

/// The weights of the photometric loss's terms.
#[derive(Clone, Copy, Debug)]
pub struct PhotometricWeights<T> {
    /// λ of D-SSIM in (1 − λ)·L1 + λ·(1 − SSIM).
    pub ssim: T,
    /// μ of the image-gradient term G, added to the above (0: not computed).
    pub image_gradient: T,
}

/// The value of the terms and the cotangent of every render.
#[derive(Clone, Debug)]
pub struct ExposureLoss<T> {
    /// (1 − λ)·L1 + λ·(1 − SSIM) + μ·G of the mean render.
    pub photometric: T,
    /// The L1 part.
    pub l1: T,
    /// The SSIM of the mean render.
    pub ssim: T,
    /// The weighted event-generation loss summed over the pairs (0 without events).
    pub events: T,
    /// The mean of the renders, (3, H, W).
    pub prediction: Vec<T>,
    /// dL/d render s, (`channels`, H, W) as asked for (the planes past the third are zero).
    pub d_renders: Vec<Vec<T>>,
}

/// The terms of one frame: `renders` are S planar (3, H, W) linear RGB images (each may carry
/// further planes, ignored), `observed` the frame (3, H, W), `weights` λ and μ; the cotangents are
/// laid out with `channels` ≥ 3 planes (the trainer's renders carry the human probability as a
/// fourth). With `grey` the frame is a grey one (three equal planes) and the photometric terms
/// compare the luminance of the mean render ([`crate::loss::image::luminance3`]); the prediction
/// returned is that luminance. The event terms always use the renders' colour.
pub fn exposure_loss<T: Real>(
    renders: &[&[T]],
    observed: &[T],
    shape: ImageShape,
    weights: PhotometricWeights<T>,
    events: Option<ExposureEvents<'_, T>>,
    channels: usize,
    grey: bool,
) -> ExposureLoss<T> {
    let hw = shape.height * shape.width;
    let modulation = events.map_or(&[][..], |e| e.modulation);
    let modulated: Vec<std::borrow::Cow<'_, [T]>> = renders
        .par_iter()
        .enumerate()
        .map(|(s, r)| match modulation.get(s).and_then(Option::as_ref) {
            Some(m) => modulate(r, m, events.map_or(T::zero(), |e| e.log_eps), hw).into(),
            None => std::borrow::Cow::Borrowed(&r[..3 * hw]),
        })
        .collect();
    let modulated_refs: Vec<&[T]> = modulated.iter().map(|r| &r[..]).collect();
    let mean = mean_image(&modulated_refs, 3 * hw);
    let prediction = if grey {
        crate::loss::image::luminance3(&mean, hw)
    } else {
        mean
    };
    let mut d_l1 = vec![T::zero(); 3 * hw];
    let mut d_ssim = vec![T::zero(); 3 * hw];
    let l1_value = l1(&prediction, observed, Some(&mut d_l1));
    let ssim_value = ssim(&prediction, observed, shape, Some(&mut d_ssim));
    let w = weights.ssim;
    let mut photometric = (T::one() - w) * l1_value + w * (T::one() - ssim_value);
    let mut d_mean = vec![T::zero(); channels.max(3) * hw];
    d_mean
        .par_iter_mut()
        .zip(d_l1.par_iter().zip(&d_ssim))
        .for_each(|(o, (&a, &b))| *o = (T::one() - w) * a - w * b);
    if weights.image_gradient != T::zero() {
        let mut d_gradient = vec![T::zero(); 3 * hw];
        let planes = (3, shape.height, shape.width);
        let g = image_gradient_l1(&prediction, observed, planes, Some(&mut d_gradient));
        photometric = photometric + weights.image_gradient * g;
        add_scaled(&mut d_mean[..3 * hw], &d_gradient, weights.image_gradient);
    }
    if grey {
        d_mean = crate::loss::image::luminance3_backward(&d_mean, hw);
    }
    let mut d_renders = if renders.len() == 1 {
        vec![d_mean]
    } else {
        let scale = T::one() / T::of(renders.len() as f64);
        let d: Vec<T> = d_mean.par_iter().map(|&v| v * scale).collect();
        (0..renders.len())
            .into_par_iter()
            .map(|_| d.clone())
            .collect()
    };
    // d(r·M)/dr = M on the three colour planes (one task per render).
    d_renders.par_iter_mut().enumerate().for_each(|(s, d)| {
        if let Some(m) = modulation.get(s).and_then(Option::as_ref) {
            for plane in d[..3 * hw].chunks_mut(hw) {
                for (v, &g) in plane.iter_mut().zip(m) {
                    *v = *v * g;
                }
            }
        }
    });
    let mut event_value = T::zero();
    if let Some(events) = events {
        let last = |s: usize| match events.pairs {
            RenderPairs::Consecutive => s + 1,
            RenderPairs::All | RenderPairs::SilentSpans => renders.len() - 1,
        };
        let pairs: Vec<(usize, usize)> = (0..renders.len().saturating_sub(1))
            .flat_map(|s| (s + 1..=last(s)).map(move |s2| (s, s2)))
            .collect();
        // The pairs' terms in parallel, accumulated in pair order (the bits of a serial loop).
        let terms: Vec<_> = pairs
            .par_iter()
            .map(|&(s, s2)| {
                let silent = events.pairs == RenderPairs::SilentSpans;
                let expected = span_counts(events.expected, s, s2, silent)?;
                let el = if events.pool > 1 {
                    pair_event_loss_pooled(
                        renders[s],
                        renders[s2],
                        &expected,
                        events.log_eps,
                        shape.width,
                        events.pool,
                    )
                } else {
                    pair_event_loss_reach(
                        renders[s],
                        renders[s2],
                        &expected,
                        events.log_eps,
                        events.penalty,
                        (shape.width, events.reach),
                    )
                };
                Some((s, s2, el))
            })
            .collect();
        for (s, s2, el) in terms.into_iter().flatten() {
            event_value = event_value + events.weight * el.loss;
            add_scaled(&mut d_renders[s], &el.d_first, events.weight);
            add_scaled(&mut d_renders[s2], &el.d_second, events.weight);
        }
    }
    ExposureLoss {
        photometric,
        l1: l1_value,
        ssim: ssim_value,
        events: event_value,
        prediction,
        d_renders,
    }
}

/// (r + ε)·M − ε on the three colour planes of the render `r` ((≥ 3, H, W)), `m` per pixel.
fn modulate<T: Real>(r: &[T], m: &[T], log_eps: T, hw: usize) -> Vec<T> {
    let mut out = Vec::with_capacity(3 * hw);
    for plane in r[..3 * hw].chunks(hw) {
        out.extend(
            plane
                .iter()
                .zip(m)
                .map(|(&v, &g)| (v + log_eps) * g - log_eps),
        );
    }
    out
}

/// The counts of the pair of sub-exposure times (`s`, `s2` > `s`), borrowed for one interval, or
/// `None` if one of the consecutive intervals between them is uncovered: their C·E summed in order,
/// or for `silent` ([`RenderPairs::SilentSpans`]) 0 where every interval is 0 (the pixel fired
/// nothing) and NaN (free) elsewhere.
fn span_counts<T: Real>(
    consecutive: &[Option<Vec<T>>],
    s: usize,
    s2: usize,
    silent: bool,
) -> Option<std::borrow::Cow<'_, [T]>> {
    let parts = consecutive.get(s..s2)?;
    if let [Some(only)] = parts {
        return Some(std::borrow::Cow::Borrowed(only));
    }
    let fired = |y: T| {
        if y != T::zero() {
            T::of(f64::NAN)
        } else {
            T::zero()
        }
    };
    let first = parts.first()?.as_ref()?;
    let mut span: Vec<T> = if silent {
        first.iter().map(|&y| fired(y)).collect()
    } else {
        first.clone()
    };
    for part in &parts[1..] {
        for (x, &y) in span.iter_mut().zip(part.as_ref()?) {
            *x = if silent { *x + fired(y) } else { *x + y };
        }
    }
    Some(std::borrow::Cow::Owned(span))
}

/// The mean of the first `len` values of `images` (the image itself for one), summed in order.
pub fn mean_image<T: Real>(images: &[&[T]], len: usize) -> Vec<T> {
    if let [image] = images {
        return image[..len].to_vec();
    }
    // Pixel by pixel, the images summed in order: parallel over pixels, the bits of a serial loop.
    let scale = T::one() / T::of(images.len() as f64);
    (0..len)
        .into_par_iter()
        .map(|i| images.iter().fold(T::zero(), |x, image| x + image[i]) * scale)
        .collect()
}

/// `dst += weight · src`, element by element (a loss's weighted cotangent into an image's).
pub fn add_scaled<T: Real>(dst: &mut [T], src: &[T], weight: T) {
    dst.par_iter_mut()
        .zip(src)
        .for_each(|(o, &g)| *o = *o + weight * g);
}

#[cfg(test)]
mod tests {
    use super::span_counts;

    fn silent_span(
        c: &[Option<Vec<f64>>],
        s: usize,
        s2: usize,
    ) -> Option<std::borrow::Cow<'_, [f64]>> {
        span_counts(c, s, s2, true)
    }

    /// A longer span holds a pixel to no change only where every interval of it is silent; a
    /// pixel that fired anywhere in it, or was free (NaN) in one interval, is free; one uncovered
    /// interval leaves the whole span out; a consecutive pair keeps its own counts.
    #[test]
    fn a_silent_span_holds_only_the_pixels_silent_throughout() {
        let nan = f64::NAN;
        let covered = vec![
            Some(vec![0.0, 0.2, 0.0, nan]),
            Some(vec![0.0, 0.0, -0.2, 0.0]),
            Some(vec![0.0, 0.0, 0.0, 0.0]),
        ];
        let span = silent_span(&covered, 0, 3).expect("covered");
        assert_eq!(span[0], 0.0);
        assert!(span[1..].iter().all(|v| v.is_nan()), "{span:?}");
        let later = silent_span(&covered, 1, 3).expect("covered");
        assert_eq!((later[0], later[1], later[3]), (0.0, 0.0, 0.0));
        assert!(later[2].is_nan());
        let own = silent_span(&covered, 0, 1).expect("covered");
        assert_eq!(own[1], 0.2);
        let mut gap = covered.clone();
        gap[1] = None;
        assert!(silent_span(&gap, 0, 3).is_none());
        assert!(silent_span(&gap, 2, 3).is_some());
    }
}
