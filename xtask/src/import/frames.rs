//! `cargo xtask import frames`: a PNG folder + SMPL poses + a camera → scene format v1, through
//! [`synth::from_frames`] (blur windows, ESIM events, the benchmark's 7/3 split).

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use smpl_deform::BodyRef;

use super::{image_files, read_mask_any, read_poses, Poses};
use synth::from_frames::{write_scene_from_frames, FramesToScene, InputFrame};

/// Arguments of `import frames`.
#[derive(clap::Args, Debug)]
#[command(after_help = "\
The poses are used as they are, in the camera file's world frame: give a camera whose \
`world_to_camera` maps that frame to the camera (PeopleSnapshot / InstantAvatar poses are in the \
camera frame: identity extrinsics). One pose per frame, in frame order; the counts must agree.

Examples:
  cargo xtask import frames --images clip/ --fps 30 --poses fits.npz --camera cam.json --out scene
  cargo xtask import frames --images clip/ --fps 120 --poses smpl/ --camera cam.json \\
      --blur 7 --events simulate --out scene-blur   # the ZJU-MoCap-Blur recipe")]
pub struct Args {
    /// Folder of frames, PNG (8 or 16 bit, grey, RGB or RGBA; alpha ignored), JPEG or PPM, in file-name
    /// order. Grey frames (a DAVIS APS or CeleX-V camera) make a grey scene (`images.channels =
    /// 1`), which trains on the renders' luminance.
    #[arg(long)]
    pub images: PathBuf,
    /// Frame rate of the frames (frames per second).
    #[arg(long)]
    pub fps: f64,
    /// SMPL poses, one per frame: a JSON list of `{"pose": 72 values or 24 triples, "transl": [3]}`,
    /// an AMASS-style `.npz` (`poses`, `trans`), a PeopleSnapshot / InstantAvatar `.npz`
    /// (`global_orient`, `body_pose`, `transl`, `betas`) or an EasyMocap `smpl/` folder.
    #[arg(long)]
    pub poses: PathBuf,
    /// With an EasyMocap folder: the `id` of the person to follow (default the first person).
    #[arg(long)]
    pub person: Option<i64>,
    /// The camera: the project's camera JSON, a scene's `scene.json`, or an INRIA `cameras.json`
    /// list (see `--cam-index`). Its size must be the frames' size.
    #[arg(long)]
    pub camera: PathBuf,
    /// Index into an INRIA `cameras.json` list.
    #[arg(long, default_value_t = 0)]
    pub cam_index: usize,
    /// Optional folder of human masks (single-channel PNG, non-zero = human), one per frame, in
    /// file-name order.
    #[arg(long)]
    pub masks: Option<PathBuf>,
    /// Body model: `builtin:makehuman` or the path of your SMPL `.npz` (its licence is yours; the
    /// scene references it, it is not copied).
    #[arg(long, default_value = "builtin:makehuman")]
    pub body: String,
    /// Average K consecutive frames (odd) into one observed frame, keeping the middle one as the
    /// sharp reference: output rate fps / K, exposure K / fps. 1 = the frames are the observations.
    #[arg(long, default_value_t = 1)]
    pub blur: usize,
    /// The camera's exposure per frame (seconds, ≤ 1/fps) when `--blur 1`; default 1/fps.
    #[arg(long)]
    pub exposure_s: Option<f64>,
    /// `simulate`: events by ESIM over the frames, split per output frame; `none`: no events.
    #[arg(long, default_value = "none", value_parser = ["none", "simulate"])]
    pub events: String,
    /// ESIM contrast threshold C (both polarities, log-intensity units).
    #[arg(long, default_value_t = 0.2)]
    pub threshold: f32,
    /// Seed of the simulator's per-pixel threshold noise.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// How the frames' pixel codes relate to intensity: `srgb` (video, photographs) or `linear`.
    #[arg(long, default_value = "srgb", value_parser = ["srgb", "linear"])]
    pub transfer: String,
    /// Output scene directory.
    #[arg(long)]
    pub out: PathBuf,
}

/// True if the image file at `path` has one channel (grey, 8 or 16 bit).
fn is_grey_file(path: &Path) -> Result<bool> {
    let decoder = image::ImageReader::open(path)
        .and_then(|r| r.with_guessed_format())
        .with_context(|| format!("reading {}", path.display()))?
        .into_decoder()
        .with_context(|| format!("reading {}", path.display()))?;
    use image::ImageDecoder;
    Ok(matches!(
        decoder.color_type(),
        image::ColorType::L8 | image::ColorType::L16
    ))
}

/// Reads frame `path` as linear planar RGB of the camera's size.
fn read_frame(path: &Path, camera: &scene::Camera, linear: bool) -> Result<Vec<f32>> {
    let (mut rgb, h, w) = crate::common::read_rgb(path)?;
    if (w, h) != (camera.width as usize, camera.height as usize) {
        bail!(
            "{}: {w}x{h}, the camera is {}x{}",
            path.display(),
            camera.width,
            camera.height
        );
    }
    if !linear {
        rgb.iter_mut()
            .for_each(|v| *v = scene::image_io::linear_from_srgb(*v));
    }
    Ok(rgb)
}

