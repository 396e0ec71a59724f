//! The frames of the 2-D cascade baseline (`--train-on edi`): every training frame deblurred on its
//! own by the event double integral (`events::edi`), from the events of its exposure, before any
//! 3-D model sees it — the paper's "deblur first, then reconstruct" rows with the weight-free event
//! deblurring — and of the EDI warm-up (`edi_warmup`), which trains on them before the observed
//! frames.

use super::dataset::{Dataset, TrainFrame};
pub use super::event_counts::hot_pixels;
use super::event_files::read_frame_events;
use super::TrainingData;
use crate::config::TrainConfig;
use crate::TrainError;
use scene::Split;

/// The events of `[from_s, to_s)` around frame `p` (its own file and its neighbours', joined in
/// time order), or `None` when the frames' files are no evidence over that whole span (before the
/// first frame's time, outside a recording's events: `scene::Scene::event_evidence_span`).
pub fn span_events(
    data: &Dataset,
    p: usize,
    from_s: f64,
    to_s: f64,
    needed_by: &str,
) -> Result<Option<events::EventStream>, TrainError> {
    let frames = &data.frames;
    let first = (0..=p).rev().find(|&q| frames[q].time_s <= from_s);
    let Some(first) = first else {
        return Ok(None);
    };
    // Consecutive files whose evidence (`scene::Scene::event_evidence_span`) joins into one
    // interval, which must hold [from_s, to_s].
    let evidence = |q: usize| data.scene.event_evidence_span(q);
    if evidence(first).is_none_or(|(from, _)| from > from_s) {
        return Ok(None);
    }
    let mut last = first;
    while evidence(last).is_some_and(|(_, to)| to < to_s) {
        if last + 1 >= frames.len() || evidence(last + 1).is_none() {
            return Ok(None);
        }
        last += 1;
    }
    let mut stream = events::EventStream::new();
    for q in first..=last {
        stream.extend_from(&read_frame_events(data, q, needed_by)?.as_slice());
    }
    Ok(Some(stream))
}

/// The EDI image of `frame` (position `p` in `data.frames`) over its exposure, deblurred to its
/// mid-exposure time, or `None` when the event files do not cover the exposure. The pixels `hot`
/// marks (row-major H × W; empty: none) keep their blurred value.
pub fn edi_image(
    data: &Dataset,
    p: usize,
    frame: &TrainFrame,
    config: events::EdiConfig,
    log_eps: f64,
    hot: &[bool],
) -> Result<Option<Vec<f32>>, TrainError> {
    let (from, to) = (
        frame.time_s - 0.5 * frame.exposure_s,
        frame.time_s + 0.5 * frame.exposure_s,
    );
    let why = format!("EDI deblurring of frame {}", frame.index);
    let Some(stream) = span_events(data, p, from, to, &why)? else {
        return Ok(None);
    };
    let us = |t: f64| (t * 1e6).round() as i64;
    let exposure = events::Exposure {
        start_us: us(from),
        end_us: us(to),
        reference_us: us(frame.time_s),
    };
    let sensor = events::SensorSize::new(data.camera.width, data.camera.height);
    let mut gain = events::edi_gain(&stream.as_slice(), sensor, exposure, config).map_err(|e| {
        TrainError::Config(format!(
            "{}: frame {}: {e}",
            data.dir.display(),
            frame.index
        ))
    })?;
    for (g, _) in gain.iter_mut().zip(hot).filter(|(_, &h)| h) {
        *g = 1.0;
    }
    let image = events::apply_gain(&frame.image, &gain, log_eps).map_err(|e| {
        TrainError::Config(format!(
            "{}: frame {}: {e}",
            data.dir.display(),
            frame.index
        ))
    })?;
    Ok(Some(image))
}

impl TrainingData {
    /// Replaces every training frame's image by its EDI deblurring (`--train-on edi`, the 2-D
    /// cascade baseline; [`super::edi`]), with C± and ε from `config`. Frames whose exposure the
    /// event files do not cover keep their blurred image; returns how many were deblurred. A scene
    /// without events is an error naming the first frame without an `events` file.
    pub fn use_edi_images(
        &mut self,
        data: &Dataset,
        config: &TrainConfig,
    ) -> Result<usize, TrainError> {
        let deblurred = self.edi_images(data, config)?;
        let count = deblurred.iter().flatten().count();
        for (frame, image) in self.frames.iter_mut().zip(deblurred) {
            if let Some(image) = image {
                frame.image = image;
            }
        }
        Ok(count)
    }

    /// Prepares the EDI warm-up (`edi_warmup`): every training frame's EDI deblurring as
    /// [`TrainingData::use_edi_images`] makes it, kept beside the observed image
    /// ([`TrainingData::warmup_images`]); returns how many frames were deblurred.
    pub fn enable_edi_warmup(
        &mut self,
        data: &Dataset,
        config: &TrainConfig,
    ) -> Result<usize, TrainError> {
        let deblurred = self.edi_images(data, config)?;
        let count = deblurred.iter().flatten().count();
        self.warmup_images = self
            .frames
            .iter()
            .zip(deblurred)
            .map(|(frame, image)| image.unwrap_or_else(|| frame.image.clone()))
            .collect();
        Ok(count)
    }

    /// Every training frame's EDI deblurring (`None` where the event files do not cover its
    /// exposure), with C± and ε from `config`.
    fn edi_images(
        &self,
        data: &Dataset,
        config: &TrainConfig,
    ) -> Result<Vec<Option<Vec<f32>>>, TrainError> {
        let edi = events::EdiConfig {
            c_pos: f64::from(config.event_threshold),
            c_neg: f64::from(config.event_threshold_neg.unwrap_or(config.event_threshold)),
        };
        let training = data
            .frames
            .iter()
            .enumerate()
            .filter(|(_, f)| f.split == Split::Train);
        let hot = hot_pixels(data, config.event_hot_pixel_filter, "EDI deblurring")?;
        let log_eps = f64::from(config.event_log_eps);
        training
            .map(|(p, source)| super::edi::edi_image(data, p, source, edi, log_eps, &hot))
            .collect()
    }
}
