//! AEDAT 4 and Prophesee readers: round trips / hand-encoded words, cross-format agreement, bad
//! input and a fuzz test over random bytes (Err, never a panic, never a header-sized allocation).

use events::io::aedat4::{write_aedat4, Aedat4Reader, Compression};
use events::io::prophesee::PropheseeReader;
use events::io::{read_all, EventReader};
use events::{read_events, write_events, Event, EventStream, SensorSize};

#[path = "common/random_stream.rs"]
mod random_stream;
use random_stream::random_stream;

/// `n` random events on a 346×260 sensor, 0–6 µs apart from 5 ms on.
fn sample(n: usize) -> EventStream {
    random_stream(n, SensorSize::new(346, 260), 5_000, 7, 7)
}

#[test]
fn aedat4_round_trips_with_every_compression_and_agrees_with_text_and_npz() {
    let dir = tempfile::tempdir().expect("tempdir");
    let s = sample(20_000);
    for c in [
        Compression::None,
        Compression::Lz4,
        Compression::Lz4High,
        Compression::Zstd,
        Compression::ZstdHigh,
    ] {
        let p = dir.path().join(format!("{c:?}.aedat4"));
        write_aedat4(&p, &s, c).expect("write");
        let r = read_events(&p).expect("read");
        assert_eq!(r, s, "compression {c:?}");
    }
    // Same stream through text and npz.
    let pt = dir.path().join("s.txt");
    let pn = dir.path().join("s.npz");
    write_events(&pt, &s).expect("text");
    write_events(&pn, &s).expect("npz");
    let from_text = read_events(&pt).expect("text");
    let mut from_npz = read_events(&pn).expect("npz");
    from_npz.sensor = s.sensor;
    let from_aedat = read_events(dir.path().join("None.aedat4")).expect("aedat");
    assert_eq!(from_text, from_aedat);
    assert_eq!(from_npz, from_aedat);
}

/// More packets than one read-ahead batch (16 × 8192 events), so later batches are decompressed in
/// the background while earlier ones are decoded.
#[test]
fn aedat4_reads_many_batches_in_order_and_raises_a_late_error_after_the_packets_before_it() {
    let dir = tempfile::tempdir().expect("tempdir");
    let s = sample(40 * 8192 + 5);
    for c in [Compression::Lz4, Compression::Zstd] {
        let p = dir.path().join(format!("many-{c:?}.aedat4"));
        write_aedat4(&p, &s, c).expect("write");
        assert_eq!(read_events(&p).expect("read"), s, "compression {c:?}");
        // Inside a one-thread rayon pool the reader must not wait on a task that pool would run.
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .expect("pool");
        let inside = pool.install(|| read_events(&p)).expect("read in pool");
        assert_eq!(inside, s, "compression {c:?}, inside a pool");
        // Truncated in its last quarter: every whole packet before the cut is delivered, then the
        // error.
        let bytes = std::fs::read(&p).expect("bytes");
        let cut = &bytes[..bytes.len() * 3 / 4];
        let mut r = Aedat4Reader::new(cut, cut.len() as u64, "cut.aedat4").expect("header");
        let mut got = EventStream::new();
        let err = loop {
            match r.read_chunk(&mut got, 5000) {
                Ok(0) => panic!("truncated file read to the end without an error"),
                Ok(_) => {}
                Err(e) => break e,
            }
        };
        assert!(err.to_string().contains("cut.aedat4"), "{err}");
        assert!(
            got.len() > 16 * 8192,
            "only {} events before the error",
            got.len()
        );
        assert_eq!(got.len() % 8192, 0, "a partial packet was delivered");
        assert_eq!(got.t[..], s.t[..got.len()]);
    }
}

/// `bytes_read` counts the packets handed out, not the ones read ahead (a progress bar, and
/// `read_all`'s size estimate, would otherwise run ahead of the events).
#[test]
fn aedat4_bytes_read_follows_the_decoded_packets_not_the_read_ahead() {
    let dir = tempfile::tempdir().expect("tempdir");
    let s = sample(40 * 8192);
    let p = dir.path().join("progress.aedat4");
    write_aedat4(&p, &s, Compression::Zstd).expect("write");
    let mut r = Aedat4Reader::open(&p).expect("open");
    let total = r.total_bytes().expect("total");
    let mut got = EventStream::new();
    assert_eq!(r.read_chunk(&mut got, 2 * 8192).expect("chunk"), 2 * 8192);
    let early = r.bytes_read();
    // Two of forty packets handed out (the read-ahead has read most of the file by now).
    assert!(
        early > 0 && early < total / 10,
        "{early} of {total} bytes after 2 of 40 packets"
    );
    while r.read_chunk(&mut got, 8192).expect("chunk") > 0 {}
    let end = r.bytes_read();
    assert!(end > 9 * total / 10 && end <= total, "{end} of {total}");
    assert!(got.t == s.t && got.x == s.x && got.y == s.y && got.p == s.p);
}

