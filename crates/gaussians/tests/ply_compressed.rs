//! The PlayCanvas / SuperSplat compressed PLY layout against the format's reference tool: a file
//! written by `@playcanvas/splat-transform` 3.7.0 reads to the values that the same tool's own
//! decoder writes out (`data-fixtures/ply/README.md`), and broken files are refused by name.
#![allow(clippy::unwrap_used)]

use gaussians::ply::read_ply;
use std::path::PathBuf;

fn fixture(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../data-fixtures/ply")
        .join(name)
}

/// |a − b| ≤ 1e-5 · max(1, |b|): the reference decodes in f64 and stores f32, this reader works in
/// f32; one f32 rounding of values up to ~4 is 5e-7, so 1e-5 leaves room for a few roundings and
/// still catches any wrong bit field (the coarsest step, 8 bits of colour, is 0.014 in f_dc).
fn close(a: f32, b: f32) -> bool {
    (a - b).abs() <= 1e-5 * b.abs().max(1.0)
}

#[test]
fn a_compressed_file_reads_as_the_reference_decoder_decodes_it() {
    let ours = read_ply(fixture("splat600.compressed.ply")).unwrap();
    let reference = read_ply(fixture("splat600.decoded.ply")).unwrap();
    assert_eq!(ours.len(), 600);
    assert_eq!(ours.sh_degree, 3);
    assert_eq!(reference.sh_degree, 3);
    for i in 0..600 {
        for a in 0..3 {
            assert!(
                close(ours.means[i][a], reference.means[i][a]),
                "mean {i}.{a}"
            );
            assert!(
                close(ours.log_scales[i][a], reference.log_scales[i][a]),
                "scale {i}.{a}"
            );
        }
        for a in 0..4 {
            assert!(
                close(ours.quats[i][a], reference.quats[i][a]),
                "rot_{a} of {i}: {:?} vs {:?}",
                ours.quats[i],
                reference.quats[i]
            );
        }
        assert!(
            close(ours.opacity_logits[i], reference.opacity_logits[i]),
            "opacity {i}"
        );
    }
    for (k, (a, b)) in ours.sh.iter().zip(&reference.sh).enumerate() {
        assert!(close(*a, *b), "sh value {k}: {a} vs {b}");
    }
}

#[test]
fn the_compressed_file_keeps_the_original_gaussians_within_its_quantisation() {
    // Each decoded Gaussian lies within one 11-bit step of an original one (the tool reorders).
    let ours = read_ply(fixture("splat600.compressed.ply")).unwrap();
    let original = read_ply(fixture("splat600.ply")).unwrap();
    let step = 3.0 / 2047.0 * 1.01;
    for m in &ours.means {
        let nearest = original
            .means
            .iter()
            .map(|o| (0..3).map(|a| (o[a] - m[a]).abs()).fold(0.0f32, f32::max))
            .fold(f32::MAX, f32::min);
        assert!(
            nearest <= step * 2.0,
            "{m:?} is {nearest} from every original"
        );
    }
}

#[test]
fn broken_compressed_files_are_refused_naming_the_file_and_the_part() {
    let bytes = std::fs::read(fixture("splat600.compressed.ply")).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("broken.compressed.ply");
    // Truncated: the header's counts no longer fit.
    std::fs::write(&path, &bytes[..bytes.len() - 100]).unwrap();
    let e = read_ply(&path).unwrap_err().to_string();
    assert!(
        e.contains("broken.compressed.ply") && e.contains("claims"),
        "{e}"
    );
    // Fewer chunk rows than the vertices need.
    let header_end = bytes
        .windows(11)
        .position(|w| w == b"end_header\n")
        .unwrap()
        + 11;
    let mut fewer = String::from_utf8(bytes[..header_end].to_vec())
        .unwrap()
        .replacen("element chunk 3", "element chunk 2", 1)
        .into_bytes();
    let chunk_row = 18 * 4;
    fewer.extend_from_slice(&bytes[header_end + chunk_row..]);
    std::fs::write(&path, &fewer).unwrap();
    let e = read_ply(&path).unwrap_err().to_string();
    assert!(
        e.contains("element chunk") && e.contains("600 Gaussians"),
        "{e}"
    );
    // A packed word missing.
    let renamed =
        String::from_utf8_lossy(&bytes[..header_end]).replacen("packed_scale", "packed_scalf", 1);
    let mut missing = renamed.into_bytes();
    missing.extend_from_slice(&bytes[header_end..]);
    std::fs::write(&path, &missing).unwrap();
    let e = read_ply(&path).unwrap_err().to_string();
    assert!(e.contains("packed_scale") && e.contains("missing"), "{e}");
}
