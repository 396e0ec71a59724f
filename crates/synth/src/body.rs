//! The person: a `smpl-deform` body model dressed with procedural clothing, posed into a [`Mesh`].
//!
//! Clothing regions come from the skinning weights (the dominant SMPL joint of each vertex): torso,
//! collars and upper arms wear the shirt, pelvis and legs the trousers, ankles and feet the shoes,
//! forearms, hands, neck and face are skin, and the top and back of the head is hair. Texture
//! coordinates are cylindrical in the rest pose (around the vertical axis for torso, legs and head,
//! around the arm's axis for arms), so stripes and weaves move rigidly with the surface, which is
//! what makes the ground-truth flow checkable photometrically. The body model's own UVs are not
//! needed.

use glam::{Vec2, Vec3};
use smpl_deform::{BodyModel, SmplParams, NUM_JOINTS, SMPL_PARENTS};

use crate::error::Result;
use crate::mesh::{Material, Mesh};
use crate::texture;

/// Clothing region of a body vertex or triangle.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Region {
    /// Plaid shirt (torso, collars, upper arms).
    Shirt = 0,
    /// Plaid trousers (pelvis, thighs, shins).
    Trousers = 1,
    /// Skin (neck, face, forearms, hands).
    Skin = 2,
    /// Hair (top and back of the head).
    Hair = 3,
    /// Shoes (ankles, feet).
    Shoes = 4,
}

/// Number of [`Region`]s (materials used by the body).
pub const NUM_REGIONS: usize = 5;

/// A dressed body, ready to be posed.
#[derive(Clone, Debug)]
pub struct DressedBody {
    /// The body model.
    pub model: BodyModel,
    /// Shape coefficients used for every pose.
    pub betas: Vec<f32>,
    /// Region of each triangle.
    pub tri_region: Vec<Region>,
    /// Texture coordinates of each triangle's corners.
    pub tri_uv: Vec<[Vec2; 3]>,
    /// Height (metres) to add to the translation so the rest pose's lowest vertex touches `y = 0`.
    pub floor_offset: f32,
}

fn dominant_joint(weights: &[f32]) -> usize {
    let mut best = 0;
    for j in 1..weights.len() {
        if weights[j] > weights[best] {
            best = j;
        }
    }
    best
}

impl DressedBody {
    /// Dresses `model` (rest shape after `betas`).
    pub fn new(model: BodyModel, betas: Vec<f32>) -> Result<Self> {
        let rest: Vec<Vec3> = model
            .shaped_vertices(&betas)?
            .into_iter()
            .map(Vec3::from)
            .collect();
        let joints: Vec<Vec3> = model
            .rest_joints(&rest.iter().map(|v| v.to_array()).collect::<Vec<_>>())
            .into_iter()
            .map(Vec3::from)
            .collect();
        let head = joints[15];
        let nv = rest.len();
        // Per-vertex region and UV chart.
        let mut region = Vec::with_capacity(nv);
        let mut arm = Vec::with_capacity(nv);
        let mut axis_centre = Vec::with_capacity(nv);
        for v in 0..nv {
            let j = dominant_joint(&model.weights[v * NUM_JOINTS..(v + 1) * NUM_JOINTS]);
            let p = rest[v];
            let r = match j {
                0 | 1 | 2 | 4 | 5 => Region::Trousers,
                7 | 8 | 10 | 11 => Region::Shoes,
                3 | 6 | 9 | 13 | 14 | 16 | 17 => Region::Shirt,
                15 => {
                    let d = p - head;
                    if d.y > 0.06 || (d.z < -0.02 && d.y > -0.06) {
                        Region::Hair
                    } else {
                        Region::Skin
                    }
                }
                _ => Region::Skin,
            };
            region.push(r);
            let is_arm = matches!(j, 16..=23);
            arm.push(is_arm);
            let c = match j {
                16..=23 => {
                    if j.is_multiple_of(2) {
                        joints[16]
                    } else {
                        joints[17]
                    }
                }
                1 | 4 | 7 | 10 => joints[1],
                2 | 5 | 8 | 11 => joints[2],
                12 | 15 => head,
                _ => joints[0],
            };
            axis_centre.push(c);
        }
        let chart = |v: usize, arm_chart: bool, c: Vec3| {
            let p = rest[v];
            let tau = std::f32::consts::TAU;
            if arm_chart {
                let d = p - c;
                Vec2::new(d.z.atan2(d.y) / tau + 0.5, p.x.abs() * 2.0)
            } else {
                let d = p - c;
                Vec2::new(d.x.atan2(d.z) / tau + 0.5, p.y * 2.0)
            }
        };
        let mut tri_region = Vec::with_capacity(model.faces.len());
        let mut tri_uv = Vec::with_capacity(model.faces.len());
        for f in &model.faces {
            let [a, b, c] = f.map(|i| i as usize);
            let r = if region[b] == region[c] {
                region[b]
            } else {
                region[a]
            };
            tri_region.push(r);
            // One chart per triangle (that of its first vertex) keeps the corners consistent.
            let (arm_chart, centre) = (arm[a], axis_centre[a]);
            let mut uv = [a, b, c].map(|v| chart(v, arm_chart, centre));
            let (umin, umax) = uv.iter().fold((f32::MAX, f32::MIN), |(lo, hi), t| {
                (lo.min(t.x), hi.max(t.x))
            });
            if umax - umin > 0.5 {
                for t in &mut uv {
                    if t.x < 0.5 {
                        t.x += 1.0;
                    }
                }
            }
            tri_uv.push(uv);
        }
        let zero = SmplParams {
            pose: vec![0.0; 3 * NUM_JOINTS],
            betas: betas.clone(),
            transl: [0.0; 3],
        };
        let posed = model.pose(&zero)?;
        let min_y = posed
            .vertices
            .iter()
            .map(|v| v[1])
            .fold(f32::INFINITY, f32::min);
        Ok(Self {
            model,
            betas,
            tri_region,
            tri_uv,
            floor_offset: -min_y,
        })
    }

