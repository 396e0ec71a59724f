//! The exposure model's timing and poses: a frame integrates light over `[t − E/2, t + E/2]`
//! (`time_s`, the scene's `exposure_s`), so its prediction is the mean of S renders at times inside
//! that interval, each at the body pose of its time.
//!
//! **Times**: the midpoint rule, `t + E·((s + ½)/S − ½)` for s = 0…S−1 — the quadrature of a box
//! exposure with the smallest error for smooth motion and no randomness (a stratified jitter would
//! make every step's blur model different and the run's bits depend on one more random stream, for an
//! unbiasedness the benchmark's own midpoint-sampled blur does not need).
//!
//! **Poses**: the scene gives one SMPL pose per frame, at mid exposure. Between two frames, each
//! joint's rotation follows a cubic Hermite curve in the tangent space of the earlier frame's
//! rotation (q(t) = q_i · exp(h(t)), h interpolating log(q_i⁻¹ q_j) of the neighbouring frames j with
//! finite-difference tangents: fourth-order central differences between evenly spaced frames), and the translation a cubic Hermite curve with the same
//! tangents: C¹ within a segment and, for the small rotations between video frames, across them.
//! Before the first frame and after the last, poses continue along the end tangent (linear in the
//! tangent space).
//!
//! **Cameras** (a moving camera): the same Hermite curves through the frames' cameras, by default
//! with band-limited tangents ([`Keys::band_limited_tangent`]): a hand's 8–12 Hz tremor is sampled
//! at 30 fps near half the frame rate, where central differences under-state its speed by 40–60 %.
//! The body's track takes either rule (`TrainConfig::body_interpolation`; on the generator's
//! motion band-limited tangents lower the sub-frame joint error from 0.230° to 0.193° mean).

use glam::{DQuat, DVec3};
use smpl_deform::SmplParams;

use crate::config::TrackTangents;

/// The tangent rules of the exposure model's two tracks: the body's
/// (`TrainConfig::body_interpolation`) and a moving camera's (`TrainConfig::camera_interpolation`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TrackRules {
    /// The body's joints and root translation ([`PoseTrack`]).
    pub body: TrackTangents,
    /// The camera's path ([`CameraTrack`]).
    pub camera: TrackTangents,
}

impl TrackRules {
    /// The rules `config` names.
    pub fn of(config: &crate::config::TrainConfig) -> Self {
        Self {
            body: config.body_interpolation,
            camera: config.camera_interpolation,
        }
    }
}

impl Default for TrackRules {
    /// The default configuration's rules.
    fn default() -> Self {
        Self::of(&crate::config::TrainConfig::default())
    }
}

/// The S sub-exposure times (seconds) of a frame at mid-exposure time `time_s` with exposure
/// `exposure_s` (midpoint rule, see the module documentation).
pub fn subframe_times(time_s: f64, exposure_s: f64, count: usize) -> Vec<f64> {
    let s = count.max(1) as f64;
    (0..count.max(1))
        .map(|k| time_s + exposure_s * ((k as f64 + 0.5) / s - 0.5))
        .collect()
}

/// The S slices of a frame's exposure that its S sub-exposure renders stand for, each
/// `(from, to, anchor)` in seconds: `[t − E/2 + s·E/S, t − E/2 + (s+1)·E/S)` with the render's
/// time ([`subframe_times`], the slice's middle) as anchor.
pub fn exposure_slices(time_s: f64, exposure_s: f64, count: usize) -> Vec<(f64, f64, f64)> {
    let s = count.max(1) as f64;
    let start = time_s - 0.5 * exposure_s;
    subframe_times(time_s, exposure_s, count)
        .into_iter()
        .enumerate()
        .map(|(k, anchor)| {
            let from = start + exposure_s * k as f64 / s;
            (from, from + exposure_s / s, anchor)
        })
        .collect()
}

