//! Event-based double integral (EDI; Pan et al., "Bringing a Blurry Frame Alive at High Frame-Rate
//! with an Event Camera", CVPR 2019): a blurred frame is the mean of the sharp image over its
//! exposure, and the events say how each pixel's log intensity changed from a reference time t_ref,
//! log(L(t) + ε) − log(L(t_ref) + ε) = E(t_ref → t), with E the threshold-weighted signed sum of the
//! pixel's events between the two times (C+ per positive, −C− per negative event). Hence
//!
//! B + ε = (L(t_ref) + ε) · mean_{t ∈ exposure} exp(E(t_ref → t)),
//! L(t_ref) = (B + ε) / mean_t exp(E(t_ref → t)) − ε,
//!
//! per pixel, with the mean integrated exactly over the piecewise-constant E (no time sampling).
//! It is the weight-free 2-D event deblurring: one frame at a time, no model of the scene, and every
//! event it misses (refractory period) or invents (noise) shows as a ghost.

use crate::error::{EventsError, Result};
use crate::stream::{EventSlice, SensorSize};

/// The sensor's model for [`edi_gain`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EdiConfig {
    /// C+ (log-intensity units).
    pub c_pos: f64,
    /// C− (log-intensity units, a positive number).
    pub c_neg: f64,
}

/// The exposure of one frame: `[start_us, end_us)`, deblurred to `reference_us` inside it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Exposure {
    /// First microsecond of the exposure.
    pub start_us: i64,
    /// End of the exposure (exclusive, microseconds), > `start_us`.
    pub end_us: i64,
    /// The time of the sharp image (usually the middle), in `[start_us, end_us]`.
    pub reference_us: i64,
}

/// Per pixel (row-major H × W), 1 / mean_t exp(E(t_ref → t)) over the exposure: multiply `B + ε` by
/// it to get `L(t_ref) + ε`. Events outside the exposure or the sensor are ignored; `events` must
/// be sorted by time (as every stream of this crate is).
pub fn edi_gain(
    events: &EventSlice<'_>,
    sensor: SensorSize,
    exposure: Exposure,
    config: EdiConfig,
) -> Result<Vec<f64>> {
    let Exposure {
        start_us,
        end_us,
        reference_us,
    } = exposure;
    if end_us <= start_us || !(start_us..=end_us).contains(&reference_us) {
        return Err(EventsError::arg(
            "exposure",
            format!("[{start_us}, {end_us}) µs with reference {reference_us} µs is empty or does not hold its reference"),
        ));
    }
    for (name, c) in [("c_pos", config.c_pos), ("c_neg", config.c_neg)] {
        if !(c.is_finite() && c > 0.0) {
            return Err(EventsError::arg(
                name,
                format!("{c} must be finite and > 0"),
            ));
        }
    }
    let (w, h) = (sensor.width as usize, sensor.height as usize);
    let n = w * h;
    // E(start → t) per pixel as the events arrive, the integral of exp(E) so far, and E at t_ref.
    let mut level = vec![0.0f64; n];
    let mut since_us = vec![start_us; n];
    let mut integral = vec![0.0f64; n];
    let mut at_reference: Vec<Option<f64>> = vec![None; n];
    for i in 0..events.len() {
        let t = events.t[i];
        if t < start_us || t >= end_us {
            continue;
        }
        let (x, y) = (events.x[i] as usize, events.y[i] as usize);
        if x >= w || y >= h {
            continue;
        }
        let p = y * w + x;
        if t > reference_us && at_reference[p].is_none() {
            at_reference[p] = Some(level[p]);
        }
        integral[p] += level[p].exp() * (t - since_us[p]) as f64;
        since_us[p] = t;
        level[p] += if events.p[i] > 0 {
            config.c_pos
        } else {
            -config.c_neg
        };
    }
    let duration = (end_us - start_us) as f64;
    Ok((0..n)
        .map(|p| {
            let total = integral[p] + level[p].exp() * (end_us - since_us[p]) as f64;
            let reference = at_reference[p].unwrap_or(level[p]);
            // mean_t exp(E(start → t) − E(start → t_ref)).
            duration / (total * (-reference).exp())
        })
        .collect())
}

/// Deblurs a planar linear image `(C, H, W)` (any number of planes, e.g. RGB or grey) with the
/// per-pixel gains of [`edi_gain`]: `(B + ε)·gain − ε`, clamped at 0.
pub fn apply_gain(blurred: &[f32], gain: &[f64], log_eps: f64) -> Result<Vec<f32>> {
    let n = gain.len();
    if n == 0 || !blurred.len().is_multiple_of(n) {
        return Err(EventsError::arg(
            "blurred",
            format!(
                "length {} is not a whole number of {n}-pixel planes",
                blurred.len()
            ),
        ));
    }
    Ok(blurred
        .iter()
        .enumerate()
        .map(|(i, &b)| {
            (((f64::from(b.max(0.0)) + log_eps) * gain[i % n] - log_eps).max(0.0)) as f32
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stream::{Event, EventStream};

    fn stream(events: &[(i64, i8)]) -> EventStream {
        let mut s = EventStream::new();
        for &(t, p) in events {
            s.push(Event { t, x: 0, y: 0, p });
        }
        s
    }

    #[test]
    fn a_step_in_the_middle_of_the_exposure_is_undone() {
        // The pixel is at 1 for the first half of [0, 1000) µs and at e^0.4 for the second (two
        // positive events at 500 µs): B = (1 + e^0.4)/2 (ε = 0 for the arithmetic).
        let s = stream(&[(500, 1), (500, 1)]);
        let config = EdiConfig {
            c_pos: 0.2,
            c_neg: 0.2,
        };
        let sensor = SensorSize::new(1, 1);
        let blurred = (1.0 + 0.4f64.exp()) / 2.0;
        for (reference_us, sharp) in [(250, 1.0), (750, 0.4f64.exp())] {
            let exposure = Exposure {
                start_us: 0,
                end_us: 1000,
                reference_us,
            };
            let gain = edi_gain(&s.as_slice(), sensor, exposure, config).expect("edi");
            assert!(
                (blurred * gain[0] - sharp).abs() < 1e-12,
                "{}",
                blurred * gain[0]
            );
        }
        // Without events the frame is its own sharp image.
        let quiet = EventStream::new();
        let exposure = Exposure {
            start_us: 0,
            end_us: 1000,
            reference_us: 500,
        };
        let gain = edi_gain(&quiet.as_slice(), sensor, exposure, config).expect("edi");
        assert_eq!(gain, vec![1.0]);
        let bad = Exposure {
            reference_us: 2000,
            ..exposure
        };
        assert!(edi_gain(&quiet.as_slice(), sensor, bad, config).is_err());
    }
}
