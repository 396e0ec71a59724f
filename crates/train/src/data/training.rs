//! What a training run reads and never changes: the training frames with their prepared poses, the
//! skinning loss's surface samples, and the supervision of pairs of consecutive training frames (flow
//! targets and event counts) — prepared once, refused at load time when a file is missing or wrong.

use super::dataset::Dataset;
use super::event_counts::{expected_change, hot_pixels, interval_change, slice_modulation};
use super::event_files::read_frame_events;
use crate::config::TrainConfig;
use crate::loss::optical_flow::{network_target, prepare_target, FlowTarget};
use crate::pose::body::{Body, Cast, GivenPose};
use crate::TrainError;
use flow::SpyNet;
use rasterize_cpu::Camera;
use scene::Split;

/// The refusal of a configuration (`option`) whose supervision (`what`) the data does not hold.
fn not_prepared(option: &str, what: &str) -> TrainError {
    TrainError::Config(format!(
        "{option}, but the training data has no {what} (TrainingData::prepare)"
    ))
}

/// One training frame as the loop uses it.
#[derive(Clone, Debug)]
pub struct TrainingFrame {
    /// Frame number in `scene.json`.
    pub index: u32,
    /// Observed (blurred) image, planar (3, H, W) linear RGB.
    pub image: Vec<f32>,
    /// The frame's pose (mid exposure).
    pub pose: GivenPose,
    /// The camera at mid exposure.
    pub camera: Camera,
}

/// Flow supervision of one training frame k: the next training frame and the target flow k → k+1.
#[derive(Clone, Debug)]
pub struct FlowPair {
    /// Slot (position in [`TrainingData::frames`]) of frame k+1.
    pub next_slot: usize,
    /// The supervising flow at the network's resolution, with its mask.
    pub target: FlowTarget<f32>,
}

/// Event supervision of one training frame k: the next training frame and C·E per pixel (C the
/// contrast threshold, E the signed event count of [t_k, t_{k+1})), row-major H × W.
#[derive(Clone, Debug)]
pub struct EventPair {
    /// Slot (position in [`TrainingData::frames`]) of frame k+1.
    pub next_slot: usize,
    /// Expected log-intensity change per pixel.
    pub expected: Vec<f32>,
}

/// A flow of `scene.json` between frame k and k+1 at full resolution, read and checked.
#[derive(Clone, Debug)]
pub struct PairFlow {
    /// Planar (2, H, W) flow (pixels).
    pub flow: Vec<f32>,
    /// The validity mask (H × W) `scene.json` names with it, if any.
    pub valid: Option<Vec<bool>>,
}

