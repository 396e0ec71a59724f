//! Success-path tests of the README command table's rows that had none: `ply-info`, `body`,
//! `flow`, `lpips` on EXR inputs with `--linear`, `flow-import-t7` and every `bench` target
//! (`raster`, `flow`, `events`, `deform`, `lpips`). Each test runs the built `xtask` binary on a tiny
//! input (written in the test or committed under `data-fixtures/`), asserts that it succeeds and
//! checks what it wrote: counts, sizes, finite values, and values predicted independently or by the
//! library call the command wraps.
#![allow(clippy::unwrap_used)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use serde_json::Value;

/// The workspace root (the parent of `xtask/`), where `cargo xtask` runs.
fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .unwrap()
        .to_path_buf()
}

/// Runs `xtask` with `args` in the workspace root (where the default weight paths resolve) and
/// `RUST_BACKTRACE=0`; panics with its stderr unless it succeeds, and returns its output.
fn xtask_ok(args: &[&str], env: &[(&str, &Path)]) -> Output {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_xtask"));
    cmd.args(args)
        .current_dir(root())
        .env("RUST_BACKTRACE", "0");
    for (k, v) in env {
        cmd.env(k, v);
    }
    let out = cmd.output().unwrap();
    assert!(
        out.status.success(),
        "xtask {args:?} failed ({}):\n{}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// A path as a UTF-8 argument.
fn arg(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Every non-empty line of `out`'s stdout parsed as a JSON object (any other line fails the test).
fn json_lines(out: &Output) -> Vec<Value> {
    let text = String::from_utf8_lossy(&out.stdout);
    let lines: Vec<Value> = text
        .lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            let v: Value = serde_json::from_str(l).unwrap_or_else(|e| panic!("{e}: {l:?}"));
            assert!(v.is_object(), "not a JSON object: {l:?}");
            v
        })
        .collect();
    assert!(!lines.is_empty(), "no JSON lines on stdout");
    lines
}

/// `v[key]` as a number that must be finite and positive (a timing or a rate).
fn positive(v: &Value, key: &str) -> f64 {
    let x = v[key]
        .as_f64()
        .unwrap_or_else(|| panic!("{key} is not a number in {v}"));
    assert!(x.is_finite() && x > 0.0, "{key} = {x} in {v}");
    x
}

/// `v[key]` as an array of three numbers.
fn vec3(v: &Value, key: &str) -> [f64; 3] {
    let a = v[key].as_array().unwrap_or_else(|| panic!("{key} in {v}"));
    assert_eq!(a.len(), 3, "{key} in {v}");
    [0, 1, 2].map(|i| a[i].as_f64().unwrap())
}

/// Asserts `|got − want| ≤ tol · max(1, |want|)`.
fn close(got: f64, want: f64, tol: f64, what: &str) {
    assert!(
        (got - want).abs() <= tol * want.abs().max(1.0),
        "{what}: got {got}, want {want}"
    );
}

// ---------------------------------------------------------------------------------------------
// ply-info
// ---------------------------------------------------------------------------------------------

/// `ply-info` on a PLY written here (every figure predicted: count, SH degree, extra channels,
/// bounds, mean opacity, scale range) and on the committed `splat600.ply` (600 Gaussians, degree 3).
#[test]
fn ply_info_summarises_a_written_and_a_committed_ply() {
    let dir = tempfile::tempdir().unwrap();
    // Five degree-1 Gaussians with 2 feature channels and 3 semantic classes; every summary figure
    // is known in advance.
    let means = [
        [-1.5f32, 0.25, 2.0],
        [0.5, -2.0, 3.5],
        [1.25, 1.0, 1.0],
        [0.0, 0.0, 4.0],
        [-0.5, 0.75, 2.5],
    ];
    let logits = [0.0f32, 3.0f32.ln(), -(3.0f32.ln()), 0.0, 0.0]; // opacities ½, ¾, ¼, ½, ½
    let mut set = gaussians::GaussianSet::new(1, 2, 3);
    for (i, (m, o)) in means.iter().zip(logits).enumerate() {
        let f = i as f32;
        let log_scale = [-4.0 + 0.5 * f, -2.0, -1.0 - 0.25 * f]; // min −4, max −1
        let sh: Vec<f32> = (0..12).map(|k| 0.1 * (k as f32 - f)).collect();
        set.push(
            *m,
            log_scale,
            [1.0, 0.1 * f, 0.0, 0.0],
            o,
            &sh,
            &[f, -f],
            &[0.1, 0.2 * f, -0.3],
        )
        .unwrap();
    }
    let ply = dir.path().join("five.ply");
    gaussians::write_ply(&ply, &set).unwrap();
    let out = xtask_ok(&["ply-info", arg(&ply)], &[]);
    let info = json_lines(&out);
    assert_eq!(info.len(), 1, "{info:?}");
    let info = &info[0];
    assert_eq!(info["gaussians"], 5, "{info}");
    assert_eq!(info["sh_degree"], 1, "{info}");
    assert_eq!(info["feature_dim"], 2, "{info}");
    assert_eq!(info["semantic_classes"], 3, "{info}");
    assert_eq!(info["file"].as_str().unwrap(), arg(&ply), "{info}");
    let (lo, hi) = (vec3(info, "bounds_min"), vec3(info, "bounds_max"));
    for (a, (want_lo, want_hi)) in [(-1.5, 1.25), (-2.0, 1.0), (1.0, 4.0)]
        .into_iter()
        .enumerate()
    {
        close(lo[a], want_lo, 1e-6, "bounds_min");
        close(hi[a], want_hi, 1e-6, "bounds_max");
    }
    close(
        info["opacity_mean"].as_f64().unwrap(),
        0.5,
        1e-6,
        "opacity_mean",
    );
    close(
        info["scale_min_m"].as_f64().unwrap(),
        (-4.0f64).exp(),
        1e-5,
        "scale_min_m",
    );
    close(
        info["scale_max_m"].as_f64().unwrap(),
        (-1.0f64).exp(),
        1e-5,
        "scale_max_m",
    );

    // The committed INRIA-layout file: 600 Gaussians of SH degree 3 (data-fixtures/ply/README.md).
    let splat = root().join("data-fixtures/ply/splat600.ply");
    let info = &json_lines(&xtask_ok(&["ply-info", arg(&splat)], &[]))[0];
    assert_eq!(info["gaussians"], 600, "{info}");
    assert_eq!(info["sh_degree"], 3, "{info}");
    assert_eq!(info["feature_dim"], 0, "{info}");
    assert_eq!(info["semantic_classes"], 0, "{info}");
    let (lo, hi) = (vec3(info, "bounds_min"), vec3(info, "bounds_max"));
    for a in 0..3 {
        assert!(
            lo[a].is_finite() && hi[a].is_finite() && lo[a] < hi[a],
            "{info}"
        );
    }
    let opacity = info["opacity_mean"].as_f64().unwrap();
    assert!((0.0..=1.0).contains(&opacity), "{info}");
    let (smin, smax) = (
        info["scale_min_m"].as_f64().unwrap(),
        info["scale_max_m"].as_f64().unwrap(),
    );
    assert!(smin > 0.0 && smin <= smax && smax.is_finite(), "{info}");
}

// ---------------------------------------------------------------------------------------------
// body
// ---------------------------------------------------------------------------------------------

/// An OBJ's `v` and `f` lines (faces 1-based as written).
fn read_obj(path: &Path) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
    let text = std::fs::read_to_string(path).unwrap();
    let (mut v, mut f) = (Vec::new(), Vec::new());
    for line in text.lines() {
        let mut it = line.split_whitespace();
        match it.next() {
            Some("v") => {
                let xyz: Vec<f32> = it.map(|s| s.parse().unwrap()).collect();
                assert_eq!(xyz.len(), 3, "{line:?}");
                v.push([xyz[0], xyz[1], xyz[2]]);
            }
            Some("f") => {
                let idx: Vec<u32> = it.map(|s| s.parse().unwrap()).collect();
                assert_eq!(idx.len(), 3, "{line:?}");
                f.push([idx[0], idx[1], idx[2]]);
            }
            _ => {}
        }
    }
    (v, f)
}

