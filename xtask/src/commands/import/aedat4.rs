//! `cargo xtask import aedat4`: a DAVIS recording (AEDAT 4: intensity frames + events) and one
//! SMPL pose per frame → scene format v1. Each frame keeps its own exposure (auto-exposure); the
//! events are split per frame as the format defines (`[time_s, next time_s)`).

use std::path::{Path, PathBuf};

use super::{check_out_is_free, load_body, read_mask_any, read_poses, PersonArgs, Pose, Poses};
use anyhow::{bail, Context, Result};
use events::io::aedat4_frames::{read_aedat4_frames, ApsFrame, FrameFormat};
use events::io::EventReader;

/// Arguments of `import aedat4`.
#[derive(clap::Args, Debug)]
#[command(after_help = "\
Times: the scene's time 0 is the first frame's exposure start; a frame's time is the middle of \
its exposure and its exposure its own (the scene's `exposure_s` is the median, frames that differ \
carry their own). The frames' values are taken as linear intensity (an APS pixel's output is, to \
first order, proportional to the light it collected). Events before the first frame's time \
belong to no frame and are not written (their count is printed).

The poses are used as they are, in the camera file's world frame; one pose per frame, in frame \
order.

Example:
  cargo xtask import aedat4 --file rec.aedat4 --poses fits.npz --camera davis346.json --out scene")]
pub struct Args {
    /// The AEDAT 4 recording (a `FRME` stream and an `EVTS` stream).
    #[arg(long)]
    pub file: PathBuf,
    #[command(flatten)]
    pub person: PersonArgs,
    /// Output scene directory.
    #[arg(long)]
    pub out: PathBuf,
}

/// Checks the frames: one full-sensor size and format, exposures that are intervals, midpoints
/// that increase. Returns (width, height, format).
fn check_frames(frames: &[ApsFrame], file: &Path) -> Result<(u32, u32, FrameFormat)> {
    let Some(first) = frames.first() else {
        bail!("{}: the frames stream holds no frame", file.display());
    };
    if frames.len() < 2 {
        bail!(
            "{}: one frame only; a scene needs at least two",
            file.display()
        );
    }
    let mut last_mid = None;
    for (k, f) in frames.iter().enumerate() {
        if (f.width, f.height, f.format) != (first.width, first.height, first.format) {
            bail!(
                "{}: frame {k} is {}x{} {:?}, frame 0 {}x{} {:?}: frames of one size and format are needed",
                file.display(),
                f.width,
                f.height,
                f.format,
                first.width,
                first.height,
                first.format
            );
        }
        if f.offset_x != 0 || f.offset_y != 0 {
            bail!(
                "{}: frame {k} is a region of interest at ({}, {}); full frames are needed",
                file.display(),
                f.offset_x,
                f.offset_y
            );
        }
        if f.exposure_end_us <= f.exposure_begin_us {
            bail!(
                "{}: frame {k}: exposure_end_t {} µs is not after exposure_begin_t {} µs",
                file.display(),
                f.exposure_end_us,
                f.exposure_begin_us
            );
        }
        let mid = f.exposure_begin_us + (f.exposure_end_us - f.exposure_begin_us) / 2;
        if let Some(prev) = last_mid {
            if mid <= prev {
                bail!(
                    "{}: frame {k}'s exposure midpoint {mid} µs is not after frame {}'s {prev} µs",
                    file.display(),
                    k - 1
                );
            }
        }
        last_mid = Some(mid);
    }
    Ok((first.width, first.height, first.format))
}

