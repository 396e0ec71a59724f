//! How the benchmark's camera moves over the clip: bolted down (the default), handheld, or on a
//! slow orbit around the person. A moving camera is rendered from its pose at every sub-frame
//! time, so its own motion blurs the room and fires events on every edge it moves.
//!
//! **Handheld**: the camera's centre and aim point follow smooth random paths (three sinusoids
//! per axis between 0.15 and 0.8 Hz, random phases from the seed; a few centimetres, and about a
//! degree of aim) plus a physiological tremor (one sinusoid per axis between 8 and 12 Hz, about
//! 0.2°). **Orbit**: the centre turns about the vertical axis through the aim point at a constant
//! rate, `ORBIT_DEG_PER_S`, starting from the static camera's pose at time 0.

use glam::Vec3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::camera::PinholeCamera;

/// The camera's motion over the clip.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CameraMotion {
    /// Fixed for the whole clip (the default; the scene is written in format version 1).
    #[default]
    Static,
    /// A hand holding the camera: slow drift and tremor.
    Handheld,
    /// A slow arc around the person.
    Orbit,
}

impl CameraMotion {
    /// True for [`CameraMotion::Static`] (not serialised, so settings without a motion keep their
    /// bytes).
    pub fn is_static(&self) -> bool {
        *self == Self::Static
    }
}

/// RMS amplitude of the handheld drift of the camera centre, per axis (metres).
pub const DRIFT_CM: f32 = 2.0;
/// RMS amplitude of the handheld drift of the aim point, per axis (metres; at the benchmark's
/// 2.6 m distance, 4 cm turn the view by about 0.9°).
pub const AIM_DRIFT_CM: f32 = 4.0;
/// Amplitude of the tremor of the aim point, per axis (metres; about 0.2° at 2.6 m).
pub const TREMOR_CM: f32 = 0.9;
/// Turning rate of the orbit (degrees per second).
pub const ORBIT_DEG_PER_S: f32 = 6.0;

/// One sinusoid `a · sin(2π f t + φ)`.
#[derive(Clone, Copy, Debug)]
struct Wave {
    amplitude: f32,
    hz: f32,
    phase: f32,
}

impl Wave {
    fn at(&self, t: f64) -> f32 {
        let angle = std::f64::consts::TAU * f64::from(self.hz) * t + f64::from(self.phase);
        self.amplitude * angle.sin() as f32
    }
}

/// A smooth random offset in 3-D: per axis a sum of sinusoids.
#[derive(Clone, Debug)]
struct Path3 {
    axes: [Vec<Wave>; 3],
}

impl Path3 {
    /// `count` waves per axis with frequencies in `hz` and a total RMS of `rms` per axis.
    fn random(rng: &mut ChaCha8Rng, count: usize, hz: (f32, f32), rms: f32) -> Self {
        // A sinusoid of amplitude a has RMS a/√2; `count` independent ones add in quadrature.
        let amplitude = rms * (2.0 / count as f32).sqrt();
        let mut axis = || -> Vec<Wave> {
            (0..count)
                .map(|_| Wave {
                    amplitude,
                    hz: rng.gen_range(hz.0..hz.1),
                    phase: rng.gen_range(0.0..std::f32::consts::TAU),
                })
                .collect()
        };
        Self {
            axes: [axis(), axis(), axis()],
        }
    }

    fn at(&self, t: f64) -> Vec3 {
        let sum = |waves: &[Wave]| waves.iter().map(|w| w.at(t)).sum::<f32>();
        Vec3::new(sum(&self.axes[0]), sum(&self.axes[1]), sum(&self.axes[2]))
    }
}

/// The camera at any time of the clip.
#[derive(Clone, Debug)]
pub struct CameraPath {
    motion: CameraMotion,
    base: PinholeCamera,
    hfov: f32,
    eye: Vec3,
    target: Vec3,
    drift: Path3,
    aim: Path3,
    tremor: Path3,
}

