//! What `stats.json` records of a generated benchmark, and the running sums the generator keeps
//! while it renders: the blurred frames' PSNR against the sharp ones (whole frame, the person's
//! box, outside it, each person's own box), the ground-truth flow's statistics and photometric
//! check, the event-only flow's error.

use std::path::Path;

use serde::Serialize;

use super::{mask_bbox, PSNR_CAP_DB};
use crate::config::SynthConfig;
use crate::error::{Result, SynthError};
use crate::flow::warp_error;
use crate::pose_metrics::PoseErrorStats;

/// PSNR figures of the blurred frames against the sharp references (mean over frames of the
/// per-frame PSNR, dB, data range 1, linear intensity, capped at 100 dB).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct PsnrStats {
    /// Whole image.
    pub full_frame_db: f64,
    /// Inside the bounding box of the sharp frame's human mask.
    pub human_box_db: f64,
    /// Outside that box (the static background, except where limbs leave the box during the
    /// exposure).
    pub outside_human_box_db: f64,
    /// Lowest per-frame human-box PSNR (the most blurred frame).
    pub human_box_min_db: f64,
}

/// Ground-truth flow figures over all frame pairs.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct FlowStats {
    /// Number of flow fields (frames − 1).
    pub pairs: usize,
    /// Fraction of pixels with valid flow.
    pub valid_fraction: f64,
    /// Fraction of all pixels whose (valid) flow magnitude exceeds 1 px.
    pub fraction_above_1px: f64,
    /// Fraction of human pixels (sharp mask) whose valid flow exceeds 1 px.
    pub human_fraction_above_1px: f64,
    /// Mean magnitude over valid human pixels (pixels).
    pub human_mean_magnitude_px: f64,
    /// Largest valid magnitude (pixels).
    pub max_magnitude_px: f64,
    /// Photometric check: mean |sharp_k − warp(sharp_{k+1}, flow)| over valid pixels (linear RGB).
    pub warp_mae: f64,
    /// The same error without warping (zero flow), on the same pixels: the baseline.
    pub identity_mae: f64,
    /// The photometric check restricted to valid human pixels moving more than 1 px.
    pub moving_human_warp_mae: f64,
    /// Zero-flow baseline on those pixels.
    pub moving_human_identity_mae: f64,
}

/// Event figures.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct EventStats {
    /// Events written (all frames).
    pub count: usize,
    /// Positive events written.
    pub positive: usize,
    /// Events before the first frame's mid-exposure (not written).
    pub dropped_before_first_frame: usize,
    /// Mean events per pixel per frame interval.
    pub per_pixel_per_frame: f64,
}

/// Event-only flow (`events::flow_from_events`, default settings) against the ground truth.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct CmStats {
    /// Whether it was computed (`SynthConfig::event_flow`).
    pub computed: bool,
    /// Mean end-point error over pixels with valid ground truth (pixels).
    pub epe_valid_px: f64,
    /// Mean end-point error over valid pixels whose ground-truth flow exceeds 1 px.
    pub epe_moving_px: f64,
    /// End-point error of a zero flow on those moving pixels (the baseline).
    pub zero_flow_epe_moving_px: f64,
    /// Number of moving valid pixels over all pairs.
    pub moving_pixels: usize,
}

/// Running sums of [`CmStats`].
#[derive(Default)]
pub(super) struct CmAcc {
    epe_valid: f64,
    n_valid: usize,
    epe_moving: f64,
    zero_moving: f64,
    n_moving: usize,
}

impl CmAcc {
    /// The mean errors into `stats` (0 without pixels).
    pub(super) fn finish(&self, stats: &mut CmStats) {
        let dv = |a: f64, b: usize| if b > 0 { a / b as f64 } else { 0.0 };
        stats.epe_valid_px = dv(self.epe_valid, self.n_valid);
        stats.epe_moving_px = dv(self.epe_moving, self.n_moving);
        stats.zero_flow_epe_moving_px = dv(self.zero_moving, self.n_moving);
        stats.moving_pixels = self.n_moving;
    }

    /// Adds one pair's event-only flow `cm` against the ground truth `gt` (planar u, v) on the
    /// valid pixels.
    pub(super) fn add(&mut self, cm: &[f32], gt: &[f32], valid: &[bool]) {
        let n = valid.len();
        for i in 0..n {
            if !valid[i] {
                continue;
            }
            let e = f64::from((cm[i] - gt[i]).hypot(cm[n + i] - gt[n + i]));
            self.epe_valid += e;
            self.n_valid += 1;
            let m = f64::from(gt[i].hypot(gt[n + i]));
            if m > 1.0 {
                self.epe_moving += e;
                self.zero_moving += m;
                self.n_moving += 1;
            }
        }
    }
}

