//! The frames of the 2-D cascade baseline (`--train-on edi`): every training frame deblurred on its
//! own by the event double integral (`events::edi`), from the events of its exposure, before any
//! 3-D model sees it — the paper's "deblur first, then reconstruct" rows with the weight-free event
//! deblurring.

use super::dataset::{Dataset, TrainFrame};
pub use super::event_counts::hot_pixels;
use super::event_files::read_frame_events;
use crate::TrainError;

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
