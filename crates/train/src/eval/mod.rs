//! Evaluation (DESIGN.md §6): PSNR, SSIM and LPIPS of test renders against the sharp references over
//! the full frame and inside the human bounding box (from the reference mask), mask IoU of the rendered
//! human probability thresholded at 0.5, and side-by-side strips for a person to look at.
//!
//! Works on images already rendered, so it is independent of how the model produced them. SSIM is the
//! project's one SSIM (`loss::image::ssim`: 11×11 Gaussian window, σ 1.5, zero padding, data range 1).
//! LPIPS is AlexNet v0.1 on the sRGB-encoded images (`loss::perceptual`: the images here are linear, the
//! network was trained on sRGB). The network needs at least `lpips::MIN_SIZE` (31) pixels per side:
//! a human box smaller than that is grown symmetrically about its centre (kept inside the frame) to
//! that size for LPIPS only — so a small box's LPIPS also sees a little of the scene around it — and
//! a frame smaller than that gets NaN.

use crate::camera_alignment::{align_camera, AlignedCamera, AlignmentSettings, ExposurePaths};
use crate::loss::image::{crop, ssim, ImageShape};
use crate::loss::perceptual::{lpips_distance, reference_features};
use crate::TrainError;
use lpips::Lpips;

/// One evaluated frame: planar (3, H, W) images in linear [0, 1] and (H, W) masks.
#[derive(Clone, Copy, Debug)]
pub struct EvalFrame<'a> {
    /// Width (pixels).
    pub width: usize,
    /// Height (pixels).
    pub height: usize,
    /// The model's render.
    pub render: &'a [f32],
    /// The sharp reference.
    pub reference: &'a [f32],
    /// The blurred input frame (for the blurred-input baseline figures).
    pub blurred: &'a [f32],
    /// Reference human mask (true = human); `None` when the frame has none (real data).
    pub mask: Option<&'a [bool]>,
    /// Rendered human probability per pixel, in [0, 1].
    pub human_probability: &'a [f32],
}

/// Per-frame figures.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct FrameMetrics {
    /// PSNR (dB), full frame.
    pub psnr_full: f64,
    /// SSIM, full frame.
    pub ssim_full: f64,
    /// PSNR (dB) inside the human bounding box (NaN if the mask is empty).
    pub psnr_human_box: f64,
    /// SSIM inside the human bounding box (NaN if the mask is empty).
    pub ssim_human_box: f64,
    /// IoU of rendered human probability > 0.5 against the mask (NaN without a mask).
    pub mask_iou: f64,
    /// PSNR (dB) of the blurred input against the reference, full frame.
    pub blurred_psnr_full: f64,
    /// PSNR (dB) of the blurred input against the reference, human box.
    pub blurred_psnr_human_box: f64,
    /// SSIM of the blurred input against the reference, full frame.
    pub blurred_ssim_full: f64,
    /// SSIM of the blurred input against the reference, human box.
    pub blurred_ssim_human_box: f64,
    /// LPIPS (AlexNet, v0.1; lower is closer), full frame (NaN without the network or for frames
    /// below its minimum size).
    pub lpips_full: f64,
    /// LPIPS inside the human bounding box, grown to the network's minimum size if smaller (NaN if
    /// the mask is empty).
    pub lpips_human_box: f64,
    /// LPIPS of the blurred input against the reference, full frame.
    pub blurred_lpips_full: f64,
    /// LPIPS of the blurred input against the reference, human box.
    pub blurred_lpips_human_box: f64,
    /// PSNR (dB) outside the human bounding box: the scene without the person (NaN if the mask
    /// is empty or the box covers the frame).
    pub psnr_outside_box: f64,
    /// PSNR (dB) of the blurred input outside the human bounding box.
    pub blurred_psnr_outside_box: f64,
}

