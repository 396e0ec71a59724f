//! `cargo xtask import zju`: one view of a ZJU-MoCap subject as ARAH / 3DGS-Avatar preprocess it
//! (`cam_params.json`, `models/NNNNNN.npz`, `{view}/NNNNNN.jpg` images with `{view}/NNNNNN.png`
//! masks) → scene format v1: the images and masks undistorted with the view's OpenCV
//! 5-coefficient model, the SMPL fits mapped to the project's pose layout, then optionally the
//! paper's ZJU-MoCap-Blur recipe (`--blur K`, `--events simulate`) through
//! [`synth::from_frames`].

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use scene::image_io::{undistort, Sampling};
use scene::Distortion;
use smpl_deform::zju::read_zju_model;
use synth::from_frames::{write_scene_from_frames, InputFrame};

use super::{check_out_is_free, load_body, SynthesisArgs};

/// Arguments of `import zju`.
#[derive(clap::Args, Debug)]
#[command(after_help = "\
The SMPL fits are SMPL parameters: give your own SMPL model with --body SMPL.npz (its licence is \
yours; the scene references it, it is not copied). `builtin:makehuman` runs, but its shape does \
not match the fits' betas.

Intrinsics: ZJU's K is in OpenCV's pixel convention (pixel centres at integers); the scene's \
camera adds 0.5 to cx and cy (centres at i + 0.5). The extrinsics R, T (metres) map the capture's \
world to the camera: world_to_camera = [R | T].

