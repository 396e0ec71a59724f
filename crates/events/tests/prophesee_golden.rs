//! Pins the decoding of recording-like Prophesee streams: every word type a camera writes (rows with
//! the system-type bit, single events, vector bases with VECT_12 / VECT_8, TIME_LOW step-backs
//! inside one TIME_HIGH period, a wrap of the 24-bit EVT 3.0 counter, external triggers, OTHERS and
//! CONTINUED words), built from a fixed seed, decoded to a fixed event count, first and last event
//! and FNV-1a checksum. The figures were taken from the decoder before validation was added, so a
//! change to the decoding of valid streams shows here.

use events::io::prophesee::PropheseeReader;
use events::io::{read_all, EventReader};
use events::EventStream;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// FNV-1a over every event's (t, x, y, p) little-endian bytes.
fn checksum(s: &EventStream) -> u64 {
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    let mut eat = |bytes: &[u8]| {
        for &b in bytes {
            h ^= u64::from(b);
            h = h.wrapping_mul(0x0000_0100_0000_01b3);
        }
    };
    for i in 0..s.len() {
        eat(&s.t[i].to_le_bytes());
        eat(&s.x[i].to_le_bytes());
        eat(&s.y[i].to_le_bytes());
        eat(&s.p[i].to_le_bytes());
    }
    h
}

/// Number of places where a decoded time is smaller than the one before.
fn step_backs(s: &EventStream) -> usize {
    s.t.windows(2).filter(|w| w[1] < w[0]).count()
}

/// An EVT 3.0 stream on a 640×480 sensor over 600 TIME_HIGH periods from 0xF00 (so the 24-bit
/// counter wraps once), with exactly nine TIME_LOW step-backs each followed by an event.
pub fn evt3_recording() -> Vec<u8> {
    let mut rng = ChaCha8Rng::seed_from_u64(32);
    let mut out = b"% camera_integrator_name Prophesee\n% evt 3.0\n\
                    % format EVT3;height=480;width=640\n% geometry 640x480\n% end\n"
        .to_vec();
    let mut push = |w: u16| out.extend_from_slice(&w.to_le_bytes());
    let mut step_backs_left = 9;
    for k in 0..600u16 {
        push(0x8000 | ((0xF00 + k) & 0xFFF));
        let mut low = 0u16;
        let mut stepped = false;
        while low < 4000 {
            let previous = low;
            low += rng.gen_range(1..200);
            let mut t_low = low.min(4095);
            if step_backs_left > 0 && k % 60 == 7 && !stepped && previous > 2000 {
                // Back by 1..40 µs from the previous TIME_LOW, inside the same period.
                t_low = previous - rng.gen_range(1..40);
                step_backs_left -= 1;
                stepped = true;
            }
            push(0x6000 | t_low);
            for _ in 0..rng.gen_range(1..4) {
                let system = if rng.gen_bool(0.1) { 0x800 } else { 0 };
                push(system | rng.gen_range(0..480u16));
                if rng.gen_bool(0.5) {
                    push(0x2000 | (u16::from(rng.gen_bool(0.5)) << 11) | rng.gen_range(0..640));
                } else {
                    let pol = u16::from(rng.gen_bool(0.5)) << 11;
                    push(0x3000 | pol | rng.gen_range(0..620u16));
                    push(0x4000 | rng.gen_range(1..0x1000u16));
                    if rng.gen_bool(0.5) {
                        push(0x5000 | rng.gen_range(1..0x100u16));
                    }
                }
            }
            match rng.gen_range(0..40) {
                0 => push(0xA000 | rng.gen_range(0..0x1000u16)),
                1 => {
                    push(0xE000 | rng.gen_range(0..0x1000u16));
                    push(0xF000 | rng.gen_range(0..0x1000u16));
                }
                2 => push(0x7000 | rng.gen_range(0..0x10u16)),
                _ => {}
            }
        }
    }
    assert_eq!(step_backs_left, 0, "the generator placed every step-back");
    out
}