/// Peak signal-to-noise ratio (dB) for data range 1: −10·log10(MSE). Identical images give +∞.
pub fn psnr(pred: &[f32], target: &[f32]) -> f64 {
    let n = pred.len().max(1) as f64;
    let mse = pred
        .iter()
        .zip(target)
        .map(|(&p, &t)| (f64::from(p) - f64::from(t)).powi(2))
        .sum::<f64>()
        / n;
    -10.0 * mse.log10()
}

/// Intersection over union of two binary masks given as values thresholded at 0.5. Both empty gives 1.
pub fn mask_iou(pred: &[f32], target: &[f32]) -> f64 {
    let (mut inter, mut union) = (0usize, 0usize);
    for (&p, &t) in pred.iter().zip(target) {
        let (p, t) = (p > 0.5, t > 0.5);
        inter += usize::from(p && t);
        union += usize::from(p || t);
    }
    if union == 0 {
        1.0
    } else {
        inter as f64 / union as f64
    }
}

/// Tight bounding box `(x0, y0, x1, y1)` (exclusive ends) of the true pixels of an (H, W) mask.
pub fn mask_bbox(
    mask: &[bool],
    width: usize,
    height: usize,
) -> Option<(usize, usize, usize, usize)> {
    let mut bbox: Option<(usize, usize, usize, usize)> = None;
    for y in 0..height {
        for x in 0..width {
            if mask[y * width + x] {
                bbox = Some(match bbox {
                    None => (x, y, x + 1, y + 1),
                    Some((x0, y0, x1, y1)) => (x0.min(x), y0.min(y), x1.max(x + 1), y1.max(y + 1)),
                });
            }
        }
    }
    bbox
}

/// The box `(x0, y0, x1, y1)` (exclusive ends) grown symmetrically about its centre to at least
/// `min` pixels per side, shifted to stay inside a `width` × `height` frame; `None` if the frame
/// itself is smaller than `min`.
pub fn grown_box(
    (x0, y0, x1, y1): (usize, usize, usize, usize),
    width: usize,
    height: usize,
    min: usize,
) -> Option<(usize, usize, usize, usize)> {
    let grow = |lo: usize, hi: usize, n: usize| -> Option<(usize, usize)> {
        if n < min {
            return None;
        }
        if hi - lo >= min {
            return Some((lo, hi));
        }
        let start = lo.saturating_sub((min - (hi - lo)) / 2).min(n - min);
        Some((start, start + min))
    };
    let (x0, x1) = grow(x0, x1, width)?;
    let (y0, y1) = grow(y0, y1, height)?;
    Some((x0, y0, x1, y1))
}

/// LPIPS of `render` and `blurred` against `reference` (linear planar (3, H, W)), or NaN for a size
/// the network does not take.
fn lpips_pair(
    net: &Lpips<f32>,
    render: &[f32],
    blurred: &[f32],
    reference: &[f32],
    height: usize,
    width: usize,
) -> Result<(f64, f64), TrainError> {
    if lpips::tap_sizes(height, width).is_none() {
        return Ok((f64::NAN, f64::NAN));
    }
    let features = reference_features(net, reference, height, width)?;
    let of = |image: &[f32]| -> Result<f64, TrainError> {
        Ok(f64::from(lpips_distance(
            net, image, height, width, &features,
        )?))
    };
    Ok((of(render)?, of(blurred)?))
}

