//! Simulator acceptance: the analytic brightening pixel, count scaling with speed, determinism.

use events::{simulate_sequence, EsimConfig, EventSimulator};

fn exact(c: f32) -> EsimConfig {
    EsimConfig {
        c_pos: c,
        c_neg: c,
        sigma: 0.0,
        ..EsimConfig::default()
    }
}

#[test]
fn brightening_pixel_gives_analytic_count_and_times() {
    // One pixel of a 3x2 frame brightens so that log(I + eps) rises by exactly 1.1 between t = 0 and
    // t = 1000 us; with C = 0.2 the crossings are at L0 + 0.2k, k = 1..5, i.e. t = 1000·0.2k/1.1 us.
    let cfg = exact(0.2);
    let eps = cfg.log_eps;
    let i0 = 0.2f32;
    let i1 = ((i0 + eps).ln() + 1.1).exp() - eps;
    let f0 = vec![i0; 6];
    let mut f1 = f0.clone();
    f1[4] = i1; // x = 1, y = 1
    let s = simulate_sequence(cfg, 3, 2, &[0, 1000], &[&f0, &f1]).expect("simulate");
    assert_eq!(s.len(), 5, "events {:?}", s.t);
    for k in 0..5 {
        let expected = 1000.0 * 0.2 * (k + 1) as f64 / 1.1;
        assert!(
            (s.t[k] as f64 - expected).abs() <= 1.0,
            "event {k} at {} us, expected {expected:.1} us (tolerance 1 us: rounding to us)",
            s.t[k]
        );
        assert_eq!((s.x[k], s.y[k], s.p[k]), (1, 1, 1));
    }
    // Darkening back by 1.1 from the reference (which sits at L0 + 1.0): crossings at L0 + 0.8 .. L0 + 0.0,
    // i.e. 5 negative events between t = 1000 and 2000 us.
    let mut sim = EventSimulator::new(cfg, 3, 2).expect("sim");
    sim.add_frame(0, &f0).expect("f0");
    sim.add_frame(1000, &f1).expect("f1");
    let back = sim.add_frame(2000, &f0).expect("f2");
    assert_eq!(back.len(), 5);
    assert!(back.p.iter().all(|&p| p == -1));
    // First negative crossing at L0 + 0.8: 0.3 below L0 + 1.1, out of 1.1 over 1000 us.
    assert!((back.t[0] as f64 - (1000.0 + 1000.0 * 0.3 / 1.1)).abs() <= 1.0);
}

#[test]
fn refractory_period_drops_close_events() {
    let mut cfg = exact(0.2);
    cfg.refractory_us = 300;
    let eps = cfg.log_eps;
    let f0 = vec![0.2f32];
    let f1 = vec![((0.2f32 + eps).ln() + 1.1).exp() - eps];
    let s = simulate_sequence(cfg, 1, 1, &[0, 1000], &[&f0, &f1]).expect("simulate");
    // Crossings at 182, 364, 545, 727, 909 us: kept 182, 545, 909 (gaps >= 300 us).
    assert_eq!(s.len(), 3, "{:?}", s.t);
}

/// A 1D sinusoidal texture translating horizontally by `speed` pixels per frame.
fn translating_frames(w: usize, h: usize, frames: usize, speed: f32) -> Vec<Vec<f32>> {
    (0..frames)
        .map(|k| {
            let shift = speed * k as f32;
            (0..w * h)
                .map(|i| {
                    let x = (i % w) as f32 - shift;
                    let y = (i / w) as f32;
                    0.5 + 0.3 * (x * 0.2).sin() * (0.8 + 0.2 * (y * 0.3).cos())
                })
                .collect()
        })
        .collect()
}

#[test]
fn translating_pattern_count_scales_with_speed() {
    // Shifts of 20, 40 and 80 px over 40 frames: each pixel sweeps many thresholds, so the loss to
    // threshold quantisation (< C per pixel) is small against the swept variation.
    let (w, h, n) = (64, 16, 41);
    let times: Vec<i64> = (0..n as i64).map(|k| k * 1000).collect();
    let mut counts = Vec::new();
    for speed in [0.5f32, 1.0, 2.0] {
        let frames = translating_frames(w, h, n, speed);
        let refs: Vec<&[f32]> = frames.iter().map(Vec::as_slice).collect();
        let s = simulate_sequence(
            EsimConfig {
                seed: 3,
                ..EsimConfig::default()
            },
            w,
            h,
            &times,
            &refs,
        )
        .expect("simulate");
        s.validate(None).expect("valid");
        counts.push(s.len() as f64);
    }
    // Total log-intensity variation swept is proportional to speed, so the count doubles with the
    // speed up to threshold quantisation and linear interpolation between frames; allow 15 % around the factor 2.
    for k in 0..2 {
        let ratio = counts[k + 1] / counts[k];
        assert!(
            (1.7..=2.3).contains(&ratio),
            "counts {counts:?}, ratio {ratio}"
        );
    }
}

