//! PLY acceptance tests: byte-identical round trips, every SH degree, foreign property orders and
//! extras, ASCII and big-endian bodies, and rejection of malformed files with errors naming the file and
//! the property, without allocating what a lying header claims.

#![allow(clippy::unwrap_used)] // test helpers outside #[test] fns may panic on bad fixtures

use gaussians::{read_ply, read_ply_bytes, write_ply, write_ply_bytes, GaussianSet, PlyError};
use rand::{Rng, SeedableRng};

fn random_set(n: usize, degree: usize, features: usize, classes: usize, seed: u64) -> GaussianSet {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mut s = GaussianSet::new(degree, features, classes);
    let k = (degree + 1) * (degree + 1);
    for _ in 0..n {
        let mut r = || rng.gen_range(-2.0f32..2.0);
        let mean = [r(), r(), r()];
        let log_scale = [r(), r(), r()];
        let quat = [r() + 3.0, r(), r(), r()];
        let opacity = r();
        let sh: Vec<f32> = (0..k * 3).map(|_| r()).collect();
        let f: Vec<f32> = (0..features).map(|_| r()).collect();
        let l: Vec<f32> = (0..classes).map(|_| r()).collect();
        s.push(mean, log_scale, quat, opacity, &sh, &f, &l).unwrap();
    }
    s
}

/// A hand-built PLY: (type, name) properties and rows of values, in the given format.
fn custom_ply(
    format: &str,
    props: &[(&str, &str)],
    rows: &[Vec<f64>],
    count: Option<u64>,
) -> Vec<u8> {
    let mut out = format!(
        "ply\nformat {format} 1.0\ncomment made by a test\nelement vertex {}\n",
        count.unwrap_or(rows.len() as u64)
    );
    for (ty, name) in props {
        out.push_str(&format!("property {ty} {name}\n"));
    }
    out.push_str("end_header\n");
    let mut bytes = out.into_bytes();
    for row in rows {
        if format == "ascii" {
            let line: Vec<String> = row.iter().map(|v| v.to_string()).collect();
            bytes.extend_from_slice(line.join(" ").as_bytes());
            bytes.push(b'\n');
            continue;
        }
        let be = format == "binary_big_endian";
        for ((ty, _), &v) in props.iter().zip(row) {
            match *ty {
                "float" => bytes.extend_from_slice(&if be {
                    (v as f32).to_be_bytes()
                } else {
                    (v as f32).to_le_bytes()
                }),
                "double" => {
                    bytes.extend_from_slice(&if be { v.to_be_bytes() } else { v.to_le_bytes() })
                }
                "uchar" => bytes.push(v as u8),
                "int" => bytes.extend_from_slice(&(v as i32).to_le_bytes()),
                other => panic!("test helper does not write {other}"),
            }
        }
    }
    bytes
}

const BASE: [&str; 14] = [
    "x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0", "scale_1", "scale_2",
    "rot_0", "rot_1", "rot_2", "rot_3",
];

fn base_props() -> Vec<(&'static str, &'static str)> {
    BASE.iter().map(|n| ("float", *n)).collect()
}

fn base_row(i: usize) -> Vec<f64> {
    let f = i as f64;
    vec![
        f,
        f + 0.5,
        -f,
        0.1,
        0.2,
        0.3,
        0.7,
        -1.0,
        -2.0,
        -3.0,
        1.0,
        0.0,
        0.0,
        0.0,
    ]
}

#[test]
fn write_read_write_is_byte_identical_for_every_degree() {
    for degree in 0..=3 {
        let set = random_set(37, degree, 5, 2, degree as u64);
        let bytes = write_ply_bytes(&set).unwrap();
        let back = read_ply_bytes(&bytes, "mem.ply").unwrap();
        assert_eq!(back, set, "degree {degree}");
        assert_eq!(back.sh_degree, degree);
        assert_eq!(write_ply_bytes(&back).unwrap(), bytes, "degree {degree}");
    }
}

#[test]
fn file_round_trip_is_atomic_and_exact() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("model.ply");
    let set = random_set(10, 3, 0, 0, 42);
    write_ply(&path, &set).unwrap();
    assert_eq!(read_ply(&path).unwrap(), set);
    let leftovers: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
    assert_eq!(leftovers.len(), 1, "temporary file left behind");
}

