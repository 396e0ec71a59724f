//! A frame's event file as the losses read it: in the scene's recorded encoding, and checked
//! against the span the scene format gives it (`scene::Scene::event_file_span`).

use super::dataset::Dataset;
use crate::TrainError;

/// How a frame's event file is read: a Prophesee `.raw` file with the scene's recorded encoding
/// (`events_raw_format`) for headers that do not state it; other formats as they are.
pub fn event_read_options(data: &Dataset, path: &std::path::Path) -> events::io::ReadOptions {
    let raw = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("raw"));
    events::io::ReadOptions {
        raw_format: data
            .scene
            .events_raw_format
            .filter(|_| raw)
            .map(|f| match f {
                scene::RawEventsFormat::Evt2 => events::io::prophesee::RawEncoding::Evt2,
                scene::RawEventsFormat::Evt3 => events::io::prophesee::RawEncoding::Evt3,
            }),
        lenient: false,
    }
}

/// The events of frame `p`'s `events` file (its span, `scene::Scene::event_file_span`: [t_p,
/// t_{p+1}), the last frame every later event); a frame without one is an error naming the frame,
/// the field and what needed it (`needed_by`).
pub(super) fn read_frame_events(
    data: &Dataset,
    p: usize,
    needed_by: &str,
) -> Result<events::EventStream, TrainError> {
    let (stream, path) = read_frame_file(data, p, needed_by)?;
    // Events outside the file's span mean the file is another frame's or on another clock, and
    // would supervise the wrong renders. One microsecond of slack covers the rounding of times to
    // microseconds.
    let us = |t: f64| (t * 1e6).round() as i64;
    let (from_s, to_s) = data.scene.event_file_span(p);
    let from = us(from_s);
    let to = to_s.is_finite().then(|| us(to_s));
    if let (Some(&first), Some(&last)) = (stream.t.iter().min(), stream.t.iter().max()) {
        if first < from - 1 || to.is_some_and(|to| last > to + 1) {
            let span = to.map_or_else(
                || format!("[{from} µs, the end of the recording) (the last frame's file)"),
                |to| format!("[{from}, {to}) µs (its `time_s` to the next frame's)"),
            );
            return Err(TrainError::Config(format!(
                "{}: the `events` file of frame {} holds events from {first} µs to {last} µs, \
                 outside the frame's span {span}: it is another frame's file or on another clock \
                 (needed by {needed_by})",
                path.display(),
                data.frames[p].index
            )));
        }
    }
    Ok(stream)
}

/// The events of frame `p`'s `events` file as they are, and its path; a frame without one is an
/// error naming the frame, the field and what needed it (`needed_by`).
pub(super) fn read_frame_file(
    data: &Dataset,
    p: usize,
    needed_by: &str,
) -> Result<(events::EventStream, std::path::PathBuf), TrainError> {
    let Some(rel) = &data.scene.frames[p].events else {
        return Err(TrainError::Config(format!(
            "{}: frame {} has no `events` file (needed by {needed_by})",
            data.dir.display(),
            data.frames[p].index
        )));
    };
    let path = scene::Scene::resolve(&data.dir, rel);
    let stream = events::io::read_events_with(&path, &event_read_options(data, &path))
        .map_err(|e| TrainError::Config(format!("{}: {e}", path.display())))?;
    Ok((stream, path))
}