/// Everything fixed during training: camera, training frames, body, skinning-loss samples and the
/// pair supervision.
#[derive(Clone, Debug)]
pub struct TrainingData {
    /// The scene camera: every frame's intrinsics, and its pose unless the camera moves
    /// ([`TrainingFrame::camera`]).
    pub camera: Camera,
    /// Training frames in time order (their position is the latent slot).
    pub frames: Vec<TrainingFrame>,
    /// The frames are grey (`images.channels = 1`): the photometric and perceptual losses compare
    /// the renders' Rec. 601 luminance with them.
    pub grey: bool,
    /// The body (of the first person, with several).
    pub body: Body,
    /// The other people's bodies, the scene's order (empty with one person).
    pub others: Vec<Body>,
    /// Canonical surface samples for the skinning loss.
    pub skin_points: Vec<[f32; 3]>,
    /// Body skinning weights of `skin_points`, row-major (N, 24).
    pub skin_weights: Vec<f32>,
    /// Per training slot, the flow supervision of the pair (k, k+1) (empty unless
    /// [`TrainingData::enable_flow`] was called; `None` for a frame whose next frame is not a
    /// training frame).
    pub flow_pairs: Vec<Option<FlowPair>>,
    /// The frozen flow network of the flow loss.
    pub flow_net: Option<SpyNet<f32>>,
    /// Per training slot, the event supervision of the pair (k, k+1) (empty unless
    /// [`TrainingData::enable_events`] was called).
    pub event_pairs: Vec<Option<EventPair>>,
    /// Per training slot, the poses at the sub-exposure times of the exposure model (empty unless
    /// [`TrainingData::enable_exposure`] was called).
    pub exposure_poses: Vec<Vec<GivenPose>>,
    /// Per training slot, the cameras at the same sub-exposure times, interpolated between the
    /// frames' cameras ([`crate::pose::exposure::CameraTrack`]); empty unless the camera moves and
    /// [`TrainingData::enable_exposure`] was called.
    pub exposure_cameras: Vec<Vec<Camera>>,
    /// Per training slot, per pair of consecutive sub-exposure times (s, s+1), C·E per pixel for the
    /// events of [t_s, t_{s+1}) (row-major H × W), `None` where no event file covers the interval
    /// (before the first frame's time); empty unless [`TrainingData::enable_exposure_events`] was
    /// called.
    pub exposure_events: Vec<Vec<Option<Vec<f32>>>>,
    /// Per training slot, per sub-exposure render s, the events' modulation of its slice of the
    /// exposure ([`crate::loss::photometric::ExposureEvents::modulation`]: mean over the slice of
    /// exp(E(t_s → t)) per pixel, row-major H × W), `None` where no event file covers the slice;
    /// empty unless [`TrainingData::enable_exposure_events`] was called with `event_modulation`.
    pub exposure_modulation: Vec<Vec<Option<Vec<f32>>>>,
    /// Per training slot, the image the EDI warm-up trains on (`edi_warmup`: the frame's EDI
    /// deblurring, or its observed image where the events do not cover its exposure); empty unless
    /// [`TrainingData::enable_edi_warmup`] was called.
    pub warmup_images: Vec<Vec<f32>>,
    /// The frozen LPIPS network of the perceptual loss (`None` unless
    /// [`TrainingData::enable_lpips`] was called).
    pub lpips: Option<lpips::Lpips<f32>>,
}

impl TrainingData {
    /// Prepares the training split of `data` with `body` (surface samples drawn with `seed`).
    pub fn new(data: &Dataset, body: Body, seed: u64) -> Result<Self, TrainError> {
        let others = data.other_bodies()?;
        let cast = Cast {
            first: &body,
            others: &others,
        };
        let mut frames = Vec::new();
        for f in data.frames.iter().filter(|f| f.split == Split::Train) {
            frames.push(TrainingFrame {
                index: f.index,
                image: f.image.clone(),
                pose: cast.given(&f.smpl, &f.others)?,
                camera: f.camera.clone(),
            });
        }
        if frames.is_empty() {
            return Err(TrainError::Config(format!(
                "{}: the scene has no training frames",
                data.dir.display()
            )));
        }
        let samples = smpl_deform::sample_surface(
            &body.canonical.posed.vertices,
            &body.model.faces,
            &body.model.weights,
            16_384,
            seed ^ 0x5c1_0000,
        );
        Ok(Self {
            camera: data.camera.clone(),
            frames,
            grey: data.scene.images.is_grey(),
            body,
            others,
            skin_points: samples.points,
            skin_weights: samples.weights,
            flow_pairs: Vec::new(),
            flow_net: None,
            event_pairs: Vec::new(),
            exposure_poses: Vec::new(),
            exposure_cameras: Vec::new(),
            exposure_events: Vec::new(),
            exposure_modulation: Vec::new(),
            warmup_images: Vec::new(),
            lpips: None,
        })
    }

    /// Trains on the sharp references instead of the observed frames (the ceiling of a benchmark);
    /// a training frame without a sharp reference is an error naming it.
    pub fn use_sharp_images(&mut self, data: &Dataset) -> Result<(), TrainError> {
        let training = data.frames.iter().filter(|f| f.split == Split::Train);
        for (frame, source) in self.frames.iter_mut().zip(training) {
            let Some(sharp) = &source.sharp else {
                return Err(TrainError::Config(format!(
                    "{}: frame {} has no `sharp` reference (needed by --train-on sharp)",
                    data.dir.display(),
                    source.index
                )));
            };
            frame.image = sharp.clone();
        }
        Ok(())
    }