/// Keys on each side of a band-limited tangent ([`Keys::band_limited_tangent`]). Measured on the
/// `handheld` benchmark's camera path (30 fps, 8–12 Hz tremor), RMS error of the interpolated
/// sub-exposure rotations: 4 keys 0.0153°, 8 keys 0.0059°, 12 keys 0.0075° (longer windows pass the
/// slow drift's curvature less well), against 0.0523° for [`Keys::tangent`].
const BAND_LIMITED_REACH: usize = 8;

/// The band-limited differentiator's weights `c_m`, m = 1…`BAND_LIMITED_REACH`: `(−1)^(m+1)/m`
/// under a Lanczos window `sinc(m / (reach + 1))`, scaled so that `Σ 2·m·c_m = 1` (exact on a
/// linear signal).
fn band_limited_weights() -> [f64; BAND_LIMITED_REACH] {
    let sinc = |x: f64| {
        let px = std::f64::consts::PI * x;
        if px.abs() < 1e-12 {
            1.0
        } else {
            px.sin() / px
        }
    };
    let mut weights = [0.0; BAND_LIMITED_REACH];
    for (i, w) in weights.iter_mut().enumerate() {
        let m = (i + 1) as f64;
        let sign = if i % 2 == 0 { 1.0 } else { -1.0 };
        *w = sign / m * sinc(m / (BAND_LIMITED_REACH as f64 + 1.0));
    }
    let norm: f64 = weights
        .iter()
        .enumerate()
        .map(|(i, w)| 2.0 * (i + 1) as f64 * w)
        .sum();
    weights.map(|w| w / norm)
}

/// Key times in increasing order, and the C¹ curve through values at them that both tracks use.
#[derive(Clone, Debug)]
struct Keys {
    times: Vec<f64>,
}

impl Keys {
    /// The segment `i` with `times[i] ≤ t < times[i+1]`, clamped to the first and last segment.
    fn segment(&self, t: f64) -> usize {
        let n = self.times.len();
        if n < 2 {
            return 0;
        }
        let i = self.times.partition_point(|&k| k <= t);
        i.saturating_sub(1).min(n - 2)
    }

    /// Band-limited tangent (per second) at key `j` of values `v`: the ideal differentiator of a
    /// signal sampled above twice its highest frequency, `v'(t_j) = Σ_m (−1)^(m+1) (v_(j+m) −
    /// v_(j−m)) / (m·h)`, truncated to `BAND_LIMITED_REACH` keys on each side with a Lanczos window
    /// and scaled to be exact on a linear signal. Keys past the ends are the odd reflection of the
    /// track about its end key (`v_(−m) = 2·v_0 − v_m`), which continues a linear signal exactly.
    /// `None` when the keys within reach are not evenly spaced (the caller falls back to
    /// [`Keys::tangent`]) or there are fewer than two.
    fn band_limited_tangent(&self, v: &dyn Fn(usize) -> DVec3, j: usize) -> Option<DVec3> {
        let n = self.times.len();
        if n < 2 {
            return None;
        }
        let t = &self.times;
        let (from, to) = (
            j.saturating_sub(BAND_LIMITED_REACH),
            (j + BAND_LIMITED_REACH).min(n - 1),
        );
        let h = t[from + 1] - t[from];
        let even = (from..to).all(|k| ((t[k + 1] - t[k]) - h).abs() <= 1e-9 * h.abs());
        if !even || h <= 0.0 {
            return None;
        }
        let reflected = |k: isize| -> DVec3 {
            // Odd reflection about the end keys, repeated until the index falls inside.
            let (mut k, mut sign, mut offset) = (k, 1.0, DVec3::ZERO);
            let last = n as isize - 1;
            loop {
                if k < 0 {
                    offset += v(0) * (2.0 * sign);
                    (k, sign) = (-k, -sign);
                } else if k > last {
                    offset += v(n - 1) * (2.0 * sign);
                    (k, sign) = (2 * last - k, -sign);
                } else {
                    return offset + v(k as usize) * sign;
                }
            }
        };
        let weights = band_limited_weights();
        let centre = j as isize;
        let sum = weights.iter().enumerate().fold(DVec3::ZERO, |acc, (m, w)| {
            let m = m as isize + 1;
            acc + (reflected(centre + m) - reflected(centre - m)) * *w
        });
        Some(sum / h)
    }

