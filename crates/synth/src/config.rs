//! Generator settings, presets and their validation.

use serde::{Deserialize, Serialize};

use crate::camera_motion::CameraMotion;
use crate::error::{Result, SynthError};
use crate::motion::Speed;
use crate::pose_error::PoseError;

/// Largest accepted image side (pixels).
pub const MAX_SIDE: u32 = 8192;
/// Largest accepted frame count.
pub const MAX_FRAMES: u32 = 100_000;
/// Largest accepted number of sub-frames per frame.
pub const MAX_SUBFRAMES: u32 = 256;

/// Event rate of a hot pixel unless set (events per second).
pub const DEFAULT_HOT_PIXEL_RATE_HZ: f64 = 200.0;

fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

fn default_hot_pixel_rate_hz() -> f64 {
    DEFAULT_HOT_PIXEL_RATE_HZ
}

fn is_default_hot_pixel_rate(v: &f64) -> bool {
    *v == DEFAULT_HOT_PIXEL_RATE_HZ
}

/// Named settings.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Preset {
    /// 15 frames at 64×64, S = 8, no event-only flow: the checked-in test fixture (< 2 MB).
    Tiny,
    /// The benchmark: 100 frames at 256×256, S = 16.
    Default,
    /// 400 frames at 256×256, S = 16.
    Paper,
    /// [`Preset::Default`] with the SMPL parameters of `scene.json` estimated as a monocular fitter
    /// would ([`PoseError::REALISTIC`]); the renders are the default benchmark's.
    Realistic,
}

/// Every knob of the generator. Same settings, same bytes (any thread count).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SynthConfig {
    /// Seed of the motion phases and the event simulator's noise.
    pub seed: u64,
    /// Number of frames.
    pub frames: u32,
    /// Image width (pixels).
    pub width: u32,
    /// Image height (pixels).
    pub height: u32,
    /// Sub-frames rendered per exposure (S); the blurred frame is their mean.
    pub subframes: u32,
    /// Supersampling factor per axis of the renderer (odd).
    pub supersample: u32,
    /// Motion speed.
    pub speed: Speed,
    /// Seed of the room and clothing textures and of the prop placement.
    pub texture_seed: u64,
    /// Horizontal distance from the person to the camera (metres).
    pub camera_distance: f32,
    /// Camera height above the floor (metres).
    pub camera_height: f32,
    /// Frame rate (frames per second).
    pub fps: f64,
    /// Exposure as a fraction of the frame interval (0, 1].
    pub exposure_fraction: f64,
    /// Mean positive event contrast threshold C+ (log intensity); also C− unless
    /// `event_threshold_neg` is set.
    pub event_threshold: f32,
    /// Mean negative contrast threshold C− (log intensity, a positive number) when it differs from
    /// C+ (real sensors' do); unset (and not serialised): C− = C+.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub event_threshold_neg: Option<f32>,
    /// Per-pixel threshold standard deviation σ (log intensity).
    pub event_sigma: f32,
    /// Event refractory period (microseconds).
    pub refractory_us: i64,
    /// Background-activity noise: events per second per pixel, random polarity, uniform in time
    /// (a real sensor's leak and shot noise; DAVIS346 ≈ 0.1 Hz in daylight). 0 (the default, not
    /// serialised): none.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub background_rate_hz: f64,
    /// Fraction of hot pixels, each firing one polarity at `hot_pixel_rate_hz` whatever the scene
    /// does. 0 (the default, not serialised): none.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub hot_pixel_fraction: f64,
    /// Event rate of each hot pixel (events per second; 200 by default, not serialised then).
    #[serde(
        default = "default_hot_pixel_rate_hz",
        skip_serializing_if = "is_default_hot_pixel_rate"
    )]
    pub hot_pixel_rate_hz: f64,
    /// Also estimate event-only flow (contrast maximisation, `events_cm`) for every frame pair.
    pub event_flow: bool,
    /// Body model reference (`builtin:makehuman` or an SMPL `.npz` path).
    pub body: String,
    /// Error of the SMPL parameters written to `scene.json` (an estimate like a monocular fitter's;
    /// the truth goes to `poses_true.json`). Off (all zero) by default, and then not serialised, so
    /// settings without it keep their bytes. Never changes what is rendered.
    #[serde(default, skip_serializing_if = "PoseError::is_off")]
    pub pose_error: PoseError,
    /// How the camera moves ([`CameraMotion`]); static by default, and then not serialised, so
    /// settings without it keep their bytes.
    #[serde(default, skip_serializing_if = "CameraMotion::is_static")]
    pub camera_motion: CameraMotion,
    /// RMS rotation error (degrees) of the camera poses written to `scene.json`, as a SLAM
    /// estimate's (`camera_error`; the truth goes to `cameras_true.json`); 0, not serialised, by
    /// default. Never changes what is rendered.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub camera_error_deg: f64,
    /// RMS error (cm) of the written camera centres (see `camera_error_deg`).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub camera_error_cm: f64,
    /// People in the scene (1..=4, `crate::cast`): the first dances on the spot, the others cross
    /// in front of and behind it. 1 by default, and then not serialised, so settings without it
    /// keep their bytes.
    #[serde(default = "one_person", skip_serializing_if = "is_one_person")]
    pub people: u32,
}