/// Figures of one frame; the LPIPS figures are NaN without `lpips`.
pub fn evaluate_frame(
    f: &EvalFrame<'_>,
    lpips: Option<&Lpips<f32>>,
) -> Result<FrameMetrics, TrainError> {
    let shape = ImageShape {
        channels: 3,
        height: f.height,
        width: f.width,
    };
    let mut out = FrameMetrics {
        psnr_full: psnr(f.render, f.reference),
        ssim_full: f64::from(ssim(f.render, f.reference, shape, None)),
        psnr_human_box: f64::NAN,
        ssim_human_box: f64::NAN,
        mask_iou: f.mask.map_or(f64::NAN, |mask| {
            let m: Vec<f32> = mask.iter().map(|&b| if b { 1.0 } else { 0.0 }).collect();
            mask_iou(f.human_probability, &m)
        }),
        blurred_psnr_full: psnr(f.blurred, f.reference),
        blurred_psnr_human_box: f64::NAN,
        blurred_ssim_full: f64::from(ssim(f.blurred, f.reference, shape, None)),
        blurred_ssim_human_box: f64::NAN,
        lpips_full: f64::NAN,
        lpips_human_box: f64::NAN,
        blurred_lpips_full: f64::NAN,
        blurred_lpips_human_box: f64::NAN,
        psnr_outside_box: f64::NAN,
        blurred_psnr_outside_box: f64::NAN,
    };
    if let Some(net) = lpips {
        (out.lpips_full, out.blurred_lpips_full) =
            lpips_pair(net, f.render, f.blurred, f.reference, f.height, f.width)?;
    }
    let Some(bbox) = f.mask.and_then(|mask| mask_bbox(mask, f.width, f.height)) else {
        return Ok(out);
    };
    let (x0, y0, x1, y1) = bbox;
    let inside = box_figures(f, bbox, lpips)?;
    out.psnr_human_box = inside.psnr;
    out.ssim_human_box = inside.ssim;
    out.blurred_psnr_human_box = inside.blurred_psnr;
    out.blurred_ssim_human_box = inside.blurred_ssim;
    out.lpips_human_box = inside.lpips;
    out.blurred_lpips_human_box = inside.blurred_lpips;
    let outside = |img: &[f32]| -> Vec<f32> {
        let plane = f.width * f.height;
        (0..3 * plane)
            .filter(|&i| {
                let (x, y) = (i % plane % f.width, i % plane / f.width);
                !(x0..x1).contains(&x) || !(y0..y1).contains(&y)
            })
            .map(|i| img[i])
            .collect()
    };
    let reference_outside = outside(f.reference);
    if !reference_outside.is_empty() {
        out.psnr_outside_box = psnr(&outside(f.render), &reference_outside);
        out.blurred_psnr_outside_box = psnr(&outside(f.blurred), &reference_outside);
    }
    Ok(out)
}

/// The render's and the blurred input's figures inside one box.
struct BoxFigures {
    psnr: f64,
    ssim: f64,
    lpips: f64,
    blurred_psnr: f64,
    blurred_ssim: f64,
    blurred_lpips: f64,
}

/// PSNR (dB) of planar (3, H, W) images `a` and `b` of `width` × `height` inside `bbox` = (x0,
/// y0, x1, y1), as the box figures score it.
pub fn box_psnr(
    a: &[f32],
    b: &[f32],
    width: usize,
    height: usize,
    (x0, y0, x1, y1): (usize, usize, usize, usize),
) -> f64 {
    let shape = ImageShape {
        channels: 3,
        height,
        width,
    };
    psnr(
        &crop(a, shape, x0, y0, x1, y1),
        &crop(b, shape, x0, y0, x1, y1),
    )
}

/// [`BoxFigures`] of `f` inside `bbox` `(x0, y0, x1, y1)` (exclusive ends); LPIPS (NaN without
/// `lpips`) in the box grown to the network's minimum size.
fn box_figures(
    f: &EvalFrame<'_>,
    bbox: (usize, usize, usize, usize),
    lpips: Option<&Lpips<f32>>,
) -> Result<BoxFigures, TrainError> {
    let shape = ImageShape {
        channels: 3,
        height: f.height,
        width: f.width,
    };
    let (x0, y0, x1, y1) = bbox;
    let crop_of = |img: &[f32]| crop(img, shape, x0, y0, x1, y1);
    let box_shape = ImageShape {
        channels: 3,
        height: y1 - y0,
        width: x1 - x0,
    };
    let (r, g, b) = (crop_of(f.render), crop_of(f.reference), crop_of(f.blurred));
    let mut out = BoxFigures {
        psnr: psnr(&r, &g),
        ssim: f64::from(ssim(&r, &g, box_shape, None)),
        lpips: f64::NAN,
        blurred_psnr: psnr(&b, &g),
        blurred_ssim: f64::from(ssim(&b, &g, box_shape, None)),
        blurred_lpips: f64::NAN,
    };
    if let (Some(net), Some((x0, y0, x1, y1))) =
        (lpips, grown_box(bbox, f.width, f.height, lpips::MIN_SIZE))
    {
        let crop_of = |img: &[f32]| crop(img, shape, x0, y0, x1, y1);
        (out.lpips, out.blurred_lpips) = lpips_pair(
            net,
            &crop_of(f.render),
            &crop_of(f.blurred),
            &crop_of(f.reference),
            y1 - y0,
            x1 - x0,
        )?;
    }
    Ok(out)
}

