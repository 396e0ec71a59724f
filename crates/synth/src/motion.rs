//! Procedural SMPL motion: the person turns slowly in place while the arms sweep fast (jumping-jack
//! arcs with a front/back swing), the legs step on the spot and open sideways, elbows and knees
//! bend, the torso twists, the head nods and the whole body sways sideways. Limb motion is mostly in the image plane of a camera
//! in front of the person, so it blurs.
//!
//! Pose parameters are axis-angle in each joint's parent frame, in the SMPL rest frame (y up, x to
//! the body's left, z forward). [`Speed`] scales every angular frequency (slow ×1.5, medium ×3,
//! fast ×6: each level doubles the blur length), hence the blur; amplitudes do not change. The motion is a smooth, closed-form function
//! of time, so any sub-frame time can be evaluated exactly.

use glam::{Quat, Vec3};
use smpl_deform::NUM_JOINTS;
use std::f32::consts::TAU;

/// Motion speed preset.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Speed {
    /// Frequencies ×1.5 (arm sweep 1.35 Hz, steps 0.9 Hz, sway 0.6 Hz, turn 0.225 Hz).
    Slow,
    /// Frequencies ×3.
    Medium,
    /// Frequencies ×6 (arm sweep 5.4 Hz, sway 2.4 Hz).
    Fast,
}

impl Speed {
    /// Frequency multiplier.
    pub fn factor(self) -> f32 {
        match self {
            Self::Slow => 1.5,
            Self::Medium => 3.0,
            Self::Fast => 6.0,
        }
    }

    /// Name as on the command line.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Slow => "slow",
            Self::Medium => "medium",
            Self::Fast => "fast",
        }
    }
}

/// The motion generator.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Motion {
    /// Speed preset.
    pub speed: Speed,
    /// Phase offsets (radians) drawn from the seed: turn, arms, legs, head.
    pub phases: [f32; 4],
    /// Root position on the floor at time 0 (metres, world x and z).
    pub base: [f32; 2],
    /// Walking velocity along the floor (metres per second, world x and z; zero: dancing on the
    /// spot, the first person's).
    pub walk: [f32; 2],
    /// Added to the translation's y so the feet touch the floor (metres).
    pub floor_offset: f32,
    /// Elevation of the rest-pose upper arms below horizontal (radians, see
    /// [`Motion::arm_rest_elevation`]); the motion's arm angles are absolute, whatever the rest pose.
    pub arm_rest_elevation: f32,
}

fn aa(q: Quat) -> [f32; 3] {
    let (axis, angle) = q.to_axis_angle();
    (axis * angle).to_array()
}

impl Motion {
    /// Elevation of the rest-pose upper arm below horizontal (radians; left shoulder joint 16 to left
    /// elbow 18, rest joints in metres): 0 for a T-pose, about 0.8 for an A-pose.
    pub fn arm_rest_elevation(joints_rest: &[[f32; 3]]) -> f32 {
        let (s, e) = (joints_rest[16], joints_rest[18]);
        (s[1] - e[1]).atan2((e[0] - s[0]).abs())
    }

    /// Pose (72 axis-angle values) and translation (metres) at time `t` (seconds).
    pub fn at(&self, t: f64) -> (Vec<f32>, [f32; 3]) {
        let f = self.speed.factor();
        // Phases at t, reduced in f64 so long sequences stay exact; only integer multiples of a
        // phase are used below, so every angle is continuous in t.
        let ph = |hz: f32, k: usize| -> f32 {
            ((f64::from(hz * f) * t).fract() as f32) * TAU + self.phases[k]
        };
        let mut pose = vec![[0.0f32; 3]; NUM_JOINTS];
        // Turn in place (0.15 Hz before the speed factor), ±0.7 rad, and sway sideways ±0.25 m (0.4 Hz):
        // the whole-body sway is what blurs the torso and legs, not only the thin limbs.
        pose[0] = aa(Quat::from_rotation_y(0.7 * ph(0.15, 0).sin()));
        let sway = 0.25 * ph(0.4, 3).sin();
        // Arms: jumping-jack sweep in the body's frontal plane (elevation 10° above to 80° below
        // horizontal) with a front/back swing a quarter period later, so hands trace ellipses.
        let arm = ph(0.9, 1);
        let elev = (35.0 + 45.0 * arm.sin()).to_radians() - self.arm_rest_elevation;
        let swing = 0.35 * arm.cos();
        pose[16] = aa(Quat::from_rotation_x(swing) * Quat::from_rotation_z(-elev));
        pose[17] = aa(Quat::from_rotation_x(-swing) * Quat::from_rotation_z(elev));
        let bend_l = 0.2 + 0.9 * (0.5 + 0.5 * (arm + 1.3).sin());
        let bend_r = 0.2 + 0.9 * (0.5 + 0.5 * (arm + 2.8).sin());
        pose[18] = aa(Quat::from_rotation_y(-bend_l));
        pose[19] = aa(Quat::from_rotation_y(bend_r));
        // Legs: stepping on the spot (thighs lift forward in turn, knees bend back) and opening
        // sideways with the arms.
        let step = ph(0.6, 2);
        let lift_l = 0.7 * step.sin().max(0.0);
        let lift_r = 0.7 * (-step.sin()).max(0.0);
        let open = 0.15 * (0.5 + 0.5 * arm.sin());
        pose[1] = aa(Quat::from_rotation_z(open) * Quat::from_rotation_x(-lift_l));
        pose[2] = aa(Quat::from_rotation_z(-open) * Quat::from_rotation_x(-lift_r));
        pose[4] = aa(Quat::from_rotation_x(1.6 * lift_l));
        pose[5] = aa(Quat::from_rotation_x(1.6 * lift_r));
        // Torso twist with the arms, sideways lean with the steps, head nods and turns.
        let twist = 0.25 * (arm + 0.5).sin();
        for j in [3, 6, 9] {
            pose[j] = aa(Quat::from_rotation_y(twist) * Quat::from_rotation_z(0.04 * step.sin()));
        }
        let head = ph(0.4, 3);
        pose[15] =
            aa(Quat::from_rotation_x(0.15 * head.sin()) * Quat::from_rotation_y(0.3 * head.cos()));
        // Bobbing with the steps.
        let bob = -0.02 * (lift_l + lift_r);
        let walked = [self.walk[0] * t as f32, self.walk[1] * t as f32];
        let transl = Vec3::new(
            self.base[0] + sway + walked[0],
            self.floor_offset + bob,
            self.base[1] + walked[1],
        );
        (pose.into_iter().flatten().collect(), transl.to_array())
    }
}
