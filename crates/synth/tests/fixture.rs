#![allow(clippy::unwrap_used)]
//! The checked-in fixture `data-fixtures/tiny` is exactly what the `tiny` preset generates
//! (`cargo xtask synth --preset tiny --out data-fixtures/tiny`), byte for byte, and loads.
//!
//! Set `SYNTH_FIXTURE_OUT=DIR` to keep the regenerated copy in DIR for inspection.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use synth::{generate, Preset, SynthConfig};

fn files(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    let mut out = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                let rel = p.strip_prefix(dir).unwrap().to_string_lossy().into_owned();
                if rel != "README.md" {
                    out.insert(rel, std::fs::read(&p).unwrap());
                }
            }
        }
    }
    out
}

#[test]
fn tiny_preset_regenerates_the_fixture_byte_for_byte() {
    let fixture = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../data-fixtures/tiny");
    let tmp = tempfile::tempdir().unwrap();
    let out = std::env::var_os("SYNTH_FIXTURE_OUT")
        .map(PathBuf::from)
        .unwrap_or_else(|| tmp.path().to_path_buf());
    let cfg = SynthConfig::preset(Preset::Tiny);
    generate(&cfg, &out, &mut |_, _| {}).unwrap();
    let (want, got) = (files(&fixture), files(&out));
    assert!(
        !want.is_empty(),
        "{} is empty: run `cargo xtask synth --preset tiny --out data-fixtures/tiny`",
        fixture.display()
    );
    let mut diff = Vec::new();
    for k in want.keys().chain(got.keys()) {
        if want.get(k) != got.get(k) && !diff.contains(k) {
            diff.push(k.clone());
        }
    }
    assert!(
        diff.is_empty(),
        "{} files differ from the fixture (regenerate with `cargo xtask synth --preset tiny --out data-fixtures/tiny` if the change is intended): {diff:?}",
        diff.len()
    );
    let total: usize = want.values().map(Vec::len).sum();
    assert!(total < 2_000_000, "fixture is {total} bytes");
    let s = scene::load(&fixture).unwrap();
    assert_eq!(s.frames.len(), 15);
    assert_eq!(s.split_indices(scene::Split::Test).len(), 3);
}
