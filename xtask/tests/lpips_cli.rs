//! End-to-end test of `cargo xtask lpips`: on the image pairs of `data-fixtures/lpips/reference_tiny.txt`
//! (the committed `data-fixtures/tiny` frames, 16-bit sRGB PNGs) the distance on the last line of
//! stdout agrees with the float64 numpy reference (`data-fixtures/lpips/reference_lpips.py`, an
//! independent transcription of the `lpips` 0.1.4 formulation, run by hand: the tests never run
//! Python) to 1e-5 absolute (f32 against f64: measured ≤ 2e-8; the acceptance is 1e-4); and
//! bad inputs fail with a message naming the problem, never a panic.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("xtask lives in the workspace")
        .to_path_buf()
}

fn xtask(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_xtask"))
        .args(args)
        .output()
        .expect("running the xtask binary")
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

#[test]
fn agrees_with_the_numpy_reference_on_the_tiny_frames() {
    let root = root();
    let table = std::fs::read_to_string(root.join("data-fixtures/lpips/reference_tiny.txt"))
        .expect("reading the reference distances");
    let mut pairs = 0;
    for line in table
        .lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
    {
        let fields: Vec<&str> = line.split_whitespace().collect();
        assert_eq!(fields.len(), 3, "bad reference line {line:?}");
        let want: f64 = fields[2].parse().expect("a distance");
        let (a, b) = (root.join(fields[0]), root.join(fields[1]));
        let out = xtask(&[
            "lpips",
            a.to_str().expect("UTF-8 path"),
            b.to_str().expect("UTF-8 path"),
        ]);
        assert!(out.status.success(), "{line}: {}", stderr(&out));
        let stdout = String::from_utf8_lossy(&out.stdout);
        let got: f64 = stdout
            .lines()
            .last()
            .expect("a last line")
            .trim()
            .parse()
            .expect("the last line is a number");
        assert!(
            (got - want).abs() <= 1e-5,
            "{line}: xtask says {got}, the reference {want}"
        );
        pairs += 1;
    }
    assert!(pairs >= 4, "only {pairs} reference pairs");
}

#[test]
fn refuses_images_of_different_or_too_small_sizes() {
    let root = root();
    let tiny = root.join("data-fixtures/tiny/sharp/000000.png");
    let preview = root.join("data-fixtures/tiny/preview.png");
    let out = xtask(&[
        "lpips",
        tiny.to_str().expect("UTF-8"),
        preview.to_str().expect("UTF-8"),
    ]);
    assert!(!out.status.success());
    let err = stderr(&out);
    assert!(
        err.contains("image sizes differ: 64x64 and 984x810"),
        "{err}"
    );
    assert!(!err.contains("panicked"), "{err}");

    let dir = tempfile::tempdir().expect("temp dir");
    let small = dir.path().join("small.png");
    image::save_buffer(
        &small,
        &[128u8; 3 * 30 * 40],
        40,
        30,
        image::ExtendedColorType::Rgb8,
    )
    .expect("writing a small PNG");
    let s = small.to_str().expect("UTF-8");
    let out = xtask(&["lpips", s, s]);
    assert!(!out.status.success());
    let err = stderr(&out);
    assert!(
        err.contains("image 40x30 is too small for LPIPS (AlexNet needs at least 31x31 pixels)"),
        "{err}"
    );
    let out = xtask(&["lpips", s, "/nonexistent.png"]);
    assert!(!out.status.success());
    assert!(
        stderr(&out).contains("/nonexistent.png"),
        "{}",
        stderr(&out)
    );
}
