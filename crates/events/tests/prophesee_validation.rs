//! The Prophesee EVT reader refuses what is not an EVT stream: a `.raw` file that does not state
//! its encoding (unless the caller gives it), and inside a stream every word the EVT 2.0 / 3.0
//! specifications do not allow, each error naming the file and the word's byte offset; a lenient
//! reader skips exactly those words and counts them.

use events::io::prophesee::{encode, PropheseeFormat, PropheseeReader, RawEncoding};
use events::io::{open_events_with, read_all, read_events_with, EventReader, ReadOptions};
use events::{read_events, EventStream, EventsError, SensorSize};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

#[path = "common/random_stream.rs"]
mod random_stream;
use random_stream::random_stream;

/// `n` seeded random bytes whose first is not `%` (so no header line).
fn random_bytes(n: usize, seed: u64) -> Vec<u8> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut b: Vec<u8> = (0..n).map(|_| rng.gen()).collect();
    if b[0] == b'%' {
        b[0] = 0;
    }
    b
}

fn strict() -> ReadOptions {
    ReadOptions::default()
}

fn given(format: RawEncoding, lenient: bool) -> ReadOptions {
    ReadOptions {
        raw_format: Some(format),
        lenient,
    }
}

/// Decodes `bytes` (named `name`) with `options` in small chunks, so that words straddle many
/// buffers.
fn decode(
    bytes: &[u8],
    name: &str,
    options: &ReadOptions,
) -> Result<(EventStream, u64), EventsError> {
    let mut r = PropheseeReader::with_options(bytes, name, false, options)?;
    let mut s = EventStream::new();
    while r.read_chunk(&mut s, 3)? > 0 {}
    Ok((s, r.skipped_words()))
}

/// The byte offset of a [`EventsError::BadWord`], with its message; panics on anything else.
fn bad_word(r: Result<(EventStream, u64), EventsError>) -> (u64, String) {
    match r {
        Err(e @ EventsError::BadWord { offset, .. }) => (offset, e.to_string()),
        Err(e) => panic!("expected a bad word, got {e}"),
        Ok((s, _)) => panic!("expected a bad word, decoded {} events", s.len()),
    }
}

fn evt3(header: &str, words: &[u16]) -> Vec<u8> {
    let mut out = header.as_bytes().to_vec();
    for w in words {
        out.extend_from_slice(&w.to_le_bytes());
    }
    out
}

fn evt2(header: &str, words: &[u32]) -> Vec<u8> {
    let mut out = header.as_bytes().to_vec();
    for w in words {
        out.extend_from_slice(&w.to_le_bytes());
    }
    out
}

const H3: &str = "% evt 3.0\n% geometry 10x8\n% end\n";
const H2: &str = "% evt 2.0\n% geometry 10x8\n% end\n";

#[test]
fn random_bytes_without_a_header_are_refused_naming_the_file_and_the_option() {
    let dir = tempfile::tempdir().expect("tempdir");
    let p = dir.path().join("x.raw");
    std::fs::write(&p, random_bytes(3000, 1)).expect("write");
    let e = read_events(&p).expect_err("a header-less .raw file decoded");
    let msg = e.to_string();
    assert!(matches!(e, EventsError::Format { .. }), "{msg}");
    assert!(msg.contains("x.raw"), "{msg}");
    assert!(msg.contains("--format evt2|evt3"), "{msg}");
    assert!(msg.contains("ReadOptions::raw_format"), "{msg}");
}

