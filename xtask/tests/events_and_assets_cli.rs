//! Success paths of `events voxelize`, `events flow` and `body-convert`, each checking what it wrote:
//! the voxel grid's shape, the events it sums and where they lie, the flow file against the
//! library's contrast maximisation on the same window, and
//! the converted body against the committed one.
#![allow(clippy::unwrap_used)]

use std::path::{Path, PathBuf};
use std::process::Command;

use events::{Event, EventStream, SensorSize};

fn xtask() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_xtask"));
    c.env("RUST_BACKTRACE", "0");
    c
}

/// Runs `command` and asserts success.
fn run(command: &mut Command) {
    let o = command.output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

/// The f32 values and shape of a little-endian `.npy` file (format 1.0).
fn read_npy_f32(path: &Path) -> (Vec<usize>, Vec<f32>) {
    let bytes = std::fs::read(path).unwrap();
    assert_eq!(&bytes[..8], b"\x93NUMPY\x01\x00");
    let len = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
    let header = std::str::from_utf8(&bytes[10..10 + len]).unwrap();
    assert!(header.contains("'descr': '<f4'"), "{header}");
    let inside = header.split("'shape': (").nth(1).unwrap();
    let shape: Vec<usize> = inside
        .split(')')
        .next()
        .unwrap()
        .split(',')
        .filter(|d| !d.trim().is_empty())
        .map(|d| d.trim().parse().unwrap())
        .collect();
    let data = bytes[10 + len..]
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    (shape, data)
}

/// A field of dots sweeping right at `px_per_ms` over a 48×32 sensor, each firing a positive event
/// every 50 µs where it is (a texture in both directions, so the motion is observable).
fn moving_dots(dir: &Path, px_per_ms: f64) -> PathBuf {
    let dots: Vec<(f64, u16)> = (0..96u16)
        .map(|i| (2.0 + f64::from((i * 37) % 17), (i * 11) % 32))
        .collect();
    let mut s = EventStream::new();
    for step in 0..200i64 {
        let t = step * 50; // µs
        for &(x0, y) in &dots {
            let x = x0 + px_per_ms * t as f64 / 1000.0;
            s.push(Event {
                t,
                x: x.round() as u16,
                y,
                p: 1,
            });
        }
    }
    // (`.npz` does not record the sensor: the commands take `--sensor 48x32`.)
    let path = dir.join("dots.npz");
    events::write_events(&path, &s).unwrap();
    path
}

#[test]
fn voxelize_writes_bins_that_sum_to_the_windows_polarities() {
    let dir = tempfile::tempdir().unwrap();
    let input = moving_dots(dir.path(), 2.0);
    let out = dir.path().join("grid.npy");
    run(xtask()
        .args(["events", "voxelize"])
        .arg(&input)
        .arg(&out)
        .args([
            "--bins", "4", "--t0-us", "0", "--t1-us", "5000", "--sensor", "48x32",
        ]));
    let (shape, grid) = read_npy_f32(&out);
    assert_eq!(shape, [4, 32, 48]);
    // Bilinear in time: every event of the window adds its polarity, spread over two bins.
    let total: f64 = grid.iter().map(|&v| f64::from(v)).sum();
    assert!((total - 100.0 * 96.0).abs() < 1e-2, "{total}");
    // The dots sweep right: the last bin's mass lies right of the first's.
    let centre = |b: usize| {
        let plane = &grid[b * 32 * 48..(b + 1) * 32 * 48];
        let (mut m, mut mx) = (0.0, 0.0);
        for (i, &v) in plane.iter().enumerate() {
            m += f64::from(v);
            mx += f64::from(v) * (i % 48) as f64;
        }
        mx / m
    };
    assert!(centre(3) > centre(0) + 3.0, "{} {}", centre(0), centre(3));
}

#[test]
fn events_flow_writes_the_contrast_maximisation_flow_of_the_window() {
    let dir = tempfile::tempdir().unwrap();
    let input = moving_dots(dir.path(), 2.0);
    let out = dir.path().join("f.flo");
    let viz = dir.path().join("f.png");
    run(xtask()
        .args(["events", "flow"])
        .arg(&input)
        .args([
            "--t0-us", "0", "--t1-us", "5000", "--sensor", "48x32", "--out",
        ])
        .arg(&out)
        .arg("--viz")
        .arg(&viz));
    let flow = events::read_flow(&out).unwrap();
    assert_eq!((flow.width, flow.height), (48, 32));
    // The command's flow is the library's contrast maximisation on the same window, value for
    // value, finite, and not zero where the dots moved.
    let stream = events::read_events(&input).unwrap();
    let expected = events::flow_from_events(
        &stream.window(0, 5000),
        SensorSize::new(48, 32),
        0,
        5000,
        &events::CmaxConfig::default(),
    )
    .unwrap();
    assert_eq!(flow.data, expected.data);
    assert!(flow.data.iter().all(|v| v.is_finite()));
    let moved = flow.data.iter().map(|v| v.abs()).sum::<f32>() / flow.data.len() as f32;
    assert!(moved > 1.0, "mean |flow| {moved}");
    assert!(image::open(&viz).unwrap().width() == 48);
}

#[test]
fn body_convert_reproduces_the_committed_body() {
    let assets = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/assets/makehuman-cc0");
    if !assets.join("base.obj").exists() {
        assert!(
            std::env::var_os("E_SEM3DGS_REQUIRE_SHARED_ASSETS").is_none(),
            "{} is absent but E_SEM3DGS_REQUIRE_SHARED_ASSETS is set",
            assets.display()
        );
        eprintln!(
            "SKIPPED body_convert_reproduces_the_committed_body: {} is absent",
            assets.display()
        );
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    run(xtask()
        .arg("body-convert")
        .arg("--assets")
        .arg(&assets)
        .arg("--out-dir")
        .arg(dir.path()));
    let fresh = std::fs::read(dir.path().join("makehuman.npz")).unwrap();
    let committed = std::fs::read(smpl_deform::builtin_makehuman_path()).unwrap();
    assert!(
        fresh == committed,
        "body-convert no longer writes the committed bytes"
    );
}
