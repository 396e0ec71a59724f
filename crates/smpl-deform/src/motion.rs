//! SMPL motion sequences in the layouts people have, and placing one in a scene.
//!
//! Readers (one entry point, [`read_motion`], which tells the layout from the file):
//! - **AMASS** `.npz`: `poses` `(N, 72)` SMPL or `(N, 156)` SMPL-H axis-angle (radians), `trans`
//!   `(N, 3)` metres, optional `betas`, `mocap_framerate` (a scalar), `gender` (a string or bytes
//!   array, not read) and `dmpls` (not read). SMPL-H's 30 finger joints have no SMPL counterpart:
//!   they are dropped and SMPL's two hand joints (22, 23) set to zero. World frame z up.
//! - **PeopleSnapshot / InstantAvatar** `.npz`: `global_orient` `(N, 3)`, `body_pose` `(N, 69)`,
//!   `transl` `(N, 3)`, `betas` `(1, 10)` or `(10,)`. Poses live in the OpenCV camera frame (y down,
//!   so the person's up is −y).
//! - **EasyMocap** `smpl/NNNNNN.json`, one file per frame ([`read_easymocap`]): a list of people
//!   `{"id", "Rh": [[3]], "Th": [[3]], "poses": [[72 or 69]], "shapes": [[10]]}`. EasyMocap rotates
//!   the posed body by `Rh` about the model's *origin* and then adds `Th`, where SMPL rotates about
//!   the root joint: the reader converts (`global_orient = Rh·R(poses[:3])`,
//!   `transl = Rh·j₀ + Th − j₀` with `j₀` the body's rest root joint, which the caller gives).
//!   World frame z up (EasyMocap's calibration board), by default.
//!
//! Every array's shape is checked before its data is read (through [`crate::npz::NpzReader`]), the
//! frame counts of the arrays must agree, and non-finite values are refused with the array's name.
//!
//! [`anchor_motion`] re-anchors a sequence from its own world frame into a scene (world y up, the
//! SMPL rest frame, as scene format v1 has it): it rotates the file's up axis onto +y, turns the
//! sequence about the vertical so that its first frame faces where the anchor pose faces, and moves
//! it so that its first frame's root sits where the anchor's does; the motion's own displacement
//! (walking, jumping) is kept relative to that start.

use std::io::{Read, Seek};
use std::path::Path;

use glam::{DMat3, DQuat, DVec3};

use crate::error::{Result, SmplDeformError};
use crate::npz::NpzReader;
use crate::skeleton::NUM_JOINTS;

mod easymocap;
pub use easymocap::{read_easymocap, read_easymocap_people, EasyMocapPeople};

/// Upper bound on the frames of one motion file (a 120 fps capture of about 2.3 hours).
pub const MAX_MOTION_FRAMES: u64 = 1 << 20;

/// The file layout a motion was read from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MotionLayout {
    /// AMASS-style `.npz` (`poses`, `trans`).
    Amass,
    /// PeopleSnapshot / InstantAvatar `.npz` (`global_orient`, `body_pose`, `transl`).
    PeopleSnapshot,
    /// EasyMocap's per-frame `smpl/*.json` (`Rh`, `Th`, `poses`, `shapes`).
    EasyMocap,
}

impl MotionLayout {
    /// The layout's name as printed.
    pub fn as_str(self) -> &'static str {
        match self {
            MotionLayout::Amass => "AMASS",
            MotionLayout::PeopleSnapshot => "PeopleSnapshot",
            MotionLayout::EasyMocap => "EasyMocap",
        }
    }

    /// The up axis of the layout's world frame, used when the user does not state one.
    pub fn default_up(self) -> UpAxis {
        match self {
            MotionLayout::Amass => UpAxis::PosZ,
            MotionLayout::PeopleSnapshot => UpAxis::NegY,
            MotionLayout::EasyMocap => UpAxis::PosZ,
        }
    }
}