#[test]
fn random_bytes_with_a_stated_encoding_are_refused_at_a_bad_word() {
    let dir = tempfile::tempdir().expect("tempdir");
    for (i, header) in [
        "% evt 3.0\n",
        "% evt 2.0\n",
        "% format EVT3;height=480;width=640\n",
    ]
    .iter()
    .enumerate()
    {
        for seed in 0..20 {
            let mut bytes = header.as_bytes().to_vec();
            bytes.extend_from_slice(&random_bytes(3000, seed));
            let p = dir.path().join(format!("h{i}-{seed}.raw"));
            std::fs::write(&p, &bytes).expect("write");
            let e = read_events(&p).expect_err("random words decoded");
            let msg = e.to_string();
            assert!(matches!(e, EventsError::BadWord { .. }), "{msg}");
            assert!(msg.contains(&format!("h{i}-{seed}.raw: byte ")), "{msg}");
        }
    }
    // The same bytes header-less with the encoding given: refused as well, unless lenient.
    let p = dir.path().join("given.raw");
    std::fs::write(&p, random_bytes(3000, 2)).expect("write");
    for f in [RawEncoding::Evt2, RawEncoding::Evt3] {
        let e = read_events_with(&p, &given(f, false)).expect_err("random words decoded");
        assert!(matches!(e, EventsError::BadWord { .. }), "{e}");
        let mut r = open_events_with(&p, &given(f, true)).expect("open");
        read_all(r.as_mut()).expect("lenient read");
        assert!(
            r.skipped_words() > 100,
            "{f:?}: {} skipped",
            r.skipped_words()
        );
    }
}

#[test]
fn the_encoding_given_reads_a_headerless_file_and_conflicts_are_refused() {
    let s = random_stream(2000, SensorSize::new(346, 260), 5_000, 7, 3);
    for (enc, fmt) in [
        (RawEncoding::Evt2, PropheseeFormat::Evt2),
        (RawEncoding::Evt3, PropheseeFormat::Evt3),
    ] {
        let bytes = encode(&s, fmt).expect("encode");
        let body = &bytes[bytes.windows(6).position(|w| w == b"% end\n").expect("end") + 6..];
        let (back, skipped) = decode(body, "bare.raw", &given(enc, false)).expect("decode");
        assert_eq!(
            (back.t, back.x, back.y, back.p),
            (s.t.clone(), s.x.clone(), s.y.clone(), s.p.clone())
        );
        assert_eq!(skipped, 0);
        // With the header, the same encoding given is accepted and the other one refused.
        assert!(decode(&bytes, "h.raw", &given(enc, false)).is_ok());
        let other = if enc == RawEncoding::Evt2 {
            RawEncoding::Evt3
        } else {
            RawEncoding::Evt2
        };
        let e = decode(&bytes, "h.raw", &given(other, false)).expect_err("conflict");
        assert!(e.to_string().contains("h.raw: the header states"), "{e}");
    }
    // The encoding applies to .raw files only.
    let dir = tempfile::tempdir().expect("tempdir");
    let txt = dir.path().join("s.txt");
    events::write_events(&txt, &s).expect("text");
    let e = open_events_with(&txt, &given(RawEncoding::Evt3, false))
        .err()
        .expect("refused");
    assert!(
        matches!(
            e,
            EventsError::InvalidArgument {
                name: "raw_format",
                ..
            }
        ),
        "{e}"
    );
    let dat = dir.path().join("s.dat");
    events::write_events(&dat, &s).expect("dat");
    assert!(open_events_with(&dat, &given(RawEncoding::Evt2, false)).is_err());
    // Lenient alone changes nothing for other formats.
    let lenient = ReadOptions {
        raw_format: None,
        lenient: true,
    };
    assert_eq!(
        read_events_with(&txt, &lenient).expect("text"),
        read_events(&txt).expect("text")
    );
}

