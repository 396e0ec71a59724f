//! `cargo xtask render-pose --motion FILE`: the reconstructed person moving inside the reconstructed
//! scene, seen from the training camera, as an animated GIF or a folder of PNG frames.
//!
//! A motion lives in its own world frame (AMASS and EasyMocap are z up; PeopleSnapshot poses are in
//! an OpenCV camera frame, up = −y). It is placed in the scene by [`smpl_deform::motion::anchor_motion`]: its
//! first frame takes the position and heading of a training frame's pose (`--anchor-frame`, read
//! from the scene the model was trained on, `--data`), and the rest of the motion follows relative
//! to it. The frames are resampled from the file's frame rate to the output's (`--fps`).

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

/// The anchor pose: frame `anchor` (or the model's first training frame) of the scene in `data`.
fn anchor_pose(
    loaded: &train::export::LoadedModel,
    args: &AnimationArgs,
) -> Result<(Vec<f32>, [f32; 3], u32)> {
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
    let Some(frame) = scene.frames.iter().find(|f| f.index == frame_number) else {
        bail!(
            "{}: no frame {frame_number} (--anchor-frame)",
            data.display()
        );
    };
    Ok((frame.pose_flat(), frame.transl, frame_number))
}

/// Renders `motion` with the loaded model to `out` (a `.gif`, or a folder of PNG frames).
pub fn run(
    loaded: &train::export::LoadedModel,
    motion_path: &Path,
    out: &Path,
    args: &AnimationArgs,
) -> Result<()> {
    if !(args.fps > 0.0 && args.fps <= 100.0) {
        bail!("--fps {} must be in (0, 100]", args.fps);
    }
    let motion: Motion = if motion_path.is_dir() {
        let body = &loaded.body;
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
    let (pose, transl, anchor) = anchor_pose(loaded, args)?;
    let indices = sample_indices(motion.len(), args.start, args.frames, motion_fps, args.fps);
    let used = Motion {
        poses: indices.iter().map(|&i| motion.poses[i]).collect(),
        transl: indices.iter().map(|&i| motion.transl[i]).collect(),
        ..motion.clone()
    };
    let placed = anchor_motion(&used, up, &pose, transl)?;
    println!(
        "{} motion, {} frames at {motion_fps} fps: rendering {} at {} fps from frame {}, up axis \
         {up:?}, anchored at scene frame {anchor}",
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

    let t = &loaded.model;
    let latent = t.latent_for(loaded.manifest.frame_indices.first().copied().unwrap_or(0));
    let (w, h) = (loaded.camera.width, loaded.camera.height);
    let bar = crate::common::progress_bar(placed.len() as u64, "rendering")?;
    let mut frames = Vec::with_capacity(placed.len());
    for (pose, transl) in &placed {
        let params = smpl_deform::SmplParams {
            pose: pose.to_vec(),
            betas: loaded.manifest.betas.clone(),
            transl: *transl,
        };
        let prepared = loaded.body.prepare(&params)?;
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