#[test]
fn header_is_the_inria_layout() {
    let set = random_set(1, 1, 0, 2, 1);
    let bytes = write_ply_bytes(&set).unwrap();
    let text = String::from_utf8_lossy(&bytes[..bytes.len() - 4 * (17 + 9 + 2)]).to_string();
    let props: Vec<&str> = text
        .lines()
        .filter_map(|l| l.strip_prefix("property float "))
        .collect();
    let mut want: Vec<String> = [
        "x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2",
    ]
    .map(String::from)
    .to_vec();
    want.extend((0..9).map(|j| format!("f_rest_{j}")));
    want.extend(
        [
            "opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3",
        ]
        .map(String::from),
    );
    want.extend(["semantic_0", "semantic_1"].map(String::from));
    assert_eq!(props, want);
    assert!(text.starts_with("ply\nformat binary_little_endian 1.0\nelement vertex 1\n"));
}

#[test]
fn f_rest_is_channel_major() {
    // Degree 1: f_rest_j = coefficient (j % 3) + 1 of channel j / 3.
    let mut props = base_props();
    let names: Vec<String> = (0..9).map(|j| format!("f_rest_{j}")).collect();
    for n in &names {
        props.push(("float", n.as_str()));
    }
    let mut row = base_row(0);
    row.extend((0..9).map(|j| 10.0 + j as f64));
    let set = read_ply_bytes(
        &custom_ply("binary_little_endian", &props, &[row], None),
        "t.ply",
    )
    .unwrap();
    let sh = set.sh_of(0);
    for c in 0..3 {
        for coeff in 1..4 {
            assert_eq!(sh[coeff * 3 + c], (10 + c * 3 + coeff - 1) as f32);
        }
    }
    assert_eq!(&sh[..3], &[0.1, 0.2, 0.3]);
}

#[test]
fn shuffled_order_extra_properties_ascii_and_big_endian_all_load() {
    let mut props = base_props();
    props.reverse();
    props.insert(3, ("uchar", "red"));
    props.insert(7, ("double", "confidence"));
    props.push(("float", "nx"));
    let rows: Vec<Vec<f64>> = (0..4)
        .map(|i| {
            let base = base_row(i);
            let mut r: Vec<f64> = base.iter().rev().copied().collect();
            r.insert(3, 200.0);
            r.insert(7, 0.25);
            r.push(0.0);
            r
        })
        .collect();
    let reference = {
        let rows: Vec<Vec<f64>> = (0..4).map(base_row).collect();
        read_ply_bytes(
            &custom_ply("binary_little_endian", &base_props(), &rows, None),
            "ref.ply",
        )
        .unwrap()
    };
    for format in ["binary_little_endian", "binary_big_endian", "ascii"] {
        let set = read_ply_bytes(&custom_ply(format, &props, &rows, None), "shuffled.ply")
            .unwrap_or_else(|e| panic!("{format}: {e}"));
        assert_eq!(set, reference, "{format}");
    }
    assert_eq!(reference.means[3], [3.0, 3.5, -3.0]);
}

fn error_of(bytes: &[u8]) -> String {
    match read_ply_bytes(bytes, "bad.ply") {
        Ok(_) => panic!("malformed PLY was accepted"),
        Err(e) => {
            let msg = e.to_string();
            assert!(
                msg.starts_with("bad.ply"),
                "error does not name the file: {msg}"
            );
            msg
        }
    }
}

#[test]
fn truncated_files_are_rejected() {
    let rows: Vec<Vec<f64>> = (0..3).map(base_row).collect();
    let good = custom_ply("binary_little_endian", &base_props(), &rows, None);
    let msg = error_of(&good[..good.len() - 5]);
    assert!(msg.contains("vertex"), "{msg}");
    let ascii = custom_ply("ascii", &base_props(), &rows, None);
    let cut = String::from_utf8(ascii).unwrap();
    let cut = &cut[..cut.rfind(' ').unwrap()];
    let msg = error_of(cut.as_bytes());
    assert!(msg.contains("rot_3"), "{msg}");
    // Cut inside the header.
    assert!(error_of(&good[..40]).contains("end_header"));
}

