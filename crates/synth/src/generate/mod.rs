//! The benchmark pipeline: renders S sub-frames per exposure, averages them into the blurred frame,
//! renders the sharp mid-exposure reference, derives the mask, the ground-truth flow and the events,
//! and writes a scene directory (format 1; 2 with a moving camera, 3 with several people) with
//! `stats.json` and `preview.png`.
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

use std::path::{Path, PathBuf};

use glam::Vec3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use smpl_deform::{BodyModel, BodyRef};

use crate::body::DressedBody;
use crate::camera::PinholeCamera;
use crate::camera_motion::CameraPath;
use crate::cast::{self, Person};
use crate::config::SynthConfig;
use crate::error::{Result, SynthError};
use crate::flow::ground_truth_flow;
use crate::mesh::{Light, Material, Mesh};
use crate::motion::Motion;
use crate::raster::{render_over, GBuffer, StaticSamples, NO_HIT};
use crate::{preview, room};

mod event_files;
mod scene_file;
mod stats;
use stats::{BlurAcc, FlowAcc};
pub use stats::{CmStats, EventStats, FlowStats, PsnrStats, Stats};

/// Vertical field of view of the camera (degrees).
pub const VFOV_DEG: f32 = 40.0;
/// PSNR reported for identical images (dB).
pub const PSNR_CAP_DB: f64 = 100.0;

fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> SynthError + '_ {
    move |source| SynthError::Io {
        path: path.to_path_buf(),
        source,
    }
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