    /// Finite-difference tangent (per second) at key `j` of values `v`: the fourth-order central
    /// difference where the five keys around `j` are evenly spaced (video frames), the second-order
    /// (Catmull-Rom) one where only three are, one-sided at the ends. `v(j)` is key `j`'s value; only
    /// keys within two of `j` are read.
    fn tangent(&self, v: &dyn Fn(usize) -> DVec3, j: usize) -> DVec3 {
        let n = self.times.len();
        let t = &self.times;
        if j >= 2 && j + 2 < n {
            let h = t[j + 1] - t[j];
            let even = [t[j - 1] - t[j - 2], t[j] - t[j - 1], t[j + 2] - t[j + 1]]
                .iter()
                .all(|d| (d - h).abs() <= 1e-9 * h.abs());
            if even {
                return (v(j - 2) - v(j - 1) * 8.0 + v(j + 1) * 8.0 - v(j + 2)) / (12.0 * h);
            }
        }
        let (a, b) = (j.saturating_sub(1), (j + 1).min(n - 1));
        if a == b {
            return DVec3::ZERO;
        }
        (v(b) - v(a)) / (t[b] - t[a])
    }

    /// Cubic Hermite value at `t` of key values `v` on segment `i` (linear continuation outside the
    /// keys' time range), with tangents by `rule`. Reads only the keys within two
    /// (`BAND_LIMITED_REACH` for band-limited tangents) of the segment, so a call costs the same
    /// whatever the track's length.
    fn hermite(&self, rule: TrackTangents, v: &dyn Fn(usize) -> DVec3, i: usize, t: f64) -> DVec3 {
        let n = self.times.len();
        if n < 2 {
            return v(0);
        }
        let tangent = |j: usize| match rule {
            TrackTangents::Local => self.tangent(v, j),
            TrackTangents::BandLimited => self
                .band_limited_tangent(v, j)
                .unwrap_or_else(|| self.tangent(v, j)),
        };
        if t <= self.times[0] {
            return v(0) + tangent(0) * (t - self.times[0]);
        }
        if t >= self.times[n - 1] {
            return v(n - 1) + tangent(n - 1) * (t - self.times[n - 1]);
        }
        let (t0, t1) = (self.times[i], self.times[i + 1]);
        let h = t1 - t0;
        let u = (t - t0) / h;
        let (u2, u3) = (u * u, u * u * u);
        let h00 = 2.0 * u3 - 3.0 * u2 + 1.0;
        let h10 = u3 - 2.0 * u2 + u;
        let h01 = -2.0 * u3 + 3.0 * u2;
        let h11 = u3 - u2;
        v(i) * h00 + tangent(i) * (h10 * h) + v(i + 1) * h01 + tangent(i + 1) * (h11 * h)
    }
}

/// A sequence of SMPL parameters at increasing times, interpolated at any time.
#[derive(Clone, Debug)]
pub struct PoseTrack {
    keys: Keys,
    /// The rule of the tangents at the keys.
    tangents: TrackTangents,
    /// Per key frame, per joint, the rotation.
    rotations: Vec<Vec<DQuat>>,
    translations: Vec<DVec3>,
    betas: Vec<f32>,
}

