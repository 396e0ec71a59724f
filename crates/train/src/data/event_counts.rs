//! Events as the losses read them: a window's events as the log-intensity change they report
//! (C+ per positive, C− per negative event), and the scene's hot pixels, whose events are left out.

use super::dataset::Dataset;
use super::event_files::read_frame_file;
use crate::config::TrainConfig;
use crate::TrainError;

/// C+·n⁺ − C−·n⁻ per pixel (row-major H × W) of `events`: the log-intensity change they report,
/// with C± from `config` ([`TrainConfig::event_thresholds`]; C·(n⁺ − n⁻) when C− is not set).
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

/// [`expected_change`] of the events of `slice` in `[from_us, to_us)`, then, with
/// `config.event_refractory_us`, [`unconstrain_refractory_silence`] for the events that long
/// before `from_us`: what the event loss holds one interval between sub-exposure renders to.
pub(super) fn interval_change(
    slice: &events::EventSlice<'_>,
    (from_us, to_us): (i64, i64),
    sensor: events::SensorSize,
    config: &TrainConfig,
    hot: &[bool],
) -> Vec<f32> {
    let during = slice.window(from_us, to_us);
    let mut expected = expected_change(&during, sensor, config, hot);
    let refractory_us = f64::from(config.event_refractory_us).round() as i64;
    if refractory_us > 0 {
        let before = slice.window(from_us - refractory_us, from_us);
        unconstrain_refractory_silence(&mut expected, &before, &during, sensor, hot);
    }
    expected
}

/// Leaves unconstrained ([`crate::loss::event::UNCONSTRAINED`]) every pixel of `expected` (the
/// change [`expected_change`] read from the events `during` an interval) that fired no event
/// during the interval but one `before` it — the events of the sensor's refractory period before
/// the interval's start: such a pixel's silence may be the refractory period's (crossings
/// dropped while its reference level still moved), not a steady intensity. Hot pixels (`hot`;
/// empty: none) keep what [`expected_change`] gave them. Returns how many pixels it freed.
fn unconstrain_refractory_silence(
    expected: &mut [f32],
    before: &events::EventSlice<'_>,
    during: &events::EventSlice<'_>,
    sensor: events::SensorSize,
    hot: &[bool],
) -> usize {
    // Events outside the sensor are skipped, as `events::count_frame` skips them.
    let (w, h) = (sensor.width as usize, sensor.height as usize);
    let pixel = |e: events::Event| {
        let (x, y) = (usize::from(e.x), usize::from(e.y));
        (x < w && y < h).then_some(y * w + x)
    };
    let mut fired = vec![false; expected.len()];
    for p in during.iter().filter_map(pixel) {
        fired[p] = true;
    }
    let mut freed = 0;
    for p in before.iter().filter_map(pixel) {
        let is_hot = hot.get(p).copied().unwrap_or(false);
        // `expected[p]` is 0 for a silent pixel not yet freed (NaN once freed).
        if !fired[p] && !is_hot && expected[p] == 0.0 {
            expected[p] = crate::loss::event::UNCONSTRAINED;
            freed += 1;
        }
    }
    freed
}

/// The events' modulation of one sub-exposure render's slice `(from_s, to_s, anchor_s)` of an
/// exposure: per pixel (row-major H × W), the mean over the slice of exp(E(anchor → t)), E the
/// threshold-weighted signed sum of the pixel's events between the anchor (the render's time) and
/// t — the reciprocal of `events::edi_gain` over the slice. The pixels `hot` marks report no
/// change (modulation 1). Thresholds C± as [`expected_change`].
pub(super) fn slice_modulation(
    events: &events::EventSlice<'_>,
    sensor: events::SensorSize,
    (from_s, to_s, anchor_s): (f64, f64, f64),
    config: &TrainConfig,
    hot: &[bool],
) -> Result<Vec<f32>, TrainError> {
    let us = |t: f64| (t * 1e6).round() as i64;
    let exposure = events::Exposure {
        start_us: us(from_s),
        end_us: us(to_s).max(us(from_s) + 1),
        reference_us: us(anchor_s),
    };
    let (c_pos, c_neg) = config.event_thresholds();
    let edi = events::EdiConfig {
        c_pos: f64::from(c_pos),
        c_neg: f64::from(c_neg),
    };
    let gain = events::edi_gain(events, sensor, exposure, edi)
        .map_err(|e| TrainError::Config(format!("the events' modulation of an exposure: {e}")))?;
    Ok(gain
        .iter()
        .enumerate()
        .map(|(p, &g)| {
            if hot.get(p).copied().unwrap_or(false) {
                1.0
            } else {
                (1.0 / g) as f32
            }
        })
        .collect())
}