/// The motion of the one-person benchmark a scene records: `generator` (the `generator` object
/// of the scene file `scene`, named in errors) holds the settings it was made with as `config`;
/// the body they name is loaded and [`benchmark_motion`] rebuilds the motion from them.
pub fn recorded_motion(scene: &Path, generator: Option<&serde_json::Value>) -> Result<Motion> {
    let bad = |reason: String| SynthError::GeneratorConfig {
        path: scene.to_path_buf(),
        reason,
    };
    let config = generator
        .and_then(|g| g.get("config"))
        .ok_or_else(|| bad("absent (not a synthetic benchmark)".into()))?;
    let cfg: SynthConfig =
        serde_json::from_value(config.clone()).map_err(|e| bad(e.to_string()))?;
    if cfg.people > 1 {
        return Err(bad(format!(
            "{} people: the motion is rebuilt for one person only",
            cfg.people
        )));
    }
    let model = BodyRef::parse(&cfg.body)?.load()?;
    benchmark_motion(&cfg, &DressedBody::new(model, vec![0.0; 10])?)
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
    let body = DressedBody::new(model, vec![0.0f32; 10])?;
    let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed);
    let motion = motion_from(cfg, &body, &mut rng)?;
    let (cam, camera_path) = benchmark_camera(cfg, &body, &motion)?;
    let light = Light {
        to_light: Vec3::new(0.4, 1.0, 0.7).normalize(),
        ambient: 0.35,
        diffuse: 0.65,
    };
    let (room, materials, people) = cast_in_room(cfg, body, motion)?;
    let several = people.len() > 1;
    let person_of_material = cast::person_of_material(materials.len(), &people);
    let human: Vec<bool> = materials.iter().map(|m| m.human).collect();
    let ss = cfg.supersample as usize;

    let mut sim = events::EventSimulator::new(sensor_config(cfg), w, h)?;
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
    let mut blur = BlurAcc::new(if cfg.people > 1 {
        cfg.people as usize
    } else {
        0
    });
    let mut flow_acc = FlowAcc::default();

    let mut event_files = event_files::EventFiles::new(out, cfg, sensor);

    let all_tris = room_and_body_tris(&room.mesh, &people);
    // With a static camera the room's samples are rasterized and shaded once, and every render
    // below re-rasterizes only the body over them (bit-identical to a full render); a moving
    // camera sees the room anew at every render time.
    let room_samples = (!camera_path.moves())
        .then(|| StaticSamples::new(&room.mesh, &materials, &cam, &light, ss));
    let mut prev: Option<Sharp> = None;
    let mut scene_frames = Vec::with_capacity(frames);
    for k in 0..frames {
        let tk = t_of(k);
        let mut blur_sum = vec![0.0f32; 3 * n];
        let mut sharp: Option<Sharp> = None;
        for RenderTime {
            t,
            is_sharp,
            is_sub,
        } in render_times(tk, exposure, s_count)
        {
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
            if is_sub {
                for (a, b) in blur_sum.iter_mut().zip(&r.rgb) {
                    *a += b;
                }
            }
            let grey = events::grey_from_rgb(&r.rgb, w, h)?;
            let evs = sim.add_frame(us(t), &grey)?;
            event_files.add(&evs, &mut stats.events)?;
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

        let blurred_img = scene::Rgb {
            width: cfg.width,
            height: cfg.height,
            data: blurred,
        };
        let files = write_frame_files(cfg, out, k, &blurred_img, &sharp, several)?;

        // Blur statistics.
        blur.add(&blurred_img.data, &sharp.rgb, &sharp.mask, &sharp.ids, w);

        // Flow of the previous frame to this one.
        if let Some(p) = prev.take() {
            let km = k - 1;
            let (flow, valid) = write_flow(cfg, out, km, (&p, &sharp), &all_tris)?;
            flow_acc.add_pair(&flow, &valid, &p.mask);
            event_files.ground_truth(km, &flow, &valid);
            flow_acc.add_warp(&p.rgb, &sharp.rgb, &flow, &valid, &p.mask, (w, h));
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

        scene_frames.push(scene_file::frame_entry(
            cfg,
            k,
            &people,
            camera_path
                .moves()
                .then(|| sharp.camera.to_scene().world_to_camera),
            files,
        ));
        prev = Some(sharp);
        event_files.collect_finished()?;
        progress(k as u32 + 1, cfg.frames);
    }
    let (flushed_counts, cm_acc) = event_files.finish(&mut stats.events)?;
    for (row, &k) in preview_rows.iter_mut().zip(&preview_set) {
        row.events = flushed_counts[k].clone();
    }

    stats.pose_error = scene_file::write_scene(cfg, out, &people, &cam, scene_frames)?;

    let nf = frames as f64;
    (stats.psnr_blurred_vs_sharp, stats.person_box_db) = blur.finish(frames);
    stats.flow = flow_acc.finish(frames, n);
    cm_acc.finish(&mut stats.events_cm_flow);
    stats.events.per_pixel_per_frame = stats.events.count as f64 / (n as f64 * nf);
    stats.write(out)?;
    preview::write(&out.join("preview.png"), &preview_rows, w, h)?;
    Ok(stats)
}

/// The room and everyone in it: the first person (`body` in `motion`) and `cfg.people − 1` more
/// walking across (`cast::extra_people`), with the room's and everybody's materials in order.
fn cast_in_room(
    cfg: &SynthConfig,
    body: DressedBody,
    motion: Motion,
) -> Result<(room::Room, Vec<Material>, Vec<Person>)> {
    // Texture resolution follows the image resolution.
    let side = cfg.width.max(cfg.height) as usize;
    let tex_size = (4 * side).next_power_of_two().clamp(256, 1024);
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
    Ok((room, materials, people))
}

/// The event simulator's settings: the sensor `cfg` asks for (thresholds, noise, refractory
/// period, hot pixels), seeded from the benchmark's seed.
fn sensor_config(cfg: &SynthConfig) -> events::EsimConfig {
    events::EsimConfig {
        c_pos: cfg.event_threshold,
        c_neg: cfg.event_threshold_neg.unwrap_or(cfg.event_threshold),
        sigma: cfg.event_sigma,
        refractory_us: cfg.refractory_us,
        shot_noise_hz: cfg.background_rate_hz,
        hot_pixel_fraction: cfg.hot_pixel_fraction,
        hot_pixel_rate_hz: cfg.hot_pixel_rate_hz,
        seed: cfg.seed ^ 0xE5E5_E5E5,
        ..events::EsimConfig::default()
    }
}

/// The benchmark's camera, looking at the middle of the first person standing at `t = 0` from
/// slightly to its right, and its path over the recording (`cfg.camera_motion`).
fn benchmark_camera(
    cfg: &SynthConfig,
    body: &DressedBody,
    motion: &Motion,
) -> Result<(PinholeCamera, CameraPath)> {
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
    let aspect = cfg.width as f32 / cfg.height as f32;
    let hfov = 2.0 * ((0.5 * VFOV_DEG.to_radians()).tan() * aspect).atan();
    let cam = PinholeCamera::look_at(cfg.width, cfg.height, hfov, eye, target);
    let camera_path = CameraPath::new(cfg.camera_motion, cam, (hfov, eye, target), cfg.seed);
    Ok((cam, camera_path))
}

/// The ground-truth flow from frame `km`'s sharp render to the next one's (`renders`), written to
/// `flow/km.flo` with its valid pixels' mask; returns both (planar u, v; valid per pixel).
fn write_flow(
    cfg: &SynthConfig,
    out: &Path,
    km: usize,
    (p, sharp): (&Sharp, &Sharp),
    all_tris: &[[u32; 3]],
) -> Result<(Vec<f32>, Vec<bool>)> {
    let (flow, valid) = ground_truth_flow(
        (&p.camera, &sharp.camera),
        all_tris,
        &p.positions,
        &sharp.positions,
        &p.gbuf,
        &sharp.gbuf,
    );
    let (w, h) = (cfg.width as usize, cfg.height as usize);
    let flo = events::Flow::from_planar(w, h, flow.clone())?;
    events::write_flo(out.join(format!("flow/{km:06}.flo")), &flo)?;
    scene::write_mask(
        &out.join(format!("flow/{km:06}_valid.png")),
        cfg.width,
        cfg.height,
        &valid,
    )?;
    Ok((flow, valid))
}

/// Writes frame k's blurred frame, sharp reference, mask and (with several people) person-id
/// image; returns their paths relative to `out`.
fn write_frame_files(
    cfg: &SynthConfig,
    out: &Path,
    k: usize,
    blurred: &scene::Rgb,
    sharp: &Sharp,
    several: bool,
) -> Result<scene_file::FrameFiles> {
    let enc = scene::ImageEncoding::rgb(16, scene::Transfer::Srgb);
    let files = scene_file::FrameFiles {
        image: format!("images/{k:06}.png"),
        sharp: format!("sharp/{k:06}.png"),
        mask: format!("masks/{k:06}.png"),
        person_ids: several.then(|| format!("person_ids/{k:06}.png")),
    };
    let sharp_rgb = scene::Rgb {
        width: cfg.width,
        height: cfg.height,
        data: sharp.rgb.clone(),
    };
    scene::write_rgb(&out.join(&files.image), blurred, enc)?;
    scene::write_rgb(&out.join(&files.sharp), &sharp_rgb, enc)?;
    scene::write_mask(&out.join(&files.mask), cfg.width, cfg.height, &sharp.mask)?;
    if let Some(rel) = &files.person_ids {
        scene::write_person_ids(&out.join(rel), cfg.width, cfg.height, &sharp.ids)?;
    }
    Ok(files)
}

/// One render of a frame's schedule.
struct RenderTime {
    /// Seconds.
    t: f64,
    /// The sharp mid-exposure reference.
    is_sharp: bool,
    /// A sub-frame of the exposure (averaged into the blurred frame).
    is_sub: bool,
}

/// Frame k's renders in time order: the S sub-frames at `t_k + E·((s + 0.5)/S − 0.5)` and the
/// sharp reference at `t_k` (the middle sub-frame for odd S, an extra render for even S).
fn render_times(tk: f64, exposure: f64, s_count: usize) -> Vec<RenderTime> {
    let mut times: Vec<RenderTime> = (0..s_count)
        .map(|s| RenderTime {
            t: tk + exposure * ((s as f64 + 0.5) / s_count as f64 - 0.5),
            is_sharp: false,
            is_sub: true,
        })
        .collect();
    if s_count % 2 == 1 {
        times[s_count / 2].is_sharp = true;
    } else {
        let sharp = RenderTime {
            t: tk,
            is_sharp: true,
            is_sub: false,
        };
        times.insert(s_count / 2, sharp);
    }
    times
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