    /// The clothing materials, in [`Region`] order, from `seed`.
    pub fn materials(seed: u32) -> Vec<Material> {
        let h = |k: i32| texture::hashf(seed ^ 0xB0D1, k, 0);
        let shirt_a = Vec3::new(0.6 + 0.3 * h(1), 0.15 + 0.2 * h(2), 0.1);
        let trousers_a = Vec3::new(0.08, 0.14, 0.35 + 0.1 * h(3));
        Self::materials_in(seed, shirt_a, trousers_a)
    }

    /// The materials of an extra person of a benchmark (`crate::cast`): [`DressedBody::materials`]
    /// with the shirt and trousers of palette `palette` (1, 2, 3: green and grey, blue and brown,
    /// purple and olive), so that people are told apart by their clothes.
    pub fn materials_of_palette(seed: u32, palette: u32) -> Vec<Material> {
        let (shirt_a, trousers_a) = match palette % 3 {
            1 => (Vec3::new(0.1, 0.55, 0.2), Vec3::new(0.3, 0.3, 0.32)),
            2 => (Vec3::new(0.15, 0.3, 0.75), Vec3::new(0.35, 0.2, 0.08)),
            _ => (Vec3::new(0.5, 0.12, 0.6), Vec3::new(0.3, 0.35, 0.1)),
        };
        Self::materials_in(seed, shirt_a, trousers_a)
    }

    /// The five materials with the given main shirt and trouser colours.
    fn materials_in(seed: u32, shirt_a: Vec3, trousers_a: Vec3) -> Vec<Material> {
        let size = 256;
        let shirt_b = Vec3::new(0.85, 0.82, 0.7);
        let mats = [
            texture::plaid(seed ^ 1, size, shirt_a, shirt_b, 6),
            texture::plaid(seed ^ 2, size, trousers_a, Vec3::new(0.8, 0.74, 0.55), 8),
            texture::mottled(seed ^ 3, size, Vec3::new(0.62, 0.42, 0.32), 0.12, false),
            texture::mottled(seed ^ 4, size, Vec3::new(0.12, 0.07, 0.04), 0.4, true),
            texture::checker(seed ^ 5, size, Vec3::splat(0.06), Vec3::splat(0.5), 8),
        ];
        mats.into_iter()
            .map(|texture| Material {
                texture,
                human: true,
            })
            .collect()
    }

    /// Posed vertices (world metres) for `pose` (72 axis-angle values) and `transl` (metres).
    pub fn posed_vertices(&self, pose: &[f32], transl: [f32; 3]) -> Result<Vec<Vec3>> {
        let p = self.model.pose(&SmplParams {
            pose: pose.to_vec(),
            betas: self.betas.clone(),
            transl,
        })?;
        Ok(p.vertices.into_iter().map(Vec3::from).collect())
    }

