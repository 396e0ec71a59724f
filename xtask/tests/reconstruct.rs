//! `cargo xtask reconstruct`, `eval` and `render-pose` end to end on the tiny checked-in fixture with a
//! few steps: every promised output exists and parses, the metrics are finite, an interrupted run
//! resumed with `--resume` writes the same model bytes as an uninterrupted one, and bad flags are
//! refused with a message.
#![allow(clippy::unwrap_used)]

use std::path::{Path, PathBuf};
use std::process::Command;

fn fixture() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../data-fixtures/tiny")
}

fn xtask() -> Command {
    Command::new(env!("CARGO_BIN_EXE_xtask"))
}

fn write_config(dir: &Path) -> PathBuf {
    let p = dir.join("tiny.toml");
    std::fs::write(
        &p,
        "steps = 12\nhuman_gaussians = 300\nscene_gaussians = 600\nmax_gaussians = 3000\n\
         deform_hidden = 16\nskinning_until = 6\nskinning_samples = 32\nnonrigid_from = 3\n\
         densify_from = 4\ndensify_until = 12\ndensify_every = 4\ncheckpoint_every = 5\n",
    )
    .unwrap();
    p
}

/// `eval` of the run folder `out`'s model on the fixture with `extra` flags: asserts that it
/// succeeds and returns its output and the `metrics.json` it wrote (`metrics`, relative to `out`).
fn eval(out: &Path, extra: &[&str], metrics: &Path) -> (std::process::Output, serde_json::Value) {
    let o = xtask()
        .arg("eval")
        .args(extra)
        .arg("--model")
        .arg(out.join("model"))
        .arg("--data")
        .arg(fixture())
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = std::fs::read_to_string(out.join(metrics)).unwrap();
    (o, serde_json::from_str(&text).unwrap())
}

fn reconstruct(out: &Path, config: &Path, extra: &[&str]) -> std::process::Output {
    let o = xtask()
        .arg("reconstruct")
        .arg("--data")
        .arg(fixture())
        .arg("--out")
        .arg(out)
        .arg("--config")
        .arg(config)
        .args(extra)
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "reconstruct failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    o
}