    /// The image a step trains frame `slot` on: its warm-up image during the EDI warm-up
    /// (`warmup` and [`TrainingData::warmup_images`] prepared), else the frame's image.
    pub fn target_image(&self, slot: usize, warmup: bool) -> &[f32] {
        match self.warmup_images.get(slot) {
            Some(image) if warmup => image,
            _ => &self.frames[slot].image,
        }
    }

    /// Prepares the exposure model: for every training frame, the body poses at `subframes`
    /// midpoint-rule times over its exposure `[time_s − E/2, time_s + E/2]` (E the frame's
    /// exposure: its own `exposure_s`, else the scene's), interpolated from the SMPL parameters of
    /// every frame of the scene ([`crate::pose::exposure::PoseTrack`]); with a moving camera, the
    /// cameras at the same times ([`TrainingData::exposure_cameras`]); each track's tangents by
    /// its rule in `rules`.
    pub fn enable_exposure(
        &mut self,
        data: &Dataset,
        subframes: usize,
        rules: crate::pose::exposure::TrackRules,
    ) -> Result<(), TrainError> {
        if let Some(f) = data
            .frames
            .iter()
            .find(|f| !(f.exposure_s.is_finite() && f.exposure_s > 0.0))
        {
            return Err(TrainError::Config(format!(
                "{}: frame {}: exposure_s = {}: the exposure model needs a positive exposure time",
                data.dir.display(),
                f.index,
                f.exposure_s
            )));
        }
        let paths = data.paths(rules, self.others.len());
        let (track, other_tracks) = (&paths.body, &paths.others);
        let cast = self.cast();
        let mut poses = Vec::with_capacity(self.frames.len());
        for frame in data.frames.iter().filter(|f| f.split == Split::Train) {
            let times =
                crate::pose::exposure::subframe_times(frame.time_s, frame.exposure_s, subframes);
            poses.push(
                times
                    .iter()
                    .map(|&t| {
                        let others: Vec<_> = other_tracks.iter().map(|o| o.at(t)).collect();
                        cast.given(&track.at(t), &others)
                    })
                    .collect::<Result<Vec<_>, _>>()?,
            );
        }
        self.exposure_poses = poses;
        if let Some(track) = &paths.camera {
            self.exposure_cameras = data
                .frames
                .iter()
                .filter(|f| f.split == Split::Train)
                .map(|frame| {
                    crate::pose::exposure::subframe_times(frame.time_s, frame.exposure_s, subframes)
                        .iter()
                        .map(|&t| Camera {
                            world_to_camera: track.at(t),
                            ..data.camera.clone()
                        })
                        .collect()
                })
                .collect();
        }
        Ok(())
    }

