//! The benchmark pipeline: renders S sub-frames per exposure, averages them into the blurred frame,
//! renders the sharp mid-exposure reference, derives the mask, the ground-truth flow and the events,
//! and writes a scene-format-v1 directory with `stats.json` and `preview.png`.
//!
//! Timing: frame k is centred at `t_k = k / fps`; its exposure `E = exposure_fraction / fps` is
//! sampled at the S sub-frame times `t_k + E·((s + 0.5)/S − 0.5)`; the sharp reference is rendered at
//! exactly `t_k` (for odd S it is the middle sub-frame). Every render (sub-frames and sharp, in time
//! order) feeds the event simulator, with integer-microsecond timestamps. Events with
//! `t ∈ [t_k, t_{k+1})` go to `events/k.npz` (the last frame keeps everything after `t_{N−1}`; events
//! before `t_0` are dropped and counted).
//!
//! Determinism: frames are processed in order, each render is thread-count independent
//! (`raster`), reductions run sequentially in a fixed order, and the simulator is seeded; the output
//! directory's bytes depend only on the [`SynthConfig`]. Wall-clock times are never written.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use glam::Vec3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;
use smpl_deform::{BodyModel, BodyRef};

use crate::body::DressedBody;
use crate::camera::PinholeCamera;
use crate::camera_motion::CameraPath;
use crate::cast::{self, Person};
use crate::config::SynthConfig;
use crate::error::{Result, SynthError};
use crate::flow::{ground_truth_flow, warp_error};
use crate::mesh::{Light, Mesh};
use crate::motion::Motion;
use crate::pose_metrics::PoseErrorStats;
use crate::raster::{render_over, GBuffer, StaticSamples, NO_HIT};
use crate::{preview, room};

/// Vertical field of view of the camera (degrees).
pub const VFOV_DEG: f32 = 40.0;
/// PSNR reported for identical images (dB).
pub const PSNR_CAP_DB: f64 = 100.0;

/// PSNR figures of the blurred frames against the sharp references (mean over frames of the
/// per-frame PSNR, dB, data range 1, linear intensity, capped at 100 dB).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct PsnrStats {
    /// Whole image.
    pub full_frame_db: f64,
    /// Inside the bounding box of the sharp frame's human mask.
    pub human_box_db: f64,
    /// Outside that box (the static background, except where limbs leave the box during the
    /// exposure).
    pub outside_human_box_db: f64,
    /// Lowest per-frame human-box PSNR (the most blurred frame).
    pub human_box_min_db: f64,
}

/// Ground-truth flow figures over all frame pairs.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct FlowStats {
    /// Number of flow fields (frames − 1).
    pub pairs: usize,
    /// Fraction of pixels with valid flow.
    pub valid_fraction: f64,
    /// Fraction of all pixels whose (valid) flow magnitude exceeds 1 px.
    pub fraction_above_1px: f64,
    /// Fraction of human pixels (sharp mask) whose valid flow exceeds 1 px.
    pub human_fraction_above_1px: f64,
    /// Mean magnitude over valid human pixels (pixels).
    pub human_mean_magnitude_px: f64,
    /// Largest valid magnitude (pixels).
    pub max_magnitude_px: f64,
    /// Photometric check: mean |sharp_k − warp(sharp_{k+1}, flow)| over valid pixels (linear RGB).
    pub warp_mae: f64,
    /// The same error without warping (zero flow), on the same pixels: the baseline.
    pub identity_mae: f64,
    /// The photometric check restricted to valid human pixels moving more than 1 px.
    pub moving_human_warp_mae: f64,
    /// Zero-flow baseline on those pixels.
    pub moving_human_identity_mae: f64,
}

/// Event figures.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct EventStats {
    /// Events written (all frames).
    pub count: usize,
    /// Positive events written.
    pub positive: usize,
    /// Events before the first frame's mid-exposure (not written).
    pub dropped_before_first_frame: usize,
    /// Mean events per pixel per frame interval.
    pub per_pixel_per_frame: f64,
}

/// Event-only flow (`events::flow_from_events`, default settings) against the ground truth.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct CmStats {
    /// Whether it was computed (`SynthConfig::event_flow`).
    pub computed: bool,
    /// Mean end-point error over pixels with valid ground truth (pixels).
    pub epe_valid_px: f64,
    /// Mean end-point error over valid pixels whose ground-truth flow exceeds 1 px.
    pub epe_moving_px: f64,
    /// End-point error of a zero flow on those moving pixels (the baseline).
    pub zero_flow_epe_moving_px: f64,
    /// Number of moving valid pixels over all pairs.
    pub moving_pixels: usize,
}