impl CameraPath {
    /// The path of `motion` around the static camera at `eye` looking at `target` (`base`, with
    /// horizontal field of view `hfov`); random parts drawn from `seed`.
    pub fn new(
        motion: CameraMotion,
        base: PinholeCamera,
        (hfov, eye, target): (f32, Vec3, Vec3),
        seed: u64,
    ) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0xCA3E_2A00);
        let cm = 0.01;
        Self {
            motion,
            base,
            hfov,
            eye,
            target,
            drift: Path3::random(&mut rng, 3, (0.15, 0.8), DRIFT_CM * cm),
            aim: Path3::random(&mut rng, 3, (0.15, 0.8), AIM_DRIFT_CM * cm),
            tremor: Path3::random(&mut rng, 1, (8.0, 12.0), TREMOR_CM * cm / 2f32.sqrt()),
        }
    }

    /// The camera at time `t` (seconds); exactly the static camera when the motion is static.
    pub fn at(&self, t: f64) -> PinholeCamera {
        let (w, h) = (self.base.width, self.base.height);
        match self.motion {
            CameraMotion::Static => self.base,
            CameraMotion::Handheld => {
                let eye = self.eye + self.drift.at(t);
                let target = self.target + self.aim.at(t) + self.tremor.at(t);
                PinholeCamera::look_at(w, h, self.hfov, eye, target)
            }
            CameraMotion::Orbit => {
                let angle = (f64::from(ORBIT_DEG_PER_S) * t).to_radians() as f32;
                let arm = self.eye - self.target;
                let turned = glam::Quat::from_rotation_y(angle) * arm;
                PinholeCamera::look_at(w, h, self.hfov, self.target + turned, self.target)
            }
        }
    }

    /// True unless the camera is static.
    pub fn moves(&self) -> bool {
        !self.motion.is_static()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn path(motion: CameraMotion) -> CameraPath {
        let (eye, target) = (Vec3::new(0.5, 1.3, 2.6), Vec3::new(0.0, 0.9, 0.0));
        let hfov = 0.8;
        let base = PinholeCamera::look_at(64, 64, hfov, eye, target);
        CameraPath::new(motion, base, (hfov, eye, target), 7)
    }

    fn angle_deg(a: &PinholeCamera, b: &PinholeCamera) -> f32 {
        let r = a.rot_cam_from_world * b.rot_cam_from_world.transpose();
        let cos = ((r.x_axis.x + r.y_axis.y + r.z_axis.z - 1.0) / 2.0).clamp(-1.0, 1.0);
        cos.acos().to_degrees()
    }

    #[test]
    fn a_static_camera_never_moves() {
        let p = path(CameraMotion::Static);
        assert_eq!(p.at(0.0), p.at(1.7));
        assert!(!p.moves());
    }

    #[test]
    fn a_handheld_camera_drifts_centimetres_and_trembles_within_an_exposure() {
        let p = path(CameraMotion::Handheld);
        let (mut max_shift, mut max_turn) = (0.0f32, 0.0f32);
        for k in 0..300 {
            let c = p.at(k as f64 / 30.0);
            max_shift = max_shift.max((c.centre_world() - p.eye).length());
            max_turn = max_turn.max(angle_deg(&c, &p.base));
        }
        assert!((0.02..0.12).contains(&max_shift), "{max_shift} m");
        assert!((0.3..4.0).contains(&max_turn), "{max_turn}°");
        // Inside one 33 ms exposure the tremor turns the view by a visible fraction of a degree.
        let within = angle_deg(&p.at(1.0), &p.at(1.0 + 1.0 / 30.0));
        assert!((0.01..1.0).contains(&within), "{within}°");
    }

    #[test]
    fn an_orbit_turns_at_its_rate_around_the_target() {
        let p = path(CameraMotion::Orbit);
        assert!((p.at(0.0).centre_world() - p.eye).length() < 1e-5);
        let turned = angle_deg(&p.at(1.0), &p.at(0.0));
        assert!((turned - ORBIT_DEG_PER_S).abs() < 0.05, "{turned}°");
        let radius = |c: PinholeCamera| (c.centre_world() - p.target).length();
        assert!((radius(p.at(2.0)) - radius(p.at(0.0))).abs() < 1e-5);
    }
}
