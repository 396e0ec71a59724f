//! `cargo xtask render-pose --motion FILE`: the reconstructed person moving inside the reconstructed
//! scene, seen from the training camera, as an animated GIF or a folder of PNG frames.
//!
//! A motion lives in its own world frame (AMASS and EasyMocap are z up; PeopleSnapshot poses are in
//! an OpenCV camera frame, up = −y). It is placed in the scene by [`smpl_deform::motion::anchor_motion`]: its
//! first frame takes the position and heading of a training frame's pose (`--anchor-frame`, read
//! from the scene the model was trained on, `--data`), and the rest of the motion follows relative
//! to it. The frames are resampled from the file's frame rate to the output's (`--fps`).
//!
//! A model of several people takes one motion per person, `--motion ID=FILE` (the scene's stable
//! ids), each anchored at its own person's pose of the anchor frame; a person without a motion
//! stands still in that pose. The animation ends with the shortest motion.

use anyhow::{bail, Context, Result};
use std::path::{Path, PathBuf};

use smpl_deform::motion::{anchor_motion, read_easymocap, read_motion, Motion, UpAxis};

/// Options of `render-pose --motion`.
#[derive(clap::Args, Debug)]
pub struct AnimationArgs {
    /// Frames to render (at `--fps`), or fewer when the motion ends first.
    #[arg(long, default_value_t = 60)]
    pub frames: usize,
    /// The motion's first frame to use (in the file's frames).
    #[arg(long, default_value_t = 0)]
    pub start: usize,
    /// Frame rate of the output (frames per second).
    #[arg(long, default_value_t = 30.0)]
    pub fps: f64,
    /// The motion file's frame rate, when it does not state one (AMASS files do, as
    /// `mocap_framerate`; PeopleSnapshot files do not and are taken as 30).
    #[arg(long)]
    pub motion_fps: Option<f64>,
    /// The motion file's up axis (`x`, `y`, `z`, `-x`, `-y`, `-z`); default `z` for AMASS and
    /// EasyMocap, `-y` for PeopleSnapshot (an OpenCV camera frame).
    #[arg(long, value_parser = parse_up, allow_hyphen_values = true)]
    pub up: Option<UpAxis>,
    /// The scene the model was trained on (for the anchor pose); its camera must be the model's.
    /// Default: the default benchmark, `target/benchmark/default`.
    #[arg(long)]
    pub data: Option<PathBuf>,
    /// Frame number of the scene pose the motion starts from (position and heading); default the
    /// model's first training frame.
    #[arg(long)]
    pub anchor_frame: Option<u32>,
    /// With an EasyMocap `smpl/` folder: the `id` of the person to follow (default the first
    /// person of the first file).
    #[arg(long)]
    pub person: Option<i64>,
}

fn parse_up(s: &str) -> Result<UpAxis, String> {
    UpAxis::parse(s).ok_or_else(|| format!("`{s}`: expected x, y, z, -x, -y or -z"))
}

/// Indices into the motion's frames of the output frames: `start` then steps of
/// `motion_fps / fps` frames, at most `frames` of them, none past the end.
fn sample_indices(
    len: usize,
    start: usize,
    frames: usize,
    motion_fps: f64,
    fps: f64,
) -> Vec<usize> {
    let step = motion_fps / fps;
    (0..frames)
        .map(|k| start + (k as f64 * step).round() as usize)
        .take_while(|&i| i < len)
        .collect()
}

/// A `--motion` value: `FILE`, or `ID=FILE` for the person of stable id `ID`.
#[derive(Clone, Debug, PartialEq)]
pub struct MotionArg {
    /// The person's stable id (`None`: the model's only person).
    pub person: Option<u32>,
    /// The motion file or EasyMocap folder.
    pub path: PathBuf,
}

/// Parses a `--motion` value.
pub fn parse_motion(s: &str) -> Result<MotionArg, String> {
    match s.split_once('=') {
        Some((id, path)) if !id.is_empty() && id.bytes().all(|b| b.is_ascii_digit()) => {
            let person = id.parse().map_err(|_| format!("`{id}`: not a person id"))?;
            Ok(MotionArg {
                person: Some(person),
                path: PathBuf::from(path),
            })
        }
        _ => Ok(MotionArg {
            person: None,
            path: PathBuf::from(s),
        }),
    }
}