/// The poses at each frame's exposure midpoint, interpolated from poses at their own times (µs,
/// the recording's clock) by the exposure model's spline ([`train::pose::exposure::PoseTrack`]: C¹ on
/// rotations and translation). A frame outside the poses' time span is refused by name.
fn poses_at_frames(
    list: &[Pose],
    times_us: &[i64],
    frames: &[ApsFrame],
    file: &Path,
) -> Result<Vec<Pose>> {
    let params: Vec<smpl_deform::SmplParams> = list
        .iter()
        .map(|(pose, transl)| smpl_deform::SmplParams {
            pose: pose.iter().flatten().copied().collect(),
            betas: Vec::new(),
            transl: *transl,
        })
        .collect();
    let keys: Vec<(f64, &smpl_deform::SmplParams)> = times_us
        .iter()
        .map(|&t| t as f64 * 1e-6)
        .zip(&params)
        .collect();
    // Pose times from a tracker need not be evenly spaced: the local rule.
    let track = train::pose::exposure::PoseTrack::new(&keys, train::config::TrackTangents::Local);
    let (first, last) = (times_us[0], times_us[times_us.len() - 1]);
    frames
        .iter()
        .enumerate()
        .map(|(k, f)| {
            let mid = f.exposure_begin_us + (f.exposure_end_us - f.exposure_begin_us) / 2;
            if mid < first || mid > last {
                bail!(
                    "{}: frame {k}'s exposure midpoint {mid} µs lies outside the poses' times \
                     [{first}, {last}] µs",
                    file.display()
                );
            }
            let p = track.at(mid as f64 * 1e-6);
            Ok((
                p.pose.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
                p.transl,
            ))
        })
        .collect()
}