/// `body` on the built-in body: the OBJ has the model's vertex and face counts, finite vertices equal
/// to the library's posing, the translated template at rest, and a bent elbow moves the forearm only.
#[test]
fn body_poses_the_builtin_body_to_obj() {
    let dir = tempfile::tempdir().unwrap();
    let model = smpl_deform::BodyModel::builtin_makehuman().unwrap();
    let transl = [0.1f32, -0.2, 0.3];
    let rest = vec![0.0f32; 72];
    let mut bent = rest.clone();
    bent[3 * 18 + 1] = 1.2; // left elbow, as in `bench deform`
    let mut posed = Vec::new();
    for (name, pose) in [("rest", &rest), ("bent", &bent)] {
        let params = dir.path().join(format!("{name}.json"));
        let json = serde_json::json!({"pose": pose, "betas": [], "transl": transl});
        std::fs::write(&params, json.to_string()).unwrap();
        let obj = dir.path().join(format!("{name}.obj"));
        let out = xtask_ok(
            &[
                "body",
                "--model",
                "builtin:makehuman",
                "--params",
                arg(&params),
                "--out",
                arg(&obj),
            ],
            &[],
        );
        let (v, f) = read_obj(&obj);
        let stdout = String::from_utf8_lossy(&out.stdout);
        assert!(
            stdout.contains(&format!("({} vertices, {} faces)", v.len(), f.len())),
            "{stdout}"
        );
        assert_eq!(v.len(), model.v_template.len());
        assert_eq!(f.len(), model.faces.len());
        assert!(v.len() > 1000 && f.len() > 1000, "{} {}", v.len(), f.len());
        assert!(v.iter().flatten().all(|x| x.is_finite()));
        for (got, want) in f.iter().zip(&model.faces) {
            assert_eq!(*got, want.map(|i| i + 1), "faces are the model's, 1-based");
        }
        // What the library computes for the same parameters.
        let mut p = smpl_deform::SmplParams::zero();
        p.pose.clone_from(pose);
        p.transl = transl;
        let want = model.pose(&p).unwrap().vertices;
        for (g, w) in v.iter().zip(&want) {
            for a in 0..3 {
                close(f64::from(g[a]), f64::from(w[a]), 1e-6, "posed vertex");
            }
        }
        posed.push(v);
    }
    // The built-in body has no blend shapes: the rest pose is the template, translated.
    for (g, t) in posed[0].iter().zip(&model.v_template) {
        for a in 0..3 {
            close(
                f64::from(g[a]),
                f64::from(t[a] + transl[a]),
                1e-5,
                "rest vertex",
            );
        }
    }
    // Bending the elbow moves the forearm (by centimetres) and leaves most of the body in place.
    let moved: Vec<f32> = posed[0]
        .iter()
        .zip(&posed[1])
        .map(|(a, b)| (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f32>().sqrt())
        .collect();
    let max = moved.iter().copied().fold(0.0f32, f32::max);
    let still = moved.iter().filter(|&&d| d < 1e-5).count();
    assert!(
        max > 0.05,
        "the bent elbow moved vertices by at most {max} m"
    );
    assert!(
        still > moved.len() / 2,
        "only {still} of {} vertices stayed",
        moved.len()
    );
}

// ---------------------------------------------------------------------------------------------
// flow
// ---------------------------------------------------------------------------------------------

/// `flow` with the default weights: the `.flo` header (magic, width, height), its size, finite
/// values, and the same field as the shipped network run through the library.
#[test]
fn flow_writes_a_flo_with_the_default_weights() {
    let dir = tempfile::tempdir().unwrap();
    let (w, h) = (64u32, 48u32); // not square: a swapped width and height shows
                                 // A smooth texture, and the same texture 2 px to the right.
    let texture = |x: f32, y: f32, c: usize| {
        let v = 0.5
            + 0.25 * (0.31 * x + 0.7 * c as f32).sin()
            + 0.2 * (0.23 * y - 0.11 * x + 0.3 * c as f32).cos();
        (v.clamp(0.0, 1.0) * 255.0).round() as u8
    };
    let make = |shift: f32| {
        image::RgbImage::from_fn(w, h, |x, y| {
            let (x, y) = (x as f32 - shift, y as f32);
            image::Rgb([texture(x, y, 0), texture(x, y, 1), texture(x, y, 2)])
        })
    };
    let (a, b) = (dir.path().join("a.png"), dir.path().join("b.png"));
    make(0.0).save(&a).unwrap();
    make(2.0).save(&b).unwrap();
    let flo = dir.path().join("f.flo");
    xtask_ok(
        &[
            "flow",
            "--img1",
            arg(&a),
            "--img2",
            arg(&b),
            "--out",
            arg(&flo),
        ],
        &[],
    );
    let bytes = std::fs::read(&flo).unwrap();
    let word = |o: usize| [bytes[o], bytes[o + 1], bytes[o + 2], bytes[o + 3]];
    assert_eq!(f32::from_le_bytes(word(0)), 202021.25, "the .flo magic");
    assert_eq!(i32::from_le_bytes(word(4)), w as i32, "width");
    assert_eq!(i32::from_le_bytes(word(8)), h as i32, "height");
    let n = (w * h) as usize;
    assert_eq!(
        bytes.len(),
        12 + 8 * n,
        "header + interleaved (u, v) per pixel"
    );
    let got: Vec<f32> = (0..2 * n)
        .map(|k| f32::from_le_bytes(word(12 + 4 * k)))
        .collect();
    assert!(got.iter().all(|v| v.is_finite() && v.abs() < 64.0));
    // The same images through the shipped network in the library give the same field.
    let planar = |p: &Path| {
        let img = image::open(p).unwrap().to_rgb32f();
        let mut out = vec![0.0f32; 3 * n];
        for (i, px) in img.pixels().enumerate() {
            for c in 0..3 {
                out[c * n + i] = px.0[c];
            }
        }
        out
    };
    let net =
        flow::load_safetensors(&root().join("data-fixtures/flow/spynet-synthetic.safetensors"))
            .unwrap();
    let want = net
        .forward(&planar(&a), &planar(&b), h as usize, w as usize)
        .unwrap()
        .flow;
    for i in 0..n {
        close(f64::from(got[2 * i]), f64::from(want[i]), 1e-4, "u");
        close(f64::from(got[2 * i + 1]), f64::from(want[n + i]), 1e-4, "v");
    }
    assert!(got.iter().any(|&v| v != 0.0), "an all-zero flow field");
}

// ---------------------------------------------------------------------------------------------
// lpips
// ---------------------------------------------------------------------------------------------

/// The LPIPS distance on the last line of `out`'s stdout.
fn last_number(out: &Output) -> f64 {
    let text = String::from_utf8_lossy(&out.stdout);
    let last = text.lines().last().unwrap_or_else(|| panic!("no stdout"));
    last.trim()
        .parse()
        .unwrap_or_else(|e| panic!("{e}: last line {last:?}"))
}

/// `lpips` on EXR files: 0 for identical images; for different ones the library's distance on the
/// sRGB-encoded values with `--linear` and on the stored values without (and the two differ).
#[test]
fn lpips_scores_linear_exr_images() {
    let dir = tempfile::tempdir().unwrap();
    let (w, h) = (40usize, 34usize);
    let n = w * h;
    // Linear intensities, some above 1 (clamped by the sRGB encoding of `--linear`).
    let base = |x: usize, y: usize, c: usize| {
        0.3 + 0.25 * ((x as f32) * 0.4 + c as f32).sin() + 0.5 * (y as f32 / h as f32).powi(2)
    };
    let other = |x: usize, y: usize, c: usize| {
        base(x, y, c)
            * if (x / 5 + y / 5).is_multiple_of(2) {
                0.4
            } else {
                1.0
            }
    };
    let write = |name: &str, f: &(dyn Fn(usize, usize, usize) -> f32 + Sync)| {
        let p = dir.path().join(name);
        exr::prelude::write_rgb_file(&p, w, h, |x, y| (f(x, y, 0), f(x, y, 1), f(x, y, 2)))
            .unwrap();
        let mut planar = vec![0.0f32; 3 * n];
        for c in 0..3 {
            for y in 0..h {
                for x in 0..w {
                    planar[c * n + y * w + x] = f(x, y, c);
                }
            }
        }
        (p, planar)
    };
    let (a, pa) = write("a.exr", &base);
    let (b, pb) = write("b.exr", &other);
    let a_copy = dir.path().join("a_copy.exr");
    std::fs::copy(&a, &a_copy).unwrap();

    let same = last_number(&xtask_ok(
        &["lpips", arg(&a), arg(&a_copy), "--linear"],
        &[],
    ));
    assert_eq!(same, 0.0, "identical images");
    let linear = last_number(&xtask_ok(&["lpips", arg(&a), arg(&b), "--linear"], &[]));
    let stored = last_number(&xtask_ok(&["lpips", arg(&a), arg(&b)], &[]));
    assert!(linear.is_finite() && linear > 0.0, "{linear}");
    assert!(stored.is_finite() && stored > 0.0, "{stored}");

    // The library's distance on the same values, sRGB-encoded for `--linear` and as stored without.
    let net =
        lpips::load_safetensors(&root().join("data-fixtures/lpips/alexnet-lpips-v0.1.safetensors"))
            .unwrap();
    let encode = |v: &[f32]| -> Vec<f32> {
        v.iter()
            .map(|&x| scene::image_io::srgb_from_linear(x))
            .collect()
    };
    let want_linear = f64::from(net.distance(&encode(&pa), &encode(&pb), h, w).unwrap());
    let want_stored = f64::from(net.distance(&pa, &pb, h, w).unwrap());
    close(linear, want_linear, 1e-5, "lpips --linear");
    close(stored, want_stored, 1e-5, "lpips as stored");
    assert!(
        (linear - stored).abs() > 1e-4,
        "--linear made no difference: {linear} vs {stored}"
    );
}

// ---------------------------------------------------------------------------------------------
// flow-import-t7
// ---------------------------------------------------------------------------------------------

/// A deterministic, level- and layer-dependent parameter value.
fn t7_value(level: usize, conv: usize, bias: bool, k: usize) -> f32 {
    let s = (k * 7919 + level * 104_729 + conv * 1_299_709 + usize::from(bias) * 15_485_863) % 2001;
    (s as f32 - 1000.0) * 1e-4
}

/// `flow-import-t7` on a two-level directory of Torch7 files written here: the safetensors header
/// lists every tensor with its shape, and the file loads with exactly the values written.
#[test]
fn flow_import_t7_converts_a_two_level_directory() {
    let dir = tempfile::tempdir().unwrap();
    let t7 = dir.path().join("t7");
    std::fs::create_dir(&t7).unwrap();
    let levels = 2;
    for l in 0..levels {
        for (i, &(ci, co)) in flow::LAYER_CHANNELS.iter().enumerate() {
            let k = flow::KERNEL;
            let weight: Vec<f32> = (0..co * ci * k * k)
                .map(|j| t7_value(l, i, false, j))
                .collect();
            let bias: Vec<f32> = (0..co).map(|j| t7_value(l, i, true, j)).collect();
            // Level 1 stores its biases as (1, c_out), as some exports do.
            let bias_shape = if l == 1 { vec![1, co] } else { vec![co] };
            for (what, shape, data) in [
                ("weight", vec![co, ci, k, k], weight),
                ("bias", bias_shape, bias),
            ] {
                std::fs::write(
                    t7.join(flow::t7::file_name(l, "F", i, what)),
                    flow::t7::write_float_tensor(&shape, &data),
                )
                .unwrap();
            }
        }
    }
    let out_path = dir.path().join("spynet-F.safetensors");
    let out = xtask_ok(
        &[
            "flow-import-t7",
            "--dir",
            arg(&t7),
            "--variant",
            "F",
            "--out",
            arg(&out_path),
        ],
        &[],
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("imported 2 levels"), "{err}");

    // The file's header names every tensor with its shape, and the metadata the level count.
    let bytes = std::fs::read(&out_path).unwrap();
    let len = u64::from_le_bytes(bytes[..8].try_into().unwrap()) as usize;
    let header: Value = serde_json::from_slice(&bytes[8..8 + len]).unwrap();
    let header = header.as_object().unwrap();
    assert_eq!(header.len(), 1 + levels * 10, "{header:?}");
    assert_eq!(header["__metadata__"]["levels"], "2");
    assert_eq!(header["__metadata__"]["format"], "spynet");
    for l in 0..levels {
        for (i, &(ci, co)) in flow::LAYER_CHANNELS.iter().enumerate() {
            let k = flow::KERNEL;
            let t = &header[&format!("level{l}.conv{i}.weight")];
            assert_eq!(t["dtype"], "F32");
            assert_eq!(t["shape"], serde_json::json!([co, ci, k, k]));
            assert_eq!(
                header[&format!("level{l}.conv{i}.bias")]["shape"],
                serde_json::json!([co])
            );
        }
    }
    // It loads, with the reference pyramid rule and exactly the values written.
    let net = flow::load_safetensors(&out_path).unwrap();
    assert_eq!(net.num_levels(), levels);
    assert_eq!(net.depth, flow::PyramidDepth::REFERENCE);
    let mut parameters = 0;
    for (l, level) in net.levels.iter().enumerate() {
        assert_eq!(level.len(), 5);
        for (i, conv) in level.iter().enumerate() {
            for (j, &v) in conv.weight.iter().enumerate() {
                assert_eq!(v, t7_value(l, i, false, j), "level {l} conv {i} weight {j}");
            }
            for (j, &v) in conv.bias.iter().enumerate() {
                assert_eq!(v, t7_value(l, i, true, j), "level {l} conv {i} bias {j}");
            }
            parameters += conv.weight.len() + conv.bias.len();
        }
    }
    assert_eq!(parameters, net.num_parameters());
    assert!(err.contains(&format!("({parameters} parameters)")), "{err}");
}

// ---------------------------------------------------------------------------------------------
// bench
// ---------------------------------------------------------------------------------------------

/// `bench raster` on its smallest case: one JSON line with the case's sizes and positive timings.
#[test]
fn bench_raster_prints_timings() {
    let out = xtask_ok(
        &[
            "bench",
            "raster",
            "--quick",
            "--only",
            "50k_256",
            "--threads",
            "1",
        ],
        &[],
    );
    let lines = json_lines(&out);
    assert_eq!(lines.len(), 1, "{lines:?}");
    let l = &lines[0];
    assert_eq!(l["case"], "50k_256");
    assert_eq!(l["gaussians"], 50_000);
    assert_eq!(
        (l["width"].clone(), l["height"].clone()),
        (256.into(), 256.into())
    );
    assert_eq!(l["threads"], 1);
    positive(l, "fwd_ms");
    positive(l, "fwd_bwd_ms");
    positive(l, "fwd_bwd_half_rows_ms");
    positive(l, "pairs");
}

/// `bench flow` with one level and one thread: a JSON line per image size with positive timings.
#[test]
fn bench_flow_prints_timings() {
    // The two image sizes (64², 256²) are fixed; one level and one thread are the least work.
    let out = xtask_ok(
        &[
            "bench",
            "flow",
            "--quick",
            "--threads",
            "1",
            "--levels",
            "1",
        ],
        &[],
    );
    let lines = json_lines(&out);
    assert_eq!(lines.len(), 2, "{lines:?}");
    for (l, (case, size)) in lines.iter().zip([("pair_64", 64), ("pair_256", 256)]) {
        assert_eq!(l["case"], case, "{l}");
        assert_eq!(
            (l["width"].clone(), l["height"].clone()),
            (size.into(), size.into())
        );
        assert_eq!(l["levels"], 1, "{l}");
        assert_eq!(l["threads"], 1, "{l}");
        positive(l, "fwd_ms");
        positive(l, "fwd_bwd_ms");
    }
}

/// `bench events --quick` on two cases: JSON lines whose rate is the event count over the time, and
/// no scratch file left behind.
#[test]
fn bench_events_prints_throughputs() {
    // Its scratch files go to TMPDIR: keep them in the test's directory.
    let dir = tempfile::tempdir().unwrap();
    let cases = ["voxelize_5bins_640x480", "read_evt3"];
    let out = xtask_ok(
        &["bench", "events", "--quick", "--only", &cases.join(",")],
        &[("TMPDIR", dir.path())],
    );
    let lines = json_lines(&out);
    assert_eq!(lines.len(), cases.len(), "{lines:?}");
    for (l, case) in lines.iter().zip(cases) {
        assert_eq!(l["bench"], "events", "{l}");
        assert_eq!(l["case"], case, "{l}");
        assert_eq!(l["events"], 2_000_000, "{l}");
        let secs = positive(l, "seconds");
        let rate = positive(l, "mev_per_s");
        close(rate, 2.0 / secs, 1e-9, "mev_per_s = events / seconds");
        positive(l, "target_mev_per_s");
        positive(l, "threads");
    }
    assert_eq!(
        std::fs::read_dir(dir.path()).unwrap().count(),
        0,
        "scratch files left behind"
    );
}

/// `bench deform` on 200 Gaussians: one JSON line per repetition, forward + backward their sum.
#[test]
fn bench_deform_prints_timings() {
    let out = xtask_ok(
        &[
            "bench", "deform", "--n", "200", "--hidden", "8", "--reps", "2",
        ],
        &[],
    );
    let lines = json_lines(&out);
    assert_eq!(lines.len(), 2, "one line per timed repetition: {lines:?}");
    for l in &lines {
        assert_eq!(l["bench"], "deform", "{l}");
        assert_eq!(l["n"], 200, "{l}");
        assert_eq!(l["hidden"], 8, "{l}");
        let fwd = positive(l, "forward_ms");
        let bwd = positive(l, "backward_ms");
        let both = positive(l, "forward_backward_ms");
        close(both, fwd + bwd, 1e-6, "forward_backward_ms");
    }
}

/// `bench lpips` with one thread: a JSON line per image size with positive timings.
#[test]
fn bench_lpips_prints_timings() {
    let out = xtask_ok(&["bench", "lpips", "--quick", "--threads", "1"], &[]);
    let lines = json_lines(&out);
    assert_eq!(lines.len(), 2, "{lines:?}");
    for (l, (case, size)) in lines.iter().zip([("pair_64", 64), ("pair_256", 256)]) {
        assert_eq!(l["case"], case, "{l}");
        assert_eq!(
            (l["width"].clone(), l["height"].clone()),
            (size.into(), size.into())
        );
        assert_eq!(l["threads"], 1, "{l}");
        positive(l, "features_ms");
        positive(l, "distance_ms");
        positive(l, "gradient_ms");
    }
}
