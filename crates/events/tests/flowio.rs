//! Flow-file round trips and bad-input errors.

use events::flowio::*;

fn sample_flow(w: usize, h: usize) -> Flow {
    let mut f = Flow::zeros(w, h);
    for y in 0..h {
        for x in 0..w {
            // Multiples of 1/64 so both PNG encodings (1/128 DSEC, 1/64 KITTI) are exact.
            f.set(
                x,
                y,
                (x as f32 - 3.0) * 0.25 + 1.0 / 64.0,
                (y as f32) * -0.5,
            );
        }
    }
    f
}

#[test]
fn every_format_round_trips() {
    let dir = tempfile::tempdir().expect("tempdir");
    let f = sample_flow(7, 5);
    for ext in ["flo", "npy", "exr", "png"] {
        let p = dir.path().join(format!("f.{ext}"));
        write_flow(&p, &f).expect("write");
        let g = read_flow(&p).expect("read");
        assert_eq!(f, g, "format {ext}");
    }
    let p = dir.path().join("k.png");
    let valid: Vec<bool> = (0..35).map(|i| i % 3 != 0).collect();
    write_flow_png(&p, &f, Some(&valid), FlowPngKind::Kitti).expect("write");
    let (g, v) = read_flow_png(&p, FlowPngKind::Kitti).expect("read");
    assert_eq!(f, g);
    assert_eq!(valid, v);
}

#[test]
fn npy_hwc_layout_is_read() {
    use npyz::WriterBuilder;
    let dir = tempfile::tempdir().expect("tempdir");
    let p = dir.path().join("hwc.npy");
    let f = sample_flow(4, 3);
    let mut vals = Vec::new();
    for y in 0..3 {
        for x in 0..4 {
            let (u, v) = f.at(x, y);
            vals.push(u as f64);
            vals.push(v as f64);
        }
    }
    let mut file = std::fs::File::create(&p).expect("create");
    let mut w = npyz::WriteOptions::<f64>::new()
        .default_dtype()
        .shape(&[3, 4, 2])
        .writer(&mut file)
        .begin_nd()
        .expect("npy");
    w.extend(vals).expect("write");
    w.finish().expect("finish");
    assert_eq!(read_flow_npy(&p).expect("read"), f);
}

#[test]
fn bad_flo_files_are_errors() {
    let p = std::path::Path::new("mem.flo");
    let good = encode_flo(&sample_flow(3, 2));
    assert!(decode_flo(&good, p).is_ok());
    assert!(decode_flo(&good[..good.len() - 1], p).is_err());
    assert!(decode_flo(&good[..8], p).is_err());
    let mut bad = good.clone();
    bad[0] = b'X';
    assert!(decode_flo(&bad, p).is_err());
    // Absurd header: 2^30 x 2^30 must be rejected before any allocation.
    let mut absurd = good.clone();
    absurd[4..8].copy_from_slice(&(1i32 << 30).to_le_bytes());
    absurd[8..12].copy_from_slice(&(1i32 << 30).to_le_bytes());
    let e = decode_flo(&absurd, p).expect_err("absurd");
    assert!(e.to_string().contains("exceeds"), "{e}");
    let mut neg = good;
    neg[4..8].copy_from_slice(&(-3i32).to_le_bytes());
    assert!(decode_flo(&neg, p).is_err());
}

#[test]
fn colour_code_follows_middlebury_wheel() {
    let mut f = Flow::zeros(4, 1);
    f.set(0, 0, 1.0, 0.0); // rightwards: red end of the wheel
    f.set(1, 0, 0.0, 1.0); // downwards: yellow-orange
    f.set(2, 0, -1.0, 0.0); // leftwards: cyan-ish
    let rgb = flow_to_rgb(&f, Some(1.0));
    assert_eq!(&rgb[0..3], &[255, 0, 0]);
    assert!(
        rgb[3] == 255 && rgb[4] > 200 && rgb[5] == 0,
        "down {:?}",
        &rgb[3..6]
    );
    assert_eq!(rgb[6], 0, "left has no red: {:?}", &rgb[6..9]);
    assert_eq!(&rgb[9..12], &[255, 255, 255], "zero flow is white");
}

proptest::proptest! {
    #[test]
    fn flo_decoder_never_panics(bytes in proptest::collection::vec(proptest::prelude::any::<u8>(), 0..256)) {
        let _ = decode_flo(&bytes, std::path::Path::new("fuzz.flo"));
    }
}

/// Writes `bytes` to `name` in a fresh temporary directory and runs every path-based flow reader
/// on it: each must return (Ok or Err), never panic.
fn read_with_every_flow_reader(bytes: &[u8], name: &str) {
    let dir = tempfile::tempdir().expect("tempdir");
    let p = dir.path().join(name);
    std::fs::write(&p, bytes).expect("write");
    let _ = read_flo(&p);
    let _ = read_flow_npy(&p);
    let _ = read_flow_png(&p, FlowPngKind::Dsec);
    let _ = read_flow_png(&p, FlowPngKind::Kitti);
    let _ = read_flow_exr(&p);
    let _ = read_flow(&p);
}

#[test]
fn absurd_npy_header_is_an_error_not_an_allocation() {
    // A valid npy header claiming (2, 100000, 100000) f32 (80 GB) followed by 16 bytes of data.
    let header = "{'descr': '<f4', 'fortran_order': False, 'shape': (2, 100000, 100000), }";
    let mut h = header.to_string();
    while !(10 + h.len() + 1).is_multiple_of(64) {
        h.push(' ');
    }
    h.push('\n');
    let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
    bytes.extend_from_slice(&(h.len() as u16).to_le_bytes());
    bytes.extend_from_slice(h.as_bytes());
    bytes.extend_from_slice(&[0u8; 16]);
    let dir = tempfile::tempdir().expect("tempdir");
    let p = dir.path().join("huge.npy");
    std::fs::write(&p, &bytes).expect("write");
    assert!(
        read_flow_npy(&p).is_err(),
        "an 80 GB claim in a tiny file was accepted"
    );
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(64))]
    #[test]
    fn path_flow_readers_never_panic_on_random_bytes(
        bytes in proptest::collection::vec(proptest::prelude::any::<u8>(), 0..300),
        ext in proptest::sample::select(vec!["flo", "npy", "png", "exr"]),
    ) {
        read_with_every_flow_reader(&bytes, &format!("fuzz.{ext}"));
    }

    #[test]
    fn path_flow_readers_never_panic_on_damaged_valid_files(
        cut in 0usize..400,
        flip in 0usize..400,
        ext in proptest::sample::select(vec!["flo", "npy", "png", "exr"]),
    ) {
        // Start from a valid file of the format, truncate it and flip one byte.
        let dir = tempfile::tempdir().expect("tempdir");
        let p = dir.path().join(format!("ok.{ext}"));
        let f = sample_flow(5, 4);
        match ext {
            "flo" => write_flo(&p, &f).expect("write"),
            "npy" => write_flow_npy(&p, &f).expect("write"),
            "png" => write_flow_png(&p, &f, None, FlowPngKind::Kitti).expect("write"),
            _ => write_flow_exr(&p, &f).expect("write"),
        }
        let mut bytes = std::fs::read(&p).expect("read");
        if !bytes.is_empty() {
            let i = flip % bytes.len();
            bytes[i] ^= 0xA5;
            bytes.truncate(cut.min(bytes.len()));
        }
        read_with_every_flow_reader(&bytes, &format!("fuzz.{ext}"));
    }
}
