//! The fuzzed parsers: for each, seed files made by the project's own writers (or, for formats it
//! only reads, written out here by hand), the file the worker writes each input to, and the call
//! that reads it the way the commands do. A parser's `Ok` / `Err` are both fine; only panics,
//! aborts, hangs and over-allocations are findings.

use anyhow::{bail, Context, Result};
use std::path::{Path, PathBuf};

/// Where a worker writes inputs, and what the target set up beside them.
pub struct Prepared {
    /// The input file (its extension selects the reader where readers go by extension).
    pub input: PathBuf,
    /// The directory of a scene (`scene` target: `input` is its `scene.json`).
    pub dir: PathBuf,
}

/// One fuzzed parser.
pub struct Target {
    /// Name on the command line.
    pub name: &'static str,
    /// Extension of the input file (and of saved crash files).
    pub extension: &'static str,
    /// The seed files.
    pub seeds: fn() -> Result<Vec<Vec<u8>>>,
    /// Prepares the worker's directory.
    pub prepare: fn(&Path) -> Result<Prepared>,
    /// Parses the input file; true when it was accepted.
    pub parse: fn(&Prepared) -> bool,
}

/// Every target, in the order `--target all` runs them.
pub const TARGETS: [Target; 15] = [
    Target {
        name: "ply",
        extension: "ply",
        seeds: ply_seeds,
        prepare: plain::<0>,
        parse: |p| gaussians::ply::read_ply(&p.input).is_ok(),
    },
    Target {
        name: "camera",
        extension: "json",
        seeds: camera_seeds,
        prepare: plain::<1>,
        parse: |p| scene::camera_files::read_any(&p.input, 0).is_ok(),
    },
    Target {
        name: "scene",
        extension: "json",
        seeds: scene_seeds,
        prepare: scene_dir,
        parse: |p| scene::load(&p.dir).is_ok(),
    },
    Target {
        name: "npz",
        extension: "npz",
        seeds: npz_seeds,
        prepare: plain::<2>,
        parse: parse_npz,
    },
    Target {
        name: "motion",
        extension: "npz",
        seeds: motion_seeds,
        prepare: plain::<2>,
        parse: |p| smpl_deform::motion::read_motion(&p.input).is_ok(),
    },
    Target {
        name: "safetensors",
        extension: "safetensors",
        seeds: safetensors_seeds,
        prepare: plain::<3>,
        parse: parse_safetensors,
    },
    Target {
        name: "flo",
        extension: "flo",
        seeds: flo_seeds,
        prepare: plain::<4>,
        parse: |p| events::flowio::read_flo(&p.input).is_ok(),
    },
    Target {
        name: "flow-png",
        extension: "png",
        seeds: flow_png_seeds,
        prepare: plain::<5>,
        parse: parse_flow_png,
    },
    Target {
        name: "aedat4",
        extension: "aedat4",
        seeds: aedat4_seeds,
        prepare: plain::<6>,
        parse: parse_events,
    },
    Target {
        name: "aedat4-frames",
        extension: "aedat4",
        seeds: aedat4_frames_seeds,
        prepare: plain::<6>,
        parse: |p| events::io::aedat4_frames::read_aedat4_frames(&p.input).is_ok(),
    },
    Target {
        name: "zju-model",
        extension: "npz",
        seeds: zju_model_seeds,
        prepare: plain::<2>,
        parse: |p| smpl_deform::zju::read_zju_model(&p.input).is_ok(),
    },
    Target {
        name: "events-raw",
        extension: "raw",
        seeds: raw_seeds,
        prepare: plain::<7>,
        parse: parse_raw,
    },
    Target {
        name: "dat",
        extension: "dat",
        seeds: dat_seeds,
        prepare: plain::<8>,
        parse: parse_events,
    },
    Target {
        name: "events-text",
        extension: "txt",
        seeds: text_seeds,
        prepare: plain::<9>,
        parse: parse_events,
    },
    Target {
        name: "t7",
        extension: "t7",
        seeds: t7_seeds,
        prepare: plain::<10>,
        parse: parse_t7,
    },
];

/// A target that checks the harness itself (not in `all`). Its parser acts on the sum of the
/// input's bytes modulo 10 (mutation spreads it evenly): 1 panics, 2 aborts the process, 3 never
/// returns, 4 reserves 3 GiB; anything else is accepted.
pub const SELF_TEST: Target = Target {
    name: "self-test",
    extension: "txt",
    seeds: || Ok(vec![b"self-test input".to_vec()]),
    prepare: plain::<9>,
    parse: |p| {
        let bytes = std::fs::read(&p.input).unwrap_or_default();
        match bytes.iter().map(|&b| u64::from(b)).sum::<u64>() % 10 {
            1 => panic!("self-test panic"),
            2 => std::process::abort(),
            3 => std::thread::sleep(std::time::Duration::from_secs(3600)),
            4 => {
                let big: Vec<u8> = Vec::with_capacity(3 << 30);
                std::hint::black_box(&big);
            }
            _ => {}
        }
        true
    },
};

