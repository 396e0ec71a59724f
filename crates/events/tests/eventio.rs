//! Event-file round trips, representations against slow oracles, and bad input.

use events::io::{npz, text, EventReader};
use events::{
    count_frame, read_events, time_slice_frames, voxel_grid, write_events, CountMode, Event,
    EventStream, SensorSize,
};

#[path = "common/random_stream.rs"]
mod random_stream;
use random_stream::random_stream;

/// `n` random events on a 40×30 sensor, 0–49 µs apart from 1 s on.
fn sample_stream(n: usize) -> EventStream {
    random_stream(n, SensorSize::new(40, 30), 1_000_000, 50, 12345)
}

#[test]
fn text_and_npz_round_trip_and_agree() {
    let dir = tempfile::tempdir().expect("tempdir");
    let s = sample_stream(5000);
    let pt = dir.path().join("e.txt");
    let pn = dir.path().join("e.npz");
    write_events(&pt, &s).expect("write text");
    write_events(&pn, &s).expect("write npz");
    let a = read_events(&pt).expect("read text");
    assert_eq!(a, s);
    let mut b = read_events(&pn).expect("read npz");
    assert_eq!(b.sensor, None, "npz does not state the sensor size");
    b.sensor = s.sensor;
    assert_eq!(b, s);
}

#[test]
fn text_reader_streams_in_chunks_and_skips_headers() {
    let body = "# comment\nt x y p\n0.000001 1 2 1\n0.5 3 4 0\n% other comment\n1.0000005 5 6 1\n";
    let mut r = text::TextReader::new(std::io::Cursor::new(body), "mem.txt").expect("open");
    let mut s = EventStream::new();
    assert_eq!(r.read_chunk(&mut s, 2).expect("chunk"), 2);
    assert_eq!(r.read_chunk(&mut s, 2).expect("chunk"), 1);
    assert_eq!(r.read_chunk(&mut s, 2).expect("chunk"), 0);
    assert_eq!(s.t, vec![1, 500_000, 1_000_001]);
    assert_eq!(s.p, vec![1, -1, 1]);
    assert_eq!(r.sensor(), None);
    let with_size = "346 260\n0.1 1 2 1\n";
    let r = text::TextReader::new(std::io::Cursor::new(with_size), "mem.txt").expect("open");
    assert_eq!(r.sensor(), Some(SensorSize::new(346, 260)));
}

#[test]
fn text_reader_names_the_bad_line() {
    let body = "0.1 1 2 1\n0.2 1 2 7\n";
    let mut r = text::TextReader::new(std::io::Cursor::new(body), "bad.txt").expect("open");
    let mut s = EventStream::new();
    let e = r.read_chunk(&mut s, 10).expect_err("bad polarity");
    let msg = e.to_string();
    assert!(msg.contains("bad.txt") && msg.contains("line 2"), "{msg}");
    let body = "0.1 70000 2 1\n";
    assert!(text::TextReader::new(std::io::Cursor::new(body), "bad.txt").is_err());
    let body = "0.0 1 2 1\n0.1 70000 2 1\n";
    let mut r = text::TextReader::new(std::io::Cursor::new(body), "bad.txt").expect("open");
    assert!(r.read_chunk(&mut s, 10).is_err());
}

#[test]
fn npz_with_float_seconds_and_truncation() {
    use std::io::Write;
    let dir = tempfile::tempdir().expect("tempdir");
    let p = dir.path().join("f.npz");
    // Hand-made npz: t as float64 seconds, x/y int64, p bool.
    let f = std::fs::File::create(&p).expect("create");
    let mut zw = zip::ZipWriter::new(f);
    let opts = zip::write::SimpleFileOptions::default()
        .compression_method(zip::CompressionMethod::Deflated);
    let arrays: [(&str, &str, Vec<u8>); 4] = [
        (
            "t.npy",
            "<f8",
            [0.5f64, 0.75]
                .iter()
                .flat_map(|v| v.to_le_bytes())
                .collect(),
        ),
        (
            "x.npy",
            "<i8",
            [3i64, 4].iter().flat_map(|v| v.to_le_bytes()).collect(),
        ),
        (
            "y.npy",
            "<i8",
            [5i64, 6].iter().flat_map(|v| v.to_le_bytes()).collect(),
        ),
        ("p.npy", "|b1", vec![1u8, 0]),
    ];
    for (name, descr, data) in &arrays {
        zw.start_file(*name, opts).expect("start");
        let dict = format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': (2,), }}");
        let pad = (64 - (10 + dict.len() + 1) % 64) % 64;
        let mut h = b"\x93NUMPY\x01\x00".to_vec();
        h.extend_from_slice(&((dict.len() + pad + 1) as u16).to_le_bytes());
        h.extend_from_slice(dict.as_bytes());
        h.extend(std::iter::repeat_n(b' ', pad));
        h.push(b'\n');
        zw.write_all(&h).expect("header");
        zw.write_all(data).expect("data");
    }
    zw.finish().expect("finish");
    let s = read_events(&p).expect("read");
    assert_eq!(s.t, vec![500_000, 750_000]);
    assert_eq!(s.x, vec![3, 4]);
    assert_eq!(s.p, vec![1, -1]);
    // Truncate the written file: must be an error, not a panic.
    let good = dir.path().join("g.npz");
    npz::write_npz(&good, &sample_stream(100)).expect("write");
    let bytes = std::fs::read(&good).expect("read");
    for cut in [10, bytes.len() / 2, bytes.len() - 30] {
        let bad = dir.path().join(format!("cut{cut}.npz"));
        std::fs::write(&bad, &bytes[..cut]).expect("write");
        assert!(read_events(&bad).is_err(), "cut at {cut}");
    }
}

