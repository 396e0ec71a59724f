//! The SMPL kinematic tree: 24 joint names and the parent list. Both body models (SMPL files and the
//! built-in MakeHuman body) use exactly this tree, so pose vectors are interchangeable between them.

/// Number of joints (bones) of the SMPL skeleton.
pub const NUM_JOINTS: usize = 24;

/// Number of pose-blend-shape features: (R_j − I) flattened row-major for the 23 non-root joints.
pub const NUM_POSE_FEATURES: usize = 9 * (NUM_JOINTS - 1);

/// SMPL joint names in joint order (joint 0 = pelvis = global orientation). "left" is the body's left,
/// which is +x in SMPL's rest frame (x left, y up, z forward).
pub const SMPL_JOINT_NAMES: [&str; NUM_JOINTS] = [
    "pelvis",
    "left_hip",
    "right_hip",
    "spine1",
    "left_knee",
    "right_knee",
    "spine2",
    "left_ankle",
    "right_ankle",
    "spine3",
    "left_foot",
    "right_foot",
    "neck",
    "left_collar",
    "right_collar",
    "head",
    "left_shoulder",
    "right_shoulder",
    "left_elbow",
    "right_elbow",
    "left_wrist",
    "right_wrist",
    "left_hand",
    "right_hand",
];

/// SMPL parent of each joint (`None` for the root). Parents always precede children.
pub const SMPL_PARENTS: [Option<usize>; NUM_JOINTS] = [
    None,
    Some(0),
    Some(0),
    Some(0),
    Some(1),
    Some(2),
    Some(3),
    Some(4),
    Some(5),
    Some(6),
    Some(7),
    Some(8),
    Some(9),
    Some(9),
    Some(9),
    Some(12),
    Some(13),
    Some(14),
    Some(16),
    Some(17),
    Some(18),
    Some(19),
    Some(20),
    Some(21),
];

/// The chain of joints from `joint` up to the root (inclusive at both ends) in `parents`.
pub fn parent_chain(parents: &[Option<usize>], joint: usize) -> Vec<usize> {
    let mut chain = vec![joint];
    let mut j = joint;
    while let Some(p) = parents.get(j).copied().flatten() {
        if chain.len() > parents.len() {
            break; // cycle guard; validated trees never get here
        }
        chain.push(p);
        j = p;
    }
    chain
}
