#![allow(clippy::unwrap_used)]
//! `cargo xtask events` on Prophesee `.raw` files through the binary: random bytes are refused with
//! a message naming the file and the fix and a non-zero exit, `--format` reads a header-less file,
//! `--lenient` skips and reports, and `--format` is refused for files it does not apply to.

use std::path::Path;
use std::process::Command;

use events::io::prophesee::{encode, PropheseeFormat};
use events::{Event, EventStream, SensorSize};

fn xtask(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_xtask"))
        .args(args)
        .output()
        .unwrap()
}

fn stderr(o: &std::process::Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// 3000 bytes of a fixed xorshift sequence whose first is not `%`.
fn random_bytes() -> Vec<u8> {
    let mut x = 0x9E37_79B9_7F4A_7C15u64;
    let mut b: Vec<u8> = (0..3000)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 24) as u8
        })
        .collect();
    if b[0] == b'%' {
        b[0] = 0;
    }
    b
}

fn p(path: &Path) -> &str {
    path.to_str().unwrap()
}

#[test]
fn random_bytes_as_raw_are_refused_and_lenient_reads_report_what_they_skipped() {
    let tmp = tempfile::tempdir().unwrap();
    let x = tmp.path().join("x.raw");
    std::fs::write(&x, random_bytes()).unwrap();
    let o = xtask(&["events", "info", p(&x)]);
    assert!(
        !o.status.success(),
        "random bytes accepted: {}",
        String::from_utf8_lossy(&o.stdout)
    );
    let e = stderr(&o);
    assert!(
        e.contains("x.raw") && e.contains("--format evt2|evt3"),
        "{e}"
    );
    // With the encoding given, the first bad word is named with its byte offset.
    for f in ["evt2", "evt3"] {
        let o = xtask(&["events", "info", p(&x), "--format", f]);
        assert!(!o.status.success(), "--format {f}: random words accepted");
        let e = stderr(&o);
        assert!(
            e.contains("x.raw: byte ") && e.contains("reserved type"),
            "--format {f}: {e}"
        );
    }
    // --lenient skips them, says how many on stderr and in the JSON line.
    let o = xtask(&["events", "info", p(&x), "--format", "evt3", "--lenient"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let line: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let skipped = line["skipped_words"].as_u64().unwrap();
    assert!(skipped > 100, "{line}");
    assert!(
        stderr(&o).contains(&format!("x.raw: skipped {skipped} bad words (--lenient)")),
        "{}",
        stderr(&o)
    );
    // The same refusal on every command that reads events.
    let out = tmp.path().join("out.npz");
    let flo = tmp.path().join("f.flo");
    for args in [
        vec!["events", "convert", p(&x), p(&out)],
        vec!["events", "voxelize", p(&x), p(&out)],
        vec![
            "events",
            "flow",
            p(&x),
            "--t0-us",
            "0",
            "--t1-us",
            "10",
            "--out",
            p(&flo),
        ],
    ] {
        let o = xtask(&args);
        assert!(!o.status.success(), "{args:?} accepted random bytes");
        assert!(
            stderr(&o).contains("--format evt2|evt3"),
            "{args:?}: {}",
            stderr(&o)
        );
    }
}

#[test]
fn format_reads_a_headerless_recording_and_is_refused_where_it_does_not_apply() {
    let tmp = tempfile::tempdir().unwrap();
    let mut s = EventStream::new();
    for i in 0..500u16 {
        s.push(Event {
            t: 1000 + 37 * i64::from(i),
            x: i % 320,
            y: (i * 7) % 240,
            p: if i % 3 == 0 { 1 } else { -1 },
        });
    }
    s.sensor = Some(SensorSize::new(320, 240));
    let bytes = encode(&s, PropheseeFormat::Evt3).unwrap();
    let body = bytes.windows(6).position(|w| w == b"% end\n").unwrap() + 6;
    let bare = tmp.path().join("bare.raw");
    std::fs::write(&bare, &bytes[body..]).unwrap();
    let out = tmp.path().join("out.txt");
    let o = xtask(&["events", "convert", p(&bare), p(&out), "--format", "evt3"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let back = events::read_events(&out).unwrap();
    assert_eq!(
        (back.t, back.x, back.y, back.p),
        (s.t.clone(), s.x.clone(), s.y.clone(), s.p.clone())
    );
    // The header states EVT 3.0: --format evt2 contradicts it.
    let stated = tmp.path().join("stated.raw");
    std::fs::write(&stated, &bytes).unwrap();
    let o = xtask(&["events", "info", p(&stated), "--format", "evt2"]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("stated.raw: the header states Evt3"),
        "{}",
        stderr(&o)
    );
    // A file that states its format reads as before, nothing skipped.
    let o = xtask(&["events", "info", p(&stated)]);
    assert!(o.status.success(), "{}", stderr(&o));
    let line: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(line["events"], 500);
    assert_eq!(line["skipped_words"], 0);
    assert_eq!(line["format"], "evt3");
    // --format on a file that is not .raw.
    let o = xtask(&["events", "info", p(&out), "--format", "evt3"]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("applies to Prophesee .raw files only"),
        "{}",
        stderr(&o)
    );
}