/// Runs `import frames`.
pub fn run(args: Args) -> Result<()> {
    let camera = scene::camera_files::read_any(&args.camera, args.cam_index)
        .with_context(|| format!("reading the camera {}", args.camera.display()))?;
    let images = image_files(&args.images, "frames")?;
    let masks = match &args.masks {
        Some(dir) => Some(image_files(dir, "masks")?),
        None => None,
    };
    let body_ref = BodyRef::parse(&args.body)?;
    let body = body_ref
        .load()
        .with_context(|| format!("loading the body model {}", args.body))?;
    let Poses {
        list: poses,
        times_us,
        betas,
    } = read_poses(&args.poses, &body, args.person)?;
    if times_us.is_some() {
        bail!(
            "{}: poses with `t_us` are for recordings with their own clock (`import aedat4`); \
             give one pose per frame, in frame order",
            args.poses.display()
        );
    }
    if poses.len() != images.len() {
        bail!(
            "{} holds {} poses but {} holds {} frames: one pose per frame is needed",
            args.poses.display(),
            poses.len(),
            args.images.display(),
            images.len()
        );
    }
    if let Some(m) = &masks {
        if m.len() != images.len() {
            bail!(
                "{} holds {} masks but {} holds {} frames: one mask per frame is needed",
                args.masks.as_deref().unwrap_or(Path::new("")).display(),
                m.len(),
                args.images.display(),
                images.len()
            );
        }
    }
    let mut cfg = FramesToScene {
        fps: args.fps,
        blur: args.blur,
        exposure_s: args.exposure_s,
        events: (args.events == "simulate").then(|| events::EsimConfig {
            c_pos: args.threshold,
            c_neg: args.threshold,
            seed: args.seed,
            ..events::EsimConfig::default()
        }),
        ..FramesToScene::default()
    };
    if is_grey_file(&images[0])? {
        cfg.encoding.channels = 1;
        eprintln!("grey frames: the scene trains on the renders' luminance (Rec. 601)");
    }
    cfg.check(images.len())?;
    if args.out.join(scene::SCENE_FILE).exists() {
        bail!(
            "{} already holds a scene: choose another --out or remove it",
            args.out.display()
        );
    }
    let model = match &body_ref {
        BodyRef::BuiltinMakehuman => args.body.clone(),
        BodyRef::SmplFile(p) => std::fs::canonicalize(p)
            .unwrap_or_else(|_| p.clone())
            .display()
            .to_string(),
    };
    let spec = scene::BodySpec {
        model,
        betas: betas.unwrap_or_default(),
    };
    let generator = serde_json::json!({
        "name": "xtask import frames",
        "config": {
            "images": args.images.display().to_string(),
            "poses": args.poses.display().to_string(),
            "camera": args.camera.display().to_string(),
            "fps": args.fps, "blur": args.blur, "events": args.events,
            "threshold": args.threshold, "seed": args.seed, "transfer": args.transfer,
        }
    });
    let linear = args.transfer == "linear";
    let used = images.len() / args.blur * args.blur;
    let bar = crate::common::progress_bar(used as u64, "frames")?;
    let report = write_scene_from_frames(
        &args.out,
        camera.clone(),
        spec,
        images.len(),
        &cfg,
        generator,
        |i| {
            let rgb =
                read_frame(&images[i], &camera, linear).map_err(|e| synth::SynthError::Knob {
                    knob: "images",
                    value: images[i].display().to_string(),
                    reason: format!("{e:#}"),
                })?;
            let mask =
                match &masks {
                    Some(m) => Some(read_mask_any(&m[i], &camera).map_err(|e| {
                        synth::SynthError::Knob {
                            knob: "masks",
                            value: m[i].display().to_string(),
                            reason: format!("{e:#}"),
                        }
                    })?),
                    None => None,
                };
            let (pose, transl) = poses[i].clone();
            Ok(InputFrame {
                rgb,
                mask,
                pose,
                transl,
            })
        },
        |_| bar.inc(1),
    )
    .with_context(|| format!("writing the scene {}", args.out.display()))?;
    bar.finish_and_clear();
    if report.dropped_frames > 0 {
        eprintln!(
            "note: the last {} frame(s) do not fill a window of {} and were not used",
            report.dropped_frames, args.blur
        );
    }
    if cfg.events.is_some() {
        eprintln!(
            "{} events ({} before the first frame's time, not written)",
            report.events, report.events_before_first_frame
        );
    }
    eprintln!(
        "{} frames at {:.3} fps, exposure {:.4} s",
        report.frames,
        args.fps / args.blur as f64,
        cfg.exposure()
    );
    println!("{}", crate::common::shown(&args.out).display());
    Ok(())
}