/// One person's figures in a frame of several people: its own mask (from the frame's person ids)
/// against its own rendered probability, and the render inside its own box.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct PersonMetrics {
    /// IoU of the person's rendered probability > 0.5 against its mask (NaN without person ids).
    pub mask_iou: f64,
    /// PSNR (dB) inside the person's box (NaN when it is not seen).
    pub psnr_box: f64,
    /// SSIM inside the person's box.
    pub ssim_box: f64,
    /// LPIPS inside the person's box (grown to the network's minimum size).
    pub lpips_box: f64,
    /// PSNR (dB) of the blurred input inside the box.
    pub blurred_psnr_box: f64,
    /// SSIM of the blurred input inside the box.
    pub blurred_ssim_box: f64,
    /// LPIPS of the blurred input inside the box.
    pub blurred_lpips_box: f64,
}

/// [`PersonMetrics`] of one person: `f.mask` is its own mask and `f.human_probability` its own
/// rendered probability.
pub fn evaluate_person(
    f: &EvalFrame<'_>,
    lpips: Option<&Lpips<f32>>,
) -> Result<PersonMetrics, TrainError> {
    let mut out = PersonMetrics {
        mask_iou: f.mask.map_or(f64::NAN, |mask| {
            let m: Vec<f32> = mask.iter().map(|&b| if b { 1.0 } else { 0.0 }).collect();
            mask_iou(f.human_probability, &m)
        }),
        psnr_box: f64::NAN,
        ssim_box: f64::NAN,
        lpips_box: f64::NAN,
        blurred_psnr_box: f64::NAN,
        blurred_ssim_box: f64::NAN,
        blurred_lpips_box: f64::NAN,
    };
    if let Some(bbox) = f.mask.and_then(|mask| mask_bbox(mask, f.width, f.height)) {
        let inside = box_figures(f, bbox, lpips)?;
        out.psnr_box = inside.psnr;
        out.ssim_box = inside.ssim;
        out.lpips_box = inside.lpips;
        out.blurred_psnr_box = inside.blurred_psnr;
        out.blurred_ssim_box = inside.blurred_ssim;
        out.blurred_lpips_box = inside.blurred_lpips;
    }
    Ok(out)
}

/// The mean of `get` over `frames`, skipping non-finite values (NaN when none is finite).
fn finite_mean<M>(frames: &[M], get: impl Fn(&M) -> f64) -> f64 {
    let vals: Vec<f64> = frames.iter().map(get).filter(|v| v.is_finite()).collect();
    if vals.is_empty() {
        f64::NAN
    } else {
        vals.iter().sum::<f64>() / vals.len() as f64
    }
}

/// Mean of one person's per-frame figures (NaN entries skipped per field).
pub fn mean_person_metrics(frames: &[PersonMetrics]) -> PersonMetrics {
    let mean = |get: fn(&PersonMetrics) -> f64| finite_mean(frames, get);
    PersonMetrics {
        mask_iou: mean(|m| m.mask_iou),
        psnr_box: mean(|m| m.psnr_box),
        ssim_box: mean(|m| m.ssim_box),
        lpips_box: mean(|m| m.lpips_box),
        blurred_psnr_box: mean(|m| m.blurred_psnr_box),
        blurred_ssim_box: mean(|m| m.blurred_ssim_box),
        blurred_lpips_box: mean(|m| m.blurred_lpips_box),
    }
}

