//! A scene (format v1) from a user's frames and SMPL fits: what the paper synthesised for
//! ZJU-MoCap-Blur, for users without an event camera or without blurred video.
//!
//! Input frame `i` (linear RGB, one SMPL pose each) is taken at `t_i = i / fps`. With `blur = K`
//! (odd), output frame `j` is the mean in linear intensity of the `K` consecutive input frames
//! `jK … jK + K − 1` (non-overlapping windows; frames left over at the end are dropped): a box
//! exposure of `K / fps` centred on the window's middle frame `c = jK + (K − 1)/2`, whose image is
//! kept as the sharp reference, whose pose and mask are the frame's, and whose time is the frame's
//! `time_s = t_c`. The output frame rate is `fps / K` and `exposure_s = K / fps` (the shutter open
//! the whole frame). With `K = 1` the frames are the observations as they are (no sharp
//! references) and `exposure_s` is the camera's, as given.
//!
//! Events (optional) are simulated by ESIM ([`events::EventSimulator`]) over every input frame in
//! order — between two frames the simulator interpolates log intensity linearly, the same
//! assumption its use in the benchmark makes — and written per output frame for `t ∈ [time_s,
//! next time_s)` (the last frame: every later event), microseconds from `t_0 = 0`. Events before
//! the first output frame's time belong to no frame (the trainer then has no event supervision for
//! the first half of frame 0's exposure) and are dropped and counted. With `in_between = M`, M
//! frames interpolated between each pair of consecutive input frames (by a function the caller
//! gives, e.g. the project's flow network through `flow::interpolate`: what the paper did to make
//! its averages smoother) join the event simulation at their times and, inside a window, its mean
//! (then of `K + (K − 1) M` frames).
//!
//! The split is the benchmark's: output frames `j mod 10 < 7` train, the rest test.
//!
//! Frames are streamed (one input frame and one window sum in memory), so a long video fits.

use std::path::Path;

use scene::{BodySpec, Camera, FlowRef, Frame, ImageEncoding, Scene, Split, Transfer};

use crate::error::{Result, SynthError};

/// How a sequence of frames becomes a scene.
#[derive(Clone, Debug, PartialEq)]
pub struct FramesToScene {
    /// Frame rate of the input frames (frames per second).
    pub fps: f64,
    /// `K`: consecutive input frames averaged into one observed frame (odd; 1 = no blur added).
    pub blur: usize,
    /// Exposure of each frame (seconds) when `blur = 1`; `None` = `1 / fps`. Must be `None` when
    /// `blur > 1` (the exposure is then `K / fps`).
    pub exposure_s: Option<f64>,
    /// Simulate events with this configuration; `None` = no events.
    pub events: Option<events::EsimConfig>,
    /// `M`: frames interpolated between each pair of consecutive input frames (0 = none), by the
    /// `between` function given to [`write_scene_from_frames`]; they join the blur windows' means
    /// and the event simulation, as the paper's ZJU-MoCap-Blur construction did.
    pub in_between: usize,
    /// Encoding of the written images (the benchmark's: 16-bit sRGB).
    pub encoding: ImageEncoding,
}

impl Default for FramesToScene {
    /// 30 fps, no blur added, exposure `1 / fps`, no events, no in-between frames, 16-bit sRGB
    /// images.
    fn default() -> Self {
        Self {
            fps: 30.0,
            blur: 1,
            exposure_s: None,
            events: None,
            in_between: 0,
            encoding: ImageEncoding::rgb(16, Transfer::Srgb),
        }
    }
}

/// One input frame.
#[derive(Clone, Debug)]
pub struct InputFrame {
    /// Linear RGB, planar `(3, H, W)`, camera size.
    pub rgb: Vec<f32>,
    /// Optional human mask (row-major `H × W`, `true` = human).
    pub mask: Option<Vec<bool>>,
    /// SMPL pose: 24 axis-angle triples (radians), joint 0 the global orientation, in the
    /// camera's world frame.
    pub pose: Vec<[f32; 3]>,
    /// SMPL translation (metres, camera's world frame).
    pub transl: [f32; 3],
    /// The other people's poses at this frame, in the order of `write_scene_from_frames`'s
    /// `people` (empty with one person).
    pub people: Vec<scene::PersonPose>,
    /// The camera's pose at this frame when the camera moves (`world_to_camera`, rigid 4×4);
    /// `None` = the scene camera's. A written frame takes the pose of the input frame at the
    /// middle of its blur window.
    pub world_to_camera: Option<[[f64; 4]; 4]>,
}

