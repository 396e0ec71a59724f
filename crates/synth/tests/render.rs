#![allow(clippy::unwrap_used)]
//! The mesh renderer and the ground-truth flow against slow, obviously-correct oracles.

use glam::Vec3;
use synth::camera::PinholeCamera;
use synth::flow::{ground_truth_flow, warp_error};
use synth::mesh::{Light, Material, Mesh};
use synth::raster::{render, render_over, StaticSamples, NO_HIT};
use synth::texture::{self, Texture};

fn cam(w: u32, h: u32) -> PinholeCamera {
    PinholeCamera::look_at(
        w,
        h,
        0.8,
        Vec3::new(0.1, 0.2, 3.0),
        Vec3::new(0.0, 0.0, 0.0),
    )
}

fn materials() -> Vec<Material> {
    vec![
        Material {
            texture: texture::wallpaper(3, 64),
            human: false,
        },
        Material {
            texture: Texture {
                width: 1,
                height: 1,
                data: vec![Vec3::new(0.2, 0.5, 0.9)],
            },
            human: true,
        },
    ]
}

const LIGHT: Light = Light {
    to_light: Vec3::new(0.0, 0.0, 1.0),
    ambient: 0.3,
    diffuse: 0.7,
};

/// A textured back plane at z = −1 and a small square at z = 0.5 in front of it.
fn two_planes() -> Mesh {
    let mut m = Mesh::quad(
        Vec3::new(-2.0, -2.0, -1.0),
        Vec3::X * 4.0,
        Vec3::Y * 4.0,
        4,
        4,
        1.0,
        0,
    );
    m.append(&Mesh::quad(
        Vec3::new(-0.3, -0.3, 0.5),
        Vec3::X * 0.6,
        Vec3::Y * 0.6,
        1,
        1,
        1.0,
        1,
    ));
    m
}

/// Oracle: intersect the pixel-centre ray with every triangle (Möller–Trumbore, f64) and keep the
/// nearest hit.
fn ray_cast(mesh: &Mesh, c: &PinholeCamera, x: f64, y: f64) -> Option<(u32, f64)> {
    let r = c.rot_cam_from_world;
    let t = c.t_cam_from_world;
    let d_cam = Vec3::new(
        ((x - f64::from(c.cx)) / f64::from(c.fx)) as f32,
        ((y - f64::from(c.cy)) / f64::from(c.fy)) as f32,
        1.0,
    );
    let rt = r.transpose();
    let o = -(rt * t);
    let d = rt * d_cam;
    let mut best: Option<(u32, f64)> = None;
    for (k, tri) in mesh.tris.iter().enumerate() {
        let [a, b, cc] = tri.map(|i| mesh.positions[i as usize].as_dvec3());
        let (o, d) = (o.as_dvec3(), d.as_dvec3());
        let (e1, e2) = (b - a, cc - a);
        let p = d.cross(e2);
        let det = e1.dot(p);
        if det.abs() < 1e-12 {
            continue;
        }
        let s = o - a;
        let u = s.dot(p) / det;
        let q = s.cross(e1);
        let v = d.dot(q) / det;
        let tt = e2.dot(q) / det;
        if u < -1e-9 || v < -1e-9 || u + v > 1.0 + 1e-9 || tt <= 0.0 {
            continue;
        }
        // Depth along the camera z axis: t times d_cam.z (= 1).
        if best.is_none_or(|(_, z)| tt < z) {
            best = Some((k as u32, tt));
        }
    }
    best
}