/// Mean of the per-frame figures (NaN entries, from frames without a human, are skipped per field).
pub fn mean_metrics(frames: &[FrameMetrics]) -> FrameMetrics {
    let mean = |get: fn(&FrameMetrics) -> f64| finite_mean(frames, get);
    FrameMetrics {
        psnr_full: mean(|m| m.psnr_full),
        ssim_full: mean(|m| m.ssim_full),
        psnr_human_box: mean(|m| m.psnr_human_box),
        ssim_human_box: mean(|m| m.ssim_human_box),
        mask_iou: mean(|m| m.mask_iou),
        blurred_psnr_full: mean(|m| m.blurred_psnr_full),
        blurred_psnr_human_box: mean(|m| m.blurred_psnr_human_box),
        blurred_ssim_full: mean(|m| m.blurred_ssim_full),
        blurred_ssim_human_box: mean(|m| m.blurred_ssim_human_box),
        lpips_full: mean(|m| m.lpips_full),
        lpips_human_box: mean(|m| m.lpips_human_box),
        blurred_lpips_full: mean(|m| m.blurred_lpips_full),
        blurred_lpips_human_box: mean(|m| m.blurred_lpips_human_box),
        psnr_outside_box: mean(|m| m.psnr_outside_box),
        blurred_psnr_outside_box: mean(|m| m.blurred_psnr_outside_box),
    }
}

/// A horizontal strip `blurred | render | reference | human probability (grey)` as planar (3, H, 4W),
/// with a 2-pixel white separator between panels (so the strip is 4W + 6 wide).
pub fn comparison_strip(f: &EvalFrame<'_>) -> (usize, usize, Vec<f32>) {
    comparison_strip_of_people(f, &[])
}

/// The colour each person's rendered probability is drawn in ([`comparison_strip_of_people`]),
/// by person (cycled past four): orange, sky blue, green, magenta (linear RGB).
pub const PERSON_COLOURS: [[f32; 3]; 4] = [
    [1.0, 0.35, 0.05],
    [0.1, 0.55, 1.0],
    [0.2, 0.9, 0.2],
    [0.9, 0.15, 0.8],
];

/// [`comparison_strip`] whose last panel, with several people, shows each person's rendered
/// probability (`people`, (H, W) each) in its own colour ([`PERSON_COLOURS`]); with `people`
/// empty the human probability in grey.
pub fn comparison_strip_of_people(
    f: &EvalFrame<'_>,
    people: &[Vec<f32>],
) -> (usize, usize, Vec<f32>) {
    let (w, h) = (f.width, f.height);
    let semantic = |c: usize, y: usize, x: usize| -> f32 {
        if people.is_empty() {
            return f.human_probability[y * w + x];
        }
        people
            .iter()
            .enumerate()
            .map(|(j, p)| PERSON_COLOURS[j % PERSON_COLOURS.len()][c] * p[y * w + x])
            .sum()
    };
    let sep = 2;
    let out_w = 4 * w + 3 * sep;
    let mut out = vec![1.0f32; 3 * h * out_w];
    let panels: [&dyn Fn(usize, usize, usize) -> f32; 4] = [
        &|c, y, x| f.blurred[(c * h + y) * w + x],
        &|c, y, x| f.render[(c * h + y) * w + x],
        &|c, y, x| f.reference[(c * h + y) * w + x],
        &semantic,
    ];
    for (k, panel) in panels.iter().enumerate() {
        let x_off = k * (w + sep);
        for c in 0..3 {
            for y in 0..h {
                for x in 0..w {
                    out[(c * h + y) * out_w + x_off + x] = panel(c, y, x).clamp(0.0, 1.0);
                }
            }
        }
    }
    (out_w, h, out)
}