#[test]
fn evt3_bad_words_are_named_with_their_byte_offset() {
    let h = H3.len() as u64;
    let opts = strict();
    // Reserved types 0x1, 0x9, 0xB, 0xC, 0xD at the fourth word.
    for ty in [0x1u16, 0x9, 0xB, 0xC, 0xD] {
        let b = evt3(H3, &[0x8000, 0x6000, 0x0001, (ty << 12) | 0x123, 0x2005]);
        let (off, msg) = bad_word(decode(&b, "r.raw", &opts));
        assert_eq!(off, h + 6, "{msg}");
        assert!(
            msg.contains(&format!("r.raw: byte {}: EVT 3.0 word", h + 6)),
            "{msg}"
        );
        assert!(msg.contains(&format!("reserved type {ty:#x}")), "{msg}");
    }
    // Outside the header's 10x8 sensor: a column, a row, the last valid element of a vector.
    let (off, msg) = bad_word(decode(
        &evt3(H3, &[0x8000, 0x0003, 0x2009, 0x200A]),
        "o.raw",
        &opts,
    ));
    assert_eq!(off, h + 6);
    assert!(
        msg.contains("(x=10, y=3) lies outside the header's 10x8 sensor"),
        "{msg}"
    );
    let (off, _) = bad_word(decode(&evt3(H3, &[0x0008, 0x2001]), "o.raw", &opts));
    assert_eq!(off, h + 2);
    // Base 5: VECT_8 elements 0..=4 are columns 5..=9 (inside), element 5 is column 10.
    assert!(decode(&evt3(H3, &[0x0001, 0x3005, 0x501F]), "v.raw", &opts).is_ok());
    let (off, msg) = bad_word(decode(&evt3(H3, &[0x0001, 0x3005, 0x503F]), "v.raw", &opts));
    assert_eq!(off, h + 4);
    assert!(msg.contains("(x=10, y=1)"), "{msg}");
    // A vector whose elements beyond the sensor are all invalid is fine.
    assert!(decode(&evt3(H3, &[0x0001, 0x3008, 0x4003]), "v.raw", &opts).is_ok());
    // Without the geometry, the 2048-pixel address range bounds vectors.
    let (_, msg) = bad_word(decode(
        &evt3("% evt 3.0\n", &[0x0001, 0x37FF, 0x4002]),
        "v.raw",
        &opts,
    ));
    assert!(
        msg.contains("(x=2048, y=1) lies outside the 2048x2048 address range"),
        "{msg}"
    );
    // A vector before any base, an event before any row.
    let (off, msg) = bad_word(decode(&evt3(H3, &[0x8000, 0x0001, 0x4001]), "b.raw", &opts));
    assert_eq!(off, h + 4);
    assert!(msg.contains("no base"), "{msg}");
    let (off, msg) = bad_word(decode(&evt3(H3, &[0x8000, 0x6001, 0x2001]), "y.raw", &opts));
    assert_eq!(off, h + 4);
    assert!(msg.contains("no row"), "{msg}");
    // TIME_HIGH backwards by one period: refused; from the top of the counter to its bottom
    // (within ten periods): a wrap.
    let (off, msg) = bad_word(decode(
        &evt3(H3, &[0x8800, 0x0001, 0x2001, 0x87FF]),
        "t.raw",
        &opts,
    ));
    assert_eq!(off, h + 6);
    assert!(
        msg.contains("TIME_HIGH 0x7ff after 0x800 sends time back by 4096 us"),
        "{msg}"
    );
    let (s, _) = decode(
        &evt3(H3, &[0x8FF8, 0x0001, 0x2001, 0x8002, 0x2002]),
        "w.raw",
        &opts,
    )
    .expect("a wrap");
    assert_eq!(s.t, vec![0xFF8 << 12, (1 << 24) | (0x002 << 12)]);
    assert!(
        bad_word(decode(&evt3(H3, &[0x8FF4, 0x8000]), "w.raw", &opts))
            .1
            .contains("TIME_HIGH")
    );
    // TIME_LOW steps back inside one TIME_HIGH period: legal, decoded as written.
    let (s, _) = decode(
        &evt3(H3, &[0x8001, 0x0002, 0x6100, 0x2001, 0x60F0, 0x2003]),
        "l.raw",
        &opts,
    )
    .expect("a TIME_LOW step-back");
    assert_eq!(s.t, vec![0x1100, 0x10F0]);
    // CONTINUED_4, EXT_TRIGGER, OTHERS, CONTINUED_12 are valid and carry no CD event.
    let (s, _) = decode(
        &evt3(H3, &[0x0001, 0x7003, 0xA021, 0xE123, 0xF456, 0x2004]),
        "k.raw",
        &opts,
    )
    .expect("other valid types");
    assert_eq!(s.x, vec![4]);
}