/// Makes the frames at times `ts` (each in `(0, 1)`) between consecutive frames `a` and `b`
/// (planar linear RGB, camera size), in order; e.g. from optical flow (`flow::interpolate`).
pub type Between<'a> = dyn FnMut(&[f32], &[f32], &[f32]) -> Result<Vec<Vec<f32>>> + 'a;

/// What [`write_scene_from_frames`] wrote.
#[derive(Clone, Debug, PartialEq)]
pub struct FramesReport {
    /// Output frames written.
    pub frames: usize,
    /// Input frames left over after the last whole window (not used).
    pub dropped_frames: usize,
    /// Events written (all frames).
    pub events: usize,
    /// Simulated events before the first output frame's time (belonging to no frame, not written).
    pub events_before_first_frame: usize,
}

fn bad(knob: &'static str, value: impl ToString, reason: impl Into<String>) -> SynthError {
    SynthError::Knob {
        knob,
        value: value.to_string(),
        reason: reason.into(),
    }
}

impl FramesToScene {
    /// Checks the settings; `count` is the number of input frames.
    pub fn check(&self, count: usize) -> Result<()> {
        if !(self.fps.is_finite() && self.fps > 0.0 && self.fps <= 100_000.0) {
            return Err(bad("fps", self.fps, "must be in (0, 100000]"));
        }
        if self.blur.is_multiple_of(2) {
            return Err(bad(
                "blur",
                self.blur,
                "must be odd (the middle frame of each window is the sharp reference)",
            ));
        }
        if count < self.blur {
            return Err(bad(
                "blur",
                self.blur,
                format!("needs at least {} frames, {count} given", self.blur),
            ));
        }
        match (self.blur, self.exposure_s) {
            (1, Some(e)) if !(e.is_finite() && e > 0.0 && e <= 1.0 / self.fps) => Err(bad(
                "exposure_s",
                e,
                format!("must be in (0, 1/fps = {:.6}] s", 1.0 / self.fps),
            )),
            (k, Some(_)) if k > 1 => Err(bad(
                "exposure_s",
                "given",
                "with blur K > 1 the exposure is K / fps and cannot be given",
            )),
            _ => Ok(()),
        }
    }

    /// The output frames' exposure (seconds).
    pub fn exposure(&self) -> f64 {
        if self.blur > 1 {
            self.blur as f64 / self.fps
        } else {
            self.exposure_s.unwrap_or(1.0 / self.fps)
        }
    }
}

/// The time of input frame `i` in microseconds (`i / fps`, rounded).
fn input_time_us(i: usize, fps: f64) -> i64 {
    (i as f64 * 1e6 / fps).round() as i64
}