fn one_person() -> u32 {
    1
}

fn is_one_person(v: &u32) -> bool {
    *v == 1
}

impl SynthConfig {
    /// The settings of a preset.
    pub fn preset(p: Preset) -> Self {
        let base = Self {
            seed: 0,
            frames: 100,
            width: 256,
            height: 256,
            subframes: 16,
            supersample: 3,
            speed: Speed::Fast,
            texture_seed: 0,
            camera_distance: 2.6,
            camera_height: 1.3,
            fps: 30.0,
            exposure_fraction: 1.0,
            event_threshold: 0.2,
            event_sigma: 0.03,
            refractory_us: 1000,
            event_threshold_neg: None,
            background_rate_hz: 0.0,
            hot_pixel_fraction: 0.0,
            hot_pixel_rate_hz: DEFAULT_HOT_PIXEL_RATE_HZ,
            event_flow: true,
            body: "builtin:makehuman".into(),
            pose_error: PoseError::OFF,
            camera_motion: CameraMotion::Static,
            camera_error_deg: 0.0,
            camera_error_cm: 0.0,
            people: 1,
        };
        match p {
            Preset::Tiny => Self {
                frames: 15,
                width: 64,
                height: 64,
                subframes: 8,
                // Keeps the fixture under 2 MB and its regeneration test fast; the event-only
                // flow path is exercised by the synth tests.
                event_flow: false,
                ..base
            },
            Preset::Default => base,
            Preset::Paper => Self {
                frames: 400,
                ..base
            },
            Preset::Realistic => Self {
                pose_error: PoseError::REALISTIC,
                ..base
            },
        }
    }