/// Everything written to `stats.json`.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Stats {
    /// The settings used.
    pub config: Option<SynthConfig>,
    /// Blur strength.
    pub psnr_blurred_vs_sharp: PsnrStats,
    /// Ground-truth flow.
    pub flow: FlowStats,
    /// Events.
    pub events: EventStats,
    /// Event-only (contrast maximisation) flow against the ground truth.
    pub events_cm_flow: CmStats,
    /// Frame indices shown in `preview.png`, top to bottom.
    pub preview_frames: Vec<u32>,
    /// Realised error of the SMPL parameters in `scene.json` against `poses_true.json`; absent
    /// (and not written) when the pose error is off.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pose_error: Option<PoseErrorStats>,
    /// With several people: per person (the scene's order), the blurred input's PSNR (dB) against
    /// the sharp frame in that person's own box (the bounding box of its pixels in the person-id
    /// image), averaged over the frames that show it; empty (and not written) with one person.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub person_box_db: Vec<f64>,
}

impl Stats {
    /// Writes `out/stats.json` (pretty JSON, a final newline).
    pub(super) fn write(&self, out: &Path) -> Result<()> {
        let path = out.join("stats.json");
        let mut text = serde_json::to_string_pretty(self).map_err(|source| SynthError::Json {
            path: path.clone(),
            source,
        })?;
        text.push('\n');
        std::fs::write(&path, text).map_err(|source| SynthError::Io { path, source })
    }
}

/// PSNR (dB) of `a` against `b` over the pixels `pix` keeps, of `n` per channel (`None` without
/// pixels; identical images give [`PSNR_CAP_DB`]).
fn psnr(a: &[f32], b: &[f32], n: usize, pix: impl Fn(usize) -> bool) -> Option<f64> {
    let (mut se, mut cnt) = (0.0f64, 0usize);
    for i in 0..n {
        if pix(i) {
            for c in 0..3 {
                let d = f64::from(a[c * n + i].clamp(0.0, 1.0) - b[c * n + i].clamp(0.0, 1.0));
                se += d * d;
            }
            cnt += 3;
        }
    }
    if cnt == 0 {
        return None;
    }
    let mse = se / cnt as f64;
    Some(if mse <= 0.0 {
        PSNR_CAP_DB
    } else {
        (10.0 * (1.0 / mse).log10()).min(PSNR_CAP_DB)
    })
}

/// Running sums of the blurred frames' PSNR against the sharp references ([`PsnrStats`] and, with
/// several people, each person's own box).
pub(super) struct BlurAcc {
    sum_full: f64,
    sum_box: f64,
    sum_out: f64,
    n_box: usize,
    n_out: usize,
    box_min: f64,
    /// Per person with several: (sum of box PSNRs, frames that show it).
    person_box: Vec<(f64, usize)>,
}

impl BlurAcc {
    /// Sums for `people` people's own boxes (0: one person, none kept).
    pub(super) fn new(people: usize) -> Self {
        Self {
            sum_full: 0.0,
            sum_box: 0.0,
            sum_out: 0.0,
            n_box: 0,
            n_out: 0,
            box_min: f64::INFINITY,
            person_box: vec![(0.0, 0); people],
        }
    }

    /// Adds one frame: its blurred and sharp images (planar RGB), the sharp human mask and
    /// person-id image (empty with one person), `w` pixels wide.
    pub(super) fn add(
        &mut self,
        blurred: &[f32],
        sharp: &[f32],
        mask: &[bool],
        ids: &[u8],
        w: usize,
    ) {
        let n = mask.len();
        self.sum_full += psnr(blurred, sharp, n, |_| true).unwrap_or(PSNR_CAP_DB);
        let in_box = |(x0, y0, x1, y1): (usize, usize, usize, usize)| {
            move |i: usize| {
                let (x, y) = (i % w, i / w);
                x >= x0 && x <= x1 && y >= y0 && y <= y1
            }
        };
        if let Some(bbox) = mask_bbox(mask, w) {
            let inside = in_box(bbox);
            if let Some(p) = psnr(blurred, sharp, n, inside) {
                self.sum_box += p;
                self.box_min = self.box_min.min(p);
                self.n_box += 1;
            }
            if let Some(p) = psnr(blurred, sharp, n, |i| !inside(i)) {
                self.sum_out += p;
                self.n_out += 1;
            }
        }
        for (p, acc) in self.person_box.iter_mut().enumerate() {
            let id = (p + 1) as u8;
            let own: Vec<bool> = ids.iter().map(|&v| v == id).collect();
            if let Some(bbox) = mask_bbox(&own, w) {
                if let Some(db) = psnr(blurred, sharp, n, in_box(bbox)) {
                    acc.0 += db;
                    acc.1 += 1;
                }
            }
        }
    }