/// Runs `import aedat4`.
pub fn run(args: Args) -> Result<()> {
    let (frames, _) = read_aedat4_frames(&args.file)
        .with_context(|| format!("reading the frames of {}", args.file.display()))?;
    let (w, h, format) = check_frames(&frames, &args.file)?;
    let person = &args.person;
    let camera = person.camera()?;
    if (camera.width, camera.height) != (w, h) {
        bail!(
            "the camera {} is {}x{}, the frames of {} are {w}x{h}",
            person.camera.display(),
            camera.width,
            camera.height,
            args.file.display()
        );
    }
    let (body, model) = load_body(&person.body)?;
    let Poses {
        list,
        times_us,
        betas,
        id,
        others,
        ..
    } = read_poses(&person.poses, &body, person.person)?;
    if !others.is_empty() {
        eprintln!(
            "note: `import aedat4` follows one person: person {id} (--person ID for another)"
        );
    }
    let poses = match times_us {
        Some(times) => poses_at_frames(&list, &times, &frames, &person.poses)?,
        None if list.len() != frames.len() => bail!(
            "{} holds {} poses but {} holds {} frames: one pose per frame is needed (or give \
             each pose its time as `t_us`)",
            person.poses.display(),
            list.len(),
            args.file.display(),
            frames.len()
        ),
        None => list,
    };
    let masks = person.mask_files(frames.len(), &args.file)?;
    check_out_is_free(&args.out)?;
    for sub in ["images", "masks", "events"] {
        std::fs::create_dir_all(args.out.join(sub))
            .with_context(|| format!("creating {}", args.out.join(sub).display()))?;
    }

    // Times (s from the first exposure's start) and exposures.
    let t0 = frames[0].exposure_begin_us;
    let mid_us: Vec<i64> = frames
        .iter()
        .map(|f| f.exposure_begin_us + (f.exposure_end_us - f.exposure_begin_us) / 2 - t0)
        .collect();
    let exposures: Vec<f64> = frames
        .iter()
        .map(|f| (f.exposure_end_us - f.exposure_begin_us) as f64 * 1e-6)
        .collect();
    let mut sorted = exposures.clone();
    sorted.sort_by(f64::total_cmp);
    let median = sorted[sorted.len() / 2];
    let longest = sorted[sorted.len() - 1];
    let span = (mid_us[mid_us.len() - 1] - mid_us[0]) as f64 * 1e-6;
    let mut fps = (frames.len() - 1) as f64 / span;
    if longest > 1.0 / fps {
        eprintln!(
            "note: the longest exposure ({:.2} ms) exceeds the mean frame interval ({:.2} ms); \
             the scene's nominal fps is set to 1 / longest exposure",
            longest * 1e3,
            1e3 / fps
        );
        fps = 1.0 / longest;
    }

    // Frames.
    let grey = format.channels() == 1;
    let encoding = scene::ImageEncoding {
        channels: if grey { 1 } else { 3 },
        ..scene::ImageEncoding::rgb(
            if format == FrameFormat::Gray16 { 16 } else { 8 },
            scene::Transfer::Linear,
        )
    };
    let n = (w * h) as usize;
    let bar = crate::common::progress_bar(frames.len() as u64, "frames")?;
    let mut scene_frames = Vec::with_capacity(frames.len());
    for (k, f) in frames.iter().enumerate() {
        let planar = f.to_planar();
        let data = if grey {
            planar.iter().cycle().take(3 * n).copied().collect()
        } else {
            planar
        };
        let image = format!("images/{k:06}.png");
        scene::write_rgb(
            &args.out.join(&image),
            &scene::Rgb {
                width: w,
                height: h,
                data,
            },
            encoding,
        )
        .with_context(|| format!("writing {}", args.out.join(&image).display()))?;
        let mask = match &masks {
            Some(m) => {
                let rel = format!("masks/{k:06}.png");
                let set = read_mask_any(&m[k], &camera)?;
                scene::write_mask(&args.out.join(&rel), w, h, &set)?;
                Some(rel)
            }
            None => None,
        };
        let (pose, transl) = poses[k].clone();
        scene_frames.push(scene::Frame {
            people: Vec::new(),
            person_ids: None,
            index: k as u32,
            time_s: mid_us[k] as f64 * 1e-6,
            exposure_s: ((exposures[k] - median).abs() > 0.5e-6).then_some(exposures[k]),
            world_to_camera: None,
            image,
            sharp: None,
            mask,
            pose,
            transl,
            flow_to_next: Vec::new(),
            events: Some(format!("events/{k:06}.npz")),
            split: if k % 10 < 7 {
                scene::Split::Train
            } else {
                scene::Split::Test
            },
        });
        bar.inc(1);
    }
    bar.finish_and_clear();

    // Events, streamed into per-frame files.
    let exposure_us: Vec<(i64, i64)> = frames
        .iter()
        .map(|f| (f.exposure_begin_us - t0, f.exposure_end_us - t0))
        .collect();
    let last_end = exposure_us[exposure_us.len() - 1].1;
    let split = split_events(&args.file, &args.out, t0, &mid_us, last_end, (w, h))?;
    note_exposures_outside_events(&split, &exposure_us);

    let s = scene::Scene {
        people: Vec::new(),
        format_version: scene::FORMAT_VERSION,
        camera,
        body: scene::BodySpec {
            id: 0,
            model,
            betas: betas.unwrap_or_default(),
        },
        fps,
        exposure_s: median,
        images: encoding,
        frames: scene_frames,
        events_raw_format: None,
        events_recorded_s: split
            .recorded_us
            .map(|(a, b)| [a as f64 * 1e-6, b as f64 * 1e-6]),
        generator: Some(serde_json::json!({
            "name": "xtask import aedat4",
            "config": {
                "file": args.file.display().to_string(),
                "poses": person.poses.display().to_string(),
                "camera": person.camera.display().to_string(),
                "time_zero_us": t0,
                "frame_format": format!("{format:?}"),
            }
        })),
    };
    s.write(&args.out)
        .with_context(|| format!("writing {}", args.out.display()))?;
    scene::load(&args.out).with_context(|| format!("checking {}", args.out.display()))?;
    eprintln!(
        "{} frames ({}, {}x{w}x{h}), exposure {:.2}–{:.2} ms; {} events ({} before the first \
         frame's time, not written; {} after the last exposure, kept in the last frame's file)",
        frames.len(),
        if grey { "grey" } else { "colour" },
        if grey { 1 } else { 3 },
        sorted[0] * 1e3,
        longest * 1e3,
        split.written,
        split.before,
        split.after_last_exposure,
    );
    println!("{}", crate::common::shown(&args.out).display());
    Ok(())
}