#[test]
fn gbuffer_matches_ray_casting_oracle() {
    let (w, h) = (24u32, 20u32);
    let c = cam(w, h);
    let mesh = two_planes();
    let r = render(&mesh, &materials(), &c, &LIGHT, 3);
    let mut bad = Vec::new();
    for j in 0..h as usize {
        for i in 0..w as usize {
            let k = j * w as usize + i;
            let oracle = ray_cast(&mesh, &c, i as f64 + 0.5, j as f64 + 0.5);
            let got =
                (r.gbuf.tri[k] != NO_HIT).then(|| (r.gbuf.tri[k], f64::from(r.gbuf.depth[k])));
            match (oracle, got) {
                (None, None) => {}
                (Some((_, zo)), Some((tg, zg))) => {
                    // Shared edges may go to either triangle of the same plane: compare depth, and
                    // that the barycentric point reproduces the depth.
                    if (zo - zg).abs() > 1e-4 * zo {
                        bad.push(format!("({i},{j}): depth {zg} vs oracle {zo}"));
                    }
                    let b = r.gbuf.bary[k];
                    let vi = mesh.tris[tg as usize].map(|v| mesh.positions[v as usize]);
                    let p = vi[0] * b[0] + vi[1] * b[1] + vi[2] * b[2];
                    let pc = c.cam_from_world(p);
                    let px = c.pixel_from_cam(pc);
                    if (px[0] - (i as f32 + 0.5)).abs() > 1e-3
                        || (px[1] - (j as f32 + 0.5)).abs() > 1e-3
                    {
                        bad.push(format!("({i},{j}): barycentric point projects to {px:?}"));
                    }
                }
                (o, g) => bad.push(format!("({i},{j}): hit {g:?} vs oracle {o:?}")),
            }
        }
    }
    assert!(
        bad.is_empty(),
        "{} mismatches:\n{}",
        bad.len(),
        bad.join("\n")
    );
}

#[test]
fn flat_colour_and_supersampled_edges() {
    let (w, h) = (24u32, 20u32);
    let c = cam(w, h);
    let mesh = two_planes();
    let r = render(&mesh, &materials(), &c, &LIGHT, 3);
    let n = (w * h) as usize;
    // Inside the front square: albedo × (ambient + diffuse · n·l), n·l = cos of the view angle of
    // +z seen from the camera (the light is +z in world, the normal +z).
    let k = (h as usize / 2) * w as usize + w as usize / 2;
    assert!(r.gbuf.tri[k] as usize >= mesh.tris.len() - 2);
    let want = Vec3::new(0.2, 0.5, 0.9) * (0.3 + 0.7);
    for ch in 0..3 {
        assert!(
            (r.rgb[ch * n + k] - want[ch]).abs() < 1e-5,
            "channel {ch}: {} vs {}",
            r.rgb[ch * n + k],
            want[ch]
        );
    }
    // Supersampling gives intermediate values on the square's edges: count pixels strictly between
    // the square's colour and the background's in the blue channel.
    let mixed = (0..n)
        .filter(|&i| {
            let tri = r.gbuf.tri[i];
            tri != NO_HIT && {
                let b = r.rgb[2 * n + i];
                b > 0.0 && b < 0.9 && mesh.tri_material[tri as usize] == 1
            }
        })
        .count();
    assert!(mixed > 0, "no anti-aliased edge pixels");
}

#[test]
fn render_is_thread_count_independent() {
    let c = cam(40, 30);
    let mesh = two_planes();
    let mats = materials();
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    let two = rayon::ThreadPoolBuilder::new()
        .num_threads(3)
        .build()
        .unwrap();
    let a = one.install(|| render(&mesh, &mats, &c, &LIGHT, 3));
    let b = two.install(|| render(&mesh, &mats, &c, &LIGHT, 3));
    assert_eq!(a, b);
}

#[test]
fn near_plane_clipping_keeps_the_visible_part() {
    // A floor running from behind the camera to far in front of it.
    let c = PinholeCamera::look_at(
        32,
        32,
        1.2,
        Vec3::new(0.0, 1.0, 0.0),
        Vec3::new(0.0, 0.6, -3.0),
    );
    let mesh = Mesh::quad(
        Vec3::new(-3.0, 0.0, 3.0),
        Vec3::Z * -10.0,
        Vec3::X * 6.0,
        1,
        1,
        1.0,
        0,
    );
    let r = render(&mesh, &materials(), &c, &LIGHT, 1);
    // Every pixel below the horizon ray sees the floor.
    let mut bad = 0;
    for j in 0..32usize {
        for i in 0..32usize {
            let hit = ray_cast(&mesh, &c, i as f64 + 0.5, j as f64 + 0.5).is_some();
            if hit != (r.gbuf.tri[j * 32 + i] != NO_HIT) {
                bad += 1;
            }
        }
    }
    assert_eq!(bad, 0);
}