/// Running sums of [`CmStats`].
#[derive(Default)]
struct CmAcc {
    epe_valid: f64,
    n_valid: usize,
    epe_moving: f64,
    zero_moving: f64,
    n_moving: usize,
}

impl CmAcc {
    fn add(&mut self, cm: &[f32], gt: &[f32], valid: &[bool]) {
        let n = valid.len();
        for i in 0..n {
            if !valid[i] {
                continue;
            }
            let e = f64::from((cm[i] - gt[i]).hypot(cm[n + i] - gt[n + i]));
            self.epe_valid += e;
            self.n_valid += 1;
            let m = f64::from(gt[i].hypot(gt[n + i]));
            if m > 1.0 {
                self.epe_moving += e;
                self.zero_moving += m;
                self.n_moving += 1;
            }
        }
    }
}

/// Everything written to `stats.json`.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Stats {
    /// The settings used.
    pub config: Option<SynthConfig>,
    /// Blur strength.
    pub psnr_blurred_vs_sharp: PsnrStats,
    /// Ground-truth flow.
    pub flow: FlowStats,
    /// Events.
    pub events: EventStats,
    /// Event-only (contrast maximisation) flow against the ground truth.
    pub events_cm_flow: CmStats,
    /// Frame indices shown in `preview.png`, top to bottom.
    pub preview_frames: Vec<u32>,
    /// Realised error of the SMPL parameters in `scene.json` against `poses_true.json`; absent
    /// (and not written) when the pose error is off.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pose_error: Option<PoseErrorStats>,
    /// With several people: per person (the scene's order), the blurred input's PSNR (dB) against
    /// the sharp frame in that person's own box (the bounding box of its pixels in the person-id
    /// image), averaged over the frames that show it; empty (and not written) with one person.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub person_box_db: Vec<f64>,
}

fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> SynthError + '_ {
    move |source| SynthError::Io {
        path: path.to_path_buf(),
        source,
    }
}

fn psnr(a: &[f32], b: &[f32], n: usize, pix: impl Fn(usize) -> bool) -> Option<f64> {
    let (mut se, mut cnt) = (0.0f64, 0usize);
    for i in 0..n {
        if pix(i) {
            for c in 0..3 {
                let d = f64::from(a[c * n + i].clamp(0.0, 1.0) - b[c * n + i].clamp(0.0, 1.0));
                se += d * d;
            }
            cnt += 3;
        }
    }
    if cnt == 0 {
        return None;
    }
    let mse = se / cnt as f64;
    Some(if mse <= 0.0 {
        PSNR_CAP_DB
    } else {
        (10.0 * (1.0 / mse).log10()).min(PSNR_CAP_DB)
    })
}

/// Bounding box `(x0, y0, x1, y1)` (inclusive) of the set pixels.
pub fn mask_bbox(mask: &[bool], w: usize) -> Option<(usize, usize, usize, usize)> {
    let mut b: Option<(usize, usize, usize, usize)> = None;
    for (i, &m) in mask.iter().enumerate() {
        if m {
            let (x, y) = (i % w, i / w);
            b = Some(match b {
                None => (x, y, x, y),
                Some((x0, y0, x1, y1)) => (x0.min(x), y0.min(y), x1.max(x), y1.max(y)),
            });
        }
    }
    b
}

fn human_mask(gbuf: &GBuffer, mesh: &Mesh, human: &[bool]) -> Vec<bool> {
    gbuf.tri
        .iter()
        .map(|&t| t != NO_HIT && human[mesh.tri_material[t as usize] as usize])
        .collect()
}

/// The sharp render of a frame, kept for the flow to the next one.
struct Sharp {
    /// The camera at mid exposure.
    camera: PinholeCamera,
    rgb: Vec<f32>,
    gbuf: GBuffer,
    positions: Vec<Vec3>,
    mask: Vec<bool>,
    /// Which person each pixel shows (0 = scene, p + 1 = person p); empty with one person.
    ids: Vec<u8>,
}

/// What a frame's preview row shows.
pub(crate) struct PreviewRow {
    pub blurred: Vec<f32>,
    pub sharp: Vec<f32>,
    pub mask: Vec<bool>,
    pub flow: Vec<f32>,
    pub valid: Vec<bool>,
    pub events: Vec<f32>,
}