/// The anchor frame of the scene in `data`: frame `anchor` (or the model's first training
/// frame), and its scene.
fn anchor_frame(
    loaded: &train::export::LoadedModel,
    args: &AnimationArgs,
) -> Result<(scene::Scene, usize)> {
    let data = args.data.clone().unwrap_or_else(|| {
        crate::common::target_dir()
            .join("benchmark")
            .join("default")
    });
    let scene = scene::load(&data).with_context(|| {
        format!(
            "reading the scene {} for the anchor pose (pass the scene the model was trained on \
             with --data)",
            data.display()
        )
    })?;
    if scene.camera != loaded.manifest.camera {
        bail!(
            "the model was not trained on {} (its camera differs): pass the scene it was trained \
             on with --data",
            data.display()
        );
    }
    let frame_number = args
        .anchor_frame
        .or_else(|| loaded.manifest.frame_indices.first().copied())
        .unwrap_or(0);
    let Some(k) = scene.frames.iter().position(|f| f.index == frame_number) else {
        bail!(
            "{}: no frame {frame_number} (--anchor-frame)",
            data.display()
        );
    };
    if scene.person_count() != loaded.model.people() {
        bail!(
            "{}: the scene has {} people, the model {}: pass the scene it was trained on with \
             --data",
            data.display(),
            scene.person_count(),
            loaded.model.people()
        );
    }
    Ok((scene, k))
}

/// Which motion animates each person of the model (`None`: standing still), checked against the
/// scene's stable ids.
fn motions_by_person<'a>(
    motions: &'a [MotionArg],
    ids: &[u32],
) -> Result<Vec<Option<&'a MotionArg>>> {
    let mut by_person = vec![None; ids.len()];
    for m in motions {
        let p = match m.person {
            None if ids.len() == 1 && motions.len() == 1 => 0,
            None => bail!(
                "{}: the model has {} people (ids {ids:?}): give each motion as --motion ID=FILE",
                m.path.display(),
                ids.len()
            ),
            Some(id) => ids.iter().position(|&i| i == id).with_context(|| {
                format!("--motion {id}=…: no person {id} in the scene (ids {ids:?})")
            })?,
        };
        if by_person[p].replace(m).is_some() {
            bail!("two motions for person {}", ids[p]);
        }
    }
    Ok(by_person)
}

/// Renders the `motions` with the loaded model to `out` (a `.gif`, or a folder of PNG frames).
pub fn run(
    loaded: &train::export::LoadedModel,
    motions: &[MotionArg],
    out: &Path,
    args: &AnimationArgs,
) -> Result<()> {
    if !(args.fps > 0.0 && args.fps <= 100.0) {
        bail!("--fps {} must be in (0, 100]", args.fps);
    }
    let (scene, k) = anchor_frame(loaded, args)?;
    let anchor = &scene.frames[k];
    let ids = scene.person_ids();
    let cast = loaded.cast();
    let bodies: Vec<&train::pose::body::Body> =
        std::iter::once(cast.first).chain(cast.others).collect();
    // Each person's placed poses (or its anchor pose, held), and the length of the shortest
    // motion.
    let mut tracks: Vec<Vec<(Vec<f32>, [f32; 3])>> = Vec::with_capacity(ids.len());
    let mut frames_out = usize::MAX;
    for (p, motion) in motions_by_person(motions, &ids)?.into_iter().enumerate() {
        let Some((pose, transl)) = anchor.pose_of(p) else {
            bail!("scene frame {}: no pose of person {}", anchor.index, ids[p]);
        };
        let pose: Vec<f32> = pose.iter().flatten().copied().collect();
        tracks.push(match motion {
            Some(m) => {
                let placed = placed_motion(bodies[p], &m.path, args, &pose, transl, anchor.index)?;
                frames_out = frames_out.min(placed.len());
                placed
            }
            None => vec![(pose, transl)],
        });
    }
    if frames_out == usize::MAX {
        bail!("no motion given (--motion FILE or ID=FILE)");
    }
    let t = &loaded.model;
    let latent = t.latent_for(loaded.manifest.frame_indices.first().copied().unwrap_or(0));
    let (w, h) = (loaded.camera.width, loaded.camera.height);
    let bar = crate::common::progress_bar(frames_out as u64, "rendering")?;
    let mut frames = Vec::with_capacity(frames_out);
    for f in 0..frames_out {
        let params: Vec<smpl_deform::SmplParams> = tracks
            .iter()
            .zip(&bodies)
            .map(|(track, body)| {
                let (pose, transl) = &track[f.min(track.len() - 1)];
                smpl_deform::SmplParams {
                    pose: pose.clone(),
                    betas: body.betas.clone(),
                    transl: *transl,
                }
            })
            .collect();
        let prepared = cast.prepare(&params[0], &params[1..])?;
        let r = t.render(&loaded.camera, &prepared, latent)?;
        frames.push(scene::image_io::srgb8_interleaved(
            &r.rgb,
            w as usize * h as usize,
        ));
        bar.inc(1);
    }
    bar.finish_and_clear();

    let is_gif = out
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("gif"));
    if is_gif {
        write_gif(out, &frames, w, h, args.fps)?;
    } else {
        std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
        for (k, rgb) in frames.iter().enumerate() {
            let path = out.join(format!("frame_{k:04}.png"));
            image::save_buffer(&path, rgb, w, h, image::ExtendedColorType::Rgb8)
                .with_context(|| format!("writing {}", path.display()))?;
        }
    }
    println!("{}", crate::common::shown(out).display());
    Ok(())
}

