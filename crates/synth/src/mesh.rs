//! Triangle meshes for the benchmark renderer, materials, the light, and builders for the room's
//! primitives (subdivided quads, boxes, cylinders).
//!
//! World frame: metres, y up (the SMPL rest convention), the floor is `y = 0`. Texture coordinates
//! are stored per triangle corner, in texture repeats (1.0 = one texture width), so a surface can
//! tile a texture and a cylindrical map can avoid seams.

use glam::{Vec2, Vec3};

use crate::texture::Texture;

/// A triangle mesh in world space.
#[derive(Clone, Debug, Default)]
pub struct Mesh {
    /// Vertex positions (world, metres).
    pub positions: Vec<Vec3>,
    /// Unit vertex normals (world), pointing to the lit side.
    pub normals: Vec<Vec3>,
    /// Triangles (vertex indices).
    pub tris: Vec<[u32; 3]>,
    /// Texture coordinates of each triangle's corners (texture repeats).
    pub tri_uv: Vec<[Vec2; 3]>,
    /// Material index of each triangle.
    pub tri_material: Vec<u16>,
}

/// A surface material: an albedo texture and whether it belongs to the person.
#[derive(Clone, Debug)]
pub struct Material {
    /// Albedo (linear RGB).
    pub texture: Texture,
    /// True for the person's surfaces (the human mask).
    pub human: bool,
}

/// Lambert + ambient lighting from one directional light.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Light {
    /// Unit direction towards the light (world).
    pub to_light: Vec3,
    /// Ambient term (fraction of albedo).
    pub ambient: f32,
    /// Diffuse term at normal incidence (fraction of albedo).
    pub diffuse: f32,
}

impl Mesh {
    /// Appends `other` (indices shifted).
    pub fn append(&mut self, other: &Mesh) {
        let base = self.positions.len() as u32;
        self.positions.extend_from_slice(&other.positions);
        self.normals.extend_from_slice(&other.normals);
        self.tris
            .extend(other.tris.iter().map(|t| t.map(|i| i + base)));
        self.tri_uv.extend_from_slice(&other.tri_uv);
        self.tri_material.extend_from_slice(&other.tri_material);
    }

    /// A flat quad `origin + a·edge_u + b·edge_v`, `a, b ∈ [0, 1]`, split into `nu × nv` cells of
    /// two triangles each; texture coordinates are metres along the edges times `repeats_per_m`.
    /// The normal is `edge_u × edge_v` normalised (counter-clockwise when seen from it).
    pub fn quad(
        origin: Vec3,
        edge_u: Vec3,
        edge_v: Vec3,
        nu: u32,
        nv: u32,
        repeats_per_m: f32,
        material: u16,
    ) -> Mesh {
        let normal = edge_u.cross(edge_v).normalize();
        let mut m = Mesh::default();
        let (lu, lv) = (edge_u.length(), edge_v.length());
        for j in 0..=nv {
            for i in 0..=nu {
                let (a, b) = (i as f32 / nu as f32, j as f32 / nv as f32);
                m.positions.push(origin + a * edge_u + b * edge_v);
                m.normals.push(normal);
            }
        }
        let idx = |i: u32, j: u32| j * (nu + 1) + i;
        let uv = |i: u32, j: u32| {
            Vec2::new(
                i as f32 / nu as f32 * lu * repeats_per_m,
                j as f32 / nv as f32 * lv * repeats_per_m,
            )
        };
        for j in 0..nv {
            for i in 0..nu {
                m.tris.push([idx(i, j), idx(i + 1, j), idx(i + 1, j + 1)]);
                m.tri_uv.push([uv(i, j), uv(i + 1, j), uv(i + 1, j + 1)]);
                m.tris.push([idx(i, j), idx(i + 1, j + 1), idx(i, j + 1)]);
                m.tri_uv.push([uv(i, j), uv(i + 1, j + 1), uv(i, j + 1)]);
                m.tri_material.extend([material, material]);
            }
        }
        m
    }