/// Loads the body named by `cfg.body` and generates the benchmark into `out`.
/// `progress(done, total)` is called after each frame.
pub fn generate(
    cfg: &SynthConfig,
    out: &Path,
    progress: &mut dyn FnMut(u32, u32),
) -> Result<Stats> {
    cfg.validate()?;
    let model = BodyRef::parse(&cfg.body)?.load()?;
    generate_with_body(cfg, model, out, progress)
}

/// The motion of the benchmark `cfg` with the body `body`: the generator's true SMPL parameters at
/// any time (`Motion::at`), which the scene records at mid exposure only. Tests of pose interpolation
/// compare against it.
pub fn benchmark_motion(cfg: &SynthConfig, body: &DressedBody) -> Result<Motion> {
    motion_from(cfg, body, &mut ChaCha8Rng::seed_from_u64(cfg.seed))
}

/// [`benchmark_motion`] drawing its phases from `rng` (the generator's own stream, first draws).
fn motion_from(cfg: &SynthConfig, body: &DressedBody, rng: &mut ChaCha8Rng) -> Result<Motion> {
    let phases: [f32; 4] = std::array::from_fn(|_| rng.gen_range(0.0..std::f32::consts::TAU));
    let rest_joints = body
        .model
        .rest_joints(&body.model.shaped_vertices(&body.betas)?);
    Ok(Motion {
        speed: cfg.speed,
        phases,
        base: [0.0, 0.0],
        walk: [0.0, 0.0],
        floor_offset: body.floor_offset,
        arm_rest_elevation: Motion::arm_rest_elevation(&rest_joints),
    })
}