#[test]
fn reconstruct_eval_and_render_pose_write_every_output() {
    let dir = tempfile::tempdir().unwrap();
    let config = write_config(dir.path());
    let out = dir.path().join("run");
    let o = reconstruct(&out, &config, &[]);
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains("PSNR render vs sharp"), "{stdout}");
    for f in [
        "config.json",
        "log.jsonl",
        "checkpoint.safetensors",
        "metrics.json",
        "report.html",
        "curves.svg",
        "per_frame.svg",
        "model/model.json",
        "model/canonical.ply",
        "model/networks.safetensors",
    ] {
        assert!(out.join(f).is_file(), "missing {f}");
    }
    let metrics: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("metrics.json")).unwrap()).unwrap();
    for key in [
        "test_psnr_full",
        "test_ssim_full",
        "test_psnr_human_box",
        "test_ssim_human_box",
        "mask_iou",
        "blurred_psnr_full",
        "blurred_psnr_human_box",
        "test_lpips_full",
        "test_lpips_human_box",
        "blurred_lpips_full",
        "blurred_lpips_human_box",
        "train_seconds",
    ] {
        assert!(metrics[key].as_f64().unwrap().is_finite(), "{key}");
    }
    assert_eq!(metrics["lpips_weight"], 0.0);
    assert_eq!(metrics["steps"], 12);
    assert_eq!(
        std::fs::read_to_string(out.join("log.jsonl"))
            .unwrap()
            .lines()
            .count(),
        12
    );
    let scene: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(fixture().join("scene.json")).unwrap())
            .unwrap();
    let test_frames = scene["frames"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|f| f["split"] == "test")
        .count();
    assert!(test_frames > 0);
    let strips = std::fs::read_dir(out.join("eval"))
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().starts_with("strip_"))
        .count();
    assert_eq!(
        strips, test_frames,
        "one strip per test frame of the fixture"
    );
    assert_eq!(metrics["test_frames"], test_frames);
    assert_report_is_whole(&out, test_frames);
    let posed: Vec<_> = std::fs::read_dir(out.join("model"))
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().starts_with("posed_frame_"))
        .collect();
    assert_eq!(posed.len(), 1);
    let set = gaussians::ply::read_ply(posed[0].path()).unwrap();
    assert_eq!(set.sh_degree, 3);
    assert_inria_degree3_layout(&posed[0].path(), set.len());

    // eval of the saved model reproduces the figures reconstruct wrote.
    let eval_out = dir.path().join("eval");
    let eval_dir = eval_out.to_str().unwrap();
    let (_, again) = eval(&out, &["--out", eval_dir], &eval_out.join("metrics.json"));
    assert_eq!(again["test_psnr_full"], metrics["test_psnr_full"]);
    assert_eq!(again["mask_iou"], metrics["mask_iou"]);
    assert_eq!(again["test_lpips_full"], metrics["test_lpips_full"]);
    assert_eq!(
        again["blurred_lpips_human_box"],
        metrics["blurred_lpips_human_box"]
    );
    // Re-scored in the run's own folder (the default --out), the run's own entries stay.
    let (_, in_place) = eval(&out, &[], Path::new("metrics.json"));
    assert_eq!(in_place["test_psnr_full"], metrics["test_psnr_full"]);
    // (Floats to 1e-12: serde_json's default parsing is not exactly rounded, so a value read and
    // written again may differ in its last digit.)
    for kept in ["blur_model", "seed"] {
        assert_eq!(in_place[kept], metrics[kept], "{kept}");
        assert!(!metrics[kept].is_null(), "{kept}");
    }
    let close = |a: &serde_json::Value, b: &serde_json::Value| {
        let (a, b) = (a.as_f64().unwrap(), b.as_f64().unwrap());
        (a - b).abs() <= 1e-12 * a.abs().max(b.abs())
    };
    assert!(close(&in_place["train_seconds"], &metrics["train_seconds"]));
    assert!(close(
        &in_place["step_seconds_breakdown"]["total"],
        &metrics["step_seconds_breakdown"]["total"]
    ));

    // --split train scores the training frames, into the run's `train-split/` folder.
    let (o, train_split) = eval(
        &out,
        &["--split", "train"],
        Path::new("train-split/metrics.json"),
    );
    let train_frames = scene["frames"].as_array().unwrap().len() - test_frames;
    assert_eq!(train_split["split"], "train");
    assert_eq!(train_split["test_frames"], train_frames);
    assert!(train_split["test_psnr_full"].as_f64().unwrap().is_finite());
    assert_ne!(train_split["test_psnr_full"], metrics["test_psnr_full"]);
    assert!(String::from_utf8_lossy(&o.stdout)
        .contains(&format!("train split ({train_frames} frames)")));

    // render-pose: a new pose renders to a PNG and a posed PLY.
    let poses = dir.path().join("poses.json");
    let mut pose = vec![0.0f32; 72];
    pose[16 * 3 + 2] = -1.2; // left shoulder down
    std::fs::write(
        &poses,
        serde_json::json!([{ "pose": pose, "transl": [0.0, 0.8, 0.0] }]).to_string(),
    )
    .unwrap();
    let rp = dir.path().join("poses");
    let o = xtask()
        .args(["render-pose", "--ply", "--model"])
        .arg(out.join("model"))
        .arg("--poses")
        .arg(&poses)
        .arg("--out")
        .arg(&rp)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(rp.join("render_0000.png").is_file());
    assert!(rp.join("posed_0000.ply").is_file());
    // A malformed pose is refused with the file named.
    std::fs::write(&poses, r#"{"pose": [0.0], "transl": [0, 0, 0]}"#).unwrap();
    let o = xtask()
        .args(["render-pose", "--model"])
        .arg(out.join("model"))
        .arg("--poses")
        .arg(&poses)
        .arg("--out")
        .arg(&rp)
        .output()
        .unwrap();
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("poses.json"));
    render_motions(&out.join("model"), dir.path());
}