#[test]
fn aedat4_bad_input_is_an_error() {
    let dir = tempfile::tempdir().expect("tempdir");
    let p = dir.path().join("a.aedat4");
    write_aedat4(&p, &sample(100), Compression::None).expect("write");
    let bytes = std::fs::read(&p).expect("read");
    let open = |b: &[u8]| -> Result<EventStream, events::EventsError> {
        let mut r = Aedat4Reader::new(b, b.len() as u64, "mem.aedat4")?;
        read_all(&mut r)
    };
    assert!(open(&bytes).is_ok());
    assert!(open(&bytes[..bytes.len() - 5]).is_err(), "truncated packet");
    assert!(open(&bytes[..10]).is_err(), "truncated magic");
    let mut wrong = bytes.clone();
    wrong[0] = b'X';
    assert!(open(&wrong).is_err(), "wrong magic");
    // Absurd header length: must fail before allocating 4 GiB.
    let mut absurd = bytes.clone();
    absurd[14..18].copy_from_slice(&u32::MAX.to_le_bytes());
    let e = open(&absurd).expect_err("absurd header");
    assert!(e.to_string().contains("header length"), "{e}");
    // Absurd packet size.
    let hlen = u32::from_le_bytes([bytes[14], bytes[15], bytes[16], bytes[17]]) as usize;
    let mut absurd = bytes.clone();
    absurd[18 + hlen + 4..18 + hlen + 8].copy_from_slice(&u32::MAX.to_le_bytes());
    assert!(open(&absurd).is_err(), "absurd packet size");
}

fn evt2_words(s: &EventStream) -> Vec<u8> {
    let mut out = b"% evt 2.0\n% geometry 346x260\n% end\n".to_vec();
    let mut high = -1i64;
    for e in s.iter() {
        if e.t >> 6 != high {
            high = e.t >> 6;
            out.extend_from_slice(&((0x8u32 << 28) | (high as u32 & 0x0FFF_FFFF)).to_le_bytes());
        }
        let ty = if e.p > 0 { 1u32 } else { 0 };
        let w = (ty << 28) | (((e.t & 0x3F) as u32) << 22) | ((e.x as u32) << 11) | e.y as u32;
        out.extend_from_slice(&w.to_le_bytes());
    }
    out
}

fn evt3_words(s: &EventStream) -> Vec<u8> {
    let mut out = b"% format EVT3;height=260;width=346\n% end\n".to_vec();
    let mut push = |w: u16| out.extend_from_slice(&w.to_le_bytes());
    for e in s.iter() {
        push((0x8 << 12) | ((e.t >> 12) & 0xFFF) as u16);
        push((0x6 << 12) | (e.t & 0xFFF) as u16);
        push(e.y);
        push((0x2 << 12) | (u16::from(e.p > 0) << 11) | e.x);
    }
    out
}

