//! The benchmark's triangle-mesh renderer, independent of the Gaussian rasterizer so a model can
//! never fit its own renderer's quirks.
//!
//! z-buffered rasterization with perspective-correct barycentric interpolation, near-plane
//! clipping, bilinear texture lookup, Lambert + ambient shading (two-sided), and `ss × ss`
//! supersampling on a regular grid (sample centres at `((a + 0.5) / ss, (b + 0.5) / ss)` inside each
//! pixel). Pixel (i, j) covers `[i, i+1) × [j, j+1)` in continuous pixel coordinates (centre
//! `(i + 0.5, j + 0.5)`, DESIGN.md §3). Rows are processed in bands in parallel with rayon; every
//! sample is resolved by its own depth test with ties going to the lower triangle index, so the
//! image is identical for any thread count.
//!
//! Besides the colour, the renderer returns a G-buffer of the pixel-centre sample (the middle
//! sample; `ss` must be odd): the visible triangle, its perspective-correct barycentrics and depth,
//! which is what ground-truth flow and masks are computed from.

use glam::{Vec2, Vec3};
use rayon::prelude::*;

use crate::camera::PinholeCamera;
use crate::mesh::{Light, Material, Mesh};

/// Triangle id of a pixel that sees nothing.
pub const NO_HIT: u32 = u32::MAX;
/// Near clipping plane (metres, camera z).
pub const NEAR: f32 = 0.05;
/// Pixel rows per parallel band.
const BAND: usize = 4;

/// What the pixel-centre sample of each pixel sees.
#[derive(Clone, Debug, PartialEq)]
pub struct GBuffer {
    /// Width (pixels).
    pub width: usize,
    /// Height (pixels).
    pub height: usize,
    /// Visible triangle per pixel (row-major), [`NO_HIT`] for none.
    pub tri: Vec<u32>,
    /// Perspective-correct barycentrics of the visible point in that triangle.
    pub bary: Vec<[f32; 3]>,
    /// Camera depth z of the visible point (metres; +∞ for none).
    pub depth: Vec<f32>,
}

/// A rendered frame.
#[derive(Clone, Debug, PartialEq)]
pub struct Render {
    /// Planar `(3, H, W)` linear RGB, the mean of the `ss²` samples of each pixel.
    pub rgb: Vec<f32>,
    /// Centre-sample geometry.
    pub gbuf: GBuffer,
}

/// One band's output: colours, centre-sample triangles, barycentrics, depths.
type Band = (Vec<[f32; 3]>, Vec<u32>, Vec<[f32; 3]>, Vec<f32>);

/// A triangle after clipping and projection.
#[derive(Clone, Copy)]
struct ScreenTri {
    /// Index of the source triangle.
    tri: u32,
    /// Screen positions in sample units (pixel coordinates × ss).
    p: [Vec2; 3],
    /// 1 / z per corner.
    iz: [f32; 3],
    /// Barycentrics of each corner in the source triangle.
    attr: [Vec3; 3],
    /// 1 / (signed doubled area).
    inv_area: f32,
    /// Bounding box in samples (inclusive ranges of sample indices).
    x0: i64,
    x1: i64,
    y0: i64,
    y1: i64,
}

