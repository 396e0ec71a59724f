//! `cargo xtask synth`: generate the synthetic motion-blur benchmark (scene format v1) with a
//! progress bar, then print the statistics. All the work is in the `synth` crate.

use anyhow::{Context, Result};
use std::path::PathBuf;
use std::time::Instant;

/// Preset names of the command line.
#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum PresetArg {
    /// 15 frames at 64×64, S = 8 (the checked-in fixture).
    Tiny,
    /// 100 frames at 256×256, S = 16 (the benchmark).
    Default,
    /// 400 frames at 256×256, S = 16.
    Paper,
    /// The default benchmark with estimated poses in scene.json, a VIBE/ROMP/PARE-class monocular
    /// fitter's error on 3DPW: 16° RMS per body joint, 6° root orientation, 8 cm root translation
    /// (sources and reasoning: synth::PoseError::REALISTIC, docs/FORMATS.md).
    Realistic,
}

impl PresetArg {
    /// The generator's preset of this name.
    pub fn preset(self) -> ::synth::Preset {
        match self {
            PresetArg::Tiny => ::synth::Preset::Tiny,
            PresetArg::Default => ::synth::Preset::Default,
            PresetArg::Paper => ::synth::Preset::Paper,
            PresetArg::Realistic => ::synth::Preset::Realistic,
        }
    }
}

/// Motion speed names of the command line.
#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum SpeedArg {
    /// Angular frequencies ×1.5 of the base motion (arm sweep 1.35 Hz).
    Slow,
    /// Angular frequencies ×3.
    Medium,
    /// Angular frequencies ×6 (arm sweep 5.4 Hz; the presets' speed).
    Fast,
}

/// Camera motions of the command line.
#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum CameraMotionArg {
    /// Bolted down for the whole clip (the presets'; scene format version 1).
    Static,
    /// Held in a hand: a smooth drift of a few centimetres and about a degree, and an 8-12 Hz
    /// tremor that moves the camera inside each exposure, so the room blurs too.
    Handheld,
    /// A slow arc around the person (6° per second).
    Orbit,
}

