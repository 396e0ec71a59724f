//! Procedural SMPL motion: the person turns slowly in place while the arms swing fast and the legs
//! step (marching on the spot), the elbows and knees bend with the swing, the head and spine sway.
//!
//! Pose parameters are axis-angle in each joint's parent frame, in the SMPL rest frame (y up, x to
//! the body's left, z forward). [`Speed`] scales every angular frequency (slow ×0.5, medium ×1,
//! fast ×2), hence the blur; amplitudes do not change. The motion is a smooth, closed-form function
//! of time, so any sub-frame time can be evaluated exactly.

use glam::{Quat, Vec3};
use smpl_deform::NUM_JOINTS;
use std::f32::consts::TAU;

/// Motion speed preset.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Speed {
    /// Frequencies ×0.5.
    Slow,
    /// Frequencies ×1 (arm swing 1 Hz).
    Medium,
    /// Frequencies ×2.
    Fast,
}

impl Speed {
    /// Frequency multiplier.
    pub fn factor(self) -> f32 {
        match self {
            Self::Slow => 0.5,
            Self::Medium => 1.0,
            Self::Fast => 2.0,
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
    /// Root position on the floor (metres, world x and z).
    pub base: [f32; 2],
    /// Added to the translation's y so the feet touch the floor (metres).
    pub floor_offset: f32,
    /// Shoulder rotation (radians) that lowers the rest-pose arms to hang 70° below horizontal
    /// (see [`Motion::arm_down_for`]).
    pub arm_down: f32,
}

fn aa(q: Quat) -> [f32; 3] {
    let (axis, angle) = q.to_axis_angle();
    (axis * angle).to_array()
}

impl Motion {
    /// The shoulder rotation that brings the rest-pose upper arm (left shoulder joint 16 to left
    /// elbow 18, rest joints in metres) to 70° below horizontal.
    pub fn arm_down_for(joints_rest: &[[f32; 3]]) -> f32 {
        let (s, e) = (joints_rest[16], joints_rest[18]);
        let rest_angle = (s[1] - e[1]).atan2((e[0] - s[0]).abs());
        70f32.to_radians() - rest_angle
    }

    /// Pose (72 axis-angle values) and translation (metres) at time `t` (seconds).
    pub fn at(&self, t: f64) -> (Vec<f32>, [f32; 3]) {
        let f = self.speed.factor();
        // Phases at t, computed in f64 before reduction so long sequences stay exact.
        let ph = |hz: f32, k: usize| -> f32 {
            ((f64::from(hz * f) * t).fract() as f32) * TAU + self.phases[k]
        };
        let mut pose = vec![[0.0f32; 3]; NUM_JOINTS];
        // Slow turn in place (0.12 Hz at medium), ±0.6 rad.
        let yaw = 0.6 * ph(0.125, 0).sin();
        pose[0] = aa(Quat::from_rotation_y(yaw));
        // Arms: lowered to 70° below horizontal, swinging ±0.9 rad front/back in opposite phase.
        let arm = ph(1.0, 1);
        let swing = 0.9 * arm.sin();
        let down = self.arm_down;
        pose[16] = aa(Quat::from_rotation_x(swing) * Quat::from_rotation_z(-down));
        pose[17] = aa(Quat::from_rotation_x(-swing) * Quat::from_rotation_z(down));
        let bend = 0.35 + 0.45 * (0.5 + 0.5 * (arm + 1.0).sin());
        let bend_r = 0.35 + 0.45 * (0.5 - 0.5 * (arm + 1.0).sin());
        pose[18] = aa(Quat::from_rotation_y(-bend));
        pose[19] = aa(Quat::from_rotation_y(bend_r));
        // Legs: marching on the spot, thighs lift forward in turn, knees bend back.
        let leg = ph(0.75, 2);
        let lift_l = 0.7 * leg.sin().max(0.0);
        let lift_r = 0.7 * (-leg.sin()).max(0.0);
        pose[1] = aa(Quat::from_rotation_x(-lift_l));
        pose[2] = aa(Quat::from_rotation_x(-lift_r));
        pose[4] = aa(Quat::from_rotation_x(1.6 * lift_l));
        pose[5] = aa(Quat::from_rotation_x(1.6 * lift_r));
        // Spine counter-rotation and head sway.
        let head = ph(0.5, 3);
        pose[9] =
            aa(Quat::from_rotation_y(0.25 * arm.sin()) * Quat::from_rotation_z(0.05 * leg.sin()));
        pose[15] = aa(Quat::from_rotation_x(0.15 * head.sin())
            * Quat::from_rotation_y(0.3 * (head * 0.5).cos()));
        // Bobbing with the steps.
        let bob = -0.02 * (lift_l + lift_r);
        let transl = Vec3::new(self.base[0], self.floor_offset + bob, self.base[1]);
        (pose.into_iter().flatten().collect(), transl.to_array())
    }
}