fn setup(
    p_cam: &[Vec3],
    tri: u32,
    vi: [u32; 3],
    ss: f32,
    cam: &PinholeCamera,
    wmax: i64,
    hmax: i64,
) -> [Option<ScreenTri>; 2] {
    let pc = vi.map(|i| p_cam[i as usize]);
    let corner_attr = [Vec3::X, Vec3::Y, Vec3::Z];
    // Clip the polygon against z >= NEAR (Sutherland–Hodgman, one plane).
    let mut poly = [(Vec3::ZERO, Vec3::ZERO); 4];
    let mut len = 0;
    let mut push = |v: (Vec3, Vec3)| {
        poly[len] = v;
        len += 1;
    };
    if pc.iter().all(|p| p.z >= NEAR) {
        for k in 0..3 {
            push((pc[k], corner_attr[k]));
        }
    } else if pc.iter().all(|p| p.z < NEAR) {
        return [None, None];
    } else {
        for k in 0..3 {
            let (a, b) = (
                (pc[k], corner_attr[k]),
                (pc[(k + 1) % 3], corner_attr[(k + 1) % 3]),
            );
            let (ina, inb) = (a.0.z >= NEAR, b.0.z >= NEAR);
            if ina {
                push(a);
            }
            if ina != inb {
                let t = (NEAR - a.0.z) / (b.0.z - a.0.z);
                push((a.0.lerp(b.0, t), a.1.lerp(b.1, t)));
            }
        }
    }
    let project = |p: Vec3| {
        let [u, v] = cam.pixel_from_cam(p);
        Vec2::new(u * ss, v * ss)
    };
    let mut out = [None, None];
    for k in 1..len.saturating_sub(1) {
        let c = [poly[0], poly[k], poly[k + 1]];
        let p = c.map(|(q, _)| project(q));
        let area = (p[1] - p[0]).perp_dot(p[2] - p[0]);
        if area.abs() < 1e-12 || !area.is_finite() {
            continue;
        }
        let minx = p[0].x.min(p[1].x).min(p[2].x);
        let maxx = p[0].x.max(p[1].x).max(p[2].x);
        let miny = p[0].y.min(p[1].y).min(p[2].y);
        let maxy = p[0].y.max(p[1].y).max(p[2].y);
        // Sample s has its centre at s + 0.5.
        let x0 = ((minx - 0.5).ceil() as i64).max(0);
        let x1 = ((maxx - 0.5).floor() as i64).min(wmax - 1);
        let y0 = ((miny - 0.5).ceil() as i64).max(0);
        let y1 = ((maxy - 0.5).floor() as i64).min(hmax - 1);
        if x0 > x1 || y0 > y1 {
            continue;
        }
        out[k - 1] = Some(ScreenTri {
            tri,
            p,
            iz: c.map(|(q, _)| 1.0 / q.z),
            attr: c.map(|(_, a)| a),
            inv_area: 1.0 / area,
            x0,
            x1,
            y0,
            y1,
        });
    }
    out
}

/// Renders `mesh` with `materials` seen by `cam` under `light`, with `ss × ss` samples per pixel
/// (`ss` odd, ≥ 1). Pixels that see nothing are black.
pub fn render(
    mesh: &Mesh,
    materials: &[Material],
    cam: &PinholeCamera,
    light: &Light,
    ss: usize,
) -> Render {
    render_impl(mesh, materials, cam, light, ss, None)
}

/// The samples of the static part of a scene (the first [`StaticSamples::triangle_count`]
/// triangles of every mesh later rendered over it), rasterized and shaded once so that frames whose
/// only moving geometry comes after them re-rasterize just that geometry ([`render_over`]).
///
/// Per sample (row-major over the `W·ss × H·ss` sample grid): camera depth (+∞ for none), source
/// triangle ([`NO_HIT`] for none), perspective-correct barycentrics and shaded linear RGB.
#[derive(Clone, Debug)]
pub struct StaticSamples {
    width: usize,
    height: usize,
    ss: usize,
    triangle_count: usize,
    depth: Vec<f32>,
    tri: Vec<u32>,
    bary: Vec<Vec3>,
    colour: Vec<Vec3>,
}

