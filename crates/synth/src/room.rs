//! The static set: a floor and three walls with procedural textures, and a few props.
//!
//! World frame: metres, y up, floor `y = 0`; the person stands near the origin facing +z, the
//! camera looks from +z. The room spans `x ∈ [−2, 2]`, the back wall is `z = −1.6`, the side walls
//! run to `z = 6`; walls are 2.8 m high. Prop placement and every texture come from the seed.

use glam::Vec3;

use crate::mesh::{Material, Mesh};
use crate::texture;

/// The static part of the scene: geometry and its materials (indices into `materials`).
#[derive(Clone, Debug)]
pub struct Room {
    /// Floor, walls and props.
    pub mesh: Mesh,
    /// Their materials.
    pub materials: Vec<Material>,
}

/// Builds the room from `seed`, with textures of `tex_size` texels per side.
pub fn build(seed: u32, tex_size: usize) -> Room {
    let h = |k: i32| texture::hashf(seed ^ 0x600D, k, 7);
    let mk = |t: texture::Texture| Material {
        texture: t,
        human: false,
    };
    let small = (tex_size / 2).max(64);
    let materials = vec![
        mk(texture::planks(seed ^ 11, tex_size)),
        mk(texture::wallpaper(seed ^ 12, tex_size)),
        mk(texture::bricks(seed ^ 13, tex_size, 0.02 + 0.05 * h(1))),
        mk(texture::bricks(seed ^ 14, tex_size, 0.55 + 0.1 * h(2))),
        mk(texture::checker(
            seed ^ 15,
            small,
            Vec3::new(0.7, 0.6, 0.2),
            Vec3::new(0.15, 0.3, 0.5),
            6,
        )),
        mk(texture::checker(
            seed ^ 16,
            small,
            Vec3::new(0.2, 0.5, 0.25),
            Vec3::new(0.8, 0.8, 0.75),
            4,
        )),
        mk(texture::stripes(
            seed ^ 17,
            small,
            Vec3::new(0.75, 0.3, 0.5),
            Vec3::new(0.1, 0.1, 0.12),
            6,
        )),
    ];
    let (x0, x1, zb, zf, top) = (-2.0f32, 2.0f32, -1.6f32, 6.0f32, 2.8f32);
    let mut mesh = Mesh::default();
    // Floor (normal +y): origin at back-left, edges +x and +z give −y, so use +z then +x.
    mesh.append(&Mesh::quad(
        Vec3::new(x0, 0.0, zb),
        Vec3::Z * (zf - zb),
        Vec3::X * (x1 - x0),
        16,
        8,
        0.5,
        0,
    ));
    // Back wall (normal +z).
    mesh.append(&Mesh::quad(
        Vec3::new(x0, 0.0, zb),
        Vec3::X * (x1 - x0),
        Vec3::Y * top,
        8,
        6,
        0.4,
        1,
    ));
    // Left wall x = x0 (normal +x).
    mesh.append(&Mesh::quad(
        Vec3::new(x0, 0.0, zf),
        Vec3::Z * (zb - zf),
        Vec3::Y * top,
        16,
        6,
        0.5,
        2,
    ));
    // Right wall x = x1 (normal −x).
    mesh.append(&Mesh::quad(
        Vec3::new(x1, 0.0, zb),
        Vec3::Z * (zf - zb),
        Vec3::Y * top,
        16,
        6,
        0.5,
        3,
    ));
    // Props.
    mesh.append(&Mesh::cuboid(
        Vec3::new(-1.3 + 0.2 * h(3), 0.0, -0.9 + 0.2 * h(4)),
        Vec3::new(0.55, 0.5, 0.5),
        0.4 * h(5),
        2.0,
        4,
    ));
    mesh.append(&Mesh::cuboid(
        Vec3::new(1.35 + 0.1 * h(6), 0.0, -1.1 + 0.2 * h(7)),
        Vec3::new(0.4, 1.1, 0.4),
        -0.3 * h(8),
        2.0,
        5,
    ));
    mesh.append(&Mesh::cylinder(
        Vec3::new(-1.25 + 0.1 * h(9), 0.0, 0.9 + 0.2 * h(10)),
        0.18,
        0.75,
        32,
        2.0,
        6,
    ));
    Room { mesh, materials }
}