/// The motion at `motion_path` for `body`, resampled to the output rate and anchored at the
/// scene pose `pose`, `transl` (of frame `anchor`).
fn placed_motion(
    body: &train::pose::body::Body,
    motion_path: &Path,
    args: &AnimationArgs,
    pose: &[f32],
    transl: [f32; 3],
    anchor: u32,
) -> Result<Vec<(Vec<f32>, [f32; 3])>> {
    let motion: Motion = if motion_path.is_dir() {
        let shaped = body.model.shaped_vertices(&body.betas)?;
        let root = body
            .model
            .rest_joints(&shaped)
            .first()
            .copied()
            .unwrap_or([0.0; 3]);
        read_easymocap(motion_path, root.map(f64::from), args.person)
    } else {
        read_motion(motion_path)
    }
    .with_context(|| format!("reading the motion {}", motion_path.display()))?;
    let motion_fps = args.motion_fps.or(motion.fps).unwrap_or(30.0);
    if !(motion_fps > 0.0 && motion_fps <= 10_000.0) {
        bail!("--motion-fps {motion_fps} must be in (0, 10000]");
    }
    if args.start >= motion.len() {
        bail!(
            "--start {} is past the motion's {} frames",
            args.start,
            motion.len()
        );
    }
    let up = args.up.unwrap_or_else(|| motion.layout.default_up());
    let indices = sample_indices(motion.len(), args.start, args.frames, motion_fps, args.fps);
    let used = Motion {
        poses: indices.iter().map(|&i| motion.poses[i]).collect(),
        transl: indices.iter().map(|&i| motion.transl[i]).collect(),
        ..motion.clone()
    };
    let placed = anchor_motion(&used, up, pose, transl)?;
    println!(
        "{}: {} motion, {} frames at {motion_fps} fps: rendering {} at {} fps from frame {}, up axis \
         {up:?}, anchored at scene frame {anchor}",
        motion_path.display(),
        motion.layout.as_str(),
        motion.len(),
        placed.len(),
        args.fps,
        args.start,
    );
    for d in &motion.dropped {
        println!("not used: {d}");
    }
    if motion.betas.is_some() {
        println!("not used: the file's `betas` (the avatar keeps its reconstructed shape)");
    }
    Ok(placed
        .into_iter()
        .map(|(pose, transl)| (pose.to_vec(), transl))
        .collect())
}

/// Writes an endlessly looping GIF (each frame quantised to its own 256-colour palette).
fn write_gif(path: &Path, frames: &[Vec<u8>], w: u32, h: u32, fps: f64) -> Result<()> {
    use image::codecs::gif::{GifEncoder, Repeat};
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let file =
        std::fs::File::create(path).with_context(|| format!("creating {}", path.display()))?;
    let mut enc = GifEncoder::new_with_speed(std::io::BufWriter::new(file), 10);
    enc.set_repeat(Repeat::Infinite)
        .with_context(|| format!("writing {}", path.display()))?;
    let delay = image::Delay::from_numer_denom_ms(1000, (fps.round() as u32).max(1));
    for rgb in frames {
        let rgba: Vec<u8> = rgb
            .chunks_exact(3)
            .flat_map(|p| [p[0], p[1], p[2], 255])
            .collect();
        let Some(img) = image::RgbaImage::from_raw(w, h, rgba) else {
            bail!("internal: a {w}×{h} frame of the wrong size");
        };
        enc.encode_frame(image::Frame::from_parts(img, 0, 0, delay))
            .with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::sample_indices;

    #[test]
    fn frames_are_resampled_to_the_output_rate_and_stop_at_the_end() {
        assert_eq!(sample_indices(100, 0, 4, 120.0, 30.0), vec![0, 4, 8, 12]);
        assert_eq!(sample_indices(10, 5, 60, 30.0, 30.0), vec![5, 6, 7, 8, 9]);
        assert_eq!(sample_indices(10, 0, 3, 15.0, 30.0), vec![0, 1, 1]);
    }
}