impl PoseTrack {
    /// The track of `(time_s, params)` key frames, in increasing time (at least one), with
    /// tangents at the keys by `tangents`.
    pub fn new(keys: &[(f64, &SmplParams)], tangents: TrackTangents) -> Self {
        let rotations = keys
            .iter()
            .map(|(_, p)| {
                p.pose
                    .chunks_exact(3)
                    .map(|r| {
                        DQuat::from_scaled_axis(DVec3::new(
                            f64::from(r[0]),
                            f64::from(r[1]),
                            f64::from(r[2]),
                        ))
                    })
                    .collect()
            })
            .collect();
        Self {
            keys: Keys {
                times: keys.iter().map(|(t, _)| *t).collect(),
            },
            tangents,
            rotations,
            translations: keys
                .iter()
                .map(|(_, p)| DVec3::from(p.transl.map(f64::from)))
                .collect(),
            betas: keys
                .first()
                .map(|(_, p)| p.betas.clone())
                .unwrap_or_default(),
        }
    }

    /// The SMPL parameters at time `t` (seconds).
    pub fn at(&self, t: f64) -> SmplParams {
        let i = self.keys.segment(t);
        let transl = self
            .keys
            .hermite(self.tangents, &|j| self.translations[j], i, t);
        let joints = self.rotations.first().map_or(0, Vec::len);
        let mut pose = Vec::with_capacity(3 * joints);
        for joint in 0..joints {
            let base_inverse = self.rotations[i][joint].inverse();
            // Key rotations relative to the segment's base, as tangent vectors (shortest arc).
            let local = |j: usize| {
                let mut q = base_inverse * self.rotations[j][joint];
                if q.w < 0.0 {
                    q = -q;
                }
                q.to_scaled_axis()
            };
            let base = self.rotations[i][joint];
            let q = (base
                * DQuat::from_scaled_axis(self.keys.hermite(self.tangents, &local, i, t)))
            .normalize();
            let r = q.to_scaled_axis();
            pose.extend([r.x as f32, r.y as f32, r.z as f32]);
        }
        SmplParams {
            pose,
            betas: self.betas.clone(),
            transl: [transl.x as f32, transl.y as f32, transl.z as f32],
        }
    }
}

/// A camera's pose at increasing times (the frames' mid-exposure cameras of a moving camera),
/// interpolated at any time as [`PoseTrack`] interpolates a joint: the rotation by a cubic Hermite
/// curve in the tangent space of the segment's start rotation, the camera centre (world metres)
/// by a cubic Hermite curve; the translation follows as `t = −R·c`. The tangents at the keys are
/// band-limited ([`TrackTangents::BandLimited`], a hand's tremor) or local ([`TrackTangents::Local`]).
#[derive(Clone, Debug)]
pub struct CameraTrack {
    keys: Keys,
    /// The rule of the tangents at the keys.
    tangents: TrackTangents,
    /// Per key, the world-to-camera rotation.
    rotations: Vec<DQuat>,
    /// Per key, the camera centre in world coordinates (metres).
    centres: Vec<DVec3>,
}

impl CameraTrack {
    /// The track of `(time_s, world_to_camera)` keys, in increasing time (at least one), each a
    /// rigid 4×4 matrix (rotation rows checked by the scene format), with tangents by `tangents`.
    pub fn new(keys: &[(f64, [[f64; 4]; 4])], tangents: TrackTangents) -> Self {
        let rotation = |m: &[[f64; 4]; 4]| {
            DQuat::from_mat3(&glam::DMat3::from_cols_array_2d(&[
                [m[0][0], m[1][0], m[2][0]],
                [m[0][1], m[1][1], m[2][1]],
                [m[0][2], m[1][2], m[2][2]],
            ]))
            .normalize()
        };
        let rotations: Vec<DQuat> = keys.iter().map(|(_, m)| rotation(m)).collect();
        let centres = keys
            .iter()
            .zip(&rotations)
            .map(|((_, m), r)| -(r.inverse() * DVec3::new(m[0][3], m[1][3], m[2][3])))
            .collect();
        Self {
            keys: Keys {
                times: keys.iter().map(|(t, _)| *t).collect(),
            },
            tangents,
            rotations,
            centres,
        }
    }