fn motion_fixture(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../data-fixtures/motion")
        .join(name)
}

fn render_pose_motion(
    model: &Path,
    motion: &Path,
    out: &Path,
    extra: &[&str],
) -> std::process::Output {
    xtask()
        .args(["render-pose", "--model"])
        .arg(model)
        .arg("--motion")
        .arg(motion)
        .arg("--data")
        .arg(fixture())
        .arg("--out")
        .arg(out)
        .args(extra)
        .output()
        .unwrap()
}

/// `render-pose --motion`: the AMASS fixture (numpy-written, SMPL-H, 60 fps) to a GIF with the
/// frames resampled to 30 fps, the PeopleSnapshot fixture to a PNG folder, and a wrong-shaped file
/// refused naming the array.
fn render_motions(model: &Path, dir: &Path) {
    let gif = dir.join("walk.gif");
    let o = render_pose_motion(
        model,
        &motion_fixture("walk_amass.npz"),
        &gif,
        &["--frames", "12"],
    );
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(
        stdout.contains("AMASS motion, 120 frames at 60 fps: rendering 12"),
        "{stdout}"
    );
    assert!(
        stdout.contains("finger joints"),
        "what was dropped is said: {stdout}"
    );
    let decoder = image::codecs::gif::GifDecoder::new(std::io::BufReader::new(
        std::fs::File::open(&gif).unwrap(),
    ))
    .unwrap();
    let frames = image::AnimationDecoder::into_frames(decoder)
        .collect_frames()
        .unwrap();
    assert_eq!(frames.len(), 12);
    assert_ne!(
        frames[0].buffer().as_raw(),
        frames[6].buffer().as_raw(),
        "the person moves"
    );
    let pngs = dir.join("wave");
    let o = render_pose_motion(
        model,
        &motion_fixture("wave_people_snapshot.npz"),
        &pngs,
        &["--frames", "5"],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(String::from_utf8_lossy(&o.stdout).contains("PeopleSnapshot motion, 40 frames"));
    assert!(pngs.join("frame_0004.png").is_file() && !pngs.join("frame_0005.png").exists());
    // Wrong shapes: named.
    let bad = dir.join("bad.npz");
    let mut w = smpl_deform::npz::NpzWriter::new(std::fs::File::create(&bad).unwrap(), false);
    w.add_f32("poses", &[4, 63], &[0.0; 252]).unwrap();
    w.add_f32("trans", &[4, 3], &[0.0; 12]).unwrap();
    w.finish().unwrap();
    let o = render_pose_motion(model, &bad, &dir.join("bad.gif"), &[]);
    assert!(!o.status.success());
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(
        e.contains("bad.npz") && e.contains("`poses`") && e.contains("[4, 63]"),
        "{e}"
    );
}

#[test]
fn an_interrupted_run_resumed_writes_the_same_model_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let config = write_config(dir.path());
    let straight = dir.path().join("straight");
    reconstruct(&straight, &config, &[]);
    let resumed = dir.path().join("resumed");
    // Scoring the held-out frames while training reads the model only: same bytes as without.
    let every = ["--eval-every", "4"];
    let o = reconstruct(
        &resumed,
        &config,
        &[&every[..], &["--stop-after", "7"]].concat(),
    );
    assert!(String::from_utf8_lossy(&o.stdout).contains("--resume"));
    assert!(!resumed.join("model").exists());
    reconstruct(&resumed, &config, &[&every[..], &["--resume"]].concat());
    let curve = std::fs::read_to_string(resumed.join("eval_curve.jsonl")).unwrap();
    let points: Vec<serde_json::Value> = curve
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let steps: Vec<u64> = points.iter().map(|p| p["step"].as_u64().unwrap()).collect();
    assert_eq!(steps, [4, 8, 12], "{curve}");
    assert!(points
        .iter()
        .all(|p| p["test_psnr_full"].as_f64().unwrap().is_finite()));
    for f in ["model/canonical.ply", "model/networks.safetensors"] {
        assert_eq!(
            std::fs::read(straight.join(f)).unwrap(),
            std::fs::read(resumed.join(f)).unwrap(),
            "{f} differs"
        );
    }
    assert_eq!(
        std::fs::read_to_string(resumed.join("log.jsonl"))
            .unwrap()
            .lines()
            .count(),
        12
    );
}