/// Writes a scene to `out` from `count` input frames, loading frame `i` with `load(i)` in order
/// (each exactly once) and calling `progress(i)` after each. With `cfg.in_between = M > 0`,
/// `between` makes the M frames at `t = m / (M + 1)` between consecutive frames ([`Between`]);
/// they join the events and, inside a window, its mean. `camera`, `body` and the further
/// `people` (format 3; each frame's `InputFrame::people` poses them) go into `scene.json` as given;
/// `generator` is recorded there. Returns what was written; the scene is
/// validated by [`scene::load`] before returning.
pub fn write_scene_from_frames(
    out: &Path,
    camera: Camera,
    body: BodySpec,
    people: &[scene::PersonSpec],
    count: usize,
    cfg: &FramesToScene,
    generator: serde_json::Value,
    mut load: impl FnMut(usize) -> Result<InputFrame>,
    mut between: Option<&mut Between<'_>>,
    mut progress: impl FnMut(usize),
) -> Result<FramesReport> {
    cfg.check(count)?;
    if cfg.in_between > 0 && between.is_none() {
        return Err(bad(
            "in_between",
            cfg.in_between,
            "in-between frames need an interpolation function",
        ));
    }
    let (w, h) = (camera.width as usize, camera.height as usize);
    let n = w * h;
    let k = cfg.blur;
    let half = (k - 1) / 2;
    let outputs = count / k;
    for sub in ["images", "sharp", "masks", "events"] {
        let dir = out.join(sub);
        std::fs::create_dir_all(&dir).map_err(|source| SynthError::Io { path: dir, source })?;
    }
    let mut sim = match cfg.events {
        Some(c) => Some(events::EventSimulator::new(c, w, h)?),
        None => None,
    };
    let sensor = events::SensorSize::new(camera.width, camera.height);
    let mut report = FramesReport {
        frames: outputs,
        dropped_frames: count - outputs * k,
        events: 0,
        events_before_first_frame: 0,
    };
    let time_of = |j: usize| input_time_us(j * k + half, cfg.fps);
    let mut frames: Vec<Frame> = Vec::with_capacity(outputs);
    let mut sum = vec![0.0f64; 3 * n];
    let mut splitter = EventSplitter {
        out,
        sensor,
        starts_us: (0..outputs).map(time_of).collect(),
        frame: None,
        bucket: events::EventStream::new(),
    };
    let (mut samples, mut prev): (usize, Option<Vec<f32>>) = (0, None);
    for i in 0..outputs * k {
        let frame = load(i)?;
        if frame.rgb.len() != 3 * n {
            return Err(bad(
                "frame",
                i,
                format!("{} values, expected a {w}x{h} RGB image", frame.rgb.len()),
            ));
        }
        let (j, slot) = (i / k, i % k);
        // The in-between frames from the previous frame to this one: events, and the window's
        // mean when both frames are in it.
        if let (Some(prev_rgb), Some(between)) = (&prev, between.as_mut()) {
            let ts: Vec<f32> = (1..=cfg.in_between)
                .map(|m| m as f32 / (cfg.in_between + 1) as f32)
                .collect();
            let mids = between(prev_rgb, &frame.rgb, &ts)?;
            if mids.len() != ts.len() || mids.iter().any(|m| m.len() != 3 * n) {
                return Err(bad(
                    "in_between",
                    cfg.in_between,
                    "the interpolation returned frames of the wrong number or size",
                ));
            }
            for (&t, mid) in ts.iter().zip(&mids) {
                let t_us = ((i as f64 - 1.0 + f64::from(t)) * 1e6 / cfg.fps).round() as i64;
                splitter.add(&mut sim, t_us, mid, w, h, &mut report)?;
                if slot > 0 {
                    for (s, &v) in sum.iter_mut().zip(mid) {
                        *s += f64::from(v);
                    }
                    samples += 1;
                }
            }
        }
        splitter.add(
            &mut sim,
            input_time_us(i, cfg.fps),
            &frame.rgb,
            w,
            h,
            &mut report,
        )?;
        for (s, &v) in sum.iter_mut().zip(&frame.rgb) {
            *s += f64::from(v);
        }
        samples += 1;
        if slot == half {
            let mut f = Frame {
                people: frame.people.clone(),
                person_ids: None,
                index: j as u32,
                time_s: time_of(j) as f64 * 1e-6,
                exposure_s: None,
                world_to_camera: frame.world_to_camera,
                image: format!("images/{j:06}.png"),
                sharp: None,
                mask: None,
                pose: frame.pose.clone(),
                transl: frame.transl,
                flow_to_next: Vec::<FlowRef>::new(),
                events: cfg.events.map(|_| format!("events/{j:06}.npz")),
                split: if j % 10 < 7 {
                    Split::Train
                } else {
                    Split::Test
                },
            };
            if k > 1 {
                let rel = format!("sharp/{j:06}.png");
                write_rgb(out, &rel, &frame.rgb, &camera, cfg.encoding)?;
                f.sharp = Some(rel);
            }
            if let Some(mask) = &frame.mask {
                let rel = format!("masks/{j:06}.png");
                let p = out.join(&rel);
                scene::image_io::write_mask(&p, camera.width, camera.height, mask)?;
                f.mask = Some(rel);
            }
            frames.push(f);
        }
        if slot + 1 == k {
            let mean: Vec<f32> = sum.iter().map(|&s| (s / samples as f64) as f32).collect();
            write_rgb(
                out,
                &format!("images/{j:06}.png"),
                &mean,
                &camera,
                cfg.encoding,
            )?;
            sum.iter_mut().for_each(|s| *s = 0.0);
            samples = 0;
        }
        prev = (cfg.in_between > 0).then_some(frame.rgb);
        progress(i);
    }
    if cfg.events.is_some() {
        splitter.finish(&mut report)?;
    }
    let mut scene = Scene {
        people: people.to_vec(),
        format_version: scene::FORMAT_VERSION,
        camera,
        body,
        fps: cfg.fps / k as f64,
        exposure_s: cfg.exposure(),
        images: cfg.encoding,
        frames,
        events_raw_format: None,
        events_recorded_s: None,
        generator: Some(generator),
    };
    scene.format_version = scene.format_version_needed();
    scene.write(out)?;
    scene::load(out)?;
    Ok(report)
}

