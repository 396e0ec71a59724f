//! The benchmark's people: the first one dancing on the spot near the origin (the one-person
//! benchmark's), and with `--people N` up to three more who cross the room in front of and behind
//! it while they dance, so that they occlude each other and the first one.
//!
//! Every extra person has its own clothes (textures drawn from the texture seed and its number),
//! its own motion phases and its own shape when the body model has shape blend shapes (an SMPL
//! `.npz`; the built-in body has none, so its people differ by clothes, motion and path only).
//! Their random draws come from streams of their own, so the first person — and a one-person
//! benchmark — keeps its bytes.

use glam::Vec3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::body::{DressedBody, NUM_REGIONS};
use crate::mesh::{Material, Mesh};
use crate::motion::Motion;
use crate::raster::{GBuffer, NO_HIT};
use crate::Result;

/// Most people a benchmark holds.
pub const MAX_PEOPLE: u32 = 4;

/// The paths of the extra people: (depth z of the path, metres; direction of walking, ±1). The
/// camera looks from +z, so a larger z is nearer the camera: person 1 crosses in front of the first
/// person, person 2 behind, person 3 in front again, the other way.
const PATHS: [(f32, f32); 3] = [(0.75, 1.0), (-0.7, -1.0), (0.4, -1.0)];

/// Half the distance an extra person walks over the clip (metres), centred on x = 0.
const HALF_WALK_M: f32 = 0.7;

/// One person of the benchmark.
#[derive(Clone, Debug)]
pub struct Person {
    /// The dressed body (with this person's shape).
    pub body: DressedBody,
    /// Where and how it moves.
    pub motion: Motion,
    /// Index of its first material in the scene's material list.
    pub material_base: u16,
}

impl Person {
    /// Pose (72 axis-angle values) and translation (metres) at time `t` (seconds).
    pub fn at(&self, t: f64) -> (Vec<f32>, [f32; 3]) {
        self.motion.at(t)
    }

    /// The posed mesh at time `t`.
    pub fn mesh_at(&self, t: f64) -> Result<Mesh> {
        let (pose, transl) = self.motion.at(t);
        let verts = self.body.posed_vertices(&pose, transl)?;
        Ok(self.body.mesh(verts, self.material_base))
    }
}

/// The extra people 1..`count` of a benchmark whose first person is `first` (its body and motion),
/// on a clip of `duration_s` seconds; `texture_seed` as the first person's clothes, `seed` the
/// generator's. Their materials are appended to `materials` (after the first person's).
pub fn extra_people(
    first: &Person,
    count: u32,
    (seed, texture_seed): (u64, u32),
    duration_s: f64,
    materials: &mut Vec<Material>,
) -> Result<Vec<Person>> {
    let mut out = Vec::new();
    for p in 1..count.min(MAX_PEOPLE) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x9E01_0000 ^ u64::from(p));
        let model = first.body.model.clone();
        let betas: Vec<f32> = if model.num_betas > 0 {
            (0..model.num_betas.min(10))
                .map(|_| rng.gen_range(-1.5f32..1.5))
                .collect()
        } else {
            Vec::new()
        };
        let body = DressedBody::new(model, betas)?;
        let (depth, direction) = PATHS[(p - 1) as usize];
        let speed = 2.0 * HALF_WALK_M / duration_s.max(1e-3) as f32;
        let motion = Motion {
            phases: std::array::from_fn(|_| rng.gen_range(0.0..std::f32::consts::TAU)),
            base: [first.motion.base[0] - direction * HALF_WALK_M, depth],
            walk: [direction * speed, 0.0],
            floor_offset: body.floor_offset,
            ..first.motion
        };
        let material_base = u16::try_from(materials.len()).unwrap_or(u16::MAX);
        let clothes = texture_seed ^ (0x5EED_0000 | p);
        materials.extend(DressedBody::materials_of_palette(clothes, p));
        out.push(Person {
            body,
            motion,
            material_base,
        });
    }
    Ok(out)
}

/// Per material, 0 for the scene's and `p + 1` for person `p`'s (each person owns
/// [`NUM_REGIONS`] materials from its `material_base`).
pub fn person_of_material(material_count: usize, people: &[Person]) -> Vec<u8> {
    let mut of = vec![0u8; material_count];
    for (p, person) in people.iter().enumerate() {
        let base = usize::from(person.material_base);
        for m in of.iter_mut().skip(base).take(NUM_REGIONS) {
            *m = u8::try_from(p + 1).unwrap_or(u8::MAX);
        }
    }
    of
}

/// Which person each pixel of a render shows (0 = scene, `p + 1` = person `p`), from its G-buffer
/// and the mesh it rendered.
pub fn person_ids(gbuf: &GBuffer, mesh: &Mesh, person_of_material: &[u8]) -> Vec<u8> {
    gbuf.tri
        .iter()
        .map(|&t| {
            if t == NO_HIT {
                0
            } else {
                person_of_material[usize::from(mesh.tri_material[t as usize])]
            }
        })
        .collect()
}

/// The mean of a person's posed vertices at time `t` (world metres): where it stands.
pub fn centre_at(person: &Person, t: f64) -> Result<Vec3> {
    let (pose, transl) = person.at(t);
    let v = person.body.posed_vertices(&pose, transl)?;
    Ok(v.iter().fold(Vec3::ZERO, |a, x| a + *x) / v.len().max(1) as f32)
}