#[test]
fn bad_flags_and_configs_are_refused_with_a_message() {
    let dir = tempfile::tempdir().unwrap();
    let o = xtask()
        .args(["reconstruct", "--semantic", "both", "--data"])
        .arg(fixture())
        .output()
        .unwrap();
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("one-hot"));
    let bad = dir.path().join("bad.toml");
    std::fs::write(&bad, "steps = 0\n").unwrap();
    let o = xtask()
        .args(["reconstruct", "--data"])
        .arg(fixture())
        .arg("--config")
        .arg(&bad)
        .arg("--out")
        .arg(dir.path().join("x"))
        .output()
        .unwrap();
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("steps"));
    let o = xtask()
        .args(["reconstruct", "--data"])
        .arg(dir.path().join("missing"))
        .arg("--out")
        .arg(dir.path().join("y"))
        .output()
        .unwrap();
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("missing"));
}

#[test]
fn the_flow_loss_runs_from_the_command_line_and_is_recorded() {
    let dir = tempfile::tempdir().unwrap();
    let config = write_config(dir.path());
    let weights = dir.path().join("spynet.safetensors");
    flow::save_safetensors(&flow::SpyNet::<f32>::random(2, 3), &weights).unwrap();
    let out = dir.path().join("flow");
    let o = reconstruct(
        &out,
        &config,
        &[
            "--flow-loss",
            "on",
            "--flow-source",
            "gt",
            "--flow-weight",
            "0.1",
            "--flow-tau",
            "0",
            "--flow-gradient",
            "geometry",
            "--flow-network",
            weights.to_str().unwrap(),
        ],
    );
    assert!(String::from_utf8_lossy(&o.stdout).contains("flow loss:"));
    let metrics: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("metrics.json")).unwrap()).unwrap();
    let text = metrics.to_string();
    assert!(text.contains("\"flow_loss\":true"), "{text}");
    assert!(text.contains("\"flow_source\":\"ground-truth\""), "{text}");
    assert!(text.contains("\"flow_gradient\":\"geometry\""), "{text}");
    let log = std::fs::read_to_string(out.join("log.jsonl")).unwrap();
    assert!(
        log.lines().any(|l| {
            let v: serde_json::Value = serde_json::from_str(l).unwrap();
            v["flow"].as_f64().is_some_and(|f| f > 0.0)
        }),
        "no step logged a flow loss"
    );
    // The ideal-estimator ablation (`--flow-measure warp`) runs and is recorded; a bad measure is
    // refused with the expected values.
    let out_warp = dir.path().join("warp");
    reconstruct(
        &out_warp,
        &config,
        &[
            "--flow-loss",
            "on",
            "--flow-source",
            "gt",
            "--flow-measure",
            "warp",
            "--flow-network",
            weights.to_str().unwrap(),
        ],
    );
    let metrics = std::fs::read_to_string(out_warp.join("metrics.json")).unwrap();
    assert!(metrics.contains("\"flow_measure\": \"warp\""), "{metrics}");
    let o = xtask()
        .args(["reconstruct", "--flow-measure", "raft", "--data"])
        .arg(fixture())
        .output()
        .unwrap();
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("possible values: network, warp"));
    // The event-generation loss alternative runs from the command line too.
    let out_ev = dir.path().join("events");
    let o = reconstruct(
        &out_ev,
        &config,
        &["--event-loss", "on", "--event-threshold", "0.2"],
    );
    assert!(String::from_utf8_lossy(&o.stdout).contains("event loss:"));
    let metrics = std::fs::read_to_string(out_ev.join("metrics.json")).unwrap();
    assert!(metrics.contains("\"event_loss\": true"), "{metrics}");
    // A source the scene does not have, and a missing network, are refused before training.
    for (extra, expect) in [
        (
            [
                "--flow-source",
                "events",
                "--flow-network",
                weights.to_str().unwrap(),
            ],
            "events_cm",
        ),
        (
            [
                "--flow-source",
                "gt",
                "--flow-network",
                "/nonexistent/w.safetensors",
            ],
            "train-flow",
        ),
        (
            [
                "--flow-gradient",
                "colours",
                "--flow-network",
                weights.to_str().unwrap(),
            ],
            "[possible values: all, geometry]",
        ),
    ] {
        let mut args = vec!["--flow-loss", "on"];
        args.extend(extra);
        let o = xtask()
            .arg("reconstruct")
            .arg("--data")
            .arg(fixture())
            .arg("--out")
            .arg(dir.path().join("bad"))
            .arg("--config")
            .arg(&config)
            .args(&args)
            .output()
            .unwrap();
        assert!(!o.status.success());
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains(expect), "{expect}: {err}");
    }
}

