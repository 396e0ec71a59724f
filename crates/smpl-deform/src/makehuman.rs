//! Conversion of the CC0 MakeHuman assets (hm08 base mesh + game-engine rig and weights) into a body
//! model on the SMPL 24-joint tree. Run once by `cargo xtask body-convert`; the result is committed
//! under `data-fixtures/body/`. This module must never run at pose time.
//!
//! # What the conversion does
//! 1. Reads `base.obj` with tobj (triangulated), keeps the `body` group (the closed skin surface:
//!    13380 vertices, 13378 quads → 26756 triangles, no boundary edges) with its UVs. tobj reindexes a
//!    group's vertices in order of first use, so the original vertex index of each body vertex (which
//!    the weights refer to) is recovered by exact coordinate match against the file's `v` records
//!    (body positions are unique; an ambiguity is an error).
//! 2. Units and axes: the OBJ is in decimetres, y up, facing +z, the body's left at +x, which is SMPL's
//!    frame; positions are scaled by 0.1 to metres, nothing is rotated.
//! 3. Joints: each rig bone's head is the mean of the vertices of its `joint-*` helper cube in the OBJ
//!    (the rig's `CUBE` strategy). SMPL joint positions are the heads of these bones:
//!
//!    | SMPL joint | MakeHuman bone(s) (weights summed) | joint position |
//!    |---|---|---|
//!    | 0 pelvis | pelvis (+ Root, which has no weights) | head of pelvis |
//!    | 1/2 left/right_hip | thigh_l / thigh_r | head |
//!    | 3 spine1 | spine_01 | head |
//!    | 4/5 left/right_knee | calf_l / calf_r | head |
//!    | 6 spine2 | spine_02 | head |
//!    | 7/8 left/right_ankle | foot_l / foot_r | head |
//!    | 9 spine3 | spine_03 | head |
//!    | 10/11 left/right_foot | ball_l / ball_r | head |
//!    | 12 neck | neck_01 | head |
//!    | 13/14 left/right_collar | clavicle_l / clavicle_r | head |
//!    | 15 head | head | head |
//!    | 16/17 left/right_shoulder | upperarm_l / upperarm_r | head |
//!    | 18/19 left/right_elbow | lowerarm_l / lowerarm_r | head |
//!    | 20/21 left/right_wrist | hand_l / hand_r | head |
//!    | 22/23 left/right_hand | thumb/index/middle/ring/pinky_01..03 of that side | mean of the heads of index_01, middle_01, ring_01, pinky_01 (the knuckles) |
//!
//!    The game-engine parent of every mapped bone is the bone mapped to the SMPL parent (checked), so
//!    the tree is SMPL's.
//! 4. Weights: per body vertex, the summed weights of the mapped bones, normalised to sum 1. Vertices
//!    without any weight (none in the shipped assets; checked) are an error.
//! 5. Rest pose: MakeHuman's rest pose has the arms down at ~45° (A-pose) while SMPL's rest is a
//!    T-pose, so SMPL pose vectors would mean something else. The converter rotates each shoulder about
//!    the forward (z) axis until the upper arm (shoulder→elbow, projected on the xy plane) is
//!    horizontal, and each elbow about z until the forearm is horizontal, skins the mesh with these
//!    two rotations, and stores the result (vertices and joints) as the rest pose.

use std::collections::HashMap;
use std::path::Path;

use crate::body::{BodyModel, SmplParams, UvMap};
use crate::error::{Result, SmplDeformError};
use crate::skeleton::{NUM_JOINTS, SMPL_PARENTS};

/// MakeHuman game-engine bone → SMPL joint index (finger bones map to the hand joints 22/23).
pub fn bone_to_smpl_joint(bone: &str) -> Option<usize> {
    let j = match bone {
        "Root" | "pelvis" => 0,
        "thigh_l" => 1,
        "thigh_r" => 2,
        "spine_01" => 3,
        "calf_l" => 4,
        "calf_r" => 5,
        "spine_02" => 6,
        "foot_l" => 7,
        "foot_r" => 8,
        "spine_03" => 9,
        "ball_l" => 10,
        "ball_r" => 11,
        "neck_01" => 12,
        "clavicle_l" => 13,
        "clavicle_r" => 14,
        "head" => 15,
        "upperarm_l" => 16,
        "upperarm_r" => 17,
        "lowerarm_l" => 18,
        "lowerarm_r" => 19,
        "hand_l" => 20,
        "hand_r" => 21,
        other => {
            let finger = ["thumb_", "index_", "middle_", "ring_", "pinky_"]
                .iter()
                .any(|p| other.starts_with(p));
            if finger && other.ends_with("_l") {
                22
            } else if finger && other.ends_with("_r") {
                23
            } else {
                return None;
            }
        }
    };
    Some(j)
}

