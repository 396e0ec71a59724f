//! Ground-truth optical flow from the mesh motion, its validity mask, and the photometric check.
//!
//! For the pixel-centre sample of pixel x at frame k, the visible surface point is
//! `P = Σ bᵢ Vᵢ(t_k)` (triangle and perspective-correct barycentrics from the G-buffer). The same
//! material point at frame k+1 is `Σ bᵢ Vᵢ(t_{k+1})` (same triangle, same barycentrics: vertices
//! move, topology does not), and the flow is the difference of the two projections, in pixels:
//! `x_{k+1} = x_k + F(x_k)` (DESIGN.md §3), each point projected by the camera of its frame (the
//! same camera twice when it is static). The flow is *valid* when the point lands inside the
//! image, in front of the camera, and is not hidden at k+1: its depth is at most the depth seen by
//! the pixel it lands in plus a tolerance, or that pixel sees the same triangle.

use glam::Vec3;
use rayon::prelude::*;

use crate::camera::PinholeCamera;
use crate::raster::{GBuffer, NEAR, NO_HIT};

/// Relative depth tolerance of the occlusion test.
pub const DEPTH_TOL_REL: f32 = 0.01;
/// Absolute depth tolerance of the occlusion test (metres).
pub const DEPTH_TOL_ABS: f32 = 0.02;

/// Forward flow `(2, H, W)` planar (pixels) and validity (row-major).
pub fn ground_truth_flow(
    (cam_k, cam_next): (&PinholeCamera, &PinholeCamera),
    tris: &[[u32; 3]],
    pos_k: &[Vec3],
    pos_next: &[Vec3],
    gbuf_k: &GBuffer,
    gbuf_next: &GBuffer,
) -> (Vec<f32>, Vec<bool>) {
    let (w, h) = (gbuf_k.width, gbuf_k.height);
    let n = w * h;
    let per_px: Vec<(f32, f32, bool)> = (0..n)
        .into_par_iter()
        .map(|i| {
            let t = gbuf_k.tri[i];
            if t == NO_HIT {
                return (0.0, 0.0, false);
            }
            let b = gbuf_k.bary[i];
            let vi = tris[t as usize].map(|v| v as usize);
            let at = |pos: &[Vec3]| pos[vi[0]] * b[0] + pos[vi[1]] * b[1] + pos[vi[2]] * b[2];
            let (c0, c1) = (
                cam_k.cam_from_world(at(pos_k)),
                cam_next.cam_from_world(at(pos_next)),
            );
            if c0.z < NEAR || c1.z < NEAR {
                return (0.0, 0.0, false);
            }
            let (p0, p1) = (cam_k.pixel_from_cam(c0), cam_next.pixel_from_cam(c1));
            let (u, v) = (p1[0] - p0[0], p1[1] - p0[1]);
            let inside = p1[0] >= 0.0 && p1[1] >= 0.0 && p1[0] < w as f32 && p1[1] < h as f32;
            if !inside {
                return (u, v, false);
            }
            let j = p1[1] as usize * w + p1[0] as usize;
            let visible = gbuf_next.tri[j] == t
                || c1.z <= gbuf_next.depth[j] + DEPTH_TOL_REL * c1.z + DEPTH_TOL_ABS;
            (u, v, visible)
        })
        .collect();
    let mut flow = vec![0.0f32; 2 * n];
    let mut valid = vec![false; n];
    for (i, (u, v, ok)) in per_px.into_iter().enumerate() {
        flow[i] = u;
        flow[n + i] = v;
        valid[i] = ok;
    }
    (flow, valid)
}

/// Bilinear sample of a planar `(C, H, W)` image at continuous pixel coordinates (centres at
/// `i + 0.5`), clamped at the border.
pub fn sample_bilinear(img: &[f32], w: usize, h: usize, c: usize, x: f32, y: f32) -> f32 {
    let (fx, fy) = (
        (x - 0.5).clamp(0.0, (w - 1) as f32),
        (y - 0.5).clamp(0.0, (h - 1) as f32),
    );
    let (x0, y0) = (fx.floor() as usize, fy.floor() as usize);
    let (x1, y1) = ((x0 + 1).min(w - 1), (y0 + 1).min(h - 1));
    let (ax, ay) = (fx - x0 as f32, fy - y0 as f32);
    let p = &img[c * w * h..(c + 1) * w * h];
    let top = p[y0 * w + x0] * (1.0 - ax) + p[y0 * w + x1] * ax;
    let bot = p[y1 * w + x0] * (1.0 - ax) + p[y1 * w + x1] * ax;
    top * (1.0 - ay) + bot * ay
}

/// Photometric check: mean absolute difference (linear RGB, over channels and valid pixels) between
/// frame k and frame k+1 warped back by the flow, and the same with zero flow on the same pixels
/// (the baseline the flow must beat), and the number of pixels used.
pub fn warp_error(
    img_k: &[f32],
    img_next: &[f32],
    flow: &[f32],
    valid: &[bool],
    w: usize,
    h: usize,
) -> (f64, f64, usize) {
    let n = w * h;
    let (mut e_warp, mut e_id, mut count) = (0.0f64, 0.0f64, 0usize);
    for i in 0..n {
        if !valid[i] {
            continue;
        }
        let (x, y) = ((i % w) as f32 + 0.5, (i / w) as f32 + 0.5);
        for c in 0..3 {
            let a = img_k[c * n + i];
            let warped = sample_bilinear(img_next, w, h, c, x + flow[i], y + flow[n + i]);
            e_warp += f64::from((warped - a).abs());
            e_id += f64::from((img_next[c * n + i] - a).abs());
        }
        count += 1;
    }
    let d = (3 * count.max(1)) as f64;
    (e_warp / d, e_id / d, count)
}
