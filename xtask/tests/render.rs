//! End-to-end test of `cargo xtask render`: runs the built `xtask` binary on a tiny generated scene
//! (PLY + camera JSON) to PNG and EXR, with `--loss-weights` to a gradient `.npz` (shapes, finiteness,
//! and one gradient against a finite difference of the printed loss through the whole CLI path), and
//! the bad inputs of the rasterizer issue: each must fail with a clear error, never a panic.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use gaussians::GaussianSet;

const W: u32 = 40;
const H: u32 = 30;

fn tmp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("xtask-render-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&d).expect("creating the test directory");
    d
}

fn xtask(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_xtask"))
        .args(args)
        .output()
        .expect("running the xtask binary")
}

fn path_str(p: &Path) -> &str {
    p.to_str().expect("temp paths are UTF-8")
}

/// 12 degree-1 Gaussians spread in front of the identity camera, plus tweaks from `edit`.
fn write_scene(dir: &Path, dc_shift: f32, edit: impl FnOnce(&mut GaussianSet)) -> PathBuf {
    let mut set = GaussianSet::new(1, 0, 0);
    for i in 0..12 {
        let fi = i as f32;
        let z = 2.0 + 0.15 * fi;
        let x = (fi * 0.37).sin() * 0.5 * z;
        let y = (fi * 0.53).cos() * 0.35 * z;
        let mut sh = vec![0.0f32; 12];
        for (c, v) in sh[..3].iter_mut().enumerate() {
            *v = 0.3 * ((fi + c as f32) * 0.9).sin();
        }
        sh[3..]
            .iter_mut()
            .enumerate()
            .for_each(|(k, v)| *v = 0.05 * ((k as f32) - 4.0) / 4.0);
        if i == 3 {
            sh[1] += dc_shift;
        }
        set.push(
            [x, y, z],
            [-2.3 + 0.05 * fi, -2.1, -2.5],
            [1.0, 0.1 * fi, -0.2, 0.05],
            0.5 + 0.1 * fi,
            &sh,
            &[],
            &[],
        )
        .expect("pushing a Gaussian");
    }
    edit(&mut set);
    let path = dir.join(format!("scene{dc_shift}.ply"));
    gaussians::ply::write_ply(&path, &set).expect("writing the PLY");
    path
}

fn write_camera(dir: &Path, name: &str, json: &str) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, json).expect("writing the camera");
    path
}

fn good_camera(dir: &Path) -> PathBuf {
    write_camera(
        dir,
        "camera.json",
        &format!(
            r#"{{"width":{W},"height":{H},"fx":36,"fy":36,"cx":20,"cy":15,
            "world_to_camera":[[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]}}"#
        ),
    )
}

fn write_weights(path: &Path) {
    let n = (W * H * 3) as usize;
    let data: Vec<f32> = (0..n)
        .map(|i| ((i * 37) % 11) as f32 / 11.0 - 0.3)
        .collect();
    use npyz::WriterBuilder;
    use std::io::Write;
    let mut bw = std::io::BufWriter::new(std::fs::File::create(path).expect("creating weights"));
    let mut w = npyz::WriteOptions::<f32>::new()
        .default_dtype()
        .shape(&[u64::from(H), u64::from(W), 3])
        .writer(&mut bw)
        .begin_nd()
        .expect("npy header");
    w.extend(data.iter().copied()).expect("writing weights");
    w.finish().expect("finishing weights");
    bw.flush().expect("flushing weights");
}

fn loss_of(out: &Output) -> f64 {
    let stdout = String::from_utf8_lossy(&out.stdout);
    let line = stdout.lines().last().expect("a JSON line on stdout");
    let v: serde_json::Value = serde_json::from_str(line).expect("JSON on stdout");
    v["loss"].as_f64().expect("a loss")
}

fn npz_array(path: &Path, name: &str) -> (Vec<u64>, Vec<f32>) {
    let mut npz = npyz::npz::NpzArchive::open(path).expect("opening the npz");
    let arr = npz
        .by_name(name)
        .expect("reading the npz")
        .unwrap_or_else(|| panic!("array {name} missing"));
    let shape = arr.shape().to_vec();
    (shape, arr.into_vec::<f32>().expect("f32 data"))
}

