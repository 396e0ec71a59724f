#![allow(clippy::unwrap_used)]
//! The crafted-input set: random bytes under every user-file extension, truncated real files, a
//! 10¹² count in a header and a NaN in a camera, each given to the command a user would give it to.
//! Every one must exit non-zero with a message naming the file — never a panic (exit 101) or a
//! signal — within 20 s and under a 1 GiB address-space limit (`ulimit -v`, so an allocation sized
//! by an unchecked header fails instead of succeeding lazily).

mod common;

use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const MEMORY_LIMIT_KIB: u64 = 1 << 20;
const TIME_LIMIT: Duration = Duration::from_secs(20);

/// 3000 bytes of a fixed xorshift sequence (never starting with `%`, `#`, `p` or `{`, so no format
/// recognises its first byte).
fn random_bytes() -> Vec<u8> {
    let mut x = 0x2545_F491_4F6C_DD1Du64;
    let mut b: Vec<u8> = (0..3000)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 32) as u8
        })
        .collect();
    b[0] = 0x5A;
    b
}

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../data-fixtures")
}

fn truncated(src: &Path, keep: impl Fn(usize) -> usize, dst: &Path) {
    let bytes = std::fs::read(src).unwrap();
    std::fs::write(dst, &bytes[..keep(bytes.len())]).unwrap();
}

/// A `.npy` member with the given shape and no data behind it.
fn npy_claiming(shape: &str) -> Vec<u8> {
    let mut header = format!("{{'descr': '<f8', 'fortran_order': False, 'shape': {shape}, }}");
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(' ');
    }
    header.push('\n');
    let mut b = b"\x93NUMPY\x01\x00".to_vec();
    b.extend_from_slice(&u16::try_from(header.len()).unwrap().to_le_bytes());
    b.extend_from_slice(header.as_bytes());
    b.extend_from_slice(&[0u8; 64]);
    b
}

fn npz_claiming(path: &Path, members: &[&str], shape: &str) {
    use std::io::Write;
    let mut zip = zip::ZipWriter::new(std::fs::File::create(path).unwrap());
    for name in members {
        zip.start_file(
            format!("{name}.npy"),
            zip::write::SimpleFileOptions::default(),
        )
        .unwrap();
        zip.write_all(&npy_claiming(shape)).unwrap();
    }
    zip.finish().unwrap();
}

struct Outcome {
    code: Option<i32>,
    stderr: String,
    elapsed: Duration,
}

/// Runs the xtask binary under the memory limit, killing it after the time limit.
fn run_limited(dir: &Path, args: &[&str]) -> Outcome {
    let script = format!("ulimit -v {MEMORY_LIMIT_KIB} && exec \"$0\" \"$@\"");
    let mut child = Command::new("sh")
        .arg("-c")
        .arg(script)
        .arg(env!("CARGO_BIN_EXE_xtask"))
        .args(args)
        .current_dir(dir)
        .env("RUST_BACKTRACE", "0")
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let start = Instant::now();
    let mut stderr_pipe = child.stderr.take().unwrap();
    let reader = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = stderr_pipe.read_to_string(&mut s);
        s
    });
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break Some(status);
        }
        if start.elapsed() > TIME_LIMIT {
            let _ = child.kill();
            let _ = child.wait();
            break None;
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let elapsed = start.elapsed();
    Outcome {
        code: status.and_then(|s| s.code()),
        stderr: reader.join().unwrap(),
        elapsed,
    }
}