fn write_rgb(
    out: &Path,
    rel: &str,
    rgb: &[f32],
    camera: &Camera,
    enc: ImageEncoding,
) -> Result<()> {
    let img = scene::Rgb {
        width: camera.width,
        height: camera.height,
        data: rgb.to_vec(),
    };
    Ok(scene::write_rgb(&out.join(rel), &img, enc)?)
}

/// Splits simulated events into the output frames' files: frame `j` holds `[starts_us[j],
/// starts_us[j + 1])`, the last frame every later event; events before the first start are counted,
/// not written.
struct EventSplitter<'a> {
    out: &'a Path,
    sensor: events::SensorSize,
    starts_us: Vec<i64>,
    /// The frame whose events are being gathered (`None` before the first frame's time).
    frame: Option<usize>,
    bucket: events::EventStream,
}

impl EventSplitter<'_> {
    /// Simulates the events up to the frame `rgb` at `t_us` (nothing without a simulator) and
    /// files them.
    fn add(
        &mut self,
        sim: &mut Option<events::EventSimulator>,
        t_us: i64,
        rgb: &[f32],
        w: usize,
        h: usize,
        report: &mut FramesReport,
    ) -> Result<()> {
        let Some(sim) = sim.as_mut() else {
            return Ok(());
        };
        let grey = events::simulate::grey_from_rgb(rgb, w, h)?;
        let evs = sim.add_frame(t_us, &grey)?;
        for e in 0..evs.len() {
            let te = evs.t[e];
            // Move to the frame whose interval holds `te`.
            while let Some(next) = self
                .frame
                .map_or(Some(0), |b| (b + 1 < self.starts_us.len()).then_some(b + 1))
            {
                if te < self.starts_us[next] {
                    break;
                }
                if let Some(b) = self.frame {
                    self.flush(b, report)?;
                }
                self.frame = Some(next);
            }
            if self.frame.is_none() {
                report.events_before_first_frame += 1;
                continue;
            }
            self.bucket.push(events::Event {
                t: te,
                x: evs.x[e],
                y: evs.y[e],
                p: evs.p[e],
            });
        }
        Ok(())
    }

    fn flush(&mut self, j: usize, report: &mut FramesReport) -> Result<()> {
        let p = self.out.join(format!("events/{j:06}.npz"));
        self.bucket.sensor = Some(self.sensor);
        events::write_events(&p, &self.bucket)?;
        report.events += self.bucket.len();
        self.bucket = events::EventStream::new();
        Ok(())
    }

    /// Writes the frame being gathered and an empty file for every later frame.
    fn finish(&mut self, report: &mut FramesReport) -> Result<()> {
        let first_unwritten = match self.frame {
            Some(b) => {
                self.flush(b, report)?;
                b + 1
            }
            None => 0,
        };
        for j in first_unwritten..self.starts_us.len() {
            self.flush(j, report)?;
        }
        Ok(())
    }
}