/// The target called `name`.
pub fn find(name: &str) -> Result<&'static Target> {
    if name == SELF_TEST.name {
        return Ok(&SELF_TEST);
    }
    match TARGETS.iter().find(|t| t.name == name) {
        Some(t) => Ok(t),
        None => bail!(
            "unknown fuzz target `{name}`: expected all or one of {}",
            TARGETS
                .iter()
                .map(|t| t.name)
                .collect::<Vec<_>>()
                .join(", ")
        ),
    }
}

const EXTENSIONS: [&str; 11] = [
    "ply",
    "json",
    "npz",
    "safetensors",
    "flo",
    "png",
    "aedat4",
    "raw",
    "dat",
    "txt",
    "t7",
];

fn plain<const E: usize>(dir: &Path) -> Result<Prepared> {
    Ok(Prepared {
        input: dir.join(format!("input.{}", EXTENSIONS[E])),
        dir: dir.to_path_buf(),
    })
}

/// Bytes a writer put in a file.
fn written(write: impl FnOnce(&Path) -> Result<()>, name: &str) -> Result<Vec<u8>> {
    let dir = tempfile::tempdir().context("a temporary directory for seeds")?;
    let path = dir.path().join(name);
    write(&path)?;
    std::fs::read(&path).with_context(|| format!("reading the seed {}", path.display()))
}

fn ply_seeds() -> Result<Vec<Vec<u8>>> {
    let mut seeds = Vec::new();
    for (n, degree) in [(3usize, 3usize), (2, 0)] {
        let mut set = gaussians::GaussianSet::zeros(n, degree, 0, 0);
        for (k, v) in set.means.iter_mut().enumerate() {
            *v = [k as f32, 0.5, -1.0];
        }
        for q in &mut set.quats {
            *q = [1.0, 0.0, 0.0, 0.0];
        }
        seeds.push(gaussians::ply::write_ply_bytes(&set)?);
    }
    seeds.push(
        b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n\
          property float z\nproperty float f_dc_0\nproperty float f_dc_1\nproperty float f_dc_2\n\
          property float opacity\nproperty float scale_0\nproperty float scale_1\n\
          property float scale_2\nproperty float rot_0\nproperty float rot_1\nproperty float rot_2\n\
          property float rot_3\nend_header\n0 0 0 0.1 0.2 0.3 0.5 -3 -3 -3 1 0 0 0\n\
          1 2 3 0.1 0.2 0.3 0.5 -3 -2 -1 0.5 0.5 0.5 0.5\n"
            .to_vec(),
    );
    Ok(seeds)
}

fn camera_seeds() -> Result<Vec<Vec<u8>>> {
    Ok(vec![
        br#"{"width": 64, "height": 48, "fx": 60.0, "fy": 60.0, "cx": 32.0, "cy": 24.0,
"world_to_camera": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 3], [0, 0, 0, 1]]}"#
            .to_vec(),
        br#"[{"id": 0, "img_name": "00000", "width": 64, "height": 48, "position": [0.0, 0.5, -3.0],
"rotation": [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], "fy": 60.0, "fx": 60.0}]"#
            .to_vec(),
    ])
}

fn fixture() -> PathBuf {
    crate::common::workspace_root()
        .join("data-fixtures")
        .join("tiny")
}

fn scene_seeds() -> Result<Vec<Vec<u8>>> {
    let path = fixture().join("scene.json");
    Ok(vec![
        std::fs::read(&path).with_context(|| format!("reading {}", path.display()))?
    ])
}

/// A copy of the tiny fixture's files (the scene's images, masks, events and flow) whose
/// `scene.json` each input replaces.
fn scene_dir(dir: &Path) -> Result<Prepared> {
    let scene = dir.join("scene");
    copy_dir(&fixture(), &scene)?;
    Ok(Prepared {
        input: scene.join("scene.json"),
        dir: scene,
    })
}

fn copy_dir(from: &Path, to: &Path) -> Result<()> {
    std::fs::create_dir_all(to).with_context(|| format!("creating {}", to.display()))?;
    for e in std::fs::read_dir(from).with_context(|| format!("listing {}", from.display()))? {
        let e = e?;
        let dst = to.join(e.file_name());
        if e.file_type()?.is_dir() {
            copy_dir(&e.path(), &dst)?;
        } else {
            std::fs::copy(e.path(), &dst)
                .with_context(|| format!("copying {}", e.path().display()))?;
        }
    }
    Ok(())
}