/// An EVT 2.0 stream on a 640×480 sensor: EVT_TIME_HIGH every 64 µs, CD events with their low six
/// time bits in any order inside a period, external triggers, OTHERS and CONTINUED words.
pub fn evt2_recording() -> Vec<u8> {
    let mut rng = ChaCha8Rng::seed_from_u64(33);
    let mut out = b"% evt 2.0\n% geometry 640x480\n% end\n".to_vec();
    let mut push = |w: u32| out.extend_from_slice(&w.to_le_bytes());
    for high in 1_000u32..3_000 {
        push(0x8000_0000 | high);
        for _ in 0..rng.gen_range(0..12) {
            let ty = u32::from(rng.gen_bool(0.5));
            let low = rng.gen_range(0..64u32);
            push(
                (ty << 28) | (low << 22) | (rng.gen_range(0..640u32) << 11) | rng.gen_range(0..480),
            );
        }
        match rng.gen_range(0..50) {
            0 => push(0xA000_0000 | rng.gen_range(0..0x1000_0000u32)),
            1 => {
                push(0xE000_0000 | rng.gen_range(0..0x1000_0000u32));
                push(0xF000_0000 | rng.gen_range(0..0x1000_0000u32));
            }
            _ => {}
        }
    }
    out
}

fn decode(bytes: &[u8], chunk: usize) -> EventStream {
    let mut r = PropheseeReader::new(bytes, "golden.raw", false).expect("header");
    let mut s = EventStream::new();
    while r.read_chunk(&mut s, chunk).expect("decode") > 0 {}
    s.sensor = r.sensor();
    s
}

#[test]
fn evt3_recording_decodes_exactly_as_pinned() {
    let bytes = evt3_recording();
    let s = decode(&bytes, 1 << 20);
    // Chunking changes nothing.
    assert_eq!(decode(&bytes, 7), s);
    assert_eq!(
        read_all(&mut PropheseeReader::new(&bytes[..], "g.raw", false).expect("open"))
            .expect("read"),
        s
    );
    let n = s.len();
    println!(
        "evt3: {n} events ({} positive), first ({}, {}, {}, {}), last ({}, {}, {}, {}), {} step-backs, checksum {:#018x}",
        s.positive_count(),
        s.t[0], s.x[0], s.y[0], s.p[0],
        s.t[n - 1], s.x[n - 1], s.y[n - 1], s.p[n - 1],
        step_backs(&s),
        checksum(&s)
    );
    assert_eq!(step_backs(&s), 9);
    assert_eq!(s.sensor, Some(events::SensorSize::new(640, 480)));
    assert_eq!((n, s.positive_count()), (218_906, 108_928));
    assert_eq!((s.t[0], s.x[0], s.y[0], s.p[0]), (15_728_701, 114, 102, 1));
    assert_eq!(
        (s.t[n - 1], s.x[n - 1], s.y[n - 1], s.p[n - 1]),
        (18_186_164, 480, 31, 1)
    );
    assert_eq!(checksum(&s), 0x7e1c_3572_fe3e_27d2);
}

#[test]
fn evt2_recording_decodes_exactly_as_pinned() {
    let bytes = evt2_recording();
    let s = decode(&bytes, 1 << 20);
    assert_eq!(decode(&bytes, 5), s);
    let n = s.len();
    println!(
        "evt2: {n} events ({} positive), first ({}, {}, {}, {}), last ({}, {}, {}, {}), {} step-backs, checksum {:#018x}",
        s.positive_count(),
        s.t[0], s.x[0], s.y[0], s.p[0],
        s.t[n - 1], s.x[n - 1], s.y[n - 1], s.p[n - 1],
        step_backs(&s),
        checksum(&s)
    );
    assert_eq!(s.sensor, Some(events::SensorSize::new(640, 480)));
    assert_eq!((n, s.positive_count()), (10_805, 5_395));
    assert_eq!(step_backs(&s), 4_423);
    assert_eq!((s.t[0], s.x[0], s.y[0], s.p[0]), (64_051, 447, 25, -1));
    assert_eq!(
        (s.t[n - 1], s.x[n - 1], s.y[n - 1], s.p[n - 1]),
        (191_978, 28, 208, -1)
    );
    assert_eq!(checksum(&s), 0x9a3a_494d_f767_52b6);
}