impl StaticSamples {
    /// Rasterizes and shades `static_mesh` (all of its triangles) as [`render`] would.
    pub fn new(
        static_mesh: &Mesh,
        materials: &[Material],
        cam: &PinholeCamera,
        light: &Light,
        ss: usize,
    ) -> Self {
        let (w, h) = (cam.width as usize, cam.height as usize);
        let ss = ss.max(1) | 1;
        let ctx = ShadeContext::new(static_mesh, materials, cam, light, ss);
        let stris = screen_triangles(static_mesh, cam, ss, 0);
        let bins = bin_by_band(&stris, h, ss);
        let bands: Vec<SampleBand> = bins
            .par_iter()
            .enumerate()
            .map(|(b, bin)| band_samples(&stris, bin, w, ss, b, BAND.min(h - b * BAND), None))
            .collect();
        let bw = w * ss;
        let mut out = Self {
            width: w,
            height: h,
            ss,
            triangle_count: static_mesh.tris.len(),
            depth: Vec::with_capacity(bw * h * ss),
            tri: Vec::with_capacity(bw * h * ss),
            bary: Vec::with_capacity(bw * h * ss),
            colour: Vec::with_capacity(bw * h * ss),
        };
        for (b, band) in bands.into_iter().enumerate() {
            let sy0 = b * BAND * ss;
            for (k, &t) in band.tri.iter().enumerate() {
                let (sx, sy) = (k % bw, sy0 + k / bw);
                out.colour.push(if t == NO_HIT {
                    Vec3::ZERO
                } else {
                    ctx.shade(t as usize, band.bary[k], sx, sy)
                });
            }
            out.depth.extend(band.depth);
            out.tri.extend(band.tri);
            out.bary.extend(band.bary);
        }
        out
    }

    /// Number of static triangles: the first this many triangles of a mesh rendered over these
    /// samples must be exactly the static mesh's.
    pub fn triangle_count(&self) -> usize {
        self.triangle_count
    }
}

/// [`render`] of `mesh`, whose first [`StaticSamples::triangle_count`] triangles are the static
/// mesh `base` was made from (same positions, normals, UVs and materials, same camera, light and
/// `ss`), re-rasterizing only the triangles after them. The result is bit-identical to
/// `render(mesh, ...)`: the static triangles have the lowest indices, so they are the ones a full
/// render would have rasterized first, and every shaded sample is computed by the same expression.
/// Falls back to [`render`] when `base` does not fit (other size, `ss` or more static triangles than
/// `mesh` has).
pub fn render_over(
    base: &StaticSamples,
    mesh: &Mesh,
    materials: &[Material],
    cam: &PinholeCamera,
    light: &Light,
    ss: usize,
) -> Render {
    let fits = base.width == cam.width as usize
        && base.height == cam.height as usize
        && base.ss == (ss.max(1) | 1)
        && base.triangle_count <= mesh.tris.len();
    render_impl(mesh, materials, cam, light, ss, fits.then_some(base))
}

/// Everything shading a sample needs, in camera space.
struct ShadeContext<'a> {
    mesh: &'a Mesh,
    materials: &'a [Material],
    cam: &'a PinholeCamera,
    light: &'a Light,
    ss: usize,
    l_cam: Vec3,
    n_cam: Vec<Vec3>,
}

impl<'a> ShadeContext<'a> {
    fn new(
        mesh: &'a Mesh,
        materials: &'a [Material],
        cam: &'a PinholeCamera,
        light: &'a Light,
        ss: usize,
    ) -> Self {
        Self {
            mesh,
            materials,
            cam,
            light,
            ss,
            l_cam: cam.cam_dir_from_world(light.to_light).normalize(),
            n_cam: mesh
                .normals
                .iter()
                .map(|&n| cam.cam_dir_from_world(n))
                .collect(),
        }
    }

    /// Shaded linear RGB of the sample `(sx, sy)` (sample grid coordinates) that sees triangle `t`
    /// at barycentrics `bc`: albedo × (ambient + diffuse · two-sided Lambert).
    fn shade(&self, t: usize, bc: Vec3, sx: usize, sy: usize) -> Vec3 {
        let (mesh, cam, ss) = (self.mesh, self.cam, self.ss);
        let uvs = mesh.tri_uv[t];
        let uv = uvs[0] * bc.x + uvs[1] * bc.y + uvs[2] * bc.z;
        let [i0, i1, i2] = mesh.tris[t].map(|i| i as usize);
        let n_cam = &self.n_cam;
        let mut n = (n_cam[i0] * bc.x + n_cam[i1] * bc.y + n_cam[i2] * bc.z).normalize_or(Vec3::Z);
        // View ray through the sample, camera space.
        let ray = Vec3::new(
            ((sx as f32 + 0.5) / ss as f32 - cam.cx) / cam.fx,
            ((sy as f32 + 0.5) / ss as f32 - cam.cy) / cam.fy,
            1.0,
        );
        if n.dot(ray) > 0.0 {
            n = -n;
        }
        let lambert = n.dot(self.l_cam).max(0.0);
        let m = &self.materials[mesh.tri_material[t] as usize];
        let albedo = m.texture.sample(uv.x, uv.y);
        albedo * (self.light.ambient + self.light.diffuse * lambert)
    }
}