/// The MakeHuman bone whose head is the SMPL joint's position (hands 22/23 use the knuckles).
const JOINT_BONES: [&str; 22] = [
    "pelvis",
    "thigh_l",
    "thigh_r",
    "spine_01",
    "calf_l",
    "calf_r",
    "spine_02",
    "foot_l",
    "foot_r",
    "spine_03",
    "ball_l",
    "ball_r",
    "neck_01",
    "clavicle_l",
    "clavicle_r",
    "head",
    "upperarm_l",
    "upperarm_r",
    "lowerarm_l",
    "lowerarm_r",
    "hand_l",
    "hand_r",
];

/// Decimetres → metres.
const UNIT_SCALE: f32 = 0.1;

fn conv(msg: impl Into<String>) -> SmplDeformError {
    SmplDeformError::Conversion(msg.into())
}

fn json_str<'a>(v: &'a serde_json::Value, key: &str) -> Option<&'a str> {
    v.get(key).and_then(|x| x.as_str())
}

/// Converts the MakeHuman assets in `dir` (`base.obj`, `rig.game_engine.json`,
/// `weights.game_engine.json`) into a T-posed body on the SMPL tree (see the module docs).
pub fn convert_makehuman(dir: &Path) -> Result<BodyModel> {
    let obj_path = dir.join("base.obj");
    let io = |path: &Path| {
        let path = path.to_path_buf();
        move |source| SmplDeformError::Io { path, source }
    };
    let obj_text = std::fs::read_to_string(&obj_path).map_err(io(&obj_path))?;
    let rig_path = dir.join("rig.game_engine.json");
    let rig: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&rig_path).map_err(io(&rig_path))?)
            .map_err(|e| conv(format!("{}: {e}", rig_path.display())))?;
    let weights_path = dir.join("weights.game_engine.json");
    let wjson: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&weights_path).map_err(io(&weights_path))?)
            .map_err(|e| conv(format!("{}: {e}", weights_path.display())))?;

    // Global `v` records, for recovering original indices.
    let mut global_index: HashMap<[u32; 3], usize> = HashMap::new();
    let mut ambiguous = std::collections::HashSet::new();
    let mut nv_global = 0usize;
    for line in obj_text.lines() {
        let Some(rest) = line.strip_prefix("v ") else {
            continue;
        };
        let mut it = rest.split_whitespace().map(str::parse::<f32>);
        let (Some(Ok(x)), Some(Ok(y)), Some(Ok(z))) = (it.next(), it.next(), it.next()) else {
            return Err(conv(format!("bad vertex record `{line}`")));
        };
        if global_index
            .insert([x.to_bits(), y.to_bits(), z.to_bits()], nv_global)
            .is_some()
        {
            ambiguous.insert([x.to_bits(), y.to_bits(), z.to_bits()]);
        }
        nv_global += 1;
    }

    let (models, _) = tobj::load_obj_buf(
        &mut std::io::BufReader::new(obj_text.as_bytes()),
        &tobj::LoadOptions {
            triangulate: true,
            single_index: false,
            ignore_points: true,
            ignore_lines: true,
        },
        |_| Ok((Vec::new(), Default::default())),
    )
    .map_err(|e| conv(format!("{}: {e}", obj_path.display())))?;

    let body = models
        .iter()
        .find(|m| m.name == "body")
        .ok_or_else(|| conv("no `body` group in base.obj"))?;
    let mesh = &body.mesh;
    let nv = mesh.positions.len() / 3;
    let mut local_to_global = Vec::with_capacity(nv);
    for p in mesh.positions.chunks_exact(3) {
        let key = [p[0].to_bits(), p[1].to_bits(), p[2].to_bits()];
        if ambiguous.contains(&key) {
            return Err(conv(format!("body vertex {p:?} occurs twice in base.obj")));
        }
        let g = global_index
            .get(&key)
            .ok_or_else(|| conv(format!("body vertex {p:?} not found in `v` records")))?;
        local_to_global.push(*g);
    }
    let mut global_to_local = vec![usize::MAX; nv_global];
    for (l, &g) in local_to_global.iter().enumerate() {
        global_to_local[g] = l;
    }
    let v_template: Vec<[f32; 3]> = mesh
        .positions
        .chunks_exact(3)
        .map(|p| [p[0] * UNIT_SCALE, p[1] * UNIT_SCALE, p[2] * UNIT_SCALE])
        .collect();
    let faces: Vec<[u32; 3]> = mesh
        .indices
        .chunks_exact(3)
        .map(|f| [f[0], f[1], f[2]])
        .collect();
    let uv = if !mesh.texcoords.is_empty() && mesh.texcoord_indices.len() == mesh.indices.len() {
        Some(UvMap {
            vt: mesh
                .texcoords
                .chunks_exact(2)
                .map(|t| [t[0], t[1]])
                .collect(),
            ft: mesh
                .texcoord_indices
                .chunks_exact(3)
                .map(|f| [f[0], f[1], f[2]])
                .collect(),
        })
    } else {
        None
    };

    // Joint cube centres.
    let cube_centre = |name: &str| -> Result<[f32; 3]> {
        let m = models
            .iter()
            .find(|m| m.name == name)
            .ok_or_else(|| conv(format!("no group `{name}` in base.obj")))?;
        let n = m.mesh.positions.len() / 3;
        if n == 0 {
            return Err(conv(format!("group `{name}` has no vertices")));
        }
        let mut c = [0.0f64; 3];
        for p in m.mesh.positions.chunks_exact(3) {
            for k in 0..3 {
                c[k] += f64::from(p[k]);
            }
        }
        Ok(c.map(|x| (x / n as f64) as f32 * UNIT_SCALE))
    };
    let bones = rig
        .as_object()
        .ok_or_else(|| conv("rig.game_engine.json is not an object"))?;
    let bone_head = |bone: &str| -> Result<[f32; 3]> {
        let b = bones
            .get(bone)
            .ok_or_else(|| conv(format!("rig has no bone `{bone}`")))?;
        let cube = b
            .get("head")
            .and_then(|h| json_str(h, "cube_name"))
            .ok_or_else(|| conv(format!("bone `{bone}` head has no cube_name")))?;
        cube_centre(cube)
    };
    let mut joints_a = vec![[0.0f32; 3]; NUM_JOINTS];
    for (j, bone) in JOINT_BONES.iter().enumerate() {
        joints_a[j] = bone_head(bone)?;
        // The rig's parent must map to the SMPL parent.
        if j > 0 {
            let parent = bones
                .get(*bone)
                .and_then(|b| json_str(b, "parent"))
                .ok_or_else(|| conv(format!("bone `{bone}` has no parent")))?;
            if bone_to_smpl_joint(parent) != SMPL_PARENTS[j] {
                return Err(conv(format!(
                    "bone `{bone}` has parent `{parent}`, which does not map to SMPL joint {:?}",
                    SMPL_PARENTS[j]
                )));
            }
        }
    }
    for (j, side) in [(22usize, "l"), (23, "r")] {
        let mut c = [0.0f32; 3];
        for f in ["index", "middle", "ring", "pinky"] {
            let h = bone_head(&format!("{f}_01_{side}"))?;
            for k in 0..3 {
                c[k] += h[k] / 4.0;
            }
        }
        joints_a[j] = c;
    }

    // Weights.
    let wmap = wjson
        .get("weights")
        .and_then(|w| w.as_object())
        .ok_or_else(|| conv("weights.game_engine.json has no `weights` object"))?;
    let mut weights = vec![0.0f64; nv * NUM_JOINTS];
    for (bone, list) in wmap {
        let j = bone_to_smpl_joint(bone)
            .ok_or_else(|| conv(format!("bone `{bone}` has no SMPL joint")))?;
        let list = list
            .as_array()
            .ok_or_else(|| conv(format!("weights of `{bone}` are not a list")))?;
        for pair in list {
            let (Some(vi), Some(w)) = (
                pair.get(0).and_then(|x| x.as_u64()),
                pair.get(1).and_then(|x| x.as_f64()),
            ) else {
                return Err(conv(format!("bad weight entry {pair} of `{bone}`")));
            };
            let vi = vi as usize;
            if vi >= nv_global {
                return Err(conv(format!(
                    "weight of `{bone}` on vertex {vi} out of range"
                )));
            }
            let l = global_to_local[vi];
            if l != usize::MAX {
                weights[l * NUM_JOINTS + j] += w;
            }
        }
    }
    let mut weights_f32 = vec![0.0f32; nv * NUM_JOINTS];
    for v in 0..nv {
        let row = &weights[v * NUM_JOINTS..(v + 1) * NUM_JOINTS];
        let s: f64 = row.iter().sum();
        if !(s > 0.0) {
            return Err(conv(format!(
                "body vertex {} has no skinning weight",
                local_to_global[v]
            )));
        }
        for j in 0..NUM_JOINTS {
            weights_f32[v * NUM_JOINTS + j] = (row[j] / s) as f32;
        }
    }

    let a_pose = BodyModel {
        v_template,
        faces,
        uv,
        joints_rest: joints_a,
        weights: weights_f32,
        parents: SMPL_PARENTS.to_vec(),
        shapedirs: None,
        num_betas: 0,
        posedirs: None,
        j_regressor: None,
    };
    let mut body = to_t_pose(&a_pose)?;
    orient_faces_outward(&mut body);
    Ok(body)
}