fn small_events() -> events::EventStream {
    let sensor = Some(events::SensorSize {
        width: 32,
        height: 24,
    });
    events::EventStream::from_events(
        (0..40).map(|k| events::Event {
            t: 1_000 + 37 * k,
            x: (k * 7 % 32) as u16,
            y: (k * 5 % 24) as u16,
            p: if k % 3 == 0 { -1 } else { 1 },
        }),
        sensor,
    )
}

fn npz_seeds() -> Result<Vec<Vec<u8>>> {
    let mut seeds = vec![written(
        |p| Ok(events::io::npz::write_npz(p, &small_events())?),
        "e.npz",
    )?];
    seeds.extend(motion_seeds()?);
    Ok(seeds)
}

/// Events, an SMPL motion and the flow `.npy` reader all read `.npz` / `.npy` through their own
/// checks; every one of them sees every input.
fn parse_npz(p: &Prepared) -> bool {
    let a = events::io::read_events(&p.input).is_ok();
    let b = smpl_deform::motion::read_motion(&p.input).is_ok();
    let c = smpl_deform::BodyModel::load_smpl_npz(&p.input).is_ok();
    a || b || c
}

fn motion_seeds() -> Result<Vec<Vec<u8>>> {
    use smpl_deform::npz::NpzWriter;
    let finish = |w: NpzWriter<std::io::Cursor<Vec<u8>>>| -> Result<Vec<u8>> {
        Ok(w.finish()?.into_inner())
    };
    let values = |n: usize| -> Vec<f32> { (0..n).map(|k| (k as f32 * 0.31).sin() * 0.4).collect() };
    let mut amass = NpzWriter::new(std::io::Cursor::new(Vec::new()), false);
    amass.add_f32("poses", &[3, 156], &values(3 * 156))?;
    amass.add_f32("trans", &[3, 3], &values(9))?;
    amass.add_f32("betas", &[16], &values(16))?;
    amass.add_f64("mocap_framerate", &[], &[120.0])?;
    let mut snapshot = NpzWriter::new(std::io::Cursor::new(Vec::new()), true);
    snapshot.add_f32("global_orient", &[2, 3], &values(6))?;
    snapshot.add_f32("body_pose", &[2, 69], &values(138))?;
    snapshot.add_f32("transl", &[2, 3], &values(6))?;
    snapshot.add_f32("betas", &[1, 10], &values(10))?;
    Ok(vec![finish(amass)?, finish(snapshot)?])
}

fn safetensors_seeds() -> Result<Vec<Vec<u8>>> {
    let net = flow::SpyNet::<f32>::random(1, 3);
    Ok(vec![flow::write_safetensors(&net)?])
}

/// The flow network's reader (every tensor through `nn::tensors::read_f32`'s checks).
fn parse_safetensors(p: &Prepared) -> bool {
    flow::load_safetensors(&p.input).is_ok()
}

fn small_flow() -> events::flowio::Flow {
    events::flowio::Flow {
        width: 5,
        height: 4,
        data: (0..40).map(|k| (k as f32 * 0.7).sin() * 3.0).collect(),
    }
}

fn flo_seeds() -> Result<Vec<Vec<u8>>> {
    Ok(vec![written(
        |p| Ok(events::flowio::write_flo(p, &small_flow())?),
        "f.flo",
    )?])
}

fn flow_png_seeds() -> Result<Vec<Vec<u8>>> {
    let mut seeds = Vec::new();
    for kind in [
        events::flowio::FlowPngKind::Kitti,
        events::flowio::FlowPngKind::Dsec,
    ] {
        seeds.push(written(
            |p| {
                Ok(events::flowio::write_flow_png(
                    p,
                    &small_flow(),
                    None,
                    kind,
                )?)
            },
            "f.png",
        )?);
    }
    Ok(seeds)
}

fn parse_flow_png(p: &Prepared) -> bool {
    let a = events::flowio::read_flow_png(&p.input, events::flowio::FlowPngKind::Kitti).is_ok();
    let b = events::flowio::read_flow_png(&p.input, events::flowio::FlowPngKind::Dsec).is_ok();
    a || b
}

fn aedat4_seeds() -> Result<Vec<Vec<u8>>> {
    use events::io::aedat4::{write_aedat4, Compression};
    let mut seeds = Vec::new();
    for c in [Compression::None, Compression::Lz4, Compression::Zstd] {
        seeds.push(written(
            |p| Ok(write_aedat4(p, &small_events(), c)?),
            "e.aedat4",
        )?);
    }
    Ok(seeds)
}