#[test]
fn prophesee_evt2_evt3_dat_decode() {
    let s = sample(3000);
    let w2 = evt2_words(&s);
    let mut r = PropheseeReader::new(&w2[..], "mem.raw", false).expect("evt2");
    assert_eq!(r.format(), "evt2");
    let e2 = read_all(&mut r).expect("evt2 read");
    assert_eq!(e2, s);
    // EVT 3.0 times are 24-bit: use times below 2^24 µs.
    let w3 = evt3_words(&s);
    let mut r = PropheseeReader::new(&w3[..], "mem.raw", false).expect("evt3");
    assert_eq!(r.format(), "evt3");
    let e3 = read_all(&mut r).expect("evt3 read");
    assert_eq!(e3, s);
    // EVT 3.0 vectors: base x 100, VECT_12 mask 0b1010_0000_0001 -> x 100, 109, 111; then VECT_8
    // 0b0000_0011 -> x 112, 113; TIME_HIGH wrap-around unrolled.
    let mut words = b"% evt 3.0\n".to_vec();
    for w in [
        0x8FFFu16,
        0x6005,
        0x0007,
        0x3800 | 100,
        0x4000 | 0b1010_0000_0001,
        0x5003,
        0x8000,
        0x6001,
        0x2000 | 5,
    ] {
        words.extend_from_slice(&w.to_le_bytes());
    }
    let v = read_all(&mut PropheseeReader::new(&words[..], "v.raw", false).expect("open"))
        .expect("read");
    assert_eq!(v.x, vec![100, 109, 111, 112, 113, 5]);
    assert_eq!(v.y, vec![7; 6]);
    assert_eq!(v.p, vec![1, 1, 1, 1, 1, -1]);
    assert_eq!(v.t[0], (0xFFF << 12) | 5);
    assert_eq!(v.t[5], (1 << 24) | 1);
    // .dat
    let mut dat = b"% Date 2020\n% Height 260\n% Width 346\n".to_vec();
    dat.extend_from_slice(&[0x0C, 8]);
    for e in s.iter() {
        dat.extend_from_slice(&(e.t as u32).to_le_bytes());
        let d = (e.x as u32) | ((e.y as u32) << 14) | (u32::from(e.p > 0) << 28);
        dat.extend_from_slice(&d.to_le_bytes());
    }
    let mut r = PropheseeReader::new(&dat[..], "mem.dat", true).expect("dat");
    assert_eq!(read_all(&mut r).expect("dat read"), s);
    // Truncated word.
    let mut r = PropheseeReader::new(&dat[..dat.len() - 3], "mem.dat", true).expect("dat");
    assert!(read_all(&mut r).is_err());
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(256))]
    #[test]
    fn readers_never_panic_on_random_bytes(
        body in proptest::collection::vec(proptest::prelude::any::<u8>(), 0..512),
        prefix in 0usize..4,
    ) {
        // Random bytes, optionally behind a valid magic/header so the decoders get exercised.
        let mut a = Vec::new();
        if prefix & 1 == 1 { a.extend_from_slice(events::io::aedat4::MAGIC); }
        a.extend_from_slice(&body);
        if let Ok(mut r) = Aedat4Reader::new(&a[..], a.len() as u64, "fuzz.aedat4") { let _ = read_all(&mut r); }
        let mut p = Vec::new();
        if prefix & 2 == 2 { p.extend_from_slice(b"% evt 2.0\n"); }
        p.extend_from_slice(&body);
        for dat in [false, true] {
            if let Ok(mut r) = PropheseeReader::new(&p[..], "fuzz.raw", dat) { let _ = read_all(&mut r); }
        }
        let mut e3 = b"% evt 3.0\n".to_vec();
        e3.extend_from_slice(&body);
        if let Ok(mut r) = PropheseeReader::new(&e3[..], "fuzz.raw", false) { let _ = read_all(&mut r); }
    }
}

/// A stream whose times span several 2^24 µs wraps of the EVT 3.0 counter, with jumps of exactly
/// one wrap, of several wraps, across TIME_HIGH boundaries and repeated timestamps.
fn long_stream() -> EventStream {
    let mut s = sample(5000);
    let jumps = [
        0i64,
        1,
        4095,
        4096,
        1 << 24,
        (1 << 24) - 1,
        (3 << 24) + 17,
        1 << 12,
        (1 << 24) + 4096,
        63,
        64,
    ];
    let mut extra = 0i64;
    for i in 0..s.len() {
        if i % 450 == 0 {
            extra += jumps[(i / 450) % jumps.len()];
        }
        s.t[i] += extra;
    }
    s
}