/// Arguments of `synth`. Knobs not given take the preset's value.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Output directory (created; existing files are overwritten).
    #[arg(long)]
    pub out: PathBuf,
    /// Settings to start from.
    #[arg(long, value_enum, default_value = "default")]
    pub preset: PresetArg,
    /// Seed of the motion phases and the event noise.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Number of frames (>= 2).
    #[arg(long)]
    pub frames: Option<u32>,
    /// Image width in pixels (16..=8192).
    #[arg(long)]
    pub width: Option<u32>,
    /// Image height in pixels (16..=8192).
    #[arg(long)]
    pub height: Option<u32>,
    /// Sub-frames per exposure S (1..=256).
    #[arg(long)]
    pub subframes: Option<u32>,
    /// Supersampling per axis (odd, 1..=7).
    #[arg(long)]
    pub supersample: Option<u32>,
    /// Motion speed.
    #[arg(long, value_enum)]
    pub speed: Option<SpeedArg>,
    /// Seed of the textures and prop placement.
    #[arg(long)]
    pub texture_seed: Option<u64>,
    /// Camera distance from the person (metres).
    #[arg(long)]
    pub camera_distance: Option<f32>,
    /// Camera height above the floor (metres).
    #[arg(long)]
    pub camera_height: Option<f32>,
    /// Frames per second.
    #[arg(long)]
    pub fps: Option<f64>,
    /// Exposure as a fraction of the frame interval (0, 1].
    #[arg(long)]
    pub exposure_fraction: Option<f64>,
    /// Event contrast threshold C+ (log intensity; also C− unless --event-threshold-neg is given).
    #[arg(long)]
    pub event_threshold: Option<f32>,
    /// Negative contrast threshold C− when it differs from C+ (log intensity, a positive number;
    /// real sensors' do). Default: C− = C+.
    #[arg(long)]
    pub event_threshold_neg: Option<f32>,
    /// Per-pixel threshold noise σ (log intensity).
    #[arg(long)]
    pub event_sigma: Option<f32>,
    /// Event refractory period (microseconds; the presets' 1000, as a DAVIS pixel's). A crossing
    /// closer than this to the pixel's previous event is dropped and its reference still moves.
    #[arg(long)]
    pub refractory_us: Option<i64>,
    /// Background-activity noise per pixel (events per second, random polarity; a DAVIS346 shows
    /// about 0.1 in daylight). Default 0.
    #[arg(long, value_name = "HZ")]
    pub background_rate_hz: Option<f64>,
    /// Fraction of hot pixels, each firing one polarity at --hot-pixel-rate-hz whatever the scene
    /// does (real sensors have about 1e-4 to 1e-3). Default 0.
    #[arg(long)]
    pub hot_pixel_fraction: Option<f64>,
    /// Event rate of each hot pixel (events per second). Default 200.
    #[arg(long, value_name = "HZ")]
    pub hot_pixel_rate_hz: Option<f64>,
    /// Estimate event-only flow by contrast maximisation (`events_cm` flows): true or false.
    #[arg(long)]
    pub event_flow: Option<bool>,
    /// Body model (`builtin:makehuman` or an SMPL .npz path).
    #[arg(long)]
    pub body: Option<String>,
    /// Write estimated poses to scene.json, as a monocular SMPL fitter's: DEG is the RMS, over body
    /// joints 1..=23 and frames, of the geodesic angle between the written and the true local joint
    /// rotation (degrees, 0..=30), a smooth drift plus 10 % jitter, larger at wrists, hands, ankles,
    /// feet and head than at the spine. The root orientation and translation errors follow in the
    /// `realistic` preset's proportion (DEG 16 = 6° and 8 cm) unless given below. The truth goes to
    /// poses_true.json (for evaluation; the trainer never reads it); images, masks, events and flows
    /// are unchanged. 0 = exact poses (the default).
    #[arg(long, value_name = "DEG", allow_negative_numbers = true)]
    pub pose_error: Option<f32>,
    /// RMS over frames of the root (global) orientation error (degrees, 0..=30); overrides the
    /// share set by --pose-error or the preset.
    #[arg(long, value_name = "DEG", allow_negative_numbers = true)]
    pub root_orient_error: Option<f32>,
    /// RMS over frames of the root translation error's length (cm, 0..=50), mostly along the
    /// camera ray (depth); overrides the share set by --pose-error or the preset.
    #[arg(long, value_name = "CM", allow_negative_numbers = true)]
    pub root_transl_error: Option<f32>,
    /// How the camera moves. A moving camera is rendered from its pose at every sub-frame time
    /// (its motion blurs the room and fires events on the room's edges), and each frame's camera
    /// pose at mid exposure is written to scene.json (scene format version 2).
    #[arg(long, value_enum)]
    pub camera_motion: Option<CameraMotionArg>,
    /// Write camera poses with a SLAM-like error: RMS rotation error over the frames (degrees,
    /// 0..=30), a slow drift plus 10 % jitter; the true poses go to cameras_true.json (for
    /// evaluation; the trainer never reads it). Images, events and flows are unchanged.
    #[arg(long, value_name = "DEG")]
    pub camera_error_deg: Option<f64>,
    /// RMS error of the written camera centres (cm, 0..=100); see --camera-error-deg.
    #[arg(long, value_name = "CM")]
    pub camera_error_cm: Option<f64>,
    /// People in the scene (1..=4): the first dances on the spot as in the one-person benchmark,
    /// the others, each in its own clothes and motion, cross the room in front of and behind it
    /// so that they occlude each other. With more than one, scene.json lists every person's pose
    /// per frame and person_ids/ holds which person each pixel shows (scene format version 3).
    #[arg(long, value_name = "N")]
    pub people: Option<u32>,
}

/// Builds the generator settings from the preset and the flags.
pub fn config(args: &Args) -> ::synth::SynthConfig {
    let mut c = ::synth::SynthConfig::preset(args.preset.preset());
    macro_rules! set {
        ($($f:ident),*) => { $( if let Some(v) = args.$f.clone() { c.$f = v; } )* };
    }
    set!(
        seed,
        frames,
        width,
        height,
        subframes,
        supersample,
        texture_seed,
        camera_distance,
        camera_height,
        fps,
        exposure_fraction,
        event_threshold,
        event_sigma,
        refractory_us,
        background_rate_hz,
        hot_pixel_fraction,
        hot_pixel_rate_hz,
        event_flow,
        body,
        camera_error_deg,
        camera_error_cm,
        people
    );
    if let Some(neg) = args.event_threshold_neg {
        c.event_threshold_neg = Some(neg);
    }
    if let Some(s) = args.speed {
        c.speed = match s {
            SpeedArg::Slow => ::synth::Speed::Slow,
            SpeedArg::Medium => ::synth::Speed::Medium,
            SpeedArg::Fast => ::synth::Speed::Fast,
        };
    }
    if let Some(m) = args.camera_motion {
        c.camera_motion = match m {
            CameraMotionArg::Static => ::synth::CameraMotion::Static,
            CameraMotionArg::Handheld => ::synth::CameraMotion::Handheld,
            CameraMotionArg::Orbit => ::synth::CameraMotion::Orbit,
        };
    }
    if let Some(deg) = args.pose_error {
        c.pose_error = ::synth::PoseError::scaled_realistic(deg);
    }
    if let Some(deg) = args.root_orient_error {
        c.pose_error.root_orient_rms_deg = deg;
    }
    if let Some(cm) = args.root_transl_error {
        c.pose_error.root_transl_rms_cm = cm;
    }
    c
}