/// Angle (radians, about +z) that rotates the xy-projection of `d` onto the direction `target_x`
/// (±1 along x).
fn angle_to_horizontal(d: [f32; 3], target_x: f32) -> f32 {
    let (dx, dy) = (f64::from(d[0]), f64::from(d[1]));
    let tx = f64::from(target_x);
    // atan2(cross_z(d, t), dot(d, t)) with t = (tx, 0).
    (-dy * tx).atan2(dx * tx) as f32
}

fn sub(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn rot_z(phi: f32, d: [f32; 3]) -> [f32; 3] {
    let (s, c) = phi.sin_cos();
    [c * d[0] - s * d[1], s * d[0] + c * d[1], d[2]]
}

/// Raises the arms of an A-posed body to a T-pose (see the module docs) and returns the new rest.
fn to_t_pose(a_pose: &BodyModel) -> Result<BodyModel> {
    let j = &a_pose.joints_rest;
    let mut params = SmplParams::zero();
    for (shoulder, elbow, wrist, tx) in [(16usize, 18usize, 20usize, 1.0f32), (17, 19, 21, -1.0)] {
        let phi = angle_to_horizontal(sub(j[elbow], j[shoulder]), tx);
        let fore = rot_z(phi, sub(j[wrist], j[elbow]));
        let psi = angle_to_horizontal(fore, tx);
        params.pose[3 * shoulder + 2] = phi;
        params.pose[3 * elbow + 2] = psi;
    }
    let posed = a_pose.pose(&params)?;
    let mut t = a_pose.clone();
    t.v_template = posed.vertices;
    t.joints_rest = posed.joints;
    Ok(t)
}

/// Flips every face if the mesh's signed volume is negative (so faces wind counter-clockwise seen
/// from outside).
fn orient_faces_outward(body: &mut BodyModel) {
    if signed_volume(&body.v_template, &body.faces) < 0.0 {
        for f in &mut body.faces {
            f.swap(1, 2);
        }
        if let Some(uv) = &mut body.uv {
            for f in &mut uv.ft {
                f.swap(1, 2);
            }
        }
    }
}

/// Signed volume (m³) enclosed by a triangle mesh (positive for outward, CCW faces).
pub fn signed_volume(vertices: &[[f32; 3]], faces: &[[u32; 3]]) -> f64 {
    let mut vol = 0.0f64;
    for f in faces {
        let [a, b, c] = f.map(|i| vertices[i as usize].map(f64::from));
        vol += a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0])
            + a[2] * (b[0] * c[1] - b[1] * c[0]);
    }
    vol / 6.0
}