#[test]
fn the_perceptual_loss_runs_from_the_command_line_and_is_recorded() {
    let dir = tempfile::tempdir().unwrap();
    let config = write_config(dir.path());
    let out = dir.path().join("lpips");
    let o = reconstruct(
        &out,
        &config,
        &["--blur-model", "none", "--lpips-weight", "0.1"],
    );
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains("perceptual loss: LPIPS"), "{stdout}");
    let metrics: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("metrics.json")).unwrap()).unwrap();
    assert!((metrics["lpips_weight"].as_f64().unwrap() - 0.1).abs() < 1e-6);
    assert!(metrics["step_seconds_breakdown"]["lpips"].as_f64().unwrap() > 0.0);
    let log = std::fs::read_to_string(out.join("log.jsonl")).unwrap();
    for line in log.lines() {
        let step: serde_json::Value = serde_json::from_str(line).unwrap();
        let lpips = step["lpips"].as_f64().unwrap();
        assert!(lpips > 0.0 && lpips.is_finite(), "{line}");
    }
}

#[test]
fn the_exposure_model_and_the_sharp_ceiling_run_from_the_command_line() {
    let dir = tempfile::tempdir().unwrap();
    let config = write_config(dir.path());
    // The default on a scene with events: the exposure model with events between its renders.
    let out = dir.path().join("exposure");
    let o = reconstruct(&out, &config, &["--subframes", "3"]);
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains("mean of 3 renders"), "{stdout}");
    assert!(
        stdout.contains("compares consecutive sub-exposure renders"),
        "{stdout}"
    );
    let metrics = std::fs::read_to_string(out.join("metrics.json")).unwrap();
    for field in [
        "\"blur_model\": \"exposure\"",
        "\"subframes\": 3",
        "\"event_loss\": true",
        "\"event_pairs\": \"exposure\"",
        "\"event_modulation\": true",
        "\"exposure_motion\": \"learned\"",
        "\"body_interpolation\": \"band-limited\"",
    ] {
        assert!(metrics.contains(field), "{field}: {metrics}");
    }
    assert!(stdout.contains("event modulation:"), "{stdout}");
    assert!(
        stdout.contains("change over each exposure is learned"),
        "{stdout}"
    );
    // The fixture's sensor has a 1 ms refractory period: mixed-polarity pixels are left free.
    let used = std::fs::read_to_string(out.join("config.json")).unwrap();
    assert!(used.contains("\"event_ignore_mixed\": true"), "{used}");
    // The events' modulation can be turned off on its own.
    let plain = dir.path().join("unmodulated");
    let o = reconstruct(
        &plain,
        &config,
        &["--subframes", "3", "--event-modulation", "off"],
    );
    assert!(!String::from_utf8_lossy(&o.stdout).contains("event modulation:"));
    let metrics = std::fs::read_to_string(plain.join("metrics.json")).unwrap();
    assert!(metrics.contains("\"event_modulation\": false"), "{metrics}");
    // So can the learned in-exposure motion (the previous default's given motion).
    let given = dir.path().join("given-motion");
    let o = reconstruct(
        &given,
        &config,
        &["--subframes", "3", "--exposure-motion", "given"],
    );
    assert!(!String::from_utf8_lossy(&o.stdout).contains("change over each exposure is learned"));
    let metrics = std::fs::read_to_string(given.join("metrics.json")).unwrap();
    assert!(
        metrics.contains("\"exposure_motion\": \"given\""),
        "{metrics}"
    );
    let sharp = dir.path().join("sharp");
    reconstruct(
        &sharp,
        &config,
        &["--train-on", "sharp", "--blur-model", "none"],
    );
    let metrics = std::fs::read_to_string(sharp.join("metrics.json")).unwrap();
    assert!(metrics.contains("\"train_on\": \"sharp\""), "{metrics}");
    // Events inside exposures without the exposure model are refused, naming the setting.
    let o = xtask()
        .args([
            "reconstruct",
            "--blur-model",
            "none",
            "--event-loss",
            "on",
            "--event-pairs",
            "exposure",
            "--data",
        ])
        .arg(fixture())
        .output()
        .unwrap();
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("event_pairs"));
}

