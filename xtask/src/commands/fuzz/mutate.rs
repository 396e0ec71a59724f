//! Structure-aware mutation: input `k` of seed `s` is one of the seed files with one to four
//! mutations stacked, drawn from a ChaCha8 stream keyed by `(s, k)` (so any input is reproduced
//! from its index alone, in any order and on any machine).

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Largest input made (bytes); mutations that would grow past it are cut.
const MAX_INPUT: usize = 1 << 20;

/// Integers that break size and count fields.
const INTERESTING: [u64; 12] = [
    0,
    1,
    0x7f,
    0xff,
    0x7fff,
    0xffff,
    0x7fff_ffff,
    0x8000_0000,
    0xffff_ffff,
    1 << 40,
    0x7fff_ffff_ffff_ffff,
    u64::MAX,
];

/// Text that breaks numbers in text formats (PLY headers, JSON, event text).
const TEXT_NUMBERS: [&str; 10] = [
    "0",
    "-1",
    "4294967296",
    "99999999999999999999",
    "nan",
    "inf",
    "-inf",
    "1e308",
    "-0",
    "18446744073709551615",
];

/// Input `k` of seed `seed` made from `seeds` (which must not be empty).
pub fn input(seeds: &[Vec<u8>], seed: u64, k: u64) -> Vec<u8> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ k.wrapping_mul(0x9E37_79B9_7F4A_7C15));
    rng.set_stream(k);
    let Some(first) = seeds.get(rng.gen_range(0..seeds.len().max(1))) else {
        return Vec::new();
    };
    let mut d = first.clone();
    let count = match rng.gen_range(0..8) {
        0..=3 => 1,
        4..=5 => 2,
        6 => 3,
        _ => 4,
    };
    for _ in 0..count {
        mutate_once(&mut d, seeds, &mut rng);
        d.truncate(MAX_INPUT);
    }
    d
}

fn mutate_once(d: &mut Vec<u8>, seeds: &[Vec<u8>], rng: &mut ChaCha8Rng) {
    let len = d.len();
    let at = |rng: &mut ChaCha8Rng, n: usize| if n == 0 { 0 } else { rng.gen_range(0..n) };
    match rng.gen_range(0..11) {
        // Flip one to eight bits.
        0 if len > 0 => {
            for _ in 0..rng.gen_range(1..=8) {
                let i = at(rng, len);
                d[i] ^= 1 << rng.gen_range(0..8);
            }
        }
        // An interesting byte.
        1 if len > 0 => {
            let i = at(rng, len);
            d[i] = [0u8, 1, 0x7f, 0x80, 0xff][rng.gen_range(0..5)];
        }
        // An interesting integer over 2, 4 or 8 bytes, either endianness (header fields).
        2 if len >= 8 => {
            let v = INTERESTING[rng.gen_range(0..INTERESTING.len())];
            let width = [2usize, 4, 8][rng.gen_range(0..3)];
            let i = at(rng, len - width + 1);
            let bytes = if rng.gen_bool(0.5) {
                v.to_le_bytes()
            } else {
                v.to_be_bytes()
            };
            let src = if bytes[0] == 0 && width < 8 && !rng.gen_bool(0.5) {
                &bytes[8 - width..]
            } else {
                &bytes[..width]
            };
            d[i..i + width].copy_from_slice(src);
        }
        // A non-finite or huge float (f32 or f64, little-endian, 4-aligned).
        3 if len >= 8 => {
            let i = at(rng, (len - 8) / 4 + 1) * 4;
            if rng.gen_bool(0.5) {
                let v =
                    [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, 3.0e38, -0.0][rng.gen_range(0..5)];
                d[i..i + 4].copy_from_slice(&v.to_le_bytes());
            } else {
                let v = [f64::NAN, f64::INFINITY, f64::NEG_INFINITY, 1.0e308][rng.gen_range(0..4)];
                d[i..i + 8].copy_from_slice(&v.to_le_bytes());
            }
        }
        // Truncate.
        4 => {
            let n = at(rng, len + 1);
            d.truncate(n);
        }
        // Delete a chunk.
        5 if len > 1 => {
            let a = at(rng, len);
            let n = rng.gen_range(1..=(len - a).min(256));
            d.drain(a..a + n);
        }
        // Duplicate a chunk somewhere else.
        6 if len > 1 => {
            let a = at(rng, len);
            let n = rng.gen_range(1..=(len - a).min(1024));
            let chunk: Vec<u8> = d[a..a + n].to_vec();
            let to = at(rng, len + 1);
            d.splice(to..to, chunk);
        }
        // Splice: this input's head with another seed's tail.
        7 => {
            let other = &seeds[at(rng, seeds.len())];
            let cut = at(rng, len + 1);
            let from = at(rng, other.len() + 1);
            d.truncate(cut);
            d.extend_from_slice(&other[from..]);
        }
        // A digit run of text replaced by a breaking number.
        8 => {
            let runs: Vec<(usize, usize)> = digit_runs(d);
            if let Some(&(a, b)) = runs.get(at(rng, runs.len())) {
                let t = TEXT_NUMBERS[rng.gen_range(0..TEXT_NUMBERS.len())];
                d.splice(a..b, t.bytes());
            }
        }
        // Random bytes appended or written over.
        9 => {
            let n = rng.gen_range(1..=64);
            let bytes: Vec<u8> = (0..n).map(|_| rng.gen()).collect();
            if rng.gen_bool(0.5) || len < n {
                d.extend_from_slice(&bytes);
            } else {
                let i = at(rng, len - n + 1);
                d[i..i + n].copy_from_slice(&bytes);
            }
        }
        // A chunk of zeros inserted (lengths and offsets shift).
        _ => {
            let to = at(rng, len + 1);
            let n = rng.gen_range(1..=16);
            d.splice(to..to, std::iter::repeat_n(0u8, n));
        }
    }
}

/// `[start, end)` of every run of ASCII digits (at most 4096 of them).
fn digit_runs(d: &[u8]) -> Vec<(usize, usize)> {
    let mut runs = Vec::new();
    let mut i = 0;
    while i < d.len() && runs.len() < 4096 {
        if d[i].is_ascii_digit() {
            let a = i;
            while i < d.len() && d[i].is_ascii_digit() {
                i += 1;
            }
            runs.push((a, i));
        } else {
            i += 1;
        }
    }
    runs
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inputs_are_reproducible_varied_and_bounded() {
        let seeds = vec![
            b"ply\nelement vertex 12\nend_header\n0123456789".to_vec(),
            vec![7u8; 300],
        ];
        let a: Vec<Vec<u8>> = (0..200).map(|k| input(&seeds, 5, k)).collect();
        let b: Vec<Vec<u8>> = (0..200).map(|k| input(&seeds, 5, k)).collect();
        assert_eq!(a, b, "same (seed, k), same bytes");
        let distinct: std::collections::HashSet<&Vec<u8>> = a.iter().collect();
        assert!(distinct.len() > 150, "{} distinct of 200", distinct.len());
        assert!(a.iter().all(|x| x.len() <= MAX_INPUT));
        assert_ne!(input(&seeds, 6, 0), input(&seeds, 5, 0));
        let has = |x: &Vec<u8>, t: &[u8]| x.windows(t.len()).any(|w| w == t);
        assert!(a
            .iter()
            .any(|x| has(x, b"nan") || has(x, b"inf") || has(x, b"99999")));
    }
}