#[test]
fn same_seed_same_events_any_thread_count() {
    let (w, h, n) = (40, 12, 6);
    let frames = translating_frames(w, h, n, 0.7);
    let refs: Vec<&[f32]> = frames.iter().map(Vec::as_slice).collect();
    let times: Vec<i64> = (0..n as i64).map(|k| k * 2000).collect();
    let cfg = EsimConfig {
        seed: 42,
        shot_noise_hz: 50.0,
        refractory_us: 100,
        ..EsimConfig::default()
    };
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("pool")
            .install(|| simulate_sequence(cfg, w, h, &times, &refs).expect("simulate"))
    };
    let a = run(1);
    let b = run(2);
    assert!(!a.is_empty());
    assert_eq!(a, b);
    let c =
        simulate_sequence(EsimConfig { seed: 43, ..cfg }, w, h, &times, &refs).expect("simulate");
    assert_ne!(a, c);
}

#[test]
fn bad_frames_are_errors() {
    let mut sim = EventSimulator::new(EsimConfig::default(), 2, 2).expect("sim");
    assert!(sim.add_frame(0, &[0.0; 3]).is_err());
    assert!(sim.add_frame(0, &[0.0, f32::NAN, 0.0, 0.0]).is_err());
    sim.add_frame(10, &[0.1; 4]).expect("first");
    assert!(sim.add_frame(10, &[0.2; 4]).is_err());
    assert!(EventSimulator::new(
        EsimConfig {
            c_pos: 0.0,
            ..EsimConfig::default()
        },
        2,
        2
    )
    .is_err());
}

#[test]
fn hot_pixels_fire_at_their_rate_whatever_the_scene() {
    // A static 20 × 10 scene: every event comes from the 10 hot pixels (5 % of 200).
    let cfg = EsimConfig {
        hot_pixel_fraction: 0.05,
        hot_pixel_rate_hz: 1000.0,
        ..exact(0.2)
    };
    let frame = vec![0.3f32; 200];
    let times: Vec<i64> = (0..5).map(|k| k * 2500).collect();
    let refs: Vec<&[f32]> = (0..5).map(|_| frame.as_slice()).collect();
    let s = simulate_sequence(cfg, 20, 10, &times, &refs).expect("simulate");
    let mut pixels: Vec<(u16, u16)> = s.x.iter().copied().zip(s.y.iter().copied()).collect();
    pixels.sort_unstable();
    pixels.dedup();
    assert_eq!(pixels.len(), 10, "hot pixels {pixels:?}");
    // 10 ms at 1 kHz: exactly 10 events per pixel (the intervals (t_prev, t] tile (0, 10 ms]),
    // each pixel with one polarity and its events 1000 ± 1 µs apart (rounding to µs).
    for &(x, y) in &pixels {
        let mine: Vec<usize> = (0..s.len())
            .filter(|&i| (s.x[i], s.y[i]) == (x, y))
            .collect();
        assert_eq!(mine.len(), 10, "pixel ({x}, {y})");
        assert!(mine.iter().all(|&i| s.p[i] == s.p[mine[0]]));
        for w in mine.windows(2) {
            let gap = s.t[w[1]] - s.t[w[0]];
            assert!((999..=1001).contains(&gap), "gap {gap} µs at ({x}, {y})");
        }
    }
    // Without hot pixels the static scene is silent.
    let quiet = EsimConfig {
        hot_pixel_fraction: 0.0,
        ..cfg
    };
    assert!(simulate_sequence(quiet, 20, 10, &times, &refs)
        .expect("simulate")
        .is_empty());
    let bad = EsimConfig {
        hot_pixel_fraction: 1.5,
        ..cfg
    };
    assert!(EventSimulator::new(bad, 20, 10).is_err());
}

#[test]
fn background_activity_adds_events_of_both_polarities() {
    let cfg = EsimConfig {
        shot_noise_hz: 50.0,
        ..exact(0.2)
    };
    let frame = vec![0.3f32; 64 * 64];
    let times: Vec<i64> = (0..11).map(|k| k * 10_000).collect();
    let refs: Vec<&[f32]> = (0..11).map(|_| frame.as_slice()).collect();
    let s = simulate_sequence(cfg, 64, 64, &times, &refs).expect("simulate");
    // 4096 pixels × 50 Hz × 0.1 s = 20 480 expected; Poisson, so within 5 % (≈ 7 σ).
    let n = s.len() as f64;
    assert!((n - 20_480.0).abs() < 0.05 * 20_480.0, "{n} events");
    let on = s.p.iter().filter(|&&p| p > 0).count() as f64;
    assert!((on / n - 0.5).abs() < 0.05, "ON share {}", on / n);
}