    /// The people the model is posed with.
    pub fn cast(&self) -> Cast<'_> {
        Cast {
            first: &self.body,
            others: &self.others,
        }
    }

    /// The poses training slot `slot` is rendered at: its sub-exposure poses when `exposure`
    /// (refused when [`TrainingData::prepare`] did not prepare them), else its mid-exposure pose.
    pub fn poses(&self, slot: usize, exposure: bool) -> Result<&[GivenPose], TrainError> {
        if !exposure {
            return Ok(std::slice::from_ref(&self.frames[slot].pose));
        }
        match self.exposure_poses.get(slot) {
            Some(sub) if !sub.is_empty() => Ok(sub),
            _ => Err(not_prepared("blur_model = exposure", "sub-exposure poses")),
        }
    }

    /// The cameras of the renders of [`TrainingData::poses`] (same order): the sub-exposure
    /// cameras when `exposure` and the camera moves, else the frame's camera for every render.
    pub fn cameras(&self, slot: usize, exposure: bool) -> Result<Vec<&Camera>, TrainError> {
        let count = self.poses(slot, exposure)?.len();
        Ok(match self.exposure_cameras.get(slot) {
            Some(sub) if exposure && sub.len() == count => sub.iter().collect(),
            _ => vec![&self.frames[slot].camera; count],
        })
    }

    /// The events' modulation of each sub-exposure render's slice of slot `slot`'s exposure
    /// ([`TrainingData::exposure_modulation`]), refused when [`TrainingData::prepare`] did not
    /// compute it.
    pub fn exposure_modulation(&self, slot: usize) -> Result<&[Option<Vec<f32>>], TrainError> {
        self.exposure_modulation
            .get(slot)
            .map(Vec::as_slice)
            .ok_or_else(|| not_prepared("event_modulation", "events' modulation of the exposure"))
    }

    /// C·E per pixel between consecutive sub-exposure times of slot `slot`
    /// ([`TrainingData::exposure_events`]), refused when [`TrainingData::prepare`] did not count them.
    pub fn exposure_event_counts(&self, slot: usize) -> Result<&[Option<Vec<f32>>], TrainError> {
        self.exposure_events
            .get(slot)
            .map(Vec::as_slice)
            .ok_or_else(|| not_prepared("event_pairs = exposure", "events inside exposures"))
    }

    /// The perceptual loss's network, refused when [`TrainingData::prepare`] did not set it.
    pub fn lpips_network(&self) -> Result<&lpips::Lpips<f32>, TrainError> {
        self.lpips
            .as_ref()
            .ok_or_else(|| not_prepared("lpips_weight > 0", "LPIPS network"))
    }

    /// Number of pixels per channel.
    pub fn pixels(&self) -> usize {
        self.camera.width as usize * self.camera.height as usize
    }

    /// Prepares the event-generation loss: for every pair of consecutive training frames, reads frame
    /// k's `events` file (the events of [t_k, t_{k+1})) and turns it into C·E per pixel
    /// (`config.event_thresholds()`). A pair whose frame has no events file, or whose events file
    /// cannot be read, is an error naming the frame and the file — refused here, not mid-training.
    pub fn enable_events(
        &mut self,
        data: &Dataset,
        config: &TrainConfig,
    ) -> Result<(), TrainError> {
        let (w, h) = (self.camera.width, self.camera.height);
        let sensor = events::SensorSize::new(w, h);
        let hot = hot_pixels(data, config.event_hot_pixel_filter, "the event loss")?;
        let mut pairs = vec![None; self.frames.len()];
        let found = consecutive_training_pairs(data);
        for &(slot, p) in &found {
            // A pair whose interval a recording's events do not cover supervises nothing.
            let whole = data.scene.event_file_span(p);
            if data.scene.event_evidence_span(p) != Some(whole) {
                continue;
            }
            let stream = read_frame_events(data, p, "the event loss")?;
            let expected = expected_change(&stream.as_slice(), sensor, config, &hot);
            pairs[slot] = Some(EventPair {
                next_slot: slot + 1,
                expected,
            });
        }
        if pairs.iter().all(Option::is_none) {
            return Err(TrainError::Config(format!(
                "{}: no two consecutive frames are both training frames with the recording's \
                 events between them, so the event loss has nothing to supervise",
                data.dir.display()
            )));
        }
        self.event_pairs = pairs;
        Ok(())
    }

    /// Prepares the event-generation loss inside exposures: for every training frame k and every
    /// pair of consecutive sub-exposure times (s, s+1) of `subframes` midpoint-rule times, C·E per
    /// pixel (C± = `config.event_thresholds()`, E the signed count of the events with
    /// t_s ≤ t < t_{s+1}); with `config.event_refractory_us`, a pixel silent in such an interval
    /// that fired within that long before t_s unconstrained.
    /// An exposure spans the event files of frames k−1 ([t_{k−1}, t_k)) and k ([t_k, t_{k+1})),
    /// which are joined; a frame whose exposure needs a file that `scene.json` does not name is an
    /// error naming the frame and the field. Intervals outside the files' evidence
    /// (`scene::Scene::event_evidence_span`: before the first frame's time, or outside a
    /// recording's events) get no supervision. With `config.event_modulation`, also each
    /// sub-exposure render's modulation by the events of its slice of the exposure
    /// ([`TrainingData::exposure_modulation`]; the slices tile the whole exposure).
    pub fn enable_exposure_events(
        &mut self,
        data: &Dataset,
        config: &TrainConfig,
    ) -> Result<(), TrainError> {
        let sensor = events::SensorSize::new(self.camera.width, self.camera.height);
        let hot = hot_pixels(
            data,
            config.event_hot_pixel_filter,
            "the event loss inside exposures",
        )?;
        // Each file is read once: an exposure reaches at most one file back, so the streams of
        // frames before p − 1 are dropped as the loop moves on.
        let mut loaded: std::collections::BTreeMap<usize, events::EventStream> = Default::default();
        let us = |t: f64| (t * 1e6).round() as i64;
        let mut all = Vec::with_capacity(self.frames.len());
        let mut modulation = Vec::new();
        for (p, frame) in data.frames.iter().enumerate() {
            if frame.split != Split::Train {
                continue;
            }
            let times = crate::pose::exposure::subframe_times(
                frame.time_s,
                frame.exposure_s,
                config.subframes,
            );
            // The files this exposure reaches into, joined in time order, and the span over which
            // they are evidence (`scene::Scene::event_evidence_span`: consecutive files' spans
            // join into one interval).
            let slices = crate::pose::exposure::exposure_slices(
                frame.time_s,
                frame.exposure_s,
                config.subframes,
            );
            let (first, last) = if config.event_modulation {
                (slices[0].0, slices[slices.len() - 1].1)
            } else {
                (times[0], times[times.len() - 1])
            };
            let reached = (p.saturating_sub(1)..=p + 1).filter(|&q| {
                q == p
                    || (q < p && first < frame.time_s)
                    || (q > p && data.frames.get(q).is_some_and(|f| last >= f.time_s))
            });
            let spans: Vec<(usize, (f64, f64))> = reached
                .filter_map(|q| data.scene.event_evidence_span(q).map(|s| (q, s)))
                .collect();
            let files: Vec<usize> = spans.iter().map(|&(q, _)| q).collect();
            let (covered_from, covered_to) = match (spans.first(), spans.last()) {
                (Some(&(_, (from, _))), Some(&(_, (_, to)))) => (from, to),
                _ => (f64::INFINITY, f64::NEG_INFINITY),
            };
            loaded.retain(|&q, _| q + 1 >= p);
            let mut stream = events::EventStream::new();
            for q in files {
                let stream_q = match loaded.entry(q) {
                    std::collections::btree_map::Entry::Occupied(e) => e.into_mut(),
                    std::collections::btree_map::Entry::Vacant(e) => {
                        let why = format!(
                            "the event loss inside the exposure of frame {}",
                            frame.index
                        );
                        e.insert(read_frame_events(data, q, &why)?)
                    }
                };
                stream.extend_from(&stream_q.as_slice());
            }
            let slice = stream.as_slice();
            let pairs = times
                .windows(2)
                .map(|w| {
                    (w[0] >= covered_from && w[1] <= covered_to).then(|| {
                        interval_change(&slice, (us(w[0]), us(w[1])), sensor, config, &hot)
                    })
                })
                .collect();
            all.push(pairs);
            if config.event_modulation {
                let covered =
                    |&(from, to, _): &(f64, f64, f64)| from >= covered_from && to <= covered_to;
                let per_slice = slices
                    .iter()
                    .map(|slice_s| {
                        covered(slice_s)
                            .then(|| slice_modulation(&slice, sensor, *slice_s, config, &hot))
                            .transpose()
                    })
                    .collect::<Result<Vec<_>, _>>()?;
                modulation.push(per_slice);
            }
        }
        self.exposure_events = all;
        self.exposure_modulation = modulation;
        Ok(())
    }

    /// Prepares the perceptual loss with the LPIPS network `net` (the driver loads the shipped
    /// weights); refused if the frames are smaller than the network's minimum size.
    pub fn enable_lpips(&mut self, net: lpips::Lpips<f32>) -> Result<(), TrainError> {
        let (w, h) = (self.camera.width as usize, self.camera.height as usize);
        if lpips::tap_sizes(h, w).is_none() {
            return Err(lpips::LpipsError::TooSmall {
                width: w,
                height: h,
                min: lpips::MIN_SIZE,
            }
            .into());
        }
        self.lpips = Some(net);
        Ok(())
    }

    /// Prepares the flow loss: for every training frame whose next frame in `scene.json` is also a
    /// training frame, reads the flow of `config.flow_source` (and its validity mask) and resizes it
    /// to the network's resolution (`config.flow_scale`, τ = `config.flow_tau`) — or, for
    /// `sharp-network`, runs `net` on the two sharp references at that resolution
    /// ([`network_target`]). A pair without that flow (or without sharp references), or with a flow
    /// of the wrong size, is an error naming the frame and the file — refused here, not
    /// mid-training. Frames whose next frame is a test frame (or the last frame) have no pair.
    pub fn enable_flow(
        &mut self,
        data: &Dataset,
        config: &TrainConfig,
        net: SpyNet<f32>,
    ) -> Result<(), TrainError> {
        let (w, h) = (self.camera.width as usize, self.camera.height as usize);
        let h_out = ((h as f64 * config.flow_scale as f64).round() as usize).max(1);
        let w_out = ((w as f64 * config.flow_scale as f64).round() as usize).max(1);
        let mut pairs = vec![None; self.frames.len()];
        for (slot, p) in consecutive_training_pairs(data) {
            let target = match config.flow_source.kind() {
                Some(kind) => {
                    let Some(pair) = read_pair_flow(data, p, kind)? else {
                        return Err(TrainError::Config(format!(
                            "{}: frame {} has no `{}` flow to the next training frame {} (needed \
                             by the flow loss with flow source {:?})",
                            data.dir.display(),
                            data.frames[p].index,
                            kind.as_str(),
                            data.frames[p + 1].index,
                            config.flow_source
                        )));
                    };
                    prepare_target(
                        &pair.flow,
                        pair.valid.as_deref(),
                        h,
                        w,
                        h_out,
                        w_out,
                        config.flow_tau,
                    )?
                }
                None => {
                    let (f, next) = (&data.frames[p], &data.frames[p + 1]);
                    let (Some(first), Some(second)) = (&f.sharp, &next.sharp) else {
                        return Err(TrainError::Config(format!(
                            "{}: frame {} or its next training frame {} has no sharp reference \
                             (needed by the flow loss with flow source sharp-net)",
                            data.dir.display(),
                            f.index,
                            next.index
                        )));
                    };
                    network_target(&net, first, second, h, w, h_out, w_out, config.flow_tau)?
                }
            };
            pairs[slot] = Some(FlowPair {
                next_slot: slot + 1,
                target,
            });
        }
        if pairs.iter().all(Option::is_none) {
            return Err(TrainError::Config(format!(
                "{}: no two consecutive frames are both training frames, so the flow loss has \
                 nothing to supervise",
                data.dir.display()
            )));
        }
        self.flow_pairs = pairs;
        self.flow_net = Some(net);
        Ok(())
    }
}

