//! AEDAT 4 intensity frames (`FRME`): a file with events and frames reads back both, in every
//! compression; pixel formats convert to planar values; broken frame packets and files without
//! frames are refused by name.

use events::io::aedat4::Compression;
use events::io::aedat4_frames::{
    read_aedat4_frames, write_aedat4_with_frames, ApsFrame, FrameFormat,
};
use events::{Event, EventStream, SensorSize};

fn frame(k: i64, format: FrameFormat, w: u32, h: u32) -> ApsFrame {
    let n = (w * h) as usize * format.bytes_per_pixel();
    ApsFrame {
        t_us: 10_000 + 40_000 * k,
        exposure_begin_us: 5_000 + 40_000 * k,
        exposure_end_us: 15_000 + 40_000 * k + k,
        format,
        width: w,
        height: h,
        offset_x: 0,
        offset_y: 0,
        pixels: (0..n).map(|i| ((i as i64 * 7 + k) % 251) as u8).collect(),
    }
}

fn some_events() -> EventStream {
    let mut s = EventStream::new();
    for i in 0..20_000u32 {
        s.push(Event {
            t: i64::from(i) * 7,
            x: (i % 31) as u16,
            y: (i % 23) as u16,
            p: if i % 3 == 0 { 1 } else { -1 },
        });
    }
    s.sensor = Some(SensorSize::new(31, 23));
    s
}

#[test]
fn frames_and_events_read_back_in_every_compression() {
    let dir = tempfile::tempdir().expect("tempdir");
    let frames: Vec<ApsFrame> = (0..5)
        .map(|k| frame(k, FrameFormat::Gray, 31, 23))
        .collect();
    let events = some_events();
    for c in [
        Compression::None,
        Compression::Lz4,
        Compression::Lz4High,
        Compression::Zstd,
        Compression::ZstdHigh,
    ] {
        let p = dir.path().join(format!("{c:?}.aedat4"));
        write_aedat4_with_frames(&p, &events, &frames, SensorSize::new(31, 23), c).expect("write");
        let (back, sensor) = read_aedat4_frames(&p).expect("frames");
        assert_eq!(back, frames, "{c:?}");
        assert_eq!(sensor, Some(SensorSize::new(31, 23)));
        // The event stream of the same file is untouched by the frames beside it.
        let ev = events::read_events(&p).expect("events");
        assert_eq!(ev.t, events.t);
        assert_eq!(ev.x, events.x);
    }
}

#[test]
fn pixel_formats_convert_to_planar_values() {
    let mut g16 = frame(0, FrameFormat::Gray16, 2, 1);
    g16.pixels = vec![0x00, 0x00, 0xFF, 0xFF];
    assert_eq!(g16.to_planar(), vec![0.0, 1.0]);
    let mut bgr = frame(0, FrameFormat::Bgr, 1, 1);
    bgr.pixels = vec![0, 51, 255]; // blue 0, green 51, red 255
    assert_eq!(bgr.to_planar(), vec![1.0, 0.2, 0.0]);
    let mut bgra = frame(0, FrameFormat::Bgra, 1, 1);
    bgra.pixels = vec![255, 0, 0, 9];
    assert_eq!(bgra.to_planar(), vec![0.0, 0.0, 1.0]);
}

#[test]
fn broken_frame_packets_and_files_without_frames_are_refused() {
    let dir = tempfile::tempdir().expect("tempdir");
    // Events only: no FRME stream.
    let p = dir.path().join("events-only.aedat4");
    events::io::aedat4::write_aedat4(&p, &some_events(), Compression::None).expect("write");
    let msg = read_aedat4_frames(&p).expect_err("no frames").to_string();
    assert!(
        msg.contains("events-only.aedat4") && msg.contains("FRME"),
        "{msg}"
    );
    // A frame whose pixel vector is shorter than its size: the header claims more than is there.
    let p = dir.path().join("short.aedat4");
    let mut f = frame(0, FrameFormat::Gray, 8, 8);
    f.pixels.truncate(10);
    write_aedat4_with_frames(
        &p,
        &EventStream::new(),
        &[f],
        SensorSize::new(8, 8),
        Compression::None,
    )
    .expect("write");
    let msg = read_aedat4_frames(&p).expect_err("short").to_string();
    assert!(
        msg.contains("short.aedat4") && msg.contains("10 pixel bytes"),
        "{msg}"
    );
    // A truncated file names the packet's byte offset.
    let p2 = dir.path().join("cut.aedat4");
    let good = dir.path().join("good.aedat4");
    write_aedat4_with_frames(
        &good,
        &EventStream::new(),
        &[frame(0, FrameFormat::Gray, 8, 8)],
        SensorSize::new(8, 8),
        Compression::None,
    )
    .expect("write");
    let bytes = std::fs::read(&good).expect("read");
    std::fs::write(&p2, &bytes[..bytes.len() - 5]).expect("write");
    let msg = read_aedat4_frames(&p2).expect_err("cut").to_string();
    assert!(msg.contains("cut.aedat4") && msg.contains("byte"), "{msg}");
}

#[test]
fn aedat4_events_outside_the_sensor_or_back_in_time_are_refused() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mut s = some_events();
    // The description states 31×23; an event at x = 40 lies outside.
    s.x[5000] = 40;
    let p = dir.path().join("outside.aedat4");
    events::io::aedat4::write_aedat4(&p, &s, Compression::None).expect("write");
    let msg = events::read_events(&p).expect_err("outside").to_string();
    assert!(
        msg.contains("outside.aedat4") && msg.contains("(40, 9)") && msg.contains("31x23"),
        "{msg}"
    );
    // An event earlier than the one before it (in a later packet).
    let mut s = some_events();
    s.t[10_000] = 5;
    let p = dir.path().join("back.aedat4");
    events::io::aedat4::write_aedat4(&p, &s, Compression::Lz4).expect("write");
    let msg = events::read_events(&p).expect_err("back").to_string();
    assert!(
        msg.contains("back.aedat4") && msg.contains("goes back") && msg.contains("to 5 us"),
        "{msg}"
    );
}