/// A signed coordinate axis: the "up" direction of a motion file's world frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum UpAxis {
    /// +x.
    PosX,
    /// −x.
    NegX,
    /// +y (the SMPL rest frame and scene format v1).
    PosY,
    /// −y (OpenCV camera frames).
    NegY,
    /// +z (AMASS, most motion-capture worlds).
    PosZ,
    /// −z.
    NegZ,
}

impl UpAxis {
    /// Parses `x`, `-x`, `y`, `-y`, `z` or `-z` (a leading `+` is allowed).
    pub fn parse(s: &str) -> Option<Self> {
        Some(match s.trim_start_matches('+') {
            "x" => UpAxis::PosX,
            "-x" => UpAxis::NegX,
            "y" => UpAxis::PosY,
            "-y" => UpAxis::NegY,
            "z" => UpAxis::PosZ,
            "-z" => UpAxis::NegZ,
            _ => return None,
        })
    }

    /// The axis as a unit vector.
    pub fn vector(self) -> DVec3 {
        match self {
            UpAxis::PosX => DVec3::X,
            UpAxis::NegX => DVec3::NEG_X,
            UpAxis::PosY => DVec3::Y,
            UpAxis::NegY => DVec3::NEG_Y,
            UpAxis::PosZ => DVec3::Z,
            UpAxis::NegZ => DVec3::NEG_Z,
        }
    }
}

/// A motion: per frame the 72 SMPL axis-angle values (joint 0 the global orientation) and the
/// translation (metres), in the file's world frame.
#[derive(Clone, Debug)]
pub struct Motion {
    /// The layout it was read from.
    pub layout: MotionLayout,
    /// Per frame, `3 × 24` axis-angle values (radians).
    pub poses: Vec<[f32; 3 * NUM_JOINTS]>,
    /// Per frame, the SMPL translation (metres).
    pub transl: Vec<[f32; 3]>,
    /// The file's shape parameters, when it has them (informative: a reconstructed avatar keeps
    /// its own shape).
    pub betas: Option<Vec<f32>>,
    /// The file's frame rate (frames per second), when it states one.
    pub fps: Option<f64>,
    /// What the file holds that this reader did not use, one phrase each.
    pub dropped: Vec<String>,
}

impl Motion {
    /// Number of frames.
    pub fn len(&self) -> usize {
        self.poses.len()
    }

    /// True when the motion has no frames (never, for a motion the readers return).
    pub fn is_empty(&self) -> bool {
        self.poses.is_empty()
    }
}