fn aedat4_frames_seeds() -> Result<Vec<Vec<u8>>> {
    use events::io::aedat4::Compression;
    use events::io::aedat4_frames::{write_aedat4_with_frames, ApsFrame, FrameFormat};
    let frame = |k: i64, format: FrameFormat| ApsFrame {
        t_us: 1000 * k,
        exposure_begin_us: 1000 * k - 200,
        exposure_end_us: 1000 * k + 200,
        format,
        width: 4,
        height: 3,
        offset_x: 0,
        offset_y: 0,
        pixels: (0..12 * format.bytes_per_pixel())
            .map(|i| (i * 13) as u8)
            .collect(),
    };
    let mut seeds = Vec::new();
    for (c, format) in [
        (Compression::None, FrameFormat::Gray),
        (Compression::Lz4, FrameFormat::Bgr),
        (Compression::Zstd, FrameFormat::Gray16),
    ] {
        seeds.push(written(
            |p| {
                Ok(write_aedat4_with_frames(
                    p,
                    &small_events(),
                    &[frame(1, format), frame(2, format)],
                    events::SensorSize::new(4, 3),
                    c,
                )?)
            },
            "f.aedat4",
        )?);
    }
    Ok(seeds)
}

fn zju_model_seeds() -> Result<Vec<Vec<u8>>> {
    let mut seeds = Vec::new();
    for (flat, betas) in [(false, true), (true, false)] {
        let mut w = smpl_deform::npz::NpzWriter::new(std::io::Cursor::new(Vec::new()), false);
        let shape = |n: u64| if flat { vec![n] } else { vec![1, n] };
        let values = |n: usize| (0..n).map(|i| i as f32 * 0.01).collect::<Vec<f32>>();
        for (key, n) in [
            ("root_orient", 3),
            ("pose_body", 63),
            ("pose_hand", 6),
            ("trans", 3),
        ] {
            w.add_f32(key, &shape(n as u64), &values(n))?;
        }
        if betas {
            w.add_f32("betas", &shape(10), &values(10))?;
        }
        seeds.push(w.finish()?.into_inner());
    }
    Ok(seeds)
}

fn parse_events(p: &Prepared) -> bool {
    events::io::read_events(&p.input).is_ok()
}

fn raw_seeds() -> Result<Vec<Vec<u8>>> {
    use events::io::prophesee::{write_raw, PropheseeFormat};
    let mut seeds = Vec::new();
    for f in [PropheseeFormat::Evt2, PropheseeFormat::Evt3] {
        seeds.push(written(|p| Ok(write_raw(p, &small_events(), f)?), "e.raw")?);
    }
    Ok(seeds)
}

/// A `.raw` file read strictly, then leniently (skipping bad words), then with each encoding
/// stated for a header that lacks it.
fn parse_raw(p: &Prepared) -> bool {
    use events::io::{prophesee::RawEncoding, read_events_with, ReadOptions};
    let strict = events::io::read_events(&p.input).is_ok();
    let lenient = read_events_with(
        &p.input,
        &ReadOptions {
            raw_format: None,
            lenient: true,
        },
    )
    .is_ok();
    let stated = [RawEncoding::Evt2, RawEncoding::Evt3].into_iter().any(|e| {
        read_events_with(
            &p.input,
            &ReadOptions {
                raw_format: Some(e),
                lenient: true,
            },
        )
        .is_ok()
    });
    strict || lenient || stated
}

fn dat_seeds() -> Result<Vec<Vec<u8>>> {
    Ok(vec![written(
        |p| Ok(events::io::prophesee::write_dat(p, &small_events())?),
        "e.dat",
    )?])
}

fn text_seeds() -> Result<Vec<Vec<u8>>> {
    Ok(vec![written(
        |p| Ok(events::io::text::write_text(p, &small_events())?),
        "e.txt",
    )?])
}

fn t7_seeds() -> Result<Vec<Vec<u8>>> {
    let data: Vec<f32> = (0..24).map(|k| k as f32 * 0.5 - 3.0).collect();
    Ok(vec![
        flow::t7::write_float_tensor(&[2, 3, 2, 2], &data),
        flow::t7::write_float_tensor(&[4], &data[..4]),
    ])
}

fn parse_t7(p: &Prepared) -> bool {
    std::fs::read(&p.input).is_ok_and(|bytes| flow::t7::parse_float_tensor(&bytes, "input").is_ok())
}