    /// The world-to-camera matrix at time `t` (seconds).
    pub fn at(&self, t: f64) -> [[f64; 4]; 4] {
        let i = self.keys.segment(t);
        let rule = self.tangents;
        let centre = self.keys.hermite(rule, &|j| self.centres[j], i, t);
        let base = self.rotations[i];
        let local = |j: usize| {
            let mut q = base.inverse() * self.rotations[j];
            if q.w < 0.0 {
                q = -q;
            }
            q.to_scaled_axis()
        };
        let r = (base * DQuat::from_scaled_axis(self.keys.hermite(rule, &local, i, t))).normalize();
        let m = glam::DMat3::from_quat(r);
        let tr = -(r * centre);
        let row = |k: usize| [m.col(0)[k], m.col(1)[k], m.col(2)[k], tr[k]];
        [row(0), row(1), row(2), [0.0, 0.0, 0.0, 1.0]]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_slices_tile_the_exposure_around_their_renders_times() {
        let slices = exposure_slices(2.0, 0.03, 5);
        let times = subframe_times(2.0, 0.03, 5);
        assert!((slices[0].0 - 1.985).abs() < 1e-12 && (slices[4].1 - 2.015).abs() < 1e-12);
        for (k, &(from, to, anchor)) in slices.iter().enumerate() {
            assert!((to - from - 0.006).abs() < 1e-12);
            assert_eq!(anchor, times[k]);
            assert!((anchor - 0.5 * (from + to)).abs() < 1e-12);
            if k > 0 {
                assert_eq!(from, slices[k - 1].1);
            }
        }
    }

    #[test]
    fn midpoint_times_span_the_exposure_symmetrically() {
        let t = subframe_times(1.0, 0.2, 4);
        assert_eq!(t.len(), 4);
        for (a, b) in t.iter().zip([0.925, 0.975, 1.025, 1.075]) {
            assert!((a - b).abs() < 1e-12, "{t:?}");
        }
        assert_eq!(subframe_times(2.0, 0.1, 1), vec![2.0]);
    }

    fn params(angle: f32, x: f32) -> SmplParams {
        let mut pose = vec![0.0f32; 72];
        pose[3 * 16 + 2] = angle; // a shoulder about z
        SmplParams {
            pose,
            betas: vec![],
            transl: [x, 0.0, 0.0],
        }
    }

    #[test]
    fn the_track_passes_through_its_keys_and_follows_a_uniform_rotation_exactly() {
        // A joint turning at a constant rate and a body moving at constant speed: the Hermite curve
        // with finite-difference tangents reproduces both exactly between the keys.
        let keys: Vec<(f64, SmplParams)> = (0..5)
            .map(|k| (k as f64 * 0.1, params(0.3 * k as f32, 0.05 * k as f32)))
            .collect();
        let refs: Vec<(f64, &SmplParams)> = keys.iter().map(|(t, p)| (*t, p)).collect();
        let track = PoseTrack::new(&refs, TrackTangents::Local);
        for (t, p) in &keys {
            let at = track.at(*t);
            assert!((at.pose[50] - p.pose[50]).abs() < 1e-6, "{t}");
            assert!((at.transl[0] - p.transl[0]).abs() < 1e-6);
        }
        for t in [0.13, 0.25, 0.31] {
            let at = track.at(t);
            assert!(
                (f64::from(at.pose[50]) - 3.0 * t).abs() < 1e-5,
                "{t}: {}",
                at.pose[50]
            );
            assert!((f64::from(at.transl[0]) - 0.5 * t).abs() < 1e-6, "{t}");
        }
        // Outside the keys: continued along the end tangent.
        let before = track.at(-0.05);
        assert!(
            (f64::from(before.pose[50]) + 0.15).abs() < 1e-5,
            "{}",
            before.pose[50]
        );
    }
}