/// What INRIA's reference readers require of a 3DGS PLY, checked the way they read it: SIBR's viewer
/// reads fixed 248-byte rows of the degree-3 layout after the header, and the Python `load_ply`
/// asserts exactly 45 `f_rest_*` properties. The header must list exactly these 62 float properties
/// in this order, binary little-endian, and the body must be `count × 248` bytes.
fn assert_inria_degree3_layout(path: &std::path::Path, count: usize) {
    let bytes = std::fs::read(path).unwrap();
    let end = b"end_header\n";
    let header_len = bytes
        .windows(end.len())
        .position(|w| w == end)
        .expect("a PLY header")
        + end.len();
    let header = std::str::from_utf8(&bytes[..header_len]).unwrap();
    let mut expected: Vec<String> = [
        "x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    expected.extend((0..45).map(|j| format!("f_rest_{j}")));
    expected.push("opacity".into());
    expected.extend((0..3).map(|j| format!("scale_{j}")));
    expected.extend((0..4).map(|j| format!("rot_{j}")));
    let properties: Vec<String> = header
        .lines()
        .filter_map(|l| l.strip_prefix("property float "))
        .map(str::to_string)
        .collect();
    assert_eq!(properties, expected, "{header}");
    assert_eq!(
        header.lines().filter(|l| l.starts_with("property")).count(),
        62,
        "only float properties"
    );
    assert!(header.contains("format binary_little_endian 1.0"));
    assert!(header.contains(&format!("element vertex {count}\n")));
    assert_eq!(bytes.len() - header_len, count * 248);
}

/// `report.html` has its sections, one strip per test frame, and every file it references exists.
fn assert_report_is_whole(out: &Path, test_frames: usize) {
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(html.starts_with("<!DOCTYPE html>") && html.trim_end().ends_with("</html>"));
    for section in [
        "<h2>Summary</h2>",
        "<h2>Training</h2>",
        "<h2>Test frames</h2>",
        "<h2>Comparison strips</h2>",
    ] {
        assert!(html.contains(section), "report.html lacks {section}");
    }
    let refs: Vec<&str> = html
        .split("src=\"")
        .skip(1)
        .filter_map(|r| r.split('"').next())
        .collect();
    assert_eq!(
        refs.iter().filter(|r| r.starts_with("eval/strip_")).count(),
        test_frames
    );
    for r in refs {
        assert!(
            out.join(r).is_file(),
            "report.html references {r}, which does not exist"
        );
    }
}