    /// The posed body as a mesh with smooth normals; body materials start at `material_base`.
    pub fn mesh(&self, vertices: Vec<Vec3>, material_base: u16) -> Mesh {
        let mut m = Mesh {
            normals: vec![Vec3::Y; vertices.len()],
            positions: vertices,
            tris: self.model.faces.clone(),
            tri_uv: self.tri_uv.clone(),
            tri_material: self
                .tri_region
                .iter()
                .map(|&r| material_base + r as u16)
                .collect(),
        };
        m.smooth_normals_from(0, 0);
        m
    }
}

/// A crude 24-joint figure of tapered boxes on the SMPL tree (rest T-pose, y up, feet at `y ≈ 0`,
/// facing +z), rigidly skinned. For tests that must not depend on the body asset; the benchmark
/// uses `builtin:makehuman`.
pub fn capsule_body() -> BodyModel {
    let j: [[f32; 3]; NUM_JOINTS] = [
        [0.0, 0.95, 0.0],
        [0.09, 0.88, 0.0],
        [-0.09, 0.88, 0.0],
        [0.0, 1.05, 0.0],
        [0.1, 0.5, 0.0],
        [-0.1, 0.5, 0.0],
        [0.0, 1.18, 0.0],
        [0.1, 0.09, -0.02],
        [-0.1, 0.09, -0.02],
        [0.0, 1.28, 0.0],
        [0.1, 0.02, 0.1],
        [-0.1, 0.02, 0.1],
        [0.0, 1.48, 0.0],
        [0.07, 1.42, 0.0],
        [-0.07, 1.42, 0.0],
        [0.0, 1.6, 0.0],
        [0.18, 1.42, 0.0],
        [-0.18, 1.42, 0.0],
        [0.45, 1.42, 0.0],
        [-0.45, 1.42, 0.0],
        [0.7, 1.42, 0.0],
        [-0.7, 1.42, 0.0],
        [0.78, 1.42, 0.0],
        [-0.78, 1.42, 0.0],
    ];
    let mut v_template = Vec::new();
    let mut faces = Vec::new();
    let mut weights = Vec::new();
    // One box per bone (parent -> child), skinned to the parent; the head gets its own box.
    let mut bones: Vec<(usize, Vec3, Vec3, f32)> = Vec::new();
    for c in 1..NUM_JOINTS {
        let Some(p) = SMPL_PARENTS[c] else { continue };
        let r = match c {
            3 | 6 | 9 => 0.15,
            1 | 2 => 0.08,
            4 | 5 | 7 | 8 => 0.06,
            12 => 0.05,
            _ => 0.04,
        };
        bones.push((p, Vec3::from(j[p]), Vec3::from(j[c]), r));
    }
    bones.push((
        15,
        Vec3::from(j[15]) - Vec3::Y * 0.05,
        Vec3::from(j[15]) + Vec3::Y * 0.17,
        0.09,
    ));
    for (bone, a, b, r) in bones {
        let axis = (b - a).normalize_or(Vec3::Y);
        let side = if axis.y.abs() > 0.9 { Vec3::X } else { Vec3::Y };
        let u = axis.cross(side).normalize() * r;
        let w = axis.cross(u).normalize() * r;
        let base = v_template.len() as u32;
        for end in [a, b] {
            for (su, sw) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
                v_template.push((end + u * su + w * sw).to_array());
                let mut row = [0.0f32; NUM_JOINTS];
                row[bone] = 1.0;
                weights.extend_from_slice(&row);
            }
        }
        let quads = [
            [0, 1, 5, 4],
            [1, 2, 6, 5],
            [2, 3, 7, 6],
            [3, 0, 4, 7],
            [3, 2, 1, 0],
            [4, 5, 6, 7],
        ];
        for q in quads {
            faces.push([base + q[0], base + q[1], base + q[2]]);
            faces.push([base + q[0], base + q[2], base + q[3]]);
        }
    }
    BodyModel {
        v_template,
        faces,
        uv: None,
        joints_rest: j.to_vec(),
        weights,
        parents: SMPL_PARENTS.to_vec(),
        shapedirs: None,
        num_betas: 0,
        posedirs: None,
        j_regressor: None,
    }
}