/// Like [`generate`] with an already loaded body model (`cfg.body` is only recorded).
pub fn generate_with_body(
    cfg: &SynthConfig,
    model: BodyModel,
    out: &Path,
    progress: &mut dyn FnMut(u32, u32),
) -> Result<Stats> {
    cfg.validate()?;
    let (w, h) = (cfg.width as usize, cfg.height as usize);
    let n = w * h;
    let several_dirs: &[&str] = if cfg.people > 1 { &["person_ids"] } else { &[] };
    for sub in ["images", "sharp", "masks", "flow", "events"]
        .iter()
        .chain(several_dirs)
    {
        let d = out.join(sub);
        std::fs::create_dir_all(&d).map_err(io_err(&d))?;
    }
    let betas = vec![0.0f32; 10];
    let body = DressedBody::new(model, betas.clone())?;
    let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed);
    let motion = motion_from(cfg, &body, &mut rng)?;
    // Camera: looks at the middle of the standing body, slightly from the right.
    let (pose0, transl0) = motion.at(0.0);
    let v0 = body.posed_vertices(&pose0, transl0)?;
    let top = v0.iter().map(|v| v.y).fold(f32::MIN, f32::max);
    let centre_xz = v0.iter().fold(Vec3::ZERO, |a, v| a + *v) / v0.len().max(1) as f32;
    let target = Vec3::new(centre_xz.x, 0.5 * top, centre_xz.z);
    let eye = Vec3::new(
        centre_xz.x + 0.2 * cfg.camera_distance,
        cfg.camera_height,
        centre_xz.z + cfg.camera_distance,
    );
    let aspect = w as f32 / h as f32;
    let hfov = 2.0 * ((0.5 * VFOV_DEG.to_radians()).tan() * aspect).atan();
    let cam = PinholeCamera::look_at(cfg.width, cfg.height, hfov, eye, target);
    let camera_path = CameraPath::new(cfg.camera_motion, cam, (hfov, eye, target), cfg.seed);
    let light = Light {
        to_light: Vec3::new(0.4, 1.0, 0.7).normalize(),
        ambient: 0.35,
        diffuse: 0.65,
    };
    // Texture resolution follows the image resolution.
    let tex_size = (4 * w.max(h)).next_power_of_two().clamp(256, 1024);
    let tex_seed = (cfg.texture_seed ^ (cfg.texture_seed >> 32)) as u32;
    let room = room::build(tex_seed, tex_size);
    let body_base = room.materials.len() as u16;
    let mut materials = room.materials.clone();
    materials.extend(DressedBody::materials(tex_seed));
    let first = Person {
        body,
        motion,
        material_base: body_base,
    };
    let duration_s = f64::from(cfg.frames - 1) / cfg.fps;
    let others = cast::extra_people(
        &first,
        cfg.people,
        (cfg.seed, tex_seed),
        duration_s,
        &mut materials,
    )?;
    let people: Vec<Person> = std::iter::once(first).chain(others).collect();
    let several = people.len() > 1;
    let person_of_material = cast::person_of_material(materials.len(), &people);
    let human: Vec<bool> = materials.iter().map(|m| m.human).collect();
    let ss = cfg.supersample as usize;

    let esim = events::EsimConfig {
        c_pos: cfg.event_threshold,
        c_neg: cfg.event_threshold_neg.unwrap_or(cfg.event_threshold),
        sigma: cfg.event_sigma,
        refractory_us: cfg.refractory_us,
        shot_noise_hz: cfg.background_rate_hz,
        hot_pixel_fraction: cfg.hot_pixel_fraction,
        hot_pixel_rate_hz: cfg.hot_pixel_rate_hz,
        seed: cfg.seed ^ 0xE5E5_E5E5,
        ..events::EsimConfig::default()
    };
    let mut sim = events::EventSimulator::new(esim, w, h)?;
    let sensor = sim.sensor();

    let frames = cfg.frames as usize;
    let s_count = cfg.subframes as usize;
    let fps = cfg.fps;
    let exposure = cfg.exposure_fraction / fps;
    let t_of = |k: usize| k as f64 / fps;
    let us = |t: f64| (t * 1e6).round() as i64;
    let preview_set: Vec<usize> = {
        let rows = 4.min(frames - 1);
        let mut v: Vec<usize> = (0..rows)
            .map(|i| (i * (frames - 2)) / (rows - 1).max(1))
            .collect();
        v.dedup();
        v
    };
    let mut preview_rows: Vec<PreviewRow> = Vec::new();
    let mut pending_preview: Option<PreviewRow> = None;

    let mut stats = Stats {
        config: Some(cfg.clone()),
        events_cm_flow: CmStats {
            computed: cfg.event_flow,
            ..CmStats::default()
        },
        preview_frames: preview_set.iter().map(|&k| k as u32).collect(),
        ..Stats::default()
    };
    let (mut sum_full, mut sum_box, mut sum_out, mut n_box, mut n_out) =
        (0.0, 0.0, 0.0, 0usize, 0usize);
    let mut box_min = f64::INFINITY;
    let (mut valid_px, mut moving_px, mut human_px, mut human_moving, mut human_mag) =
        (0usize, 0usize, 0usize, 0usize, 0.0f64);
    let (mut warp_sum, mut id_sum, mut warp_px) = (0.0f64, 0.0f64, 0usize);
    let (mut hwarp_sum, mut hid_sum, mut hwarp_px) = (0.0f64, 0.0f64, 0usize);
    let mut max_mag = 0.0f64;

    // Event bucketing.
    let mut bucket = events::EventStream::new();
    bucket.sensor = Some(sensor);
    let mut bucket_k = 0usize;
    let mut flushed_counts: Vec<Vec<f32>> = Vec::new();
    let event_path = |k: usize| format!("events/{k:06}.npz");
    let cm_config = events::CmaxConfig::default();
    // Writes bucket k; returns its two-channel count frame and, when enabled and k has a next
    // frame, the event-only flow of [t_k, t_{k+1}) computed on a helper thread (contrast
    // maximisation is sequential; it overlaps the rendering of the next frames). Its result does
    // not depend on when it runs, and results are consumed in frame order (`cm_jobs`).
    let flush = |k: usize,
                 s: &mut events::EventStream,
                 st: &mut EventStats|
     -> Result<(Vec<f32>, Option<CmJob>)> {
        let p = out.join(event_path(k));
        events::write_events(&p, s)?;
        st.count += s.len();
        st.positive += s.positive_count();
        let frame = events::count_frame(&s.as_slice(), sensor, events::CountMode::TwoChannel);
        let mut cm = None;
        if cfg.event_flow && k + 1 < frames {
            let (evs, (t_a, t_b)) = (s.clone(), (us(t_of(k)), us(t_of(k + 1))));
            let path = out.join(format!("flow/{k:06}_cm.flo"));
            let handle = std::thread::spawn(move || -> Result<Vec<f32>> {
                let f = events::flow_from_events(&evs.as_slice(), sensor, t_a, t_b, &cm_config)?;
                events::write_flo(path, &f)?;
                Ok(f.data)
            });
            cm = Some(CmJob { k, handle });
        }
        s.clear();
        Ok((frame, cm))
    };
    // Event-only flow jobs in flight, oldest first.
    let mut cm_jobs: std::collections::VecDeque<CmJob> = std::collections::VecDeque::new();
    // Ground-truth and event-only flows meet here (either may be ready first).
    let mut gt_wait: BTreeMap<usize, (Vec<f32>, Vec<bool>)> = BTreeMap::new();
    let mut cm_wait: BTreeMap<usize, Vec<f32>> = BTreeMap::new();
    let mut cm_acc = CmAcc::default();
    let mut pair = |k: usize,
                    gt: Option<(Vec<f32>, Vec<bool>)>,
                    cm: Option<Vec<f32>>,
                    gt_wait: &mut BTreeMap<usize, (Vec<f32>, Vec<bool>)>,
                    cm_wait: &mut BTreeMap<usize, Vec<f32>>| {
        if let Some(g) = gt {
            gt_wait.insert(k, g);
        }
        if let Some(c) = cm {
            cm_wait.insert(k, c);
        }
        if let (Some((g, v)), Some(c)) = (gt_wait.get(&k), cm_wait.get(&k)) {
            cm_acc.add(c, g, v);
            gt_wait.remove(&k);
            cm_wait.remove(&k);
        }
    };

    let all_tris = room_and_body_tris(&room.mesh, &people);
    // With a static camera the room's samples are rasterized and shaded once, and every render
    // below re-rasterizes only the body over them (bit-identical to a full render); a moving
    // camera sees the room anew at every render time.
    let room_samples = (!camera_path.moves())
        .then(|| StaticSamples::new(&room.mesh, &materials, &cam, &light, ss));
    let mut prev: Option<Sharp> = None;
    let mut scene_frames = Vec::with_capacity(frames);
    // Per person with several: (sum of box PSNRs, frames that show it).
    let mut person_box = vec![(0.0f64, 0usize); if several { people.len() } else { 0 }];
    for k in 0..frames {
        let tk = t_of(k);
        // Render times in order; `None` marks the sharp render.
        let mut times: Vec<(f64, bool)> = (0..s_count)
            .map(|s| {
                (
                    tk + exposure * ((s as f64 + 0.5) / s_count as f64 - 0.5),
                    false,
                )
            })
            .collect();
        let odd_middle = s_count % 2 == 1;
        if odd_middle {
            times[s_count / 2].1 = true;
        } else {
            times.insert(s_count / 2, (tk, true));
        }
        let mut blur_sum = vec![0.0f32; 3 * n];
        let mut sharp: Option<Sharp> = None;
        for &(t, is_sharp) in &times {
            let mut mesh = room.mesh.clone();
            for person in &people {
                mesh.append(&person.mesh_at(t)?);
            }
            let cam_t = camera_path.at(t);
            let r = match &room_samples {
                Some(room_samples) => {
                    render_over(room_samples, &mesh, &materials, &cam, &light, ss)
                }
                None => {
                    let room_now = StaticSamples::new(&room.mesh, &materials, &cam_t, &light, ss);
                    render_over(&room_now, &mesh, &materials, &cam_t, &light, ss)
                }
            };
            let is_sub = !is_sharp || odd_middle;
            if is_sub {
                for (a, b) in blur_sum.iter_mut().zip(&r.rgb) {
                    *a += b;
                }
            }
            let grey = events::grey_from_rgb(&r.rgb, w, h)?;
            let evs = sim.add_frame(us(t), &grey)?;
            for e in evs.iter() {
                if e.t < us(t_of(0)) {
                    stats.events.dropped_before_first_frame += 1;
                    continue;
                }
                while bucket_k + 1 < frames && e.t >= us(t_of(bucket_k + 1)) {
                    let (f, job) = flush(bucket_k, &mut bucket, &mut stats.events)?;
                    flushed_counts.push(f);
                    cm_jobs.extend(job);
                    bucket_k += 1;
                }
                bucket.push(e);
            }
            if is_sharp {
                let mask = human_mask(&r.gbuf, &mesh, &human);
                let ids = if several {
                    cast::person_ids(&r.gbuf, &mesh, &person_of_material)
                } else {
                    Vec::new()
                };
                sharp = Some(Sharp {
                    ids,
                    camera: cam_t,
                    rgb: r.rgb,
                    gbuf: r.gbuf,
                    positions: mesh.positions,
                    mask,
                });
            }
        }
        let Some(sharp) = sharp else {
            unreachable!("the sharp render is always in the schedule")
        };
        let inv = 1.0 / s_count as f32;
        let blurred: Vec<f32> = blur_sum.iter().map(|v| v * inv).collect();

        // Files of frame k.
        let enc = scene::ImageEncoding::rgb(16, scene::Transfer::Srgb);
        let image = format!("images/{k:06}.png");
        let sharp_rel = format!("sharp/{k:06}.png");
        let mask_rel = format!("masks/{k:06}.png");
        let rgb = |data: Vec<f32>| scene::Rgb {
            width: cfg.width,
            height: cfg.height,
            data,
        };
        let blurred_img = rgb(blurred);
        scene::write_rgb(&out.join(&image), &blurred_img, enc)?;
        scene::write_rgb(&out.join(&sharp_rel), &rgb(sharp.rgb.clone()), enc)?;
        scene::write_mask(&out.join(&mask_rel), cfg.width, cfg.height, &sharp.mask)?;
        let ids_rel = several.then(|| format!("person_ids/{k:06}.png"));
        if let Some(rel) = &ids_rel {
            scene::write_person_ids(&out.join(rel), cfg.width, cfg.height, &sharp.ids)?;
        }

        // Blur statistics.
        let full = psnr(&blurred_img.data, &sharp.rgb, n, |_| true).unwrap_or(PSNR_CAP_DB);
        sum_full += full;
        if let Some((x0, y0, x1, y1)) = mask_bbox(&sharp.mask, w) {
            let inside = |i: usize| {
                let (x, y) = (i % w, i / w);
                x >= x0 && x <= x1 && y >= y0 && y <= y1
            };
            if let Some(p) = psnr(&blurred_img.data, &sharp.rgb, n, inside) {
                sum_box += p;
                box_min = box_min.min(p);
                n_box += 1;
            }
            if let Some(p) = psnr(&blurred_img.data, &sharp.rgb, n, |i| !inside(i)) {
                sum_out += p;
                n_out += 1;
            }
        }

        for (p, acc) in person_box.iter_mut().enumerate() {
            let id = (p + 1) as u8;
            let own: Vec<bool> = sharp.ids.iter().map(|&v| v == id).collect();
            if let Some((x0, y0, x1, y1)) = mask_bbox(&own, w) {
                let inside = |i: usize| {
                    let (x, y) = (i % w, i / w);
                    x >= x0 && x <= x1 && y >= y0 && y <= y1
                };
                if let Some(db) = psnr(&blurred_img.data, &sharp.rgb, n, inside) {
                    acc.0 += db;
                    acc.1 += 1;
                }
            }
        }

        // Flow of the previous frame to this one.
        if let Some(p) = prev.take() {
            let (flow, valid) = ground_truth_flow(
                (&p.camera, &sharp.camera),
                &all_tris,
                &p.positions,
                &sharp.positions,
                &p.gbuf,
                &sharp.gbuf,
            );
            let km = k - 1;
            let flo = events::Flow::from_planar(w, h, flow.clone())?;
            events::write_flo(out.join(format!("flow/{km:06}.flo")), &flo)?;
            scene::write_mask(
                &out.join(format!("flow/{km:06}_valid.png")),
                cfg.width,
                cfg.height,
                &valid,
            )?;
            for i in 0..n {
                if valid[i] {
                    let m = f64::from(flow[i].hypot(flow[n + i]));
                    valid_px += 1;
                    max_mag = max_mag.max(m);
                    if m > 1.0 {
                        moving_px += 1;
                    }
                    if p.mask[i] {
                        human_px += 1;
                        human_mag += m;
                        if m > 1.0 {
                            human_moving += 1;
                        }
                    }
                }
            }
            if cfg.event_flow {
                pair(
                    km,
                    Some((flow.clone(), valid.clone())),
                    None,
                    &mut gt_wait,
                    &mut cm_wait,
                );
            }
            let (e, b, c) = warp_error(&p.rgb, &sharp.rgb, &flow, &valid, w, h);
            warp_sum += e * c as f64;
            id_sum += b * c as f64;
            warp_px += c;
            let hvalid: Vec<bool> = (0..n)
                .map(|i| valid[i] && p.mask[i] && flow[i].hypot(flow[n + i]) > 1.0)
                .collect();
            let (e, b, c) = warp_error(&p.rgb, &sharp.rgb, &flow, &hvalid, w, h);
            hwarp_sum += e * c as f64;
            hid_sum += b * c as f64;
            hwarp_px += c;
            if let Some(mut row) = pending_preview.take() {
                row.flow = flow;
                row.valid = valid;
                preview_rows.push(row);
            }
        }
        if preview_set.contains(&k) {
            pending_preview = Some(PreviewRow {
                blurred: blurred_img.data.clone(),
                sharp: sharp.rgb.clone(),
                mask: sharp.mask.clone(),
                flow: Vec::new(),
                valid: Vec::new(),
                events: Vec::new(),
            });
        }

        let mut flow_to_next = Vec::new();
        if k + 1 < frames {
            flow_to_next.push(scene::FlowRef {
                kind: scene::FlowKind::GroundTruth,
                path: format!("flow/{k:06}.flo"),
                valid_mask: Some(format!("flow/{k:06}_valid.png")),
            });
            if cfg.event_flow {
                flow_to_next.push(scene::FlowRef {
                    kind: scene::FlowKind::EventsCm,
                    path: format!("flow/{k:06}_cm.flo"),
                    valid_mask: None,
                });
            }
        }
        let (pose, transl) = people[0].at(tk);
        let others: Vec<scene::PersonPose> = people[1..]
            .iter()
            .zip(1u32..)
            .map(|(person, id)| {
                let (pose, transl) = person.at(tk);
                scene::PersonPose {
                    id,
                    pose: pose.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
                    transl,
                }
            })
            .collect();
        scene_frames.push(scene::Frame {
            people: others,
            person_ids: ids_rel,
            index: k as u32,
            time_s: tk,
            exposure_s: None,
            world_to_camera: camera_path
                .moves()
                .then(|| sharp.camera.to_scene().world_to_camera),
            image,
            sharp: Some(sharp_rel),
            mask: Some(mask_rel),
            pose: pose.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
            transl,
            flow_to_next,
            events: Some(event_path(k)),
            split: if k % 10 < 7 {
                scene::Split::Train
            } else {
                scene::Split::Test
            },
        });
        prev = Some(sharp);
        // Collect finished event-only flows in order; at most two in flight.
        while cm_jobs
            .front()
            .is_some_and(|j| j.handle.is_finished() || cm_jobs.len() > 2)
        {
            if let Some(job) = cm_jobs.pop_front() {
                let (k, cm) = job.join()?;
                pair(k, None, Some(cm), &mut gt_wait, &mut cm_wait);
            }
        }
        progress(k as u32 + 1, cfg.frames);
    }
    // Remaining event buckets (the last one, and empty ones if nothing happened).
    while bucket_k < frames {
        let (f, job) = flush(bucket_k, &mut bucket, &mut stats.events)?;
        flushed_counts.push(f);
        cm_jobs.extend(job);
        bucket_k += 1;
    }
    while let Some(job) = cm_jobs.pop_front() {
        let (k, cm) = job.join()?;
        pair(k, None, Some(cm), &mut gt_wait, &mut cm_wait);
    }
    for (row, &k) in preview_rows.iter_mut().zip(&preview_set) {
        row.events = flushed_counts[k].clone();
    }

    // The scene's SMPL parameters so far are the true ones; with a pose error they become an
    // estimate and the truth goes to its own file (everything rendered above is unchanged).
    let mut generator = serde_json::json!({
        "name": "synth",
        "config": cfg,
    });
    if cfg.pose_error.is_off() {
        // A truth file left by an earlier generation into `out` would not be this scene's.
        crate::true_poses::TruePoses::remove(out)?;
    } else {
        stats.pose_error = Some(crate::pose_error::apply(
            cfg,
            &people[0].body,
            cam.centre_world(),
            &mut scene_frames,
            out,
        )?);
        generator["true_poses"] = serde_json::json!(crate::true_poses::TRUE_POSES_FILE);
    }
    if cfg.camera_error_on() {
        let truth = crate::camera_error::apply(
            &mut scene_frames,
            &cam.to_scene().world_to_camera,
            (cfg.camera_error_deg, cfg.camera_error_cm),
            cfg.seed,
        );
        truth.write(out)?;
        generator["true_cameras"] = serde_json::json!(crate::camera_error::TRUE_CAMERAS_FILE);
    } else {
        // A truth file left by an earlier generation into `out` would not be this scene's.
        crate::camera_error::TrueCameras::remove(out)?;
    }
    let mut sc = scene::Scene {
        events_raw_format: None,
        events_recorded_s: None,
        people: people[1..]
            .iter()
            .zip(1u32..)
            .map(|(person, id)| scene::PersonSpec {
                id,
                betas: person.body.betas.clone(),
            })
            .collect(),
        format_version: scene::FORMAT_VERSION,
        camera: cam.to_scene(),
        body: scene::BodySpec {
            id: 0,
            model: cfg.body.clone(),
            betas,
        },
        fps,
        exposure_s: exposure,
        images: scene::ImageEncoding::rgb(16, scene::Transfer::Srgb),
        frames: scene_frames,
        generator: Some(generator),
    };
    sc.format_version = sc.format_version_needed();
    sc.write(out)?;

    let nf = frames as f64;
    let total_px = ((frames - 1) * n) as f64;
    stats.psnr_blurred_vs_sharp = PsnrStats {
        full_frame_db: sum_full / nf,
        human_box_db: if n_box > 0 {
            sum_box / n_box as f64
        } else {
            PSNR_CAP_DB
        },
        outside_human_box_db: if n_out > 0 {
            sum_out / n_out as f64
        } else {
            PSNR_CAP_DB
        },
        human_box_min_db: if box_min.is_finite() {
            box_min
        } else {
            PSNR_CAP_DB
        },
    };
    stats.person_box_db = person_box
        .iter()
        .map(|&(sum, count)| {
            if count > 0 {
                sum / count as f64
            } else {
                PSNR_CAP_DB
            }
        })
        .collect();
    let div = |a: f64, b: usize| if b > 0 { a / b as f64 } else { 0.0 };
    stats.flow = FlowStats {
        pairs: frames - 1,
        valid_fraction: valid_px as f64 / total_px,
        fraction_above_1px: moving_px as f64 / total_px,
        human_fraction_above_1px: div(human_moving as f64, human_px),
        human_mean_magnitude_px: div(human_mag, human_px),
        max_magnitude_px: max_mag,
        warp_mae: div(warp_sum, warp_px),
        identity_mae: div(id_sum, warp_px),
        moving_human_warp_mae: div(hwarp_sum, hwarp_px),
        moving_human_identity_mae: div(hid_sum, hwarp_px),
    };
    let dv = |a: f64, b: usize| if b > 0 { a / b as f64 } else { 0.0 };
    stats.events_cm_flow.epe_valid_px = dv(cm_acc.epe_valid, cm_acc.n_valid);
    stats.events_cm_flow.epe_moving_px = dv(cm_acc.epe_moving, cm_acc.n_moving);
    stats.events_cm_flow.zero_flow_epe_moving_px = dv(cm_acc.zero_moving, cm_acc.n_moving);
    stats.events_cm_flow.moving_pixels = cm_acc.n_moving;
    stats.events.per_pixel_per_frame = stats.events.count as f64 / (n as f64 * nf);
    let stats_path = out.join("stats.json");
    let mut text = serde_json::to_string_pretty(&stats).map_err(|source| SynthError::Json {
        path: stats_path.clone(),
        source,
    })?;
    text.push('\n');
    std::fs::write(&stats_path, text).map_err(io_err(&stats_path))?;
    preview::write(&out.join("preview.png"), &preview_rows, w, h)?;
    Ok(stats)
}

/// An event-only flow being computed on a helper thread for frame pair (k, k+1).
struct CmJob {
    k: usize,
    handle: std::thread::JoinHandle<Result<Vec<f32>>>,
}

impl CmJob {
    /// Waits for the flow (planar u then v, pixels).
    fn join(self) -> Result<(usize, Vec<f32>)> {
        match self.handle.join() {
            Ok(r) => Ok((self.k, r?)),
            Err(panic) => std::panic::resume_unwind(panic),
        }
    }
}

/// The triangles of the room and every person's body, as the frame's mesh holds them (the room's
/// vertices first, then each person's in order).
fn room_and_body_tris(room: &Mesh, people: &[Person]) -> Vec<[u32; 3]> {
    let mut base = room.positions.len() as u32;
    let mut t = room.tris.clone();
    for person in people {
        let faces = &person.body.model.faces;
        t.extend(faces.iter().map(|f| f.map(|i| i + base)));
        base += person.body.model.v_template.len() as u32;
    }
    t
}

/// Paths of the files a generated directory holds besides `scene.json` (for tests and docs).
pub fn output_dirs() -> [PathBuf; 5] {
    ["images", "sharp", "masks", "flow", "events"].map(PathBuf::from)
}