/// One evaluated frame of a dataset.
#[derive(Clone, Debug)]
pub struct EvaluatedFrame {
    /// Frame number.
    pub index: u32,
    /// Its camera's test-time alignment, when asked for ([`crate::camera_alignment`]).
    pub alignment: Option<AlignedCamera>,
    /// Its figures.
    pub metrics: FrameMetrics,
    /// With several people, each person's own figures (the model's person order; empty with one).
    pub people: Vec<PersonMetrics>,
    /// The comparison strip (width, height, planar RGB).
    pub strip: (usize, usize, Vec<f32>),
}

/// Renders every frame of `split` with the model and scores it against the sharp reference (or, for
/// data without one, against the observed frame — the figures then measure fidelity to the input);
/// LPIPS with `lpips` (NaN without).
/// Unseen frames use the latent of the nearest training frame and, with pose correction, the
/// correction interpolated from their neighbouring training frames ([`crate::model::Model::corrected_params`]),
/// and with camera correction the camera's ([`crate::model::Model::render_frame`]); with
/// `alignment`, each frame's camera is then aligned to its observed frame
/// ([`crate::camera_alignment`]).
pub fn evaluate_split(
    model: &crate::model::Model,
    cast: &crate::pose::body::Cast<'_>,
    data: &crate::data::Dataset,
    (split, alignment): (scene::Split, Option<&AlignmentSettings>),
    lpips: Option<&Lpips<f32>>,
) -> Result<Vec<EvaluatedFrame>, crate::TrainError> {
    let (w, h) = (data.camera.width as usize, data.camera.height as usize);
    let grey = data.scene.images.is_grey();
    let paths = alignment
        .filter(|a| a.steps > 0)
        .and_then(|a| a.exposure.as_ref())
        .map(|sampling| ExposurePaths::new(data, sampling));
    let mut out = Vec::new();
    for f in data.frames.iter().filter(|f| f.split == split) {
        let pose = cast.prepare(&model.corrected_params(f.index, &f.smpl), &f.others)?;
        let latent = model.latent_for(f.index);
        let corrected = model.corrected_camera(f.index, &f.camera);
        let alignment = match alignment {
            Some(settings) if settings.steps > 0 => {
                let renders = match &paths {
                    Some(paths) if f.exposure_s > 0.0 => paths.renders(model, cast, f)?,
                    _ => vec![(corrected.clone(), pose.clone())],
                };
                let renders: Vec<_> = renders.iter().map(|(c, p)| (c.clone(), p)).collect();
                Some(align_camera(
                    model,
                    (&corrected, &f.camera),
                    &renders,
                    latent,
                    (&f.image, grey),
                    settings,
                )?)
            }
            _ => None,
        };
        let raster = alignment.as_ref().map_or(&corrected, |a| &a.camera);
        let r = model.render_frame_from(raster, &f.camera, &pose, latent)?;
        // Grey frames are compared with the render's luminance, as in training.
        let grey_render = grey.then(|| crate::loss::image::luminance3(&r.rgb, w * h));
        let frame = EvalFrame {
            width: w,
            height: h,
            render: grey_render.as_deref().unwrap_or(&r.rgb),
            reference: f.sharp.as_deref().unwrap_or(&f.image),
            blurred: &f.image,
            mask: f.mask.as_deref(),
            human_probability: &r.human,
        };
        let mut people = Vec::with_capacity(r.people.len());
        for (j, probability) in r.people.iter().enumerate() {
            let own: Option<Vec<bool>> = f
                .person_ids
                .as_ref()
                .map(|ids| ids.iter().map(|&id| usize::from(id) == j + 1).collect());
            let person = EvalFrame {
                mask: own.as_deref(),
                human_probability: probability,
                ..frame
            };
            people.push(evaluate_person(&person, lpips)?);
        }
        out.push(EvaluatedFrame {
            index: f.index,
            alignment,
            metrics: evaluate_frame(&frame, lpips)?,
            people,
            strip: comparison_strip_of_people(&frame, &r.people),
        });
    }
    Ok(out)
}

#[cfg(test)]
mod tests;
