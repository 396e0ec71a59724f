//! `cargo xtask fuzz` in the test suite: a few thousand mutated inputs for every parser of user
//! files, so that a parser which starts to panic, hang or over-allocate fails CI (the million-input
//! runs are a command, recorded in docs/BENCHMARKS.md), and an unknown target is refused.
#![allow(clippy::unwrap_used)]

use std::process::Command;

fn xtask() -> Command {
    Command::new(env!("CARGO_BIN_EXE_xtask"))
}

/// Every fuzz target, in the order `--target all` runs them.
const TARGETS: [&str; 15] = [
    "ply",
    "camera",
    "scene",
    "npz",
    "motion",
    "safetensors",
    "flo",
    "flow-png",
    "aedat4",
    "aedat4-frames",
    "zju-model",
    "events-raw",
    "dat",
    "events-text",
    "t7",
];

#[test]
fn the_readme_counts_and_lists_the_fuzz_targets_that_run() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let readme = std::fs::read_to_string(root.join("README.md")).unwrap();
    let count = format!("fuzzing ({} targets)", TARGETS.len());
    assert!(readme.contains(&count), "README.md lacks `{count}`");
    let listed = format!("`cargo xtask fuzz --target all\\|{}", TARGETS.join("\\|"));
    assert!(readme.contains(&listed), "README.md lacks `{listed}`");
}

#[test]
fn every_parser_survives_a_few_thousand_mutated_inputs() {
    let o = xtask()
        .args([
            "fuzz", "--target", "all", "--inputs", "3000", "--seed", "20261126",
        ])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "fuzzing found something:\n{stdout}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    // No target runs that this list (and the README) does not name.
    let summaries = stdout.lines().filter(|l| l.ends_with(" findings")).count();
    assert_eq!(summaries, TARGETS.len(), "{stdout}");
    for target in TARGETS {
        let line = stdout
            .lines()
            .find(|l| l.starts_with(&format!("{target}: ")))
            .unwrap_or_else(|| panic!("no summary line for {target}:\n{stdout}"));
        assert!(
            line.contains("3000 inputs") && line.ends_with(" 0 findings"),
            "{line}"
        );
    }
}

#[test]
fn an_unknown_target_is_refused_with_the_list() {
    let o = xtask()
        .args(["fuzz", "--target", "jpeg", "--inputs", "1"])
        .output()
        .unwrap();
    assert!(!o.status.success());
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(
        e.contains("unknown fuzz target `jpeg`") && e.contains("events-raw"),
        "{e}"
    );
}

#[test]
fn panics_aborts_and_hangs_are_caught_saved_and_fail_the_command() {
    let o = xtask()
        .args([
            "fuzz",
            "--target",
            "self-test",
            "--inputs",
            "40",
            "--seed",
            "3",
            "--time-limit-ms",
            "100",
        ])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(!o.status.success(), "{stdout}");
    for what in [
        "panicked: self-test panic",
        "the worker died",
        "a hang",
        "grew peak virtual memory",
    ] {
        assert!(stdout.contains(what), "no `{what}` finding:\n{stdout}");
    }
    let saved = stdout
        .lines()
        .filter_map(|l| {
            l.rsplit_once('(')
                .map(|(_, f)| f.trim_end_matches(')').to_string())
        })
        .filter(|f| f.contains("crash-"))
        .collect::<Vec<_>>();
    assert!(!saved.is_empty(), "{stdout}");
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    for f in saved {
        let path = if std::path::Path::new(&f).is_absolute() {
            f.clone().into()
        } else {
            root.join(&f)
        };
        assert!(
            path.is_file() || std::path::Path::new(&f).is_file(),
            "{f} was not saved"
        );
    }
}