/// Slots of consecutive training frames: `(slot of k, position of k in data.frames)` for every
/// training frame whose next frame in `scene.json` is also a training frame (slot k+1 = slot k + 1).
pub fn consecutive_training_pairs(data: &Dataset) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut slot = 0usize;
    for (p, f) in data.frames.iter().enumerate() {
        if f.split != Split::Train {
            continue;
        }
        if data
            .frames
            .get(p + 1)
            .is_some_and(|n| n.split == Split::Train)
        {
            out.push((slot, p));
        }
        slot += 1;
    }
    out
}

/// The `kind` flow that `scene.json` names for frame `p` (towards frame `p + 1`) and its validity
/// mask, read and checked against the camera; `None` when the frame names no such flow. An unreadable
/// file, or a flow or mask of the wrong size, is an error naming the file. The one reader of pair
/// flows: the flow loss, the flow network's training and the diagnostic examples use it.
pub fn read_pair_flow(
    data: &Dataset,
    p: usize,
    kind: scene::FlowKind,
) -> Result<Option<PairFlow>, TrainError> {
    let Some(fr) = data.scene.frames.get(p).and_then(|f| f.flow(kind)) else {
        return Ok(None);
    };
    let (w, h) = (data.camera.width as usize, data.camera.height as usize);
    let path = scene::Scene::resolve(&data.dir, &fr.path);
    let flow = events::read_flow(&path)
        .map_err(|e| TrainError::Config(format!("{}: {e}", path.display())))?;
    if (flow.width, flow.height) != (w, h) {
        return Err(TrainError::Config(format!(
            "{}: flow is {}x{}, the camera is {w}x{h}",
            path.display(),
            flow.width,
            flow.height
        )));
    }
    let valid = match &fr.valid_mask {
        Some(rel) => {
            let mp = scene::Scene::resolve(&data.dir, rel);
            let (mw, mh, m) = scene::read_mask(&mp)?;
            if (mw as usize, mh as usize) != (w, h) {
                return Err(TrainError::Config(format!(
                    "{}: mask is {mw}x{mh}, the camera is {w}x{h}",
                    mp.display()
                )));
            }
            Some(m)
        }
        None => None,
    };
    Ok(Some(PairFlow {
        flow: flow.data,
        valid,
    }))
}

