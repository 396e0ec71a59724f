#![allow(clippy::unwrap_used)]
//! `cargo xtask deblur-edi` end to end through the binary on the tiny fixture: one PNG per frame
//! whose exposure the events cover, `edi.json` with the scores against the sharp references, and
//! the EDI frames sharper than the blurred ones they come from.

use std::path::PathBuf;
use std::process::Command;

fn fixture() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../data-fixtures/tiny")
}

#[test]
fn deblur_edi_writes_frames_sharper_than_the_blurred_input() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("edi");
    let o = Command::new(env!("CARGO_BIN_EXE_xtask"))
        .args(["deblur-edi", "--data"])
        .arg(fixture())
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "deblur-edi failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("edi.json")).unwrap()).unwrap();
    // The first frame's exposure starts before the first events file: 14 of 15 deblurred.
    assert_eq!(summary["frames_deblurred"], 14, "{summary}");
    assert_eq!(summary["frames_uncovered"], serde_json::json!([0]));
    let pngs = std::fs::read_dir(&out)
        .unwrap()
        .filter(|e| {
            e.as_ref()
                .unwrap()
                .file_name()
                .to_string_lossy()
                .ends_with(".png")
        })
        .count();
    assert_eq!(pngs, 14);
    let mean = &summary["mean"];
    let (edi, blurred) = (
        mean["psnr_human_box"].as_f64().unwrap(),
        mean["blurred_psnr_human_box"].as_f64().unwrap(),
    );
    assert!(
        edi > blurred + 0.5,
        "EDI {edi:.2} dB, blurred {blurred:.2} dB in the box"
    );
}