#[test]
fn evt2_bad_words_are_named_with_their_byte_offset() {
    let h = H2.len() as u64;
    let opts = strict();
    let cd = |on: u32, t: u32, x: u32, y: u32| (on << 28) | (t << 22) | (x << 11) | y;
    for ty in [0x2u32, 0x3, 0x4, 0x5, 0x6, 0x7, 0x9, 0xB, 0xC, 0xD] {
        let b = evt2(H2, &[0x8000_0001, cd(1, 3, 1, 1), (ty << 28) | 5]);
        let (off, msg) = bad_word(decode(&b, "r2.raw", &opts));
        assert_eq!(off, h + 8, "{msg}");
        assert!(
            msg.contains(&format!(
                "EVT 2.0 word {:#010x} has the reserved type {ty:#x}",
                (ty << 28) | 5
            )),
            "{msg}"
        );
    }
    let (off, msg) = bad_word(decode(
        &evt2(H2, &[0x8000_0001, cd(0, 0, 9, 8)]),
        "o2.raw",
        &opts,
    ));
    assert_eq!(off, h + 4);
    assert!(
        msg.contains("(x=9, y=8) lies outside the header's 10x8 sensor"),
        "{msg}"
    );
    let (off, msg) = bad_word(decode(
        &evt2(H2, &[0x8000_0100, 0x8000_00FF]),
        "t2.raw",
        &opts,
    ));
    assert_eq!(off, h + 4);
    assert!(msg.contains("sends time back by 64 us"), "{msg}");
    // The 28-bit TIME_HIGH loops from its top to its bottom: unrolled (times keep increasing).
    let (s, _) = decode(
        &evt2(
            H2,
            &[0x8FFF_FFFF, cd(1, 1, 1, 1), 0x8000_0002, cd(0, 2, 2, 2)],
        ),
        "w2.raw",
        &opts,
    )
    .expect("a loop");
    assert_eq!(
        s.t,
        vec![(0x0FFF_FFFF << 6) | 1, (((1i64 << 28) + 2) << 6) | 2]
    );
    // EXT_TRIGGER, OTHERS, CONTINUED are valid; the low six time bits may go back inside a period.
    let (s, _) = decode(
        &evt2(
            H2,
            &[
                0x8000_0001,
                cd(1, 9, 1, 1),
                0xA000_0001,
                0xE000_0002,
                0xF000_0003,
                cd(0, 4, 2, 2),
            ],
        ),
        "k2.raw",
        &opts,
    )
    .expect("other valid types");
    assert_eq!(s.t, vec![64 + 9, 64 + 4]);
}

/// A long stream with bad words inserted at known places: the strict reader names the first one's
/// offset across chunk boundaries, the lenient reader skips exactly them and decodes the rest as if
/// they were not there.
#[test]
fn lenient_reading_skips_and_counts_exactly_the_bad_words() {
    let s = random_stream(5000, SensorSize::new(346, 260), 5_000, 7, 9);
    for (fmt, ws, bad) in [
        (
            PropheseeFormat::Evt3,
            2usize,
            vec![0x1111u32, 0x9999, 0xB000, 0xDFFF, 0x0800 | 300],
        ),
        (
            PropheseeFormat::Evt2,
            4,
            vec![
                0x2000_0000,
                0x9000_0001,
                0x1000_0000 | (400 << 11),
                300, // CD_OFF at y = 300
            ],
        ),
    ] {
        let clean = encode(&s, fmt).expect("encode");
        let body_at = clean.windows(6).position(|w| w == b"% end\n").expect("end") + 6;
        let words = (clean.len() - body_at) / ws;
        // The EVT 3.0 row word 0x0800 | 300 (row 300 of a 260-row sensor, system-type bit set) is
        // valid itself; the events that use it are bad: it goes right before an ADDR_X.
        let mut dirty = clean[..body_at].to_vec();
        let mut first_bad = None;
        let mut k = 0;
        for i in 0..words {
            let w = &clean[body_at + i * ws..body_at + (i + 1) * ws];
            let before_event =
                ws == 4 || bad.get(k).is_some_and(|b| b >> 12 != 0) || w[1] >> 4 == 0x2;
            if k < bad.len() && i >= (k + 1) * words / (bad.len() + 1) && before_event {
                first_bad.get_or_insert(dirty.len() as u64);
                if ws == 2 {
                    dirty.extend_from_slice(&(bad[k] as u16).to_le_bytes());
                } else {
                    dirty.extend_from_slice(&bad[k].to_le_bytes());
                }
                k += 1;
            }
            dirty.extend_from_slice(w);
        }
        assert_eq!(k, bad.len());
        let (off, msg) = bad_word(decode(&dirty, "dirty.raw", &strict()));
        assert_eq!(Some(off), first_bad, "{fmt:?}: {msg}");
        let (back, skipped) = decode(
            &dirty,
            "dirty.raw",
            &ReadOptions {
                raw_format: None,
                lenient: true,
            },
        )
        .expect("lenient");
        if fmt == PropheseeFormat::Evt2 {
            // Every inserted EVT 2.0 word is bad on its own.
            assert_eq!(skipped, bad.len() as u64);
            let first_diff = (0..s.len().min(back.len())).find(|&i| back.get(i) != s.get(i));
            assert_eq!((back.len(), first_diff), (s.len(), None), "{fmt:?}");
        } else {
            // The out-of-sensor row is a valid word; the events on that row until the next
            // ADDR_Y are the bad ones, each skipped.
            assert!(skipped > 4, "{skipped}");
            assert_eq!(back.len() as u64 + skipped - 4, s.len() as u64);
        }
    }
}