/// A pair of consecutive frames with sharp references and their ground-truth flow, prepared for the
/// flow diagnostics (the examples scoring flow networks on the benchmark).
#[derive(Clone, Debug)]
pub struct SharpFlowPair<'a> {
    /// Position of frame k in `Dataset::frames`.
    pub position: usize,
    /// Frames k and k+1.
    pub frames: (&'a super::TrainFrame, &'a super::TrainFrame),
    /// Their sharp references, planar (3, H, W).
    pub sharp: (&'a [f32], &'a [f32]),
    /// The ground-truth flow at full resolution, planar (2, H, W).
    pub flow: Vec<f32>,
    /// The target at the requested size with τ applied (the flow loss's mask M).
    pub target: FlowTarget<f32>,
    /// The target at the requested size over every valid pixel (no τ).
    pub all: FlowTarget<f32>,
}

/// Every pair (k, k+1) of `data` whose frame k names a ground-truth flow, with both sharp references
/// and the flow resized to `(h_out, w_out)` (τ = `tau` for [`SharpFlowPair::target`]). A pair without
/// sharp references is an error naming the frames.
pub fn sharp_flow_pairs(
    data: &Dataset,
    (h_out, w_out): (usize, usize),
    tau: f32,
) -> Result<Vec<SharpFlowPair<'_>>, TrainError> {
    let (w, h) = (data.camera.width as usize, data.camera.height as usize);
    let mut out = Vec::new();
    for k in 0..data.frames.len().saturating_sub(1) {
        let Some(pair) = read_pair_flow(data, k, scene::FlowKind::GroundTruth)? else {
            continue;
        };
        let valid = pair.valid.as_deref();
        let target = prepare_target(&pair.flow, valid, h, w, h_out, w_out, tau)?;
        let all = prepare_target(&pair.flow, valid, h, w, h_out, w_out, -1.0)?;
        let (a, b) = (&data.frames[k], &data.frames[k + 1]);
        let (Some(sharp_a), Some(sharp_b)) = (&a.sharp, &b.sharp) else {
            return Err(TrainError::Config(format!(
                "{}: frame {} or {} has no sharp reference",
                data.dir.display(),
                a.index,
                b.index
            )));
        };
        out.push(SharpFlowPair {
            position: k,
            frames: (a, b),
            sharp: (sharp_a, sharp_b),
            flow: pair.flow,
            target,
            all,
        });
    }
    Ok(out)
}
