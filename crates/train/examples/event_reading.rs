//! How well does a reading of a pixel's events predict its log-intensity change? Between two
//! consecutive sharp references (frame k's mid-exposure to frame k+1's, exactly frame k's event
//! file) the true change of every pixel is log(Y_{k+1} + ε) − log(Y_k + ε), Y the luma of the
//! linear render. Each reading turns the pixel's events into a change: every event as g
//! thresholds, or an event that follows its pixel's previous event within two refractory periods
//! (where the sensor may have dropped crossings) as b thresholds. Printed per reading, over the
//! pixels whose events are all of one polarity: the least-squares slope of the true change on the
//! reading, the mean absolute error, the mean shortfall |true| − |reading| and the fraction of
//! pixels the reading over-states by more than half a threshold (where a lower bound with the
//! default margin would pull the change past the truth).
//!
//! ```text
//! cargo run --release -p train --example event_reading -- DATA [REFRACTORY_US]
//! ```

use std::path::PathBuf;

/// One reading's tallies.
#[derive(Default, Clone, Copy)]
struct Tally {
    sxy: f64,
    sxx: f64,
    abs: f64,
    short: f64,
    over: f64,
    n: f64,
}

fn luma_log(img: &[f32], plane: usize, eps: f64) -> Vec<f64> {
    (0..plane)
        .map(|i| {
            let y: f64 = (0..3)
                .map(|c| train::loss::event::LUMA[c] * f64::from(img[c * plane + i].max(0.0)))
                .sum();
            (y + eps).ln()
        })
        .collect()
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let dir = PathBuf::from(
        args.first()
            .ok_or("usage: event_reading DATA [REFRACTORY_US]")?,
    );
    let data = train::data::load_dataset(&dir)?;
    let refractory: i64 = args
        .get(1)
        .map(|s| s.parse())
        .transpose()?
        .or(data.recorded("refractory_us").map(|r| r as i64))
        .unwrap_or(0);
    let c = data.recorded("event_threshold").unwrap_or(0.2);
    let (w, h) = (data.camera.width as usize, data.camera.height as usize);
    let plane = w * h;
    let in_sensor = |e: &events::Event| (e.x as usize) < w && (e.y as usize) < h;
    let eps = 1e-3;
    // Readings: (label, g for an isolated event, b for an event within 2r of its predecessor).
    let readings: Vec<(String, f64, f64)> = vec![
        ("g 1".into(), 1.0, 1.0),
        ("g 1.25".into(), 1.25, 1.25),
        ("g 1.5".into(), 1.5, 1.5),
        ("iso 1, burst 1.5".into(), 1.0, 1.5),
        ("iso 1, burst 2".into(), 1.0, 2.0),
        ("iso 1, burst 2.5".into(), 1.0, 2.5),
        ("iso 1, burst 3".into(), 1.0, 3.0),
        ("iso 1.1, burst 2".into(), 1.1, 2.0),
    ];
    let mut tallies = vec![Tally::default(); readings.len()];
    let mut previous: Option<events::EventStream> = None;
    let mut bursts = 0usize;
    let mut all_events = 0usize;
    for k in 0..data.frames.len().saturating_sub(1) {
        let Some(rel) = &data.scene.frames[k].events else {
            continue;
        };
        let (Some(a), Some(b)) = (&data.frames[k].sharp, &data.frames[k + 1].sharp) else {
            continue;
        };
        let path = scene::Scene::resolve(&data.dir, rel);
        let stream =
            events::io::read_events_with(&path, &train::data::event_read_options(&data, &path))?;
        let (la, lb) = (luma_log(a, plane, eps), luma_log(b, plane, eps));
        // Last event time per pixel, seeded from the previous file.
        let mut last = vec![i64::MIN; plane];
        if let Some(prev) = &previous {
            for e in prev.iter().filter(in_sensor) {
                last[e.y as usize * w + e.x as usize] = e.t;
            }
        }
        let mut pos = vec![0usize; plane];
        let mut neg = vec![0usize; plane];
        let mut read = vec![vec![0.0f64; plane]; readings.len()];
        for e in stream.iter().filter(in_sensor) {
            let i = e.y as usize * w + e.x as usize;
            let burst = last[i] != i64::MIN && e.t - last[i] < 2 * refractory;
            last[i] = e.t;
            bursts += usize::from(burst);
            all_events += 1;
            let s = if e.p > 0 { 1.0 } else { -1.0 };
            if e.p > 0 {
                pos[i] += 1;
            } else {
                neg[i] += 1;
            }
            for (r, &(_, g, b)) in read.iter_mut().zip(&readings) {
                r[i] += s * c * if burst { b } else { g };
            }
        }
        for i in 0..plane {
            if (pos[i] == 0) == (neg[i] == 0) {
                continue;
            }
            let truth = lb[i] - la[i];
            for (t, r) in tallies.iter_mut().zip(&read) {
                let x = r[i];
                t.sxy += x * truth;
                t.sxx += x * x;
                t.abs += (truth - x).abs();
                t.short += (truth.abs() - x.abs()) * f64::from(truth.signum() == x.signum());
                t.over += f64::from(x.signum() * (x - truth) > 0.5 * c);
                t.n += 1.0;
            }
        }
        previous = Some(stream);
    }
    println!(
        "{} events, {:.1} % within 2 refractory periods ({} µs) of their pixel's previous; C {c}",
        all_events,
        100.0 * bursts as f64 / all_events.max(1) as f64,
        refractory
    );
    println!("reading | slope true/read | mean |err| | mean shortfall | over-stated (> C/2)");
    for ((label, ..), t) in readings.iter().zip(&tallies) {
        println!(
            "{label:>18} | {:.3} | {:.4} | {:.4} | {:.2} %",
            t.sxy / t.sxx,
            t.abs / t.n,
            t.short / t.n,
            100.0 * t.over / t.n
        );
    }
    Ok(())
}