/// A `.dat` file: the text header, event type 0x0C and size 8, then `(t, x, y, p)` records as
/// given (`p` the raw polarity nibble).
fn dat(events: &[(u32, u32, u32, u32)]) -> Vec<u8> {
    let mut out = b"% Date 2026-11-26\n% Height 480\n% Width 640\n".to_vec();
    out.extend_from_slice(&[0x0C, 8]);
    for &(t, x, y, p) in events {
        out.extend_from_slice(&t.to_le_bytes());
        out.extend_from_slice(&(x | (y << 14) | (p << 28)).to_le_bytes());
    }
    out
}

/// [`decode`] for a `.dat` stream.
fn decode_dat(
    bytes: &[u8],
    name: &str,
    options: &ReadOptions,
) -> Result<(EventStream, u64), EventsError> {
    let mut r = PropheseeReader::with_options(bytes, name, true, options)?;
    let mut s = EventStream::new();
    while r.read_chunk(&mut s, 3)? > 0 {}
    Ok((s, r.skipped_words()))
}

#[test]
fn dat_events_with_a_bad_polarity_or_time_going_back_are_named_and_wraps_are_kept() {
    let header = dat(&[]).len() as u64;
    // A polarity nibble of 5 at the third event: named by its byte offset; lenient skips it.
    let bytes = dat(&[(10, 1, 2, 1), (20, 3, 4, 0), (30, 5, 6, 5), (40, 7, 8, 1)]);
    let (offset, msg) = bad_word(decode_dat(&bytes, "p.dat", &strict()));
    assert_eq!(offset, header + 16);
    assert!(msg.contains("p.dat") && msg.contains("polarity 5"), "{msg}");
    let (s, skipped) = decode_dat(
        &bytes,
        "p.dat",
        &ReadOptions {
            lenient: true,
            ..strict()
        },
    )
    .unwrap();
    assert_eq!((s.len(), skipped), (3, 1));
    assert_eq!(s.t, vec![10, 20, 40]);
    // Time going back by 15 µs: named.
    let bytes = dat(&[(10, 1, 2, 1), (25, 3, 4, 0), (10, 5, 6, 1)]);
    let (offset, msg) = bad_word(decode_dat(&bytes, "b.dat", &strict()));
    assert_eq!(offset, header + 16);
    assert!(msg.contains("goes back 15 us"), "{msg}");
    // The 32-bit counter's wrap from its top to its bottom is not a step back: times keep rising.
    let top = u32::MAX - 5;
    let bytes = dat(&[(top, 1, 2, 1), (3, 3, 4, 0), (9, 5, 6, 1)]);
    let (s, _) = decode_dat(&bytes, "w.dat", &strict()).unwrap();
    let base = 1i64 << 32;
    assert_eq!(s.t, vec![i64::from(top), base + 3, base + 9]);
    // Events that repeat a time are in order.
    let (s, _) = decode_dat(&dat(&[(7, 1, 1, 1), (7, 2, 2, 0)]), "e.dat", &strict()).unwrap();
    assert_eq!(s.len(), 2);
}