Example (the paper's view 1, ZJU-MoCap-Blur-like):
  cargo xtask import zju --root CoreView_377 --view 1 --body smpl_neutral.npz \\
      --blur 7 --events simulate --out scene-377")]
pub struct Args {
    /// The subject directory (holds `cam_params.json`, `models/`, one folder per view).
    #[arg(long)]
    pub root: PathBuf,
    /// The camera (view) to import, as named in `cam_params.json` (the paper uses view 1).
    #[arg(long, default_value = "1")]
    pub view: String,
    /// Body model: the path of your SMPL `.npz`, or `builtin:makehuman`.
    #[arg(long)]
    pub body: String,
    /// Frame rate of the capture (ZJU-MoCap: 50 fps).
    #[arg(long, default_value_t = 50.0)]
    pub fps: f64,
    /// Import every STEP-th frame from FIRST (`FIRST:STEP`, before any blur window).
    #[arg(long, default_value = "0:1")]
    pub frames: String,
    /// Frames to import at most (after `--frames`).
    #[arg(long)]
    pub max_frames: Option<usize>,
    #[command(flatten)]
    pub synthesis: SynthesisArgs,
    /// Output scene directory.
    #[arg(long)]
    pub out: PathBuf,
}

/// The numbers of a JSON value, flattened (nested lists of numbers).
fn numbers(v: &serde_json::Value, what: &str, count: usize) -> Result<Vec<f64>> {
    fn walk(v: &serde_json::Value, out: &mut Vec<f64>) -> bool {
        match v {
            serde_json::Value::Number(n) => n.as_f64().map(|x| out.push(x)).is_some(),
            serde_json::Value::Array(a) => a.iter().all(|x| walk(x, out)),
            _ => false,
        }
    }
    let mut out = Vec::new();
    if !walk(v, &mut out) || out.len() != count || !out.iter().all(|x| x.is_finite()) {
        bail!("{what}: expected {count} finite numbers");
    }
    Ok(out)
}

/// The view's camera (scene convention) and lens from `cam_params.json`, for images `w × h`.
fn read_camera(root: &Path, view: &str, (w, h): (u32, u32)) -> Result<(scene::Camera, Distortion)> {
    let path = root.join("cam_params.json");
    let text =
        std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
    let all: serde_json::Value =
        serde_json::from_str(&text).with_context(|| format!("{}: not JSON", path.display()))?;
    let Some(cam) = all.get(view) else {
        let names = all
            .get("all_cam_names")
            .map(|v| v.to_string())
            .unwrap_or_else(|| "(no all_cam_names)".into());
        bail!(
            "{}: no camera named `{view}`; it lists {names}",
            path.display()
        );
    };
    let field = |key: &str, count: usize| -> Result<Vec<f64>> {
        let v = cam
            .get(key)
            .with_context(|| format!("{}: camera `{view}` has no `{key}`", path.display()))?;
        numbers(
            v,
            &format!("{}: camera `{view}`.{key}", path.display()),
            count,
        )
    };
    let k = field("K", 9)?;
    let r = field("R", 9)?;
    let t = field("T", 3)?;
    // ZJU-MoCap's lenses are OpenCV's 5-coefficient model; anything else is refused rather than
    // guessed (8 coefficients would be the rational model this importer does not apply).
    let d = Distortion::from_opencv(&field("D", 5)?).with_context(|| {
        format!(
            "{}: camera `{view}`.D: expected 5 finite OpenCV coefficients",
            path.display()
        )
    })?;
    let camera = scene::Camera {
        width: w,
        height: h,
        fx: k[0],
        fy: k[4],
        cx: k[2] + 0.5,
        cy: k[5] + 0.5,
        world_to_camera: [
            [r[0], r[1], r[2], t[0]],
            [r[3], r[4], r[5], t[1]],
            [r[6], r[7], r[8], t[2]],
            [0.0, 0.0, 0.0, 1.0],
        ],
    };
    camera
        .validate()
        .with_context(|| format!("{}: camera `{view}`", path.display()))?;
    Ok((camera, d))
}

fn files(dir: &Path, ext: &str) -> Result<Vec<PathBuf>> {
    let mut out: Vec<PathBuf> = std::fs::read_dir(dir)
        .with_context(|| format!("reading {}", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.extension()
                .and_then(|e| e.to_str())
                .is_some_and(|e| e.eq_ignore_ascii_case(ext))
        })
        .collect();
    out.sort();
    Ok(out)
}

/// Runs `import zju`.
pub fn run(args: Args) -> Result<()> {
    let view_dir = args.root.join(&args.view);
    let images = files(&view_dir, "jpg")?;
    let masks = files(&view_dir, "png")?;
    if images.is_empty() {
        bail!("{}: no .jpg images", view_dir.display());
    }
    let models = files(&args.root.join("models"), "npz")?;
    if masks.len() != images.len() || models.len() < images.len() {
        bail!(
            "{} holds {} images and {} masks, {} holds {} SMPL fits: one mask and one fit per image are needed",
            view_dir.display(),
            images.len(),
            masks.len(),
            args.root.join("models").display(),
            models.len()
        );
    }
    let (first, step) = args
        .frames
        .split_once(':')
        .and_then(|(a, b)| Some((a.parse::<usize>().ok()?, b.parse::<usize>().ok()?)))
        .filter(|&(_, s)| s > 0)
        .with_context(|| {
            format!(
                "--frames {}: expected FIRST:STEP with STEP > 0",
                args.frames
            )
        })?;
    let mut chosen: Vec<usize> = (first..images.len()).step_by(step).collect();
    if let Some(m) = args.max_frames {
        chosen.truncate(m);
    }
    if chosen.is_empty() {
        bail!(
            "--frames {} selects none of {} frames",
            args.frames,
            images.len()
        );
    }
    let (w, h) = image::image_dimensions(&images[chosen[0]])
        .with_context(|| format!("reading {}", images[chosen[0]].display()))?;
    let (camera, lens) = read_camera(&args.root, &args.view, (w, h))?;
    let (_, model) = load_body(&args.body)?;
    let first_model = read_zju_model(&models[chosen[0]])
        .with_context(|| format!("reading {}", models[chosen[0]].display()))?;
    check_out_is_free(&args.out)?;
    let cfg = args.synthesis.config(args.fps / step as f64, None);
    cfg.check(chosen.len())?;
    let spec = scene::BodySpec {
        id: 0,
        model,
        betas: first_model.betas.clone().unwrap_or_default(),
    };
    let generator = serde_json::json!({
        "name": "xtask import zju",
        "config": {
            "root": args.root.display().to_string(), "view": args.view, "fps": args.fps,
            "frames": args.frames, "blur": cfg.blur, "events": args.synthesis.events,
            "threshold": args.synthesis.threshold, "seed": args.synthesis.seed,
            "distortion": [lens.k1, lens.k2, lens.p1, lens.p2, lens.k3],
        }
    });
    let used = chosen.len() / cfg.blur * cfg.blur;
    let bar = crate::common::progress_bar(used as u64, "frames")?;
    let n = (w * h) as usize;
    let image_err = |path: &Path, e: anyhow::Error| synth::SynthError::Image {
        path: path.to_path_buf(),
        message: format!("{e:#}"),
    };
    let mut between = args.synthesis.between(h as usize, w as usize)?;
    let report = write_scene_from_frames(
        &args.out,
        camera.clone(),
        spec,
        &[],
        chosen.len(),
        &cfg,
        generator,
        |i| {
            let k = chosen[i];
            let (rgb, ih, iw) =
                crate::common::read_rgb(&images[k]).map_err(|e| image_err(&images[k], e))?;
            if (iw as u32, ih as u32) != (w, h) {
                return Err(image_err(
                    &images[k],
                    anyhow::anyhow!("{iw}x{ih}, the first image is {w}x{h}"),
                ));
            }
            let linear: Vec<f32> = rgb
                .iter()
                .map(|&v| scene::image_io::linear_from_srgb(v))
                .collect();
            let mask_img = image::open(&masks[k])
                .map_err(|e| image_err(&masks[k], e.into()))?
                .to_luma8();
            if (mask_img.width(), mask_img.height()) != (w, h) {
                return Err(image_err(
                    &masks[k],
                    anyhow::anyhow!("the mask is not {w}x{h}"),
                ));
            }
            let mask: Vec<f32> = mask_img.pixels().map(|p| f32::from(p.0[0] > 0)).collect();
            let rgb = undistort(&linear, 3, &camera, &lens, Sampling::Bilinear);
            let mask = undistort(&mask, 1, &camera, &lens, Sampling::Nearest);
            let fit = read_zju_model(&models[k]).map_err(synth::SynthError::Body)?;
            debug_assert_eq!(mask.len(), n);
            Ok(InputFrame {
                rgb,
                mask: Some(mask.iter().map(|&m| m > 0.5).collect()),
                pose: fit
                    .pose
                    .chunks_exact(3)
                    .map(|c| [c[0], c[1], c[2]])
                    .collect(),
                transl: fit.transl,
                people: Vec::new(),
                world_to_camera: None,
            })
        },
        between.as_deref_mut(),
        |_| bar.inc(1),
    )
    .with_context(|| format!("writing the scene {}", args.out.display()))?;
    bar.finish_and_clear();
    eprintln!(
        "{} frames at {:.3} fps from view {} ({}x{}), exposure {:.4} s{}",
        report.frames,
        cfg.fps / cfg.blur as f64,
        args.view,
        w,
        h,
        cfg.exposure(),
        if cfg.events.is_some() {
            format!(", {} events", report.events)
        } else {
            String::new()
        }
    );
    println!("{}", crate::common::shown(&args.out).display());
    Ok(())
}
