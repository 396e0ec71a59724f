//! `cargo xtask import frames`: a PNG folder + SMPL poses + a camera (and, for a moving camera, its
//! pose per frame) → a scene (format version 1, or 2 with per-frame cameras), through
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
    /// A moving camera's pose per frame: a COLMAP text model (a folder with `cameras.txt` and
    /// `images.txt`, matched to the frames by file name; intrinsics must equal `--camera`'s and
    /// carry no distortion), or a JSON list with one camera per frame in frame order (the
    /// project's camera objects or INRIA `cameras.json` entries). The scene is written in format
    /// version 2 with each frame's pose; `--camera` gives the intrinsics.
    #[arg(long)]
    pub cameras: Option<PathBuf>,
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

/// One camera per frame of `images` from `path` (see `Args::cameras`); a camera whose intrinsics
/// are not `camera`'s is refused, naming its frame.
fn frame_cameras(
    path: &Path,
    images: &[PathBuf],
    camera: &scene::Camera,
) -> Result<Vec<scene::Camera>> {
    let list = if path.is_dir() {
        let model = scene::colmap::read_text_model(path)?;
        let mut by_name = std::collections::BTreeMap::new();
        for image in model {
            let stem = Path::new(&image.name)
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default();
            by_name.insert(stem, image.camera);
        }
        images
            .iter()
            .map(|f| {
                let name = f.file_name().map(|n| n.to_string_lossy().into_owned());
                let found = name.as_ref().and_then(|n| by_name.get(n));
                let Some(c) = found else {
                    bail!(
                        "{}: no registered image named {} in the COLMAP model",
                        path.display(),
                        f.display()
                    );
                };
                Ok(c.clone())
            })
            .collect::<Result<Vec<_>>>()?
    } else {
        let text =
            std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        let entries: Vec<serde_json::Value> = serde_json::from_str(&text)
            .with_context(|| format!("{}: expected a JSON list of cameras", path.display()))?;
        let list = entries
            .iter()
            .enumerate()
            .map(|(k, e)| {
                let one = if e.get("fx").is_some() {
                    scene::camera_files::from_json_str(&e.to_string(), path)
                } else {
                    scene::camera_files::inria_list_from_str(&format!("[{e}]"), path)
                        .map(|mut v| v.remove(0))
                };
                one.with_context(|| format!("{}: camera {k}", path.display()))
            })
            .collect::<Result<Vec<_>>>()?;
        if list.len() != images.len() {
            bail!(
                "{} holds {} cameras but there are {} frames: one camera per frame is needed",
                path.display(),
                list.len(),
                images.len()
            );
        }
        list
    };
    let same = |a: f64, b: f64| (a - b).abs() <= 1e-6 * b.abs().max(1.0);
    for (c, image) in list.iter().zip(images) {
        let intrinsics_agree = (c.width, c.height) == (camera.width, camera.height)
            && same(c.fx, camera.fx)
            && same(c.fy, camera.fy)
            && same(c.cx, camera.cx)
            && same(c.cy, camera.cy);
        if !intrinsics_agree {
            bail!(
                "{}: the camera of {} ({}x{}, f {} {}, c {} {}) does not have --camera's intrinsics",
                path.display(),
                image.display(),
                c.width,
                c.height,
                c.fx,
                c.fy,
                c.cx,
                c.cy
            );
        }
        c.validate()
            .with_context(|| format!("{}: the camera of {}", path.display(), image.display()))?;
    }
    Ok(list)
}

/// Runs `import frames`.
pub fn run(args: Args) -> Result<()> {
    let person = &args.person;
    let camera = person.camera()?;
    let images = image_files(&args.images, "frames")?;
    let masks = person.mask_files(images.len(), &args.images)?;
    let (body, model) = load_body(&person.body)?;
    let read = read_poses(&person.poses, &body, person.person)?;
    let (people, several) = (read.people(), !read.others.is_empty());
    let Poses {
        list: poses,
        times_us,
        betas,
        id,
        ..
    } = &read;
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
    let frame_cameras = args
        .cameras
        .as_ref()
        .map(|path| frame_cameras(path, &images, &camera))
        .transpose()?;
    let mut cfg = args.synthesis.config(args.fps, args.exposure_s);
    if is_grey_file(&images[0])? {
        cfg.encoding.channels = 1;
        eprintln!("grey frames: the scene trains on the renders' luminance (Rec. 601)");
    }
    cfg.check(images.len())?;
    check_out_is_free(&args.out)?;
    let spec = scene::BodySpec {
        // The first person's id names it among several; one person keeps the default 0.
        id: if several { *id } else { 0 },
        model,
        betas: betas.clone().unwrap_or_default(),
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
        &people,
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
                people: read.others_at(i),
                world_to_camera: frame_cameras.as_ref().map(|c| c[i].world_to_camera),
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