/// The sample buffers of one band of [`BAND`] pixel rows: depth, source triangle, barycentrics.
struct SampleBand {
    depth: Vec<f32>,
    tri: Vec<u32>,
    bary: Vec<Vec3>,
}

/// Triangles of `mesh` from index `first_tri` on, clipped to the near plane and projected to the
/// sample grid, in triangle order (a clipped triangle may give two).
fn screen_triangles(
    mesh: &Mesh,
    cam: &PinholeCamera,
    ss: usize,
    first_tri: usize,
) -> Vec<ScreenTri> {
    let (w, h) = (cam.width as usize, cam.height as usize);
    let (sw, sh) = ((w * ss) as i64, (h * ss) as i64);
    let p_cam: Vec<Vec3> = mesh
        .positions
        .par_iter()
        .map(|&p| cam.cam_from_world(p))
        .collect();
    mesh.tris
        .par_iter()
        .enumerate()
        .skip(first_tri)
        .flat_map_iter(|(t, &vi)| {
            setup(&p_cam, t as u32, vi, ss as f32, cam, sw, sh)
                .into_iter()
                .flatten()
        })
        .collect()
}

/// Indices into `stris` of the triangles touching each band of [`BAND`] pixel rows, in order.
fn bin_by_band(stris: &[ScreenTri], h: usize, ss: usize) -> Vec<Vec<u32>> {
    let band_samples = (BAND * ss) as i64;
    let mut bins: Vec<Vec<u32>> = vec![Vec::new(); h.div_ceil(BAND)];
    for (i, st) in stris.iter().enumerate() {
        for b in (st.y0 / band_samples)..=(st.y1 / band_samples) {
            bins[b as usize].push(i as u32);
        }
    }
    bins
}

/// Rasterizes the triangles `bin` (indices into `stris`) into band `b` (`rows` pixel rows from
/// pixel row `b · BAND`, `width` pixels), starting from `base`'s samples when given, else from
/// empty ones. A sample keeps the nearest triangle; at equal depth the one met first (the lower
/// index) stays.
fn band_samples(
    stris: &[ScreenTri],
    bin: &[u32],
    width: usize,
    ss: usize,
    b: usize,
    rows: usize,
    base: Option<&StaticSamples>,
) -> SampleBand {
    let (bw, bh) = (width * ss, rows * ss);
    let start = b * BAND * ss * bw;
    let mut sb = match base {
        Some(s) => SampleBand {
            depth: s.depth[start..start + bw * bh].to_vec(),
            tri: s.tri[start..start + bw * bh].to_vec(),
            bary: s.bary[start..start + bw * bh].to_vec(),
        },
        None => SampleBand {
            depth: vec![f32::INFINITY; bw * bh],
            tri: vec![NO_HIT; bw * bh],
            bary: vec![Vec3::ZERO; bw * bh],
        },
    };
    let sy0 = (b * BAND * ss) as i64;
    for &si in bin {
        let st = &stris[si as usize];
        let ya = st.y0.max(sy0);
        let yb = st.y1.min(sy0 + bh as i64 - 1);
        for sy in ya..=yb {
            let py = sy as f32 + 0.5;
            for sx in st.x0..=st.x1 {
                let q = Vec2::new(sx as f32 + 0.5, py);
                let l0 = (st.p[2] - st.p[1]).perp_dot(q - st.p[1]) * st.inv_area;
                let l1 = (st.p[0] - st.p[2]).perp_dot(q - st.p[2]) * st.inv_area;
                let l2 = 1.0 - l0 - l1;
                if l0 < 0.0 || l1 < 0.0 || l2 < 0.0 {
                    continue;
                }
                let iz = l0 * st.iz[0] + l1 * st.iz[1] + l2 * st.iz[2];
                let z = 1.0 / iz;
                let k = (sy - sy0) as usize * bw + sx as usize;
                if z < sb.depth[k] {
                    sb.depth[k] = z;
                    sb.tri[k] = st.tri;
                    let (b0, b1, b2) = (l0 * st.iz[0] * z, l1 * st.iz[1] * z, l2 * st.iz[2] * z);
                    sb.bary[k] = st.attr[0] * b0 + st.attr[1] * b1 + st.attr[2] * b2;
                }
            }
        }
    }
    sb
}