#[test]
fn render_writes_png_exr_and_gradients() {
    let dir = tmp_dir("ok");
    let ply = write_scene(&dir, 0.0, |_| {});
    let cam = good_camera(&dir);
    let png = dir.join("out.png");
    let out = xtask(&[
        "render",
        "--ply",
        path_str(&ply),
        "--camera",
        path_str(&cam),
        "--out",
        path_str(&png),
        "--bg",
        "0.1",
        "0.2",
        "0.3",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let img = image::open(&png).expect("reading the PNG").to_rgb8();
    assert_eq!(img.dimensions(), (W, H));
    // Background (0.1, 0.2, 0.3) ≈ (26, 51, 77) in the corners; splats change the centre region.
    let differs = img.pixels().filter(|p| p.0 != [26, 51, 77]).count();
    assert!(
        differs > 50,
        "only {differs} pixels differ from the background"
    );

    let exr = dir.join("out.exr");
    let out = xtask(&[
        "render",
        "--ply",
        path_str(&ply),
        "--camera",
        path_str(&cam),
        "--out",
        path_str(&exr),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let bytes = std::fs::read(&exr).expect("reading the EXR");
    assert_eq!(&bytes[..4], &[0x76, 0x2f, 0x31, 0x01], "EXR magic number");

    // Gradients: shapes, finiteness, and dL/d sh[3, 0, 1] against a finite difference of the loss
    // the CLI prints. The colour is linear in the DC coefficient (no clamp is hit at these values)
    // and L is linear in the colour, so the difference quotient is exact up to f32 rounding of the
    // image sums (~1e-6 relative of L ≈ O(10)); h = 0.05 ⇒ tolerance 2e-3 absolute + 1e-2 relative.
    let weights = dir.join("w.npy");
    write_weights(&weights);
    let grads = dir.join("g.npz");
    let out = xtask(&[
        "render",
        "--ply",
        path_str(&ply),
        "--camera",
        path_str(&cam),
        "--out",
        path_str(&png),
        "--loss-weights",
        path_str(&weights),
        "--grads-out",
        path_str(&grads),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    for (name, shape) in [
        ("means", vec![12u64, 3]),
        ("log_scales", vec![12, 3]),
        ("quats", vec![12, 4]),
        ("opacity_logits", vec![12]),
        ("sh", vec![12, 4, 3]),
    ] {
        let (s, v) = npz_array(&grads, name);
        assert_eq!(s, shape, "{name} shape");
        assert!(
            v.iter().all(|x| x.is_finite()),
            "{name} has a non-finite entry"
        );
        assert!(v.iter().any(|&x| x != 0.0), "{name} is all zero");
    }
    let (_, sh) = npz_array(&grads, "sh");
    let analytic = f64::from(sh[3 * 12 + 1]);
    let h = 0.05f32;
    let loss_at = |shift: f32| {
        let p = write_scene(&dir, shift, |_| {});
        let g = dir.join("g_fd.npz");
        let out = xtask(&[
            "render",
            "--ply",
            path_str(&p),
            "--camera",
            path_str(&cam),
            "--out",
            path_str(&png),
            "--loss-weights",
            path_str(&weights),
            "--grads-out",
            path_str(&g),
        ]);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        loss_of(&out)
    };
    let numeric = (loss_at(h) - loss_at(-h)) / (2.0 * f64::from(h));
    assert!(
        analytic.abs() > 1e-3,
        "gradient too small to test: {analytic}"
    );
    assert!(
        (numeric - analytic).abs() <= 2e-3 + 1e-2 * numeric.abs().max(analytic.abs()),
        "dL/dsh: numeric {numeric} vs analytic {analytic}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

fn assert_clean_failure(out: &Output, needle: &str) {
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success(),
        "expected a failure, stderr: {stderr}"
    );
    assert!(!stderr.contains("panicked"), "panicked: {stderr}");
    assert!(
        stderr.to_lowercase().contains(needle),
        "error should mention {needle:?}: {stderr}"
    );
}

#[test]
fn render_rejects_bad_input_with_clear_errors() {
    let dir = tmp_dir("bad");
    let ply = write_scene(&dir, 0.0, |_| {});
    let png = dir.join("out.png");
    let run = |ply: &Path, cam: &Path| {
        xtask(&[
            "render",
            "--ply",
            path_str(ply),
            "--camera",
            path_str(cam),
            "--out",
            path_str(&png),
        ])
    };
    let cam = |name: &str, w: &str, fx: &str, row2: &str| {
        write_camera(
            &dir,
            name,
            &format!(
                r#"{{"width":{w},"height":30,"fx":{fx},"fy":36,"cx":20,"cy":15,
            "world_to_camera":[[1,0,0,0],[0,1,0,0],{row2},[0,0,0,1]]}}"#
            ),
        )
    };
    assert_clean_failure(
        &run(&ply, &cam("singular.json", "40", "36", "[0,0,0,0]")),
        "singular",
    );
    assert_clean_failure(
        &run(&ply, &cam("zero.json", "0", "36", "[0,0,1,0]")),
        "size",
    );
    assert_clean_failure(
        &run(&ply, &cam("nan.json", "40", "NaN", "[0,0,1,0]")),
        "camera",
    );
    assert_clean_failure(
        &run(&ply, &cam("huge.json", "20000", "36", "[0,0,1,0]")),
        "size",
    );
    // `write_ply` refuses zero quaternions, so zero Gaussian 5's rot_0..rot_3 in the file's bytes.
    let zero_q = dir.join("zero_quat.ply");
    std::fs::write(&zero_q, zero_quaternion_bytes(&ply, 5)).expect("writing the patched PLY");
    assert_clean_failure(&run(&zero_q, &good_camera(&dir)), "quaternion");
    let _ = std::fs::remove_dir_all(&dir);
}

/// The bytes of a binary little-endian PLY of float properties with vertex `index`'s rot_0..rot_3
/// set to 0.
fn zero_quaternion_bytes(ply: &Path, index: usize) -> Vec<u8> {
    let mut bytes = std::fs::read(ply).expect("reading the PLY");
    let marker = b"end_header\n";
    let body = bytes
        .windows(marker.len())
        .position(|w| w == marker)
        .expect("a PLY header")
        + marker.len();
    let header = String::from_utf8_lossy(&bytes[..body]).to_string();
    assert!(header.contains("binary_little_endian"), "{header}");
    let props: Vec<&str> = header
        .lines()
        .filter_map(|l| l.strip_prefix("property float "))
        .collect();
    assert_eq!(
        header.lines().filter(|l| l.starts_with("property")).count(),
        props.len(),
        "only float properties expected: {header}"
    );
    let stride = 4 * props.len();
    for k in 0..4 {
        let p = props
            .iter()
            .position(|&n| n == format!("rot_{k}"))
            .expect("rot_k property");
        let at = body + index * stride + 4 * p;
        bytes[at..at + 4].copy_from_slice(&0.0f32.to_le_bytes());
    }
    bytes
}