#[test]
fn every_crafted_input_is_refused_by_name_within_the_limits() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let fx = fixtures();
    let rnd = random_bytes();
    for ext in ["raw", "dat", "aedat4", "ply", "flo", "npz", "safetensors"] {
        std::fs::write(d.join(format!("random.{ext}")), &rnd).unwrap();
    }
    // Scenes: random bytes as scene.json; the tiny fixture with a random and a truncated flow file.
    std::fs::create_dir_all(d.join("random-scene")).unwrap();
    std::fs::write(d.join("random-scene/scene.json"), &rnd).unwrap();
    let tiny_with = |name: &str, damage: &dyn Fn(&Path)| {
        let scene = d.join(name);
        common::copy_dir(&fx.join("tiny"), &scene);
        damage(&scene.join("flow/000003.flo"));
    };
    tiny_with("scene-random-flo", &|f| std::fs::write(f, &rnd).unwrap());
    tiny_with("scene-cut-flo", &|f| truncated(f, |n| n - 5, f));
    // Real files, cut inside a word / packet / row.
    let events = fx.join("tiny/events/000005.npz");
    for ext in ["raw", "dat", "aedat4"] {
        let whole = d.join(format!("whole.{ext}"));
        let o = Command::new(env!("CARGO_BIN_EXE_xtask"))
            .args(["events", "convert"])
            .arg(&events)
            .arg(&whole)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    }
    // EVT 3.0 words are 2 bytes and .dat events 8 after a header; AEDAT 4 packets are length-prefixed.
    truncated(&d.join("whole.raw"), |n| n - 1, &d.join("cut.raw"));
    truncated(&d.join("whole.dat"), |n| n - 3, &d.join("cut.dat"));
    truncated(&d.join("whole.aedat4"), |n| n / 2, &d.join("cut.aedat4"));
    truncated(&fx.join("ply/splat600.ply"), |n| n - 7, &d.join("cut.ply"));
    truncated(
        &fx.join("ply/splat600.compressed.ply"),
        |n| n / 2,
        &d.join("cut.compressed.ply"),
    );
    truncated(
        &fx.join("flow/spynet-synthetic.safetensors"),
        |n| n - 100,
        &d.join("cut.safetensors"),
    );
    // 10^12 counts in headers.
    let props = [
        "x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0", "scale_1", "scale_2",
        "rot_0", "rot_1", "rot_2", "rot_3",
    ];
    let mut ply =
        "ply\nformat binary_little_endian 1.0\nelement vertex 1000000000000\n".to_string();
    for p in props {
        ply.push_str(&format!("property float {p}\n"));
    }
    ply.push_str("end_header\n");
    let mut ply = ply.into_bytes();
    ply.extend_from_slice(&[0u8; 560]);
    std::fs::write(d.join("huge.ply"), ply).unwrap();
    npz_claiming(
        &d.join("huge-events.npz"),
        &["t", "x", "y", "p"],
        "(1000000000000,)",
    );
    npz_claiming(
        &d.join("huge-body.npz"),
        &[
            "v_template",
            "shapedirs",
            "posedirs",
            "J_regressor",
            "weights",
            "f",
            "kintree_table",
        ],
        "(1000000000000, 3)",
    );
    let mut st = 1_000_000_000_000u64.to_le_bytes().to_vec();
    st.extend_from_slice(b"{}      ");
    std::fs::write(d.join("huge.safetensors"), st).unwrap();
    // NaN in a camera, as Python's json.dump writes it.
    std::fs::write(
        d.join("nan-camera.json"),
        r#"{"width": 64, "height": 64, "fx": NaN, "fy": 50.0, "cx": 32.0, "cy": 32.0,
            "position": [0, 0, 0], "rotation": [[1, 0, 0], [0, 1, 0], [0, 0, 1]]}"#,
    )
    .unwrap();
    std::fs::write(
        d.join("pose.json"),
        r#"{"pose": [0.0], "betas": [], "transl": [0, 0, 0]}"#,
    )
    .unwrap();
    let splat = fx.join("ply/splat600.ply");
    let splat = splat.to_str().unwrap();
    let image = fx.join("tiny/preview.png");
    let image = image.to_str().unwrap();

    // (the file the message must name, the command)
    let cases: Vec<(&str, Vec<&str>)> = vec![
        ("random.raw", vec!["events", "info", "random.raw"]),
        ("random.dat", vec!["events", "info", "random.dat"]),
        ("random.aedat4", vec!["events", "info", "random.aedat4"]),
        ("random.npz", vec!["events", "info", "random.npz"]),
        ("random.ply", vec!["ply-info", "random.ply"]),
        (
            "random.ply",
            vec![
                "render",
                "--ply",
                "random.ply",
                "--camera",
                "nan-camera.json",
                "--out",
                "o.png",
            ],
        ),
        (
            "random.npz",
            vec![
                "body",
                "--model",
                "random.npz",
                "--params",
                "pose.json",
                "--out",
                "o.npy",
            ],
        ),
        (
            "random.safetensors",
            vec![
                "flow",
                "--img1",
                image,
                "--img2",
                image,
                "--weights",
                "random.safetensors",
                "--out",
                "o.flo",
            ],
        ),
        (
            "random.safetensors",
            vec!["lpips", image, image, "--weights", "random.safetensors"],
        ),
        (
            "scene.json",
            vec![
                "reconstruct",
                "--data",
                "random-scene",
                "--out",
                "o",
                "--steps",
                "1",
            ],
        ),
        (
            "000003.flo",
            vec![
                "reconstruct",
                "--data",
                "scene-random-flo",
                "--out",
                "o",
                "--steps",
                "1",
            ],
        ),
        (
            "000003.flo",
            vec![
                "reconstruct",
                "--data",
                "scene-cut-flo",
                "--out",
                "o",
                "--steps",
                "1",
            ],
        ),
        ("cut.raw", vec!["events", "info", "cut.raw"]),
        ("cut.dat", vec!["events", "info", "cut.dat"]),
        ("cut.aedat4", vec!["events", "info", "cut.aedat4"]),
        ("cut.ply", vec!["ply-info", "cut.ply"]),
        ("cut.compressed.ply", vec!["ply-info", "cut.compressed.ply"]),
        (
            "cut.safetensors",
            vec![
                "flow",
                "--img1",
                image,
                "--img2",
                image,
                "--weights",
                "cut.safetensors",
                "--out",
                "o.flo",
            ],
        ),
        ("huge.ply", vec!["ply-info", "huge.ply"]),
        ("huge-events.npz", vec!["events", "info", "huge-events.npz"]),
        (
            "huge-body.npz",
            vec![
                "body",
                "--model",
                "huge-body.npz",
                "--params",
                "pose.json",
                "--out",
                "o.npy",
            ],
        ),
        (
            "huge.safetensors",
            vec![
                "flow",
                "--img1",
                image,
                "--img2",
                image,
                "--weights",
                "huge.safetensors",
                "--out",
                "o.flo",
            ],
        ),
        (
            "nan-camera.json",
            vec![
                "render",
                "--ply",
                splat,
                "--camera",
                "nan-camera.json",
                "--out",
                "o.png",
            ],
        ),
    ];
    let mut failures = Vec::new();
    for (file, args) in &cases {
        let o = run_limited(d, args);
        let first_line = o.stderr.lines().next().unwrap_or("").to_string();
        let verdict = match o.code {
            None if o.elapsed > TIME_LIMIT => Some("ran longer than 20 s".to_string()),
            None => Some("killed by a signal (abort or memory)".to_string()),
            Some(0) => Some("exit 0: accepted".to_string()),
            Some(101) => Some("exit 101: panicked".to_string()),
            Some(_) if o.stderr.contains("panicked") => Some("panicked".to_string()),
            Some(_) if !o.stderr.contains(file) => Some(format!("message does not name {file}")),
            Some(_) => None,
        };
        if let Some(v) = verdict {
            failures.push(format!("{args:?}: {v}\n{}", o.stderr));
        } else {
            eprintln!(
                "ok ({:.2} s) {args:?}: {first_line}",
                o.elapsed.as_secs_f64()
            );
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n---\n"));
}
