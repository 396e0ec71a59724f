//! `cargo xtask ablate` end to end on the tiny checked-in fixture with a few steps: the table, the
//! JSON and the image grid are written, a failed run is recorded and the others go on, `--seeds`
//! runs every row once per seed and reports each measure's spread, and bad lists are refused.
#![allow(clippy::unwrap_used)]

mod common;

use std::path::Path;
use std::process::{Command, Output};

/// `ablate` on the tiny fixture into `out` with the few-step configuration `config` and `extra`
/// options.
fn ablate(out: &Path, config: &Path, extra: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_xtask"))
        .arg("ablate")
        .arg("--data")
        .arg(common::fixture())
        .arg("--out")
        .arg(out)
        .arg("--config")
        .arg(config)
        .args(extra)
        .output()
        .unwrap()
}

/// Asserts that `o` succeeded, showing its error output if not.
fn assert_success(o: &Output) {
    assert!(
        o.status.success(),
        "ablate failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
}

#[test]
fn ablate_writes_a_table_json_and_grid_and_records_failed_runs() {
    let dir = tempfile::tempdir().unwrap();
    let config = common::tiny_config(dir.path());
    let out = dir.path().join("ablate");
    // The tiny fixture has no event-only flow: that run must fail and be recorded.
    assert_success(&ablate(&out, &config, &["--only", "one-hot,flow-events"]));
    let md = std::fs::read_to_string(out.join("ablation.md")).unwrap();
    assert!(md.contains("| 1 | `one-hot` |"), "{md}");
    assert!(md.contains(" LPIPS full | LPIPS human box |"), "{md}");
    assert!(
        md.contains("| 2 | `flow-events` |") && md.contains("failed"),
        "{md}"
    );
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("ablation.json")).unwrap()).unwrap();
    assert!(json[0]["metrics"]["test_psnr_full"].as_f64().unwrap() > 5.0);
    assert!(json[1]["error"].as_str().is_some());
    let grid = image::open(out.join("ablation_grid.png")).unwrap();
    assert!(grid.width() > 28 && grid.height() > 0);
    // An unknown run name is refused.
    let o = ablate(
        &dir.path().join("unknown"),
        &config,
        &["--only", "everything"],
    );
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("semantic-none"));
}

#[test]
fn ablate_runs_every_row_once_per_seed_and_reports_the_spread() {
    let dir = tempfile::tempdir().unwrap();
    let config = common::tiny_config(dir.path());
    let out = dir.path().join("ablate");
    assert_success(&ablate(
        &out,
        &config,
        &["--only", "one-hot", "--seeds", "0,1"],
    ));
    for seed in [0, 1] {
        let metrics = out.join(format!("one-hot/seed-{seed}/metrics.json"));
        let m: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&metrics).unwrap()).unwrap();
        assert_eq!(m["seed"].as_u64(), Some(seed), "{}", metrics.display());
    }
    let md = std::fs::read_to_string(out.join("ablation.md")).unwrap();
    assert!(md.contains("| 2 | `one-hot/seed-1` |"), "{md}");
    assert!(
        md.contains("## Over seeds") && md.contains("| `one-hot` | 2/2 |"),
        "{md}"
    );
    let over: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(out.join("ablation_over_seeds.json")).unwrap(),
    )
    .unwrap();
    let psnr = &over[0]["measures"]["test_psnr_full"];
    let per_seed: Vec<f64> = psnr["per_seed"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v["value"].as_f64().unwrap())
        .collect();
    assert_eq!(per_seed.len(), 2);
    // Different seeds train different models; the summary is their mean and range.
    assert_ne!(per_seed[0], per_seed[1]);
    let mean = psnr["mean"].as_f64().unwrap();
    assert!((mean - (per_seed[0] + per_seed[1]) / 2.0).abs() < 1e-9);
    assert_eq!(psnr["max"].as_f64().unwrap(), per_seed[0].max(per_seed[1]));
    // A seed given twice is refused before anything runs.
    let refused = dir.path().join("refused");
    let o = ablate(&refused, &config, &["--only", "one-hot", "--seeds", "2,2"]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("seed 2 is given twice"));
    assert!(!refused.join("one-hot").exists());
}
