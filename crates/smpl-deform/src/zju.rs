//! One frame's SMPL fit in ZJU-MoCap as ARAH and 3DGS-Avatar preprocess it (`models/NNNNNN.npz`):
//! `root_orient` (3), `pose_body` (63, joints 1–21), `pose_hand` (6, joints 22–23), `trans` (3,
//! metres), `betas` (10); other arrays (`minimal_shape`, `bone_transforms`, …) are not read. Each
//! may be stored flat or with a leading axis of 1. The SMPL pose is the concatenation, in SMPL's
//! joint order.

use std::path::Path;

use crate::error::Result;
use crate::npz::NpzReader;
use crate::skeleton::NUM_JOINTS;

/// One ZJU-MoCap frame's SMPL parameters.
#[derive(Clone, Debug, PartialEq)]
pub struct ZjuModel {
    /// 72 axis-angle values (radians), joint 0 the global orientation.
    pub pose: [f32; 3 * NUM_JOINTS],
    /// SMPL translation (metres, the capture's world frame).
    pub transl: [f32; 3],
    /// Shape coefficients, when the file has them.
    pub betas: Option<Vec<f32>>,
}

/// Reads `path` (see the module documentation); a missing array, a wrong shape or a non-finite
/// value is an error naming the array.
pub fn read_zju_model(path: &Path) -> Result<ZjuModel> {
    let mut npz = NpzReader::open(path)?;
    let mut vector = |key: &str, n: u64| -> Result<Vec<f64>> {
        let (_, data) = npz.read_float(
            key,
            |s| s == [n] || s == [1, n],
            &format!("({n},) or (1, {n})"),
        )?;
        Ok(data)
    };
    let root = vector("root_orient", 3)?;
    let body = vector("pose_body", 63)?;
    let hand = vector("pose_hand", 6)?;
    let trans = vector("trans", 3)?;
    let mut pose = [0.0f32; 3 * NUM_JOINTS];
    for (dst, &src) in pose.iter_mut().zip(root.iter().chain(&body).chain(&hand)) {
        *dst = src as f32;
    }
    let betas = if npz.has("betas") {
        let (_, b) = npz.read_float(
            "betas",
            |s| matches!(s, [n] | [1, n] if (1..=300).contains(n)),
            "(B,) or (1, B) with B ≤ 300",
        )?;
        Some(b.into_iter().map(|v| v as f32).collect())
    } else {
        None
    };
    Ok(ZjuModel {
        pose,
        transl: [trans[0] as f32, trans[1] as f32, trans[2] as f32],
        betas,
    })
}
