//! `cargo xtask import frames`: a PNG folder + SMPL poses + a camera → scene format v1, through
//! [`synth::from_frames`] (blur windows, ESIM events, the benchmark's 7/3 split).

use std::path::{Path, PathBuf};

use super::{
    check_out_is_free, image_files, load_body, read_mask_any, read_poses, PersonArgs, Poses,
    SynthesisArgs,
};
use anyhow::{bail, Context, Result};
use synth::from_frames::{write_scene_from_frames, InputFrame};

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
    #[command(flatten)]
    pub person: PersonArgs,
    #[command(flatten)]
    pub synthesis: SynthesisArgs,
    /// The camera's exposure per frame (seconds, ≤ 1/fps) when `--blur 1`; default 1/fps.
    #[arg(long)]
    pub exposure_s: Option<f64>,
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
    let person = &args.person;
    let camera = person.camera()?;
    let images = image_files(&args.images, "frames")?;
    let masks = person.mask_files(images.len(), &args.images)?;
    let (body, model) = load_body(&person.body)?;
    let Poses {
        list: poses,
        times_us,
        betas,
    } = read_poses(&person.poses, &body, person.person)?;
    if times_us.is_some() {
        bail!(
            "{}: poses with `t_us` are for recordings with their own clock (`import aedat4`); \
             give one pose per frame, in frame order",
            person.poses.display()
        );
    }
    if poses.len() != images.len() {
        bail!(
            "{} holds {} poses but {} holds {} frames: one pose per frame is needed",
            person.poses.display(),
            poses.len(),
            args.images.display(),
            images.len()
        );
    }
    let mut cfg = args.synthesis.config(args.fps, args.exposure_s);
    if is_grey_file(&images[0])? {
        cfg.encoding.channels = 1;
        eprintln!("grey frames: the scene trains on the renders' luminance (Rec. 601)");
    }
    cfg.check(images.len())?;
    check_out_is_free(&args.out)?;
    let spec = scene::BodySpec {
        model,
        betas: betas.unwrap_or_default(),
    };
    let generator = serde_json::json!({
        "name": "xtask import frames",
        "config": {
            "images": args.images.display().to_string(),
            "poses": person.poses.display().to_string(),
            "camera": person.camera.display().to_string(),
            "fps": args.fps, "blur": args.synthesis.blur, "events": args.synthesis.events,
            "threshold": args.synthesis.threshold, "seed": args.synthesis.seed,
            "transfer": args.transfer,
        }
    });
    let linear = args.transfer == "linear";
    let used = images.len() / cfg.blur * cfg.blur;
    let bar = crate::common::progress_bar(used as u64, "frames")?;
    let mut between = args
        .synthesis
        .between(camera.height as usize, camera.width as usize)?;
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
        between.as_deref_mut(),
        |_| bar.inc(1),
    )
    .with_context(|| format!("writing the scene {}", args.out.display()))?;
    bar.finish_and_clear();
    if report.dropped_frames > 0 {
        eprintln!(
            "note: the last {} frame(s) do not fill a window of {} and were not used",
            report.dropped_frames, cfg.blur
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
        args.fps / cfg.blur as f64,
        cfg.exposure()
    );
    println!("{}", crate::common::shown(&args.out).display());
    Ok(())
}