/// What [`split_events`] wrote.
struct SplitEvents {
    /// Events written into the frames' files.
    written: u64,
    /// Events before the first frame's time (not written).
    before: u64,
    /// Times (µs from time 0) of the recording's first and last event; `None` without events.
    recorded_us: Option<(i64, i64)>,
    /// Events after the last exposure's end (kept in the last frame's file, unused).
    after_last_exposure: u64,
}

/// Says which exposures (µs from time 0, `[begin, end]` per frame) reach outside the recording's
/// events: those times are no evidence, and the scene's `events_recorded_s` keeps the losses off
/// them (`scene::Scene::event_evidence_span`).
fn note_exposures_outside_events(split: &SplitEvents, exposure_us: &[(i64, i64)]) {
    let Some((first, last)) = split.recorded_us else {
        eprintln!("note: the recording holds no events: the scene's frames have empty event files");
        return;
    };
    for (k, &(begin, end)) in exposure_us.iter().enumerate() {
        if begin < first || end > last {
            eprintln!(
                "note: frame {k}'s exposure [{begin}, {end}] µs reaches outside the recording's \
                 events [{first}, {last}] µs: no loss reads events there"
            );
        }
    }
}

/// Streams the recording's events into `out/events/NNNNNN.npz` by the scene format's rule
/// (`scene::Scene::event_file_span`): frame `k` holds `[mid_k, mid_{k+1})` (µs from `t0`), the
/// last frame every later event; events before the first frame and after `last_end_us` (the last
/// exposure's end) are counted.
fn split_events(
    file: &Path,
    out: &Path,
    t0: i64,
    mid_us: &[i64],
    last_end_us: i64,
    (w, h): (u32, u32),
) -> Result<SplitEvents> {
    let mut reader = events::io::aedat4::Aedat4Reader::open(file)
        .with_context(|| format!("reading the events of {}", file.display()))?;
    let sensor = events::SensorSize::new(w, h);
    let mut bucket = events::EventStream::new();
    bucket.sensor = Some(sensor);
    let (mut k, mut written, mut before) = (0usize, 0u64, 0u64);
    let mut recorded = None;
    let mut after_last_exposure = 0u64;
    let flush = |k: usize, b: &mut events::EventStream| -> Result<u64> {
        let p = out.join(format!("events/{k:06}.npz"));
        events::write_events(&p, b).with_context(|| format!("writing {}", p.display()))?;
        let n = b.len() as u64;
        *b = events::EventStream::new();
        b.sensor = Some(sensor);
        Ok(n)
    };
    let mut chunk = events::EventStream::new();
    loop {
        chunk.clear();
        let got = reader
            .read_chunk(&mut chunk, 1 << 20)
            .with_context(|| format!("reading the events of {}", file.display()))?;
        if got == 0 {
            break;
        }
        for i in 0..chunk.len() {
            let t = chunk.t[i] - t0;
            recorded = Some(recorded.map_or((t, t), |(a, b): (i64, i64)| (a.min(t), b.max(t))));
            after_last_exposure += u64::from(t > last_end_us);
            if t < mid_us[0] {
                before += 1;
                continue;
            }
            if chunk.x[i] as u32 >= w || chunk.y[i] as u32 >= h {
                bail!(
                    "{}: event at ({}, {}) lies outside the {w}x{h} frames",
                    file.display(),
                    chunk.x[i],
                    chunk.y[i]
                );
            }
            while k + 1 < mid_us.len() && t >= mid_us[k + 1] {
                written += flush(k, &mut bucket)?;
                k += 1;
            }
            bucket.push(events::Event {
                t,
                x: chunk.x[i],
                y: chunk.y[i],
                p: chunk.p[i],
            });
        }
    }
    while k < mid_us.len() {
        written += flush(k, &mut bucket)?;
        k += 1;
    }
    Ok(SplitEvents {
        written,
        before,
        recorded_us: recorded,
        after_last_exposure,
    })
}