/// Runs `synth`.
pub fn run(args: Args) -> Result<()> {
    let cfg = config(&args);
    cfg.validate().context("refusing the settings")?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    crate::common::remove_stamp(&args.out)?;
    let bar = crate::common::progress_bar(u64::from(cfg.frames), "synth frames")?;
    let start = Instant::now();
    let stats = ::synth::generate(&cfg, &args.out, &mut |done, _| {
        bar.set_position(u64::from(done))
    })
    .with_context(|| format!("generating the benchmark into {}", args.out.display()))?;
    bar.finish_and_clear();
    // The stamp `reconstruct` and `ablate` check, so that a benchmark generated here under
    // target/benchmark/<preset> with a preset's settings is not generated again by them.
    crate::common::write_stamp(&args.out, &cfg)?;
    let secs = start.elapsed().as_secs_f64();
    let p = &stats.psnr_blurred_vs_sharp;
    let f = &stats.flow;
    println!(
        "wrote {} ({} frames {}x{}, S={}, speed {}) in {secs:.1} s with {} threads",
        args.out.display(),
        cfg.frames,
        cfg.width,
        cfg.height,
        cfg.subframes,
        cfg.speed.as_str(),
        rayon_threads(),
    );
    println!(
        "blurred vs sharp PSNR: full {:.2} dB, human box {:.2} dB (min {:.2}), outside box {:.2} dB",
        p.full_frame_db, p.human_box_db, p.human_box_min_db, p.outside_human_box_db
    );
    if !stats.person_box_db.is_empty() {
        let boxes: Vec<String> = stats
            .person_box_db
            .iter()
            .enumerate()
            .map(|(p, db)| format!("person {p} {db:.2} dB"))
            .collect();
        println!(
            "blurred vs sharp PSNR in each person's own box: {}",
            boxes.join(", ")
        );
    }
    println!(
        "GT flow: valid {:.1}%, > 1 px {:.1}% of pixels ({:.1}% of human pixels), human mean {:.2} px, max {:.1} px",
        100.0 * f.valid_fraction,
        100.0 * f.fraction_above_1px,
        100.0 * f.human_fraction_above_1px,
        f.human_mean_magnitude_px,
        f.max_magnitude_px
    );
    println!(
        "GT flow photometric check (sharp k vs warped sharp k+1, mean |error|, linear): {:.4} (zero flow: {:.4}); moving human pixels {:.4} (zero flow: {:.4})",
        f.warp_mae, f.identity_mae, f.moving_human_warp_mae, f.moving_human_identity_mae
    );
    println!(
        "events: {} ({} positive), {:.3} per pixel per frame",
        stats.events.count, stats.events.positive, stats.events.per_pixel_per_frame
    );
    let cm = &stats.events_cm_flow;
    if cm.computed {
        println!(
            "event-only flow (contrast maximisation) vs GT: EPE {:.2} px on valid pixels, {:.2} px on pixels moving > 1 px (zero flow: {:.2} px)",
            cm.epe_valid_px, cm.epe_moving_px, cm.zero_flow_epe_moving_px
        );
    }
    if let Some(e) = &stats.pose_error {
        println!(
            "pose error in scene.json (truth in {}): body joints mean {:.2}° RMS {:.2}° (frame-to-frame change {:.2}° RMS), root orientation mean {:.2}° RMS {:.2}°, root translation mean {:.2} cm RMS {:.2} cm; MPJPE {:.1} mm, PA-MPJPE {:.1} mm, MPJAE {:.1}°, acceleration error {:.1} mm/frame² ({:.1} on a still body)",
            ::synth::TRUE_POSES_FILE,
            e.joint_mean_deg,
            e.joint_rms_deg,
            e.joint_step_rms_deg,
            e.root_orient_mean_deg,
            e.root_orient_rms_deg,
            e.root_transl_mean_cm,
            e.root_transl_rms_cm,
            e.mpjpe_mm,
            e.pa_mpjpe_mm,
            e.mpjae_deg,
            e.accel_error_mm,
            e.accel_error_still_mm
        );
    }
    println!(
        "see {} and {}",
        args.out.join("preview.png").display(),
        args.out.join("stats.json").display()
    );
    Ok(())
}

fn rayon_threads() -> usize {
    std::env::var("RAYON_NUM_THREADS")
        .ok()
        .and_then(|v| v.parse().ok())
        .filter(|&n: &usize| n > 0)
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
}