/// Reads a motion `.npz` file, telling AMASS from PeopleSnapshot by its arrays.
pub fn read_motion(path: &Path) -> Result<Motion> {
    let file = std::fs::File::open(path).map_err(|source| SmplDeformError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    read_motion_npz(std::io::BufReader::new(file))
}

/// [`read_motion`] from any seekable reader holding an `.npz`.
pub fn read_motion_npz<R: Read + Seek>(reader: R) -> Result<Motion> {
    let mut npz = NpzReader::new(reader)?;
    if npz.has("poses") {
        read_amass(&mut npz)
    } else if npz.has("body_pose") || npz.has("global_orient") {
        read_people_snapshot(&mut npz)
    } else {
        Err(SmplDeformError::MissingKey {
            key: "poses (AMASS) or global_orient + body_pose + transl (PeopleSnapshot)".into(),
        })
    }
}

fn frames_ok(n: u64) -> bool {
    (1..=MAX_MOTION_FRAMES).contains(&n)
}

/// Reads a `(N, width)` float array (one of `widths`), returning `N`, the width and the data.
fn read_rows<R: Read + Seek>(
    npz: &mut NpzReader<R>,
    key: &str,
    widths: &[u64],
) -> Result<(usize, usize, Vec<f64>)> {
    let expected = format!(
        "(N, {}) with 1 ≤ N ≤ {MAX_MOTION_FRAMES}",
        widths
            .iter()
            .map(u64::to_string)
            .collect::<Vec<_>>()
            .join(" or ")
    );
    let (shape, data) = npz.read_float(
        key,
        |s| s.len() == 2 && frames_ok(s[0]) && widths.contains(&s[1]),
        &expected,
    )?;
    Ok((shape[0] as usize, shape[1] as usize, data))
}

fn read_betas<R: Read + Seek>(npz: &mut NpzReader<R>) -> Result<Option<Vec<f32>>> {
    if !npz.has("betas") {
        return Ok(None);
    }
    let (_, data) = npz.read_float(
        "betas",
        |s| match s {
            [n] => (1..=300).contains(n),
            [1, n] => (1..=300).contains(n),
            _ => false,
        },
        "(B,) or (1, B) with B ≤ 300",
    )?;
    Ok(Some(data.into_iter().map(|v| v as f32).collect()))
}

fn same_frames(key: &str, found: usize, n: usize, width: u64) -> Result<()> {
    if found == n {
        return Ok(());
    }
    Err(SmplDeformError::WrongShape {
        key: key.into(),
        found: vec![found as u64, width],
        expected: format!("({n}, {width}): one row per frame of the other arrays"),
    })
}

fn read_amass<R: Read + Seek>(npz: &mut NpzReader<R>) -> Result<Motion> {
    let (n, width, poses) = read_rows(npz, "poses", &[72, 156])?;
    let (n_trans, _, trans) = read_rows(npz, "trans", &[3])?;
    same_frames("trans", n_trans, n, 3)?;
    let betas = read_betas(npz)?;
    let fps = if npz.has("mocap_framerate") {
        let (_, v) = npz.read_float("mocap_framerate", |s| s.is_empty() || s == [1], "a scalar")?;
        let fps = v[0];
        if !(fps > 0.0 && fps <= 10_000.0) {
            return Err(SmplDeformError::InvalidParams {
                field: "mocap_framerate".into(),
                reason: format!("{fps} is not a frame rate in (0, 10000]"),
            });
        }
        Some(fps)
    } else {
        None
    };
    let mut dropped = Vec::new();
    if width == 156 {
        dropped.push(
            "SMPL-H's 30 finger joints (SMPL's hand joints 22 and 23 are set to zero)".to_string(),
        );
    }
    for key in ["gender", "dmpls"] {
        if npz.has(key) {
            dropped.push(format!("`{key}`"));
        }
    }
    // SMPL and SMPL-H share joints 0..=21 in the same order.
    let body = if width == 72 { 72 } else { 66 };
    let mut out_poses = Vec::with_capacity(n);
    for row in poses.chunks_exact(width) {
        let mut p = [0.0f32; 3 * NUM_JOINTS];
        for (dst, &src) in p.iter_mut().zip(&row[..body]) {
            *dst = src as f32;
        }
        out_poses.push(p);
    }
    Ok(Motion {
        layout: MotionLayout::Amass,
        poses: out_poses,
        transl: triples(&trans),
        betas,
        fps,
        dropped,
    })
}

fn read_people_snapshot<R: Read + Seek>(npz: &mut NpzReader<R>) -> Result<Motion> {
    let (n, _, orient) = read_rows(npz, "global_orient", &[3])?;
    let (n_body, _, body) = read_rows(npz, "body_pose", &[69])?;
    same_frames("body_pose", n_body, n, 69)?;
    let (n_t, _, transl) = read_rows(npz, "transl", &[3])?;
    same_frames("transl", n_t, n, 3)?;
    let betas = read_betas(npz)?;
    let poses = orient
        .chunks_exact(3)
        .zip(body.chunks_exact(69))
        .map(|(o, b)| {
            let mut p = [0.0f32; 3 * NUM_JOINTS];
            for (dst, &src) in p.iter_mut().zip(o.iter().chain(b)) {
                *dst = src as f32;
            }
            p
        })
        .collect();
    Ok(Motion {
        layout: MotionLayout::PeopleSnapshot,
        poses,
        transl: triples(&transl),
        betas,
        fps: None,
        dropped: Vec::new(),
    })
}

fn triples(flat: &[f64]) -> Vec<[f32; 3]> {
    flat.chunks_exact(3)
        .map(|c| [c[0] as f32, c[1] as f32, c[2] as f32])
        .collect()
}

fn rotation_of(axis_angle: &[f32]) -> DQuat {
    let v = DVec3::new(
        f64::from(axis_angle[0]),
        f64::from(axis_angle[1]),
        f64::from(axis_angle[2]),
    );
    let angle = v.length();
    if angle < 1e-12 {
        DQuat::IDENTITY
    } else {
        DQuat::from_axis_angle(v / angle, angle)
    }
}

pub(crate) fn axis_angle_of(q: DQuat) -> [f32; 3] {
    let (axis, angle) = q.normalize().to_axis_angle();
    let v = axis * angle;
    [v.x as f32, v.y as f32, v.z as f32]
}

/// The rotation taking the unit vector `from` onto +y (about `from × y`; a half turn about x when
/// `from` is −y).
fn rotation_to_y(from: DVec3) -> DQuat {
    if from.dot(DVec3::Y) < -1.0 + 1e-12 {
        DQuat::from_axis_angle(DVec3::X, std::f64::consts::PI)
    } else {
        DQuat::from_rotation_arc(from.normalize(), DVec3::Y)
    }
}

/// Heading of a root orientation in a y-up world: the angle about +y of where the body faces (its
/// canonical +z), projected on the floor (radians; 0 = facing +z).
fn heading(root: DQuat) -> f64 {
    let f = root * DVec3::Z;
    f.x.atan2(f.z)
}

/// Places `motion` (whose world frame has `up` as its up axis) in a scene with world y up, anchored
/// at `anchor_pose` / `anchor_transl` (a frame of the scene: 72 axis-angle values, metres): frame 0
/// of the result faces the anchor's heading and has the anchor's translation; later frames keep the
/// motion's rotation and displacement relative to frame 0. Joint rotations other than the root are
/// unchanged. The SMPL root joint's rest position cancels out of the translation, so no body model
/// is needed.
pub fn anchor_motion(
    motion: &Motion,
    up: UpAxis,
    anchor_pose: &[f32],
    anchor_transl: [f32; 3],
) -> Result<Vec<([f32; 3 * NUM_JOINTS], [f32; 3])>> {
    if anchor_pose.len() != 3 * NUM_JOINTS || anchor_pose.iter().any(|v| !v.is_finite()) {
        return Err(SmplDeformError::InvalidParams {
            field: "anchor pose".into(),
            reason: format!("expected 72 finite values, found {}", anchor_pose.len()),
        });
    }
    let (Some(first_pose), Some(first_transl)) = (motion.poses.first(), motion.transl.first())
    else {
        return Err(SmplDeformError::InvalidParams {
            field: "motion".into(),
            reason: "no frames".into(),
        });
    };
    let to_y = rotation_to_y(up.vector());
    let anchor_root = rotation_of(&anchor_pose[..3]);
    let first_root = to_y * rotation_of(&first_pose[..3]);
    let turn = DQuat::from_axis_angle(DVec3::Y, heading(anchor_root) - heading(first_root));
    let place = turn * to_y;
    let place_m = DMat3::from_quat(place);
    let t0 = DVec3::new(
        f64::from(first_transl[0]),
        f64::from(first_transl[1]),
        f64::from(first_transl[2]),
    );
    let ta = DVec3::new(
        f64::from(anchor_transl[0]),
        f64::from(anchor_transl[1]),
        f64::from(anchor_transl[2]),
    );
    let out = motion
        .poses
        .iter()
        .zip(&motion.transl)
        .map(|(pose, t)| {
            let mut p = *pose;
            let root = place * rotation_of(&pose[..3]);
            p[..3].copy_from_slice(&axis_angle_of(root));
            let ti = DVec3::new(f64::from(t[0]), f64::from(t[1]), f64::from(t[2]));
            let moved = ta + place_m * (ti - t0);
            (p, [moved.x as f32, moved.y as f32, moved.z as f32])
        })
        .collect();
    Ok(out)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::npz::NpzWriter;
    use std::io::Cursor;

    fn archive(arrays: &[(&str, Vec<u64>, Vec<f32>)]) -> Cursor<Vec<u8>> {
        let mut w = NpzWriter::new(Cursor::new(Vec::new()), false);
        for (key, shape, data) in arrays {
            w.add_f32(key, shape, data).unwrap();
        }
        let mut c = w.finish().unwrap();
        c.set_position(0);
        c
    }

    fn ramp(n: usize, scale: f32) -> Vec<f32> {
        (0..n).map(|k| (k as f32 * 0.37).sin() * scale).collect()
    }

    #[test]
    fn amass_smpl_h_keeps_the_body_joints_and_drops_the_fingers() {
        let n = 4;
        let poses = ramp(n * 156, 0.5);
        let trans = ramp(n * 3, 1.0);
        let m = read_motion_npz(archive(&[
            ("poses", vec![n as u64, 156], poses.clone()),
            ("trans", vec![n as u64, 3], trans.clone()),
            ("mocap_framerate", vec![], vec![120.0]),
        ]))
        .unwrap();
        assert_eq!(m.layout, MotionLayout::Amass);
        assert_eq!(m.len(), n);
        assert_eq!(m.fps, Some(120.0));
        for (k, p) in m.poses.iter().enumerate() {
            assert_eq!(&p[..66], &poses[k * 156..k * 156 + 66]);
            assert!(p[66..].iter().all(|&v| v == 0.0));
        }
        assert_eq!(m.transl[2], [trans[6], trans[7], trans[8]]);
        assert!(m.dropped[0].contains("finger"));
    }

    #[test]
    fn people_snapshot_joins_orientation_and_body_pose() {
        let n = 3;
        let orient = ramp(n * 3, 0.3);
        let body = ramp(n * 69, 0.2);
        let m = read_motion_npz(archive(&[
            ("global_orient", vec![n as u64, 3], orient.clone()),
            ("body_pose", vec![n as u64, 69], body.clone()),
            ("transl", vec![n as u64, 3], ramp(n * 3, 1.0)),
            ("betas", vec![1, 10], vec![0.1; 10]),
        ]))
        .unwrap();
        assert_eq!(m.layout, MotionLayout::PeopleSnapshot);
        assert_eq!(&m.poses[1][..3], &orient[3..6]);
        assert_eq!(&m.poses[1][3..], &body[69..138]);
        assert_eq!(m.betas.as_deref(), Some(&[0.1f32; 10][..]));
    }

    #[test]
    fn wrong_shapes_and_counts_are_refused_naming_the_array() {
        let e = read_motion_npz(archive(&[
            ("poses", vec![4, 70], ramp(280, 0.1)),
            ("trans", vec![4, 3], ramp(12, 0.1)),
        ]))
        .unwrap_err()
        .to_string();
        assert!(e.contains("`poses`") && e.contains("72 or 156"), "{e}");
        let e = read_motion_npz(archive(&[
            ("poses", vec![4, 72], ramp(288, 0.1)),
            ("trans", vec![5, 3], ramp(15, 0.1)),
        ]))
        .unwrap_err()
        .to_string();
        assert!(e.contains("`trans`") && e.contains("(4, 3)"), "{e}");
        let e = read_motion_npz(archive(&[
            ("global_orient", vec![2, 3], ramp(6, 0.1)),
            ("transl", vec![2, 3], ramp(6, 0.1)),
        ]))
        .unwrap_err()
        .to_string();
        assert!(e.contains("body_pose"), "{e}");
        let e = read_motion_npz(archive(&[("x", vec![1], vec![0.0])]))
            .unwrap_err()
            .to_string();
        assert!(e.contains("poses"), "{e}");
        let mut bad = ramp(288, 0.1);
        bad[100] = f32::NAN;
        let e = read_motion_npz(archive(&[
            ("poses", vec![4, 72], bad),
            ("trans", vec![4, 3], ramp(12, 0.1)),
        ]))
        .unwrap_err()
        .to_string();
        assert!(e.contains("`poses`") && e.contains("100"), "{e}");
    }

    fn quat_close(a: DQuat, b: DQuat) -> bool {
        a.dot(b).abs() > 1.0 - 1e-9
    }

    #[test]
    fn anchoring_puts_frame_zero_on_the_anchor_and_keeps_the_relative_motion() {
        // A z-up motion: the body turned upright (+90° about x takes SMPL's y-up rest to z-up),
        // facing some heading, walking 1 m along its world x and rising 0.1 m.
        let upright = DQuat::from_axis_angle(DVec3::X, std::f64::consts::FRAC_PI_2);
        let yaw_z = DQuat::from_axis_angle(DVec3::Z, 0.7);
        let mut poses = Vec::new();
        let mut transl = Vec::new();
        for k in 0..3 {
            let mut p = [0.0f32; 72];
            let r = axis_angle_of(yaw_z * upright);
            p[..3].copy_from_slice(&r);
            p[5] = 0.1 * k as f32;
            poses.push(p);
            transl.push([k as f32 * 0.5, 2.0, 0.9 + 0.05 * k as f32]);
        }
        let motion = Motion {
            layout: MotionLayout::Amass,
            poses,
            transl,
            betas: None,
            fps: None,
            dropped: vec![],
        };
        let mut anchor = [0.0f32; 72];
        anchor[..3].copy_from_slice(&axis_angle_of(DQuat::from_axis_angle(DVec3::Y, -1.2)));
        let at = [0.3, 0.95, 4.0];
        let placed = anchor_motion(&motion, UpAxis::PosZ, &anchor, at).unwrap();
        // Frame 0: the anchor's translation and, facing-wise, its heading; upright in y.
        assert_eq!(placed[0].1, at);
        let r0 = rotation_of(&placed[0].0[..3]);
        assert!((heading(r0) - (-1.2)).abs() < 1e-6);
        assert!(
            (r0 * DVec3::Y - DVec3::Y).length() < 1e-6,
            "upright in the scene"
        );
        // Other joints untouched.
        assert_eq!(placed[2].0[3..], motion.poses[2][3..]);
        // Displacements keep their length, and the rise (file z) becomes scene y.
        let d =
            DVec3::from_array(placed[2].1.map(f64::from)) - DVec3::from_array(at.map(f64::from));
        assert!((d.length() - (1.0f64 + 0.01).sqrt()).abs() < 1e-5, "{d}");
        assert!((d.y - 0.1).abs() < 1e-5, "{d}");
        // Relative rotations between frames are preserved.
        let rel_file =
            rotation_of(&motion.poses[0][..3]).inverse() * rotation_of(&motion.poses[2][..3]);
        let rel_scene = r0.inverse() * rotation_of(&placed[2].0[..3]);
        assert!(quat_close(rel_file, rel_scene));
    }

    #[test]
    fn easymocap_rotates_about_the_origin_and_is_converted_to_smpl_roots() {
        let dir = tempfile::tempdir().unwrap();
        let j0 = [0.01, -0.2, 0.03];
        let rh = [0.3, -0.5, 0.2];
        let th = [1.0, 0.5, 3.0];
        let mut poses = vec![0.0; 72];
        poses[5] = 0.4;
        for (k, name) in [(1, "000001.json"), (0, "000000.json")] {
            let frame = serde_json::json!([
                {"id": 3, "Rh": [[0.0, 0.0, 0.0]], "Th": [[0.0, 0.0, 0.0]], "poses": [vec![0.0; 72]], "shapes": [vec![0.0; 10]]},
                {"id": 0, "Rh": [rh], "Th": [[th[0] + k as f64, th[1], th[2]]], "poses": [poses.clone()], "shapes": [vec![0.5; 10]]}
            ]);
            std::fs::write(dir.path().join(name), frame.to_string()).unwrap();
        }
        let m = read_easymocap(dir.path(), j0, Some(0)).unwrap();
        assert_eq!(m.layout, MotionLayout::EasyMocap);
        assert_eq!(m.len(), 2);
        assert_eq!(m.poses[0][5], 0.4);
        assert_eq!(m.betas.as_deref(), Some(&[0.5f32; 10][..]));
        // A point of the body, placed both ways, lands in the same place.
        let v = DVec3::new(0.2, 0.4, -0.1);
        let r = DQuat::from_scaled_axis(DVec3::from_array(rh));
        let easymocap = r * v + DVec3::from_array(th);
        let smpl_r = rotation_of(&m.poses[0][..3]);
        let smpl = smpl_r * (v - DVec3::from_array(j0))
            + DVec3::from_array(j0)
            + DVec3::from_array(m.transl[0].map(f64::from));
        assert!((easymocap - smpl).length() < 1e-5, "{easymocap} vs {smpl}");
        assert!(
            (m.transl[1][0] - m.transl[0][0] - 1.0).abs() < 1e-5,
            "files in name order"
        );
        // Errors name the file and the field.
        std::fs::write(
            dir.path().join("000002.json"),
            r#"[{"id": 0, "Rh": [[0, 0]], "Th": [[0, 0, 0]], "poses": [[0]]}]"#,
        )
        .unwrap();
        let e = read_easymocap(dir.path(), j0, Some(0))
            .unwrap_err()
            .to_string();
        assert!(e.contains("000002.json") && e.contains("`Rh`"), "{e}");
        let e = read_easymocap(dir.path(), j0, Some(7))
            .unwrap_err()
            .to_string();
        assert!(e.contains("000000.json") && e.contains("id 7"), "{e}");
    }

    #[test]
    fn easymocap_people_are_those_in_every_frame() {
        let dir = tempfile::tempdir().unwrap();
        let person = |id: i64, x: f64| serde_json::json!({"id": id, "Rh": [[0.0, 0.0, 0.0]], "Th": [[x, 0.0, 0.0]], "poses": [vec![0.0; 72]]});
        let frames = [
            serde_json::json!([person(5, 1.0), person(3, 0.0), person(1, 2.0)]),
            serde_json::json!([person(1, 2.5), person(5, 1.5)]),
        ];
        for (k, frame) in frames.iter().enumerate() {
            std::fs::write(dir.path().join(format!("{k:06}.json")), frame.to_string()).unwrap();
        }
        let found = read_easymocap_people(dir.path(), [0.0; 3]).unwrap();
        let ids: Vec<i64> = found.people.iter().map(|(id, _)| *id).collect();
        assert_eq!(
            ids,
            [5, 1],
            "the first frame's order, people of every frame only"
        );
        assert_eq!(found.partial, [(3, 1)]);
        assert_eq!(found.people[1].1.transl[1][0], 2.5);
        assert_eq!(found.people[0].1.len(), 2);
    }

    #[test]
    fn up_axes_parse_and_half_turns_work() {
        assert_eq!(UpAxis::parse("-y"), Some(UpAxis::NegY));
        assert_eq!(UpAxis::parse("+z"), Some(UpAxis::PosZ));
        assert_eq!(UpAxis::parse("w"), None);
        for up in [
            UpAxis::PosX,
            UpAxis::NegX,
            UpAxis::PosY,
            UpAxis::NegY,
            UpAxis::PosZ,
            UpAxis::NegZ,
        ] {
            let v = rotation_to_y(up.vector()) * up.vector();
            assert!((v - DVec3::Y).length() < 1e-12, "{up:?}");
        }
    }
}