#[test]
fn prophesee_writers_round_trip_losslessly() {
    use events::io::prophesee::{encode, write_dat, write_raw, PropheseeFormat};
    let dir = tempfile::tempdir().expect("tempdir");
    let long = long_stream();
    let span = long.t[long.len() - 1] - long.t[0];
    assert!(span > 5 << 24, "the stream spans {span} us");
    for (name, s) in [("short", sample(20_000)), ("long", long)] {
        for (fmt, ext) in [
            (PropheseeFormat::Evt2, "raw"),
            (PropheseeFormat::Evt3, "raw"),
            (PropheseeFormat::Dat, "dat"),
        ] {
            let p = dir.path().join(format!("{name}_{fmt:?}.{ext}"));
            if fmt == PropheseeFormat::Dat {
                write_dat(&p, &s).expect("write dat");
            } else {
                write_raw(&p, &s, fmt).expect("write raw");
            }
            let mut r = PropheseeReader::open(&p).expect("open");
            assert_eq!(r.encoding(), fmt, "{name}");
            let back = read_all(&mut r).expect("read");
            assert_eq!(back, s, "{name} {fmt:?}");
            // The in-memory encoder writes the same bytes as the file writer.
            let bytes = std::fs::read(&p).expect("bytes");
            assert_eq!(encode(&s, fmt).expect("encode"), bytes, "{name} {fmt:?}");
        }
    }
    // EVT 3.0 words are emitted only on change: one TIME_HIGH + TIME_LOW + ADDR_Y + ADDR_X for
    // the first event, then one ADDR_X per event on the same row and time.
    let mut same = EventStream::new();
    for x in 0..10u16 {
        same.push(Event {
            t: 77,
            x,
            y: 3,
            p: 1,
        });
    }
    let bytes = encode(&same, PropheseeFormat::Evt3).expect("encode");
    let body = bytes.len() - bytes.windows(6).position(|w| w == b"% end\n").expect("end") - 6;
    assert_eq!(body, 2 * (3 + 10));
}

#[test]
fn every_format_reads_the_same_stream() {
    let dir = tempfile::tempdir().expect("tempdir");
    let s = sample(20_000);
    let mut first: Option<EventStream> = None;
    for ext in ["txt", "npz", "aedat4", "raw", "dat"] {
        let p = dir.path().join(format!("s.{ext}"));
        write_events(&p, &s).expect("write");
        let mut r = read_events(&p).expect("read");
        // npz stores no sensor size.
        r.sensor = r.sensor.or(s.sensor);
        assert_eq!(r, s, "{ext}");
        if let Some(f) = &first {
            assert_eq!(&r, f, "{ext}");
        }
        first.get_or_insert(r);
    }
    // EVT 2.0 through write_raw.
    let p = dir.path().join("s2.raw");
    events::io::prophesee::write_raw(&p, &s, events::io::prophesee::PropheseeFormat::Evt2)
        .expect("evt2");
    assert_eq!(read_events(&p).expect("read evt2"), s);
}

#[test]
fn prophesee_writers_refuse_what_the_format_cannot_hold() {
    use events::io::prophesee::{write_dat, write_raw, PropheseeFormat};
    use events::EventsError;
    let dir = tempfile::tempdir().expect("tempdir");
    let one = |t: i64, x: u16, y: u16| {
        let mut s = EventStream::new();
        s.push(Event { t, x, y, p: 1 });
        s
    };
    let raw = dir.path().join("bad.raw");
    let dat = dir.path().join("bad.dat");
    let is_arg = |r: Result<(), EventsError>| matches!(r, Err(EventsError::InvalidArgument { .. }));
    for fmt in [PropheseeFormat::Evt2, PropheseeFormat::Evt3] {
        assert!(write_raw(&raw, &one(0, 2047, 2047), fmt).is_ok(), "{fmt:?}");
        assert!(is_arg(write_raw(&raw, &one(0, 2048, 0), fmt)), "{fmt:?} x");
        assert!(is_arg(write_raw(&raw, &one(0, 0, 2048), fmt)), "{fmt:?} y");
        assert!(
            is_arg(write_raw(&raw, &one(-1, 0, 0), fmt)),
            "{fmt:?} t < 0"
        );
    }
    assert!(is_arg(write_raw(
        &raw,
        &one(1 << 34, 0, 0),
        PropheseeFormat::Evt2
    )));
    assert!(write_dat(&dat, &one(u32::MAX as i64, 16383, 16383)).is_ok());
    assert!(is_arg(write_dat(&dat, &one(0, 16384, 0))), "dat x");
    assert!(is_arg(write_dat(&dat, &one(0, 0, 16384))), "dat y");
    assert!(
        is_arg(write_dat(&dat, &one(u32::MAX as i64 + 1, 0, 0))),
        "dat t"
    );
    // EVT 3.0 cannot encode decreasing times.
    let mut back = one(10, 0, 0);
    back.push(Event {
        t: 9,
        x: 0,
        y: 0,
        p: 1,
    });
    assert!(matches!(
        write_raw(&raw, &back, PropheseeFormat::Evt3),
        Err(EventsError::NonMonotonic { index: 1, .. })
    ));
    // write_events dispatches on the extension.
    assert!(is_arg(write_events(&raw, &one(0, 4000, 0))));
    assert!(is_arg(write_events(&dat, &one(0, 20000, 0))));
}