/// Slow oracle: the E-RAFT formula, one event at a time, in f64.
fn voxel_oracle(s: &EventStream, sensor: SensorSize, bins: usize, t0: i64, t1: i64) -> Vec<f64> {
    let (w, h) = (sensor.width as usize, sensor.height as usize);
    let mut g = vec![0.0f64; bins * w * h];
    for e in s.iter() {
        let tn = ((bins - 1) as f64 * (e.t - t0) as f64 / (t1 - t0) as f64)
            .clamp(0.0, (bins - 1) as f64);
        for b in 0..bins {
            let wgt = (1.0 - (b as f64 - tn).abs()).max(0.0);
            g[b * w * h + e.y as usize * w + e.x as usize] +=
                wgt * if e.p > 0 { 1.0 } else { -1.0 };
        }
    }
    g
}

#[test]
fn voxel_grid_matches_oracle() {
    let s = sample_stream(3000);
    let sensor = SensorSize::new(40, 30);
    let (t0, t1) = (s.t[0], *s.t.last().expect("non-empty") + 1);
    for bins in [1, 2, 5] {
        let g = voxel_grid(&s.as_slice(), sensor, bins, t0, t1, false).expect("voxel");
        let o = voxel_oracle(&s, sensor, bins, t0, t1);
        for (a, b) in g.iter().zip(&o) {
            // f32 accumulation of at most a few events per voxel: 1e-4 absolute.
            assert!((*a as f64 - b).abs() < 1e-4, "bins {bins}: {a} vs {b}");
        }
    }
    let g = voxel_grid(&s.as_slice(), sensor, 5, t0, t1, true).expect("voxel");
    let nz: Vec<f64> = g.iter().filter(|v| **v != 0.0).map(|v| *v as f64).collect();
    let mean = nz.iter().sum::<f64>() / nz.len() as f64;
    let var = nz.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / nz.len() as f64;
    assert!(
        mean.abs() < 1e-5 && (var - 1.0).abs() < 1e-4,
        "mean {mean} var {var}"
    );
    assert!(voxel_grid(&s.as_slice(), sensor, 0, t0, t1, false).is_err());
    assert!(voxel_grid(&s.as_slice(), sensor, 3, t1, t0, false).is_err());
}

#[test]
fn count_and_slice_frames() {
    let sensor = SensorSize::new(3, 2);
    let s = EventStream::from_events(
        [
            Event {
                t: 0,
                x: 0,
                y: 0,
                p: 1,
            },
            Event {
                t: 10,
                x: 0,
                y: 0,
                p: -1,
            },
            Event {
                t: 20,
                x: 0,
                y: 0,
                p: 1,
            },
            Event {
                t: 90,
                x: 2,
                y: 1,
                p: -1,
            },
            Event {
                t: 95,
                x: 9,
                y: 9,
                p: -1,
            },
        ],
        None,
    );
    let v = s.as_slice();
    assert_eq!(
        count_frame(&v, sensor, CountMode::Signed)[..6],
        [1.0, 0.0, 0.0, 0.0, 0.0, -1.0]
    );
    assert_eq!(count_frame(&v, sensor, CountMode::Unsigned)[0], 3.0);
    let two = count_frame(&v, sensor, CountMode::TwoChannel);
    assert_eq!((two[0], two[6], two[11]), (2.0, 1.0, 1.0));
    let sl = time_slice_frames(&v, sensor, 2, 0, 100).expect("slices");
    assert_eq!(sl, vec![1., 0., 0., 0., 0., 0., 0., 0., 0., 0., 0., 1.]);
}

proptest::proptest! {
    #[test]
    fn text_reader_never_panics(bytes in proptest::collection::vec(proptest::prelude::any::<u8>(), 0..300)) {
        if let Ok(mut r) = text::TextReader::new(std::io::Cursor::new(bytes), "fuzz.txt") {
            let mut s = EventStream::new();
            while let Ok(n) = r.read_chunk(&mut s, 7) { if n == 0 { break; } }
        }
    }

    #[test]
    fn npz_reader_never_panics(bytes in proptest::collection::vec(proptest::prelude::any::<u8>(), 0..400)) {
        let dir = tempfile::tempdir().expect("tempdir");
        let p = dir.path().join("fuzz.npz");
        std::fs::write(&p, &bytes).expect("write");
        let _ = read_events(&p);
    }
}

#[test]
fn text_events_outside_the_sensor_line_or_back_in_time_are_refused_by_line() {
    let dir = tempfile::tempdir().expect("tempdir");
    let write = |name: &str, text: &str| {
        let p = dir.path().join(name);
        std::fs::write(&p, text).expect("write");
        p
    };
    let p = write("outside.txt", "10 10\n0.001 3 4 1\n0.002 12 4 0\n");
    let msg = events::read_events(&p).expect_err("outside").to_string();
    assert!(
        msg.contains("outside.txt") && msg.contains("line 3") && msg.contains("(12, 4)"),
        "{msg}"
    );
    let p = write("back.txt", "0.003 3 4 1\n0.002 2 4 0\n");
    let msg = events::read_events(&p).expect_err("back").to_string();
    assert!(msg.contains("line 2") && msg.contains("goes back"), "{msg}");
    // Equal times are in order; without a sensor line any coordinate is accepted.
    let p = write("ok.txt", "0.002 3 4 1\n0.002 2000 4 0\n");
    assert_eq!(events::read_events(&p).expect("ok").len(), 2);
}