    /// An axis-aligned box standing on `y = base.y`, centred at `base.x, base.z`, rotated by `yaw`
    /// (radians about +y); five faces (no bottom), outward normals.
    pub fn cuboid(base: Vec3, size: Vec3, yaw: f32, repeats_per_m: f32, material: u16) -> Mesh {
        let (s, c) = yaw.sin_cos();
        let rot = |v: Vec3| Vec3::new(c * v.x + s * v.z, v.y, -s * v.x + c * v.z);
        let h = size * 0.5;
        let corner = |x: f32, y: f32, z: f32| base + rot(Vec3::new(x * h.x, y * size.y, z * h.z));
        let faces = [
            // (origin, edge_u, edge_v): counter-clockwise seen from outside.
            (corner(-1.0, 0.0, 1.0), Vec3::X * size.x, Vec3::Y * size.y), // +z
            (corner(1.0, 0.0, -1.0), -Vec3::X * size.x, Vec3::Y * size.y), // -z
            (corner(1.0, 0.0, 1.0), -Vec3::Z * size.z, Vec3::Y * size.y), // +x
            (corner(-1.0, 0.0, -1.0), Vec3::Z * size.z, Vec3::Y * size.y), // -x
            (corner(-1.0, 1.0, 1.0), Vec3::X * size.x, -Vec3::Z * size.z), // top
        ];
        let mut m = Mesh::default();
        for (o, eu, ev) in faces {
            let n = ((size.x.max(size.z)) * 4.0).ceil() as u32;
            m.append(&Mesh::quad(
                o,
                rot(eu),
                rot(ev),
                n,
                n,
                repeats_per_m,
                material,
            ));
        }
        m
    }

    /// A vertical cylinder (side and top) standing on `base`, with smooth side normals.
    pub fn cylinder(
        base: Vec3,
        radius: f32,
        height: f32,
        segments: u32,
        repeats_per_m: f32,
        material: u16,
    ) -> Mesh {
        let mut m = Mesh::default();
        let circ = std::f32::consts::TAU * radius;
        for j in 0..=1u32 {
            for i in 0..=segments {
                let a = i as f32 / segments as f32 * std::f32::consts::TAU;
                let n = Vec3::new(a.cos(), 0.0, a.sin());
                m.positions
                    .push(base + n * radius + Vec3::Y * height * j as f32);
                m.normals.push(n);
            }
        }
        let uv = |i: u32, j: u32| {
            Vec2::new(
                i as f32 / segments as f32 * circ * repeats_per_m,
                j as f32 * height * repeats_per_m,
            )
        };
        let s1 = segments + 1;
        for i in 0..segments {
            m.tris.push([i, i + s1 + 1, i + 1]);
            m.tri_uv.push([uv(i, 0), uv(i + 1, 1), uv(i + 1, 0)]);
            m.tris.push([i, i + s1, i + s1 + 1]);
            m.tri_uv.push([uv(i, 0), uv(i, 1), uv(i + 1, 1)]);
            m.tri_material.extend([material, material]);
        }
        // Top cap: a fan around a centre vertex.
        let centre = m.positions.len() as u32;
        m.positions.push(base + Vec3::Y * height);
        m.normals.push(Vec3::Y);
        let first = m.positions.len() as u32;
        for i in 0..=segments {
            let a = i as f32 / segments as f32 * std::f32::consts::TAU;
            m.positions
                .push(base + Vec3::new(a.cos() * radius, height, a.sin() * radius));
            m.normals.push(Vec3::Y);
        }
        let cuv = |i: u32| {
            let a = i as f32 / segments as f32 * std::f32::consts::TAU;
            Vec2::new(a.cos(), a.sin()) * radius * repeats_per_m
        };
        for i in 0..segments {
            m.tris.push([centre, first + i + 1, first + i]);
            m.tri_uv.push([Vec2::ZERO, cuv(i + 1), cuv(i)]);
            m.tri_material.push(material);
        }
        m
    }

    /// Recomputes smooth vertex normals (area-weighted face normals) for the vertex range
    /// `start..`, using only triangles whose first vertex lies in that range.
    pub fn smooth_normals_from(&mut self, start: usize, first_tri: usize) {
        let mut acc = vec![Vec3::ZERO; self.positions.len() - start];
        for t in &self.tris[first_tri..] {
            let [a, b, c] = t.map(|i| self.positions[i as usize]);
            let n = (b - a).cross(c - a);
            for &i in t {
                acc[i as usize - start] += n;
            }
        }
        for (k, n) in acc.into_iter().enumerate() {
            self.normals[start + k] = n.normalize_or(Vec3::Y);
        }
    }
}