fn render_impl(
    mesh: &Mesh,
    materials: &[Material],
    cam: &PinholeCamera,
    light: &Light,
    ss: usize,
    base: Option<&StaticSamples>,
) -> Render {
    let (w, h) = (cam.width as usize, cam.height as usize);
    let ss = ss.max(1) | 1;
    let first_tri = base.map_or(0, |b| b.triangle_count);
    let stris = screen_triangles(mesh, cam, ss, first_tri);
    let bins = bin_by_band(&stris, h, ss);
    let ctx = ShadeContext::new(mesh, materials, cam, light, ss);
    let centre = ss / 2;
    let bw = w * ss;
    let bands: Vec<Band> = bins
        .par_iter()
        .enumerate()
        .map(|(b, bin)| {
            let row0 = b * BAND;
            let rows = BAND.min(h - row0);
            let sb = band_samples(&stris, bin, w, ss, b, rows, base);
            // Shade and resolve.
            let mut rgb = vec![[0.0f32; 3]; w * rows];
            let mut g_tri = vec![NO_HIT; w * rows];
            let mut g_bary = vec![[0.0f32; 3]; w * rows];
            let mut g_depth = vec![f32::INFINITY; w * rows];
            let inv = 1.0 / (ss * ss) as f32;
            let band_start = b * BAND * ss * bw;
            for r in 0..rows {
                for x in 0..w {
                    let mut acc = Vec3::ZERO;
                    for a in 0..ss {
                        for c in 0..ss {
                            let k = (r * ss + a) * bw + x * ss + c;
                            let t = sb.tri[k];
                            if t == NO_HIT {
                                continue;
                            }
                            let bc = sb.bary[k];
                            if a == centre && c == centre {
                                g_tri[r * w + x] = t;
                                g_bary[r * w + x] = bc.to_array();
                                g_depth[r * w + x] = sb.depth[k];
                            }
                            acc += match base {
                                Some(s) if (t as usize) < first_tri => s.colour[band_start + k],
                                _ => ctx.shade(t as usize, bc, x * ss + c, (row0 + r) * ss + a),
                            };
                        }
                    }
                    rgb[r * w + x] = (acc * inv).to_array();
                }
            }
            (rgb, g_tri, g_bary, g_depth)
        })
        .collect();
    let n = w * h;
    let mut out = Render {
        rgb: vec![0.0; 3 * n],
        gbuf: GBuffer {
            width: w,
            height: h,
            tri: Vec::with_capacity(n),
            bary: Vec::with_capacity(n),
            depth: Vec::with_capacity(n),
        },
    };
    let mut i = 0;
    for (rgb, t, b, d) in bands {
        for (k, px) in rgb.iter().enumerate() {
            for c in 0..3 {
                out.rgb[c * n + i + k] = px[c];
            }
        }
        i += rgb.len();
        out.gbuf.tri.extend(t);
        out.gbuf.bary.extend(b);
        out.gbuf.depth.extend(d);
    }
    out
}