/// [`expected_change`] of every pixel; [`crate::loss::event::UNCONSTRAINED`] where the pixel
/// fired both polarities and `config.event_ignore_mixed` is on.
fn counted_change(
    events: &events::EventSlice<'_>,
    sensor: events::SensorSize,
    config: &TrainConfig,
) -> Vec<f32> {
    let (c_pos, c_neg) = config.event_thresholds();
    match (config.event_threshold_neg, config.event_ignore_mixed) {
        (None, false) => events::count_frame(events, sensor, events::CountMode::Signed)
            .iter()
            .map(|c| c * c_pos)
            .collect(),
        (_, ignore_mixed) => {
            let two = events::count_frame(events, sensor, events::CountMode::TwoChannel);
            let (pos, neg) = two.split_at(two.len() / 2);
            pos.iter()
                .zip(neg)
                .map(|(&p, &n)| {
                    if ignore_mixed && p > 0.0 && n > 0.0 {
                        crate::loss::event::UNCONSTRAINED
                    } else {
                        p * c_pos - n * c_neg
                    }
                })
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

    /// Three pixels in a row: two ON events at pixel 0, one OFF and one ON at pixel 1, one OFF at
    /// pixel 2; and a configuration with C = 0.2 that reads pixel 1 through its net count.
    fn three_pixels() -> (events::SensorSize, events::EventStream, TrainConfig) {
        let mut stream = events::EventStream::new();
        for (t, x, p) in [(1, 0, 1), (2, 0, 1), (3, 1, -1), (4, 1, 1), (5, 2, -1)] {
            stream.push(events::Event { t, x, y: 0, p });
        }
        let config = TrainConfig {
            event_threshold: 0.2,
            event_ignore_mixed: false,
            ..TrainConfig::default()
        };
        (events::SensorSize::new(3, 1), stream, config)
    }

    #[test]
    fn counts_are_weighted_by_their_polarity_threshold_and_hot_pixels_report_nothing() {
        let (sensor, stream, mut config) = three_pixels();
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

    #[test]
    fn the_threshold_scale_multiplies_every_events_change_and_the_modulation() {
        let (sensor, stream, mut config) = three_pixels();
        config.event_threshold_neg = Some(0.3);
        config.event_threshold_scale = 1.25;
        assert_eq!(config.event_thresholds(), (0.25, 0.375));
        let scaled = expected_change(&stream.as_slice(), sensor, &config, &[]);
        assert!((scaled[0] - 0.5).abs() < 1e-7, "{scaled:?}");
        assert!((scaled[1] + 0.125).abs() < 1e-7, "{scaled:?}");
        assert!((scaled[2] + 0.375).abs() < 1e-7, "{scaled:?}");
        // One ON event at 750 µs of a slice [0, 1000) anchored at 500 µs: M = 0.75 + 0.25·e^{1.25 C}.
        let mut one = events::EventStream::new();
        one.push(events::Event {
            t: 750,
            x: 0,
            y: 0,
            p: 1,
        });
        let m = slice_modulation(&one.as_slice(), sensor, (0.0, 1e-3, 5e-4), &config, &[])
            .expect("a valid slice");
        let want = 0.75 + 0.25 * 0.25f64.exp();
        assert!((f64::from(m[0]) - want).abs() < 1e-6, "{m:?}");
        // Scale 1 reads the thresholds themselves, bit for bit.
        config.event_threshold_scale = 1.0;
        assert_eq!(config.event_thresholds(), (0.2, 0.3));
    }

    #[test]
    fn a_pixel_of_both_polarities_is_unconstrained_only_when_asked() {
        // Pixel 1 fired one OFF and one ON event: a net count of zero, or no constraint.
        let (sensor, stream, mut config) = three_pixels();
        let net = expected_change(&stream.as_slice(), sensor, &config, &[]);
        assert_eq!(net, vec![0.4, 0.0, -0.2]);
        config.event_ignore_mixed = true;
        let mixed = expected_change(&stream.as_slice(), sensor, &config, &[]);
        assert!(mixed[1].is_nan(), "{mixed:?}");
        assert_eq!((mixed[0], mixed[2]), (0.4, -0.2));
        // A hot pixel still reports no change.
        let hot = expected_change(&stream.as_slice(), sensor, &config, &[false, true, false]);
        assert_eq!(hot[1], 0.0);
    }

    #[test]
    fn a_silent_pixel_is_freed_only_after_an_event_just_before_the_interval() {
        // The interval is [10, 20) µs, the refractory window before it [9, 10). Pixel 0 fired at
        // 9 and stays silent: freed. Pixel 1 fired at 9 and again at 12: held to its count. Pixel
        // 2 fired only long before (not in `before`): held to no change. Pixel 3 is hot and fired
        // at 9: it keeps the no change a hot pixel reports. The event at x = 6 is outside the
        // 4-pixel sensor: skipped (not read as pixel 2 of a next row).
        let sensor = events::SensorSize::new(4, 1);
        let mut stream = events::EventStream::new();
        for (t, x, p) in [
            (2, 2, 1),
            (9, 0, 1),
            (9, 1, -1),
            (9, 3, 1),
            (9, 6, 1),
            (12, 1, 1),
        ] {
            stream.push(events::Event { t, x, y: 0, p });
        }
        let config = TrainConfig {
            event_threshold: 0.2,
            ..TrainConfig::default()
        };
        let slice = stream.as_slice();
        let during = slice.window(10, 20);
        let hot = [false, false, false, true];
        let mut expected = expected_change(&during, sensor, &config, &hot);
        assert_eq!(expected, vec![0.0, 0.2, 0.0, 0.0]);
        assert_eq!(
            interval_change(&slice, (10, 20), sensor, &config, &hot),
            expected
        );
        let before = slice.window(9, 10);
        let freed = unconstrain_refractory_silence(&mut expected, &before, &during, sensor, &hot);
        assert_eq!(freed, 1);
        assert!(expected[0].is_nan(), "{expected:?}");
        assert_eq!(expected[1..], [0.2, 0.0, 0.0]);
        let config = TrainConfig {
            event_refractory_us: 1.0,
            ..config
        };
        let read = interval_change(&slice, (10, 20), sensor, &config, &hot);
        assert!(read[0].is_nan() && read[1..] == expected[1..], "{read:?}");
    }

    #[test]
    fn a_slice_is_modulated_by_the_mean_of_exp_e_from_its_anchor() {
        // Slice [0, 1000) µs anchored at 500 µs. Pixel 0: one ON event at 750 µs, so exp(E) is 1
        // for three quarters of the slice and e^C for the last: M = 0.75 + 0.25·e^0.2. Pixel 1:
        // one OFF event at 250 µs (before the anchor), so E(anchor → t) is +C before it: M =
        // 0.25·e^0.2 + 0.75. Pixel 2: an ON event, but a hot pixel: 1.
        let sensor = events::SensorSize::new(3, 1);
        let mut stream = events::EventStream::new();
        for (t, x, p) in [(250, 1, -1), (600, 2, 1), (750, 0, 1)] {
            stream.push(events::Event { t, x, y: 0, p });
        }
        let config = TrainConfig {
            event_threshold: 0.2,
            ..TrainConfig::default()
        };
        let hot = [false, false, true];
        let m = slice_modulation(&stream.as_slice(), sensor, (0.0, 1e-3, 5e-4), &config, &hot)
            .expect("a valid slice");
        let want = 0.75 + 0.25 * 0.2f64.exp();
        assert!((f64::from(m[0]) - want).abs() < 1e-6, "{m:?}");
        assert!((f64::from(m[1]) - want).abs() < 1e-6, "{m:?}");
        assert_eq!(m[2], 1.0);
    }
}
