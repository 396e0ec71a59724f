//! Events as the losses read them: a window's events as the log-intensity change they report
//! (C+ per positive, C− per negative event), and the scene's hot pixels, whose events are left out.

use super::dataset::Dataset;
use super::event_files::read_frame_file;
use crate::config::TrainConfig;
use crate::TrainError;

/// C+·n⁺ − C−·n⁻ per pixel (row-major H × W) of `events`: the log-intensity change they report,
/// with C± from `config` (C·(n⁺ − n⁻) when C− is not set).
/// The pixels `hot` marks (empty: none) report no change, as if their events were removed.
pub(super) fn expected_change(
    events: &events::EventSlice<'_>,
    sensor: events::SensorSize,
    config: &TrainConfig,
    hot: &[bool],
) -> Vec<f32> {
    let mut change = counted_change(events, sensor, config);
    for (c, _) in change.iter_mut().zip(hot).filter(|(_, &h)| h) {
        *c = 0.0;
    }
    change
}

/// [`expected_change`] of every pixel.
fn counted_change(
    events: &events::EventSlice<'_>,
    sensor: events::SensorSize,
    config: &TrainConfig,
) -> Vec<f32> {
    let c_pos = config.event_threshold;
    match config.event_threshold_neg {
        None => events::count_frame(events, sensor, events::CountMode::Signed)
            .iter()
            .map(|c| c * c_pos)
            .collect(),
        Some(c_neg) => {
            let two = events::count_frame(events, sensor, events::CountMode::TwoChannel);
            let (pos, neg) = two.split_at(two.len() / 2);
            pos.iter()
                .zip(neg)
                .map(|(p, n)| p * c_pos - n * c_neg)
                .collect()
        }
    }
}

/// The hot pixels of the scene's events (row-major H × W; `events::hot_pixel_mask` over every
/// frame's file), or an empty mask unless `filter` (`config.event_hot_pixel_filter`). Prints how
/// many were found.
pub fn hot_pixels(data: &Dataset, filter: bool, needed_by: &str) -> Result<Vec<bool>, TrainError> {
    if !filter {
        return Ok(Vec::new());
    }
    let sensor = events::SensorSize::new(data.camera.width, data.camera.height);
    let mut all = events::EventStream::new();
    // Every event counts, wherever a file's events lie in time (which the losses check when
    // they read a frame's file for its own interval).
    for p in 0..data.frames.len() {
        if data.scene.frames[p].events.is_some() {
            all.extend_from(&read_frame_file(data, p, needed_by)?.0.as_slice());
        }
    }
    let hot = events::hot_pixel_mask(&all.as_slice(), sensor, events::HotPixelRule::default());
    let count = hot.iter().filter(|&&h| h).count();
    if count > 0 {
        println!(
            "events: {count} hot pixels (event count or net count towering over their \
             neighbours', events::hot_pixels) are not used (--event-hot-pixel-filter off to keep \
             them)"
        );
    }
    Ok(hot)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_are_weighted_by_their_polarity_threshold_and_hot_pixels_report_nothing() {
        let sensor = events::SensorSize::new(3, 1);
        let mut stream = events::EventStream::new();
        for (t, x, p) in [(1, 0, 1), (2, 0, 1), (3, 1, -1), (4, 1, 1), (5, 2, -1)] {
            stream.push(events::Event { t, x, y: 0, p });
        }
        let mut config = TrainConfig {
            event_threshold: 0.2,
            ..TrainConfig::default()
        };
        let same = expected_change(&stream.as_slice(), sensor, &config, &[]);
        assert_eq!(same, vec![0.4, 0.0, -0.2]);
        config.event_threshold_neg = Some(0.3);
        let two = expected_change(&stream.as_slice(), sensor, &config, &[]);
        assert!((two[0] - 0.4).abs() < 1e-7 && (two[1] + 0.1).abs() < 1e-7);
        assert!((two[2] + 0.3).abs() < 1e-7, "{two:?}");
        let hot = expected_change(&stream.as_slice(), sensor, &config, &[true, false, false]);
        assert_eq!(hot[0], 0.0);
        assert_eq!(hot[1..], two[1..]);
    }
}