    /// The means over `frames` frames, and each person's box mean.
    pub(super) fn finish(&self, frames: usize) -> (PsnrStats, Vec<f64>) {
        let mean = |sum: f64, count: usize| {
            if count > 0 {
                sum / count as f64
            } else {
                PSNR_CAP_DB
            }
        };
        let stats = PsnrStats {
            full_frame_db: self.sum_full / frames as f64,
            human_box_db: mean(self.sum_box, self.n_box),
            outside_human_box_db: mean(self.sum_out, self.n_out),
            human_box_min_db: if self.box_min.is_finite() {
                self.box_min
            } else {
                PSNR_CAP_DB
            },
        };
        let people = self.person_box.iter().map(|&(s, c)| mean(s, c)).collect();
        (stats, people)
    }
}

/// Running sums of [`FlowStats`] over the frame pairs.
#[derive(Default)]
pub(super) struct FlowAcc {
    valid_px: usize,
    moving_px: usize,
    human_px: usize,
    human_moving: usize,
    human_mag: f64,
    max_mag: f64,
    warp_sum: f64,
    id_sum: f64,
    warp_px: usize,
    hwarp_sum: f64,
    hid_sum: f64,
    hwarp_px: usize,
}

impl FlowAcc {
    /// Adds the flow (planar u, v) of a pair, its valid pixels and the first frame's human mask.
    pub(super) fn add_pair(&mut self, flow: &[f32], valid: &[bool], mask: &[bool]) {
        let n = valid.len();
        for i in 0..n {
            if valid[i] {
                let m = f64::from(flow[i].hypot(flow[n + i]));
                self.valid_px += 1;
                self.max_mag = self.max_mag.max(m);
                if m > 1.0 {
                    self.moving_px += 1;
                }
                if mask[i] {
                    self.human_px += 1;
                    self.human_mag += m;
                    if m > 1.0 {
                        self.human_moving += 1;
                    }
                }
            }
        }
    }

    /// Adds the photometric check of a pair: the first sharp frame against the second warped by
    /// the flow, on the valid pixels and on the valid human pixels moving more than 1 px.
    pub(super) fn add_warp(
        &mut self,
        first: &[f32],
        second: &[f32],
        flow: &[f32],
        valid: &[bool],
        mask: &[bool],
        (w, h): (usize, usize),
    ) {
        let n = valid.len();
        let (e, b, c) = warp_error(first, second, flow, valid, w, h);
        self.warp_sum += e * c as f64;
        self.id_sum += b * c as f64;
        self.warp_px += c;
        let hvalid: Vec<bool> = (0..n)
            .map(|i| valid[i] && mask[i] && flow[i].hypot(flow[n + i]) > 1.0)
            .collect();
        let (e, b, c) = warp_error(first, second, flow, &hvalid, w, h);
        self.hwarp_sum += e * c as f64;
        self.hid_sum += b * c as f64;
        self.hwarp_px += c;
    }

    /// The statistics of `frames − 1` pairs of `n` pixels.
    pub(super) fn finish(&self, frames: usize, n: usize) -> FlowStats {
        let total_px = ((frames - 1) * n) as f64;
        let div = |a: f64, b: usize| if b > 0 { a / b as f64 } else { 0.0 };
        FlowStats {
            pairs: frames - 1,
            valid_fraction: self.valid_px as f64 / total_px,
            fraction_above_1px: self.moving_px as f64 / total_px,
            human_fraction_above_1px: div(self.human_moving as f64, self.human_px),
            human_mean_magnitude_px: div(self.human_mag, self.human_px),
            max_magnitude_px: self.max_mag,
            warp_mae: div(self.warp_sum, self.warp_px),
            identity_mae: div(self.id_sum, self.warp_px),
            moving_human_warp_mae: div(self.hwarp_sum, self.hwarp_px),
            moving_human_identity_mae: div(self.hid_sum, self.hwarp_px),
        }
    }
}