#[test]
fn flow_of_a_translated_plane_is_its_projection_and_warps_back() {
    // Back plane static, front square moves by 0.05 m in x between the frames.
    let (w, h) = (48u32, 40u32);
    let c = cam(w, h);
    let m0 = two_planes();
    let mut m1 = m0.clone();
    let nback = m0.positions.len() - 4;
    for p in &mut m1.positions[nback..] {
        *p += Vec3::new(0.05, 0.0, 0.0);
    }
    let mats = vec![
        Material {
            texture: texture::wallpaper(5, 128),
            human: false,
        },
        Material {
            texture: texture::checker(9, 64, Vec3::splat(0.1), Vec3::splat(0.8), 4),
            human: true,
        },
    ];
    let r0 = render(&m0, &mats, &c, &LIGHT, 3);
    let r1 = render(&m1, &mats, &c, &LIGHT, 3);
    let (flow, valid) = ground_truth_flow(
        (&c, &c),
        &m0.tris,
        &m0.positions,
        &m1.positions,
        &r0.gbuf,
        &r1.gbuf,
    );
    let n = (w * h) as usize;
    let (mut front, mut back_invalid) = (0, 0);
    for i in 0..n {
        let t = r0.gbuf.tri[i];
        if t == NO_HIT {
            continue;
        }
        let is_front = t as usize >= m0.tris.len() - 2;
        if is_front {
            // Oracle: project the moved point directly.
            let b = r0.gbuf.bary[i];
            let vi = m0.tris[t as usize].map(|v| v as usize);
            let p0 = m0.positions[vi[0]] * b[0]
                + m0.positions[vi[1]] * b[1]
                + m0.positions[vi[2]] * b[2];
            let q0 = c.pixel_from_cam(c.cam_from_world(p0));
            let q1 = c.pixel_from_cam(c.cam_from_world(p0 + Vec3::new(0.05, 0.0, 0.0)));
            assert!(
                (flow[i] - (q1[0] - q0[0])).abs() < 1e-3
                    && (flow[n + i] - (q1[1] - q0[1])).abs() < 1e-3
            );
            assert!(flow[i] > 0.5, "the square moves right: flow {}", flow[i]);
            assert!(valid[i]);
            front += 1;
        } else {
            assert_eq!(flow[i], 0.0);
            assert_eq!(flow[n + i], 0.0);
            if !valid[i] {
                back_invalid += 1;
            }
        }
    }
    assert!(front > 20);
    // The background strip the square moves onto is hidden at k+1 (disocclusion in reverse).
    assert!(
        back_invalid > 0,
        "no occluded background pixels marked invalid"
    );
    let (warp, identity, count) =
        warp_error(&r0.rgb, &r1.rgb, &flow, &valid, w as usize, h as usize);
    assert!(count > 0);
    assert!(
        warp < 0.5 * identity,
        "warp error {warp} not well below zero-flow error {identity}"
    );
}

#[test]
fn rendering_over_cached_static_samples_is_bit_identical_to_a_full_render() {
    let c = cam(40, 30);
    let mats = materials();
    let back = Mesh::quad(
        Vec3::new(-2.0, -2.0, -1.0),
        Vec3::X * 4.0,
        Vec3::Y * 4.0,
        4,
        4,
        1.0,
        0,
    );
    let base = StaticSamples::new(&back, &mats, &c, &LIGHT, 3);
    assert_eq!(base.triangle_count(), back.tris.len());
    // The moving quad in front, sliding across, and coplanar with the back plane (every sample a
    // depth tie, which the static triangles must win as in a full render).
    for (dx, z) in [(0.0, 0.5), (0.37, 0.2), (-1.1, -0.4), (0.25, -1.0)] {
        let mut mesh = back.clone();
        mesh.append(&Mesh::quad(
            Vec3::new(-0.3 + dx, -0.3, z),
            Vec3::X * 0.6,
            Vec3::Y * 0.6,
            2,
            1,
            1.0,
            1,
        ));
        let full = render(&mesh, &mats, &c, &LIGHT, 3);
        let over = render_over(&base, &mesh, &mats, &c, &LIGHT, 3);
        assert!(full.gbuf.tri.iter().any(|&t| t as usize >= back.tris.len()) || z == -1.0);
        assert_eq!(full, over, "offset {dx}, depth {z}");
    }
    // A base that does not fit (other supersampling) falls back to a full render.
    let mut mesh = back.clone();
    mesh.append(&two_planes());
    assert_eq!(
        render_over(&base, &mesh, &mats, &c, &LIGHT, 1),
        render(&mesh, &mats, &c, &LIGHT, 1)
    );
}