    /// Refuses settings out of range, naming the knob and the accepted range.
    pub fn validate(&self) -> Result<()> {
        let knob = |knob: &'static str, value: String, reason: &str| {
            Err(SynthError::Knob {
                knob,
                value,
                reason: reason.into(),
            })
        };
        if self.frames < 2 || self.frames > MAX_FRAMES {
            return knob(
                "frames",
                self.frames.to_string(),
                "must be in 2..=100000 (flow needs a next frame)",
            );
        }
        for (name, v) in [("width", self.width), ("height", self.height)] {
            if !(16..=MAX_SIDE).contains(&v) {
                return knob(name, v.to_string(), "must be in 16..=8192 pixels");
            }
        }
        if self.subframes == 0 || self.subframes > MAX_SUBFRAMES {
            return knob(
                "subframes",
                self.subframes.to_string(),
                "must be in 1..=256",
            );
        }
        if self.supersample.is_multiple_of(2) || self.supersample > 7 {
            return knob(
                "supersample",
                self.supersample.to_string(),
                "must be odd, 1..=7",
            );
        }
        if !(self.camera_distance.is_finite() && (1.0..=5.5).contains(&self.camera_distance)) {
            return knob(
                "camera-distance",
                self.camera_distance.to_string(),
                "must be in 1.0..=5.5 metres (the room ends at 6 m)",
            );
        }
        if !(self.camera_height.is_finite() && (0.2..=2.6).contains(&self.camera_height)) {
            return knob(
                "camera-height",
                self.camera_height.to_string(),
                "must be in 0.2..=2.6 metres (walls are 2.8 m high)",
            );
        }
        if !(self.fps.is_finite() && (1.0..=1000.0).contains(&self.fps)) {
            return knob("fps", self.fps.to_string(), "must be in 1..=1000");
        }
        if !(self.exposure_fraction.is_finite()
            && self.exposure_fraction > 0.0
            && self.exposure_fraction <= 1.0)
        {
            return knob(
                "exposure-fraction",
                self.exposure_fraction.to_string(),
                "must be in (0, 1]",
            );
        }
        // Sub-frame timestamps (integer microseconds) must strictly increase.
        let spacing_us = 1e6 * self.exposure_fraction / self.fps / f64::from(self.subframes);
        if spacing_us < 4.0 {
            return knob(
                "subframes",
                self.subframes.to_string(),
                "sub-frames closer than 4 µs apart: lower subframes or fps",
            );
        }
        if !(self.event_threshold.is_finite()
            && self.event_threshold > 0.0
            && self.event_threshold < 10.0)
        {
            return knob(
                "event-threshold",
                self.event_threshold.to_string(),
                "must be in (0, 10)",
            );
        }
        if !(self.event_sigma.is_finite() && self.event_sigma >= 0.0 && self.event_sigma < 1.0) {
            return knob(
                "event-sigma",
                self.event_sigma.to_string(),
                "must be in [0, 1)",
            );
        }
        if let Some(c) = self.event_threshold_neg {
            if !(c.is_finite() && c > 0.0 && c < 10.0) {
                return knob("event-threshold-neg", c.to_string(), "must be in (0, 10)");
            }
        }
        if self.refractory_us < 0 {
            return knob(
                "refractory-us",
                self.refractory_us.to_string(),
                "must be >= 0",
            );
        }
        if !(self.background_rate_hz.is_finite() && (0.0..=1e4).contains(&self.background_rate_hz))
        {
            return knob(
                "background-rate-hz",
                self.background_rate_hz.to_string(),
                "must be in [0, 10000] events per second per pixel",
            );
        }
        if !(self.hot_pixel_fraction.is_finite() && (0.0..0.5).contains(&self.hot_pixel_fraction)) {
            return knob(
                "hot-pixel-fraction",
                self.hot_pixel_fraction.to_string(),
                "must be in [0, 0.5)",
            );
        }
        if !(self.hot_pixel_rate_hz.is_finite()
            && self.hot_pixel_rate_hz > 0.0
            && self.hot_pixel_rate_hz <= 1e5)
        {
            return knob(
                "hot-pixel-rate-hz",
                self.hot_pixel_rate_hz.to_string(),
                "must be in (0, 100000] events per second",
            );
        }
        if !(self.camera_error_deg.is_finite() && (0.0..=30.0).contains(&self.camera_error_deg)) {
            return knob(
                "camera-error-deg",
                self.camera_error_deg.to_string(),
                "must be in [0, 30] degrees",
            );
        }
        if !(self.camera_error_cm.is_finite() && (0.0..=100.0).contains(&self.camera_error_cm)) {
            return knob(
                "camera-error-cm",
                self.camera_error_cm.to_string(),
                "must be in [0, 100] cm",
            );
        }
        if !(1..=crate::cast::MAX_PEOPLE).contains(&self.people) {
            return knob("people", self.people.to_string(), "must be in 1..=4");
        }
        if self.people > 1 && !self.pose_error.is_off() {
            return knob(
                "people",
                self.people.to_string(),
                "a pose error is simulated for one person only (drop --pose-error or the realistic preset)",
            );
        }
        self.pose_error.validate()
    }

    /// True when the written camera poses carry an estimation error.
    pub fn camera_error_on(&self) -> bool {
        self.camera_error_deg > 0.0 || self.camera_error_cm > 0.0
    }
}