#[test]
fn wrong_counts_are_rejected() {
    let rows: Vec<Vec<f64>> = (0..3).map(base_row).collect();
    let more = custom_ply("binary_little_endian", &base_props(), &rows, Some(4));
    assert!(matches!(
        read_ply_bytes(&more, "bad.ply"),
        Err(PlyError::TooLarge { count: 4, .. })
    ));
    let fewer = custom_ply("binary_little_endian", &base_props(), &rows, Some(2));
    assert!(matches!(
        read_ply_bytes(&fewer, "bad.ply"),
        Err(PlyError::TrailingData { bytes: 56, .. })
    ));
    // f_rest count that is not 3·(K−1) for a square K.
    let mut props = base_props();
    props.push(("float", "f_rest_0"));
    props.push(("float", "f_rest_1"));
    let mut row = base_row(0);
    row.extend([0.0, 0.0]);
    let msg = error_of(&custom_ply("binary_little_endian", &props, &[row], None));
    assert!(msg.contains("f_rest"), "{msg}");
}

#[test]
fn absurd_vertex_count_is_rejected_without_allocating() {
    let rows: Vec<Vec<f64>> = (0..1).map(base_row).collect();
    let huge = custom_ply(
        "binary_little_endian",
        &base_props(),
        &rows,
        Some(1_000_000_000_000),
    );
    let start = std::time::Instant::now();
    let msg = error_of(&huge);
    assert!(
        msg.contains("element `vertex` claims 1000000000000 rows"),
        "{msg}"
    );
    assert!(start.elapsed().as_secs_f64() < 1.0);
    // Overflowing count × row size.
    let overflow = custom_ply(
        "binary_little_endian",
        &base_props(),
        &rows,
        Some(u64::MAX / 2),
    );
    assert!(matches!(
        read_ply_bytes(&overflow, "bad.ply"),
        Err(PlyError::TooLarge { .. })
    ));
    // ASCII bodies grow with the data, so a lying header just runs out of lines.
    let ascii = custom_ply("ascii", &base_props(), &rows, Some(1_000_000_000_000));
    assert!(matches!(
        read_ply_bytes(&ascii, "bad.ply"),
        Err(PlyError::Truncated { vertex: 1, .. })
    ));
}

#[test]
fn nan_values_are_rejected_naming_the_property() {
    let mut rows: Vec<Vec<f64>> = (0..3).map(base_row).collect();
    rows[2][8] = f64::NAN; // scale_1
    for format in ["binary_little_endian", "ascii"] {
        let msg = error_of(&custom_ply(format, &base_props(), &rows, None));
        assert!(
            msg.contains("scale_1") && msg.contains("vertex 2"),
            "{format}: {msg}"
        );
    }
}

#[test]
fn non_float_types_and_missing_properties_are_rejected() {
    let mut props = base_props();
    props[6] = ("int", "opacity");
    let rows: Vec<Vec<f64>> = (0..2).map(base_row).collect();
    let msg = error_of(&custom_ply("binary_little_endian", &props, &rows, None));
    assert!(msg.contains("`opacity`") && msg.contains("float"), "{msg}");
    let props: Vec<(&str, &str)> = base_props()
        .into_iter()
        .filter(|p| p.1 != "rot_2")
        .collect();
    let rows: Vec<Vec<f64>> = (0..2)
        .map(|i| {
            let mut r = base_row(i);
            r.remove(12);
            r
        })
        .collect();
    let msg = error_of(&custom_ply("binary_little_endian", &props, &rows, None));
    assert!(msg.contains("`rot_2`") && msg.contains("missing"), "{msg}");
    assert!(error_of(b"not a ply file").contains("magic"));
}

#[test]
fn zero_quaternions_are_refused_on_write() {
    let mut set = random_set(3, 0, 0, 0, 1);
    set.quats[1] = [0.0; 4];
    let dir = tempfile::tempdir().unwrap();
    let err = write_ply(dir.path().join("z.ply"), &set)
        .unwrap_err()
        .to_string();
    assert!(err.contains("z.ply") && err.contains("quats"), "{err}");
}
