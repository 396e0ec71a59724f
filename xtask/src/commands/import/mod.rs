//! `cargo xtask import <layout>`: a scene (format v1) from the data people have. Each layout writes
//! a validated scene directory that `cargo xtask reconstruct --data SCENE` trains on.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use clap::Subcommand;
use smpl_deform::motion::{read_easymocap, read_easymocap_people, read_motion};

mod aedat4;
mod frames;
mod zju;

/// The layouts `import` reads.
#[derive(Subcommand, Debug)]
pub enum Command {
    /// A folder of video frames (PNG) plus one SMPL pose per frame. Optionally synthesises what the
    /// paper synthesised for ZJU-MoCap-Blur: blur by averaging K consecutive frames (the middle
    /// frame kept as the sharp reference) and events by ESIM over the frames.
    Frames(frames::Args),
    /// A DAVIS recording (AEDAT 4 with an intensity-frame stream and an event stream) plus one SMPL
    /// pose per frame: the frames at their own exposure times, the events split per frame.
    Aedat4(aedat4::Args),
    /// One view of a ZJU-MoCap subject as ARAH / 3DGS-Avatar preprocess it (cam_params.json,
    /// models/*.npz, {view}/*.jpg + *.png masks): undistorted, SMPL fits mapped, optionally with
    /// the ZJU-MoCap-Blur recipe (--blur K, --events simulate).
    Zju(zju::Args),
}

/// The person and camera arguments `import frames` and `import aedat4` share.
#[derive(clap::Args, Debug)]
pub struct PersonArgs {
    /// SMPL poses, one per frame: a JSON list of `{"pose": 72 values or 24 triples, "transl": [3]}`,
    /// an AMASS-style `.npz` (`poses`, `trans`), a PeopleSnapshot / InstantAvatar `.npz`
    /// (`global_orient`, `body_pose`, `transl`, `betas`) or an EasyMocap `smpl/` folder. For
    /// `import aedat4`, JSON entries may also carry `t_us`, the pose's time on the recording's clock
    /// (µs): the pose at each frame's exposure midpoint is then interpolated (C¹ spline).
    #[arg(long)]
    pub poses: PathBuf,
    /// With an EasyMocap folder: the `id` of the one person to follow (default: every person seen
    /// in all frames — a scene with several people, format 3 — and the first one alone for
    /// `import aedat4`).
    #[arg(long)]
    pub person: Option<i64>,
    /// The camera: the project's camera JSON, a scene's `scene.json`, or an INRIA `cameras.json`
    /// list (see `--cam-index`). Its size must be the frames' size.
    #[arg(long)]
    pub camera: PathBuf,
    /// Index into an INRIA `cameras.json` list.
    #[arg(long, default_value_t = 0)]
    pub cam_index: usize,
    /// Optional folder of human masks (single-channel PNG, non-zero = human), one per frame, in
    /// file-name order.
    #[arg(long)]
    pub masks: Option<PathBuf>,
    /// Body model: `builtin:makehuman` or the path of your SMPL `.npz` (its licence is yours; the
    /// scene references it, it is not copied).
    #[arg(long, default_value = "builtin:makehuman")]
    pub body: String,
}

impl PersonArgs {
    /// The camera of `--camera` / `--cam-index`.
    pub fn camera(&self) -> Result<scene::Camera> {
        scene::camera_files::read_any(&self.camera, self.cam_index)
            .with_context(|| format!("reading the camera {}", self.camera.display()))
    }

    /// The mask files of `--masks` (none without it), which must be one per frame of the
    /// `frames` frames of `source`.
    pub fn mask_files(&self, frames: usize, source: &Path) -> Result<Option<Vec<PathBuf>>> {
        let Some(dir) = &self.masks else {
            return Ok(None);
        };
        let m = image_files(dir, "masks")?;
        if m.len() != frames {
            bail!(
                "{} holds {} masks but {} holds {frames} frames: one mask per frame is needed",
                dir.display(),
                m.len(),
                source.display()
            );
        }
        Ok(Some(m))
    }
}

/// The synthesis arguments `import frames` and `import zju` share (the ZJU-MoCap-Blur recipe).
#[derive(clap::Args, Debug)]
pub struct SynthesisArgs {
    /// Average K consecutive frames (odd) into one observed frame, keeping the middle one as the
    /// sharp reference: output rate fps / K, exposure K / fps. 1 = the frames are the observations.
    #[arg(long, default_value_t = 1)]
    pub blur: usize,
    /// `simulate`: events by ESIM over the frames, split per output frame; `none`: no events.
    #[arg(long, default_value = "none", value_parser = ["none", "simulate"])]
    pub events: String,
    /// ESIM contrast threshold C (both polarities, log-intensity units).
    #[arg(long, default_value_t = 0.2)]
    pub threshold: f32,
    /// Seed of the simulator's per-pixel threshold noise.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Frames interpolated between each pair of consecutive frames by the project's flow network
    /// (`--flow-weights`), joining the blur windows and the event simulation (the paper's
    /// construction); 0 = none. Costs two flow estimates per pair at the frames' size.
    #[arg(long, default_value_t = 0)]
    pub in_between: usize,
    /// Flow weights for `--in-between` (default: the project's own).
    #[arg(long)]
    pub flow_weights: Option<PathBuf>,
}

impl SynthesisArgs {
    /// The interpolation of `--in-between` (`None` without it): flows both ways between the two
    /// frames by the flow network, then `flow::interpolate::frame_between` at each time.
    pub fn between(
        &self,
        h: usize,
        w: usize,
    ) -> Result<Option<Box<synth::from_frames::Between<'static>>>> {
        if self.in_between == 0 {
            return Ok(None);
        }
        let path = self
            .flow_weights
            .clone()
            .unwrap_or_else(crate::common::shipped_flow_network);
        let net = flow::load_safetensors(&path)
            .with_context(|| format!("loading the flow weights {}", path.display()))?;
        Ok(Some(Box::new(move |a: &[f32], b: &[f32], ts: &[f32]| {
            let err = |e: flow::FlowError| synth::SynthError::Knob {
                knob: "in_between",
                value: "flow".into(),
                reason: e.to_string(),
            };
            let (ab, ba) = flow::interpolate::flows_between(&net, a, b, h, w).map_err(err)?;
            ts.iter()
                .map(|&t| {
                    flow::interpolate::frame_between(a, b, (&ab, &ba), 3, h, w, t).map_err(err)
                })
                .collect()
        })))
    }

    /// The importer settings for frames at `fps` (exposure: the camera's when not blurring).
    pub fn config(&self, fps: f64, exposure_s: Option<f64>) -> synth::from_frames::FramesToScene {
        synth::from_frames::FramesToScene {
            fps,
            blur: self.blur,
            in_between: self.in_between,
            exposure_s,
            events: (self.events == "simulate").then(|| events::EsimConfig {
                c_pos: self.threshold,
                c_neg: self.threshold,
                seed: self.seed,
                ..events::EsimConfig::default()
            }),
            ..synth::from_frames::FramesToScene::default()
        }
    }
}

/// Loads `--body` and returns it with the name the scene records: `builtin:makehuman`, or the
/// SMPL file's absolute path.
pub(super) fn load_body(body: &str) -> Result<(smpl_deform::BodyModel, String)> {
    let body_ref = smpl_deform::BodyRef::parse(body)?;
    let model = body_ref
        .load()
        .with_context(|| format!("loading the body model {body}"))?;
    let name = match &body_ref {
        smpl_deform::BodyRef::BuiltinMakehuman => body.to_string(),
        smpl_deform::BodyRef::SmplFile(p) => std::fs::canonicalize(p)
            .unwrap_or_else(|_| p.clone())
            .display()
            .to_string(),
    };
    Ok((model, name))
}

/// Refuses an output directory that already holds a scene.
pub(super) fn check_out_is_free(out: &Path) -> Result<()> {
    if out.join(scene::SCENE_FILE).exists() {
        bail!(
            "{} already holds a scene: choose another --out or remove it",
            out.display()
        );
    }
    Ok(())
}

/// Runs `import`.
pub fn run(command: Command) -> Result<()> {
    match command {
        Command::Frames(args) => frames::run(args),
        Command::Aedat4(args) => aedat4::run(args),
        Command::Zju(args) => zju::run(args),
    }
}

/// The image files of a folder in file-name order (PNG or PPM/PNM).
pub(super) fn image_files(dir: &Path, what: &str) -> Result<Vec<PathBuf>> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .with_context(|| format!("reading the {what} folder {}", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.extension().and_then(|e| e.to_str()).is_some_and(|e| {
                ["png", "ppm", "pnm", "jpg", "jpeg"].contains(&e.to_ascii_lowercase().as_str())
            })
        })
        .collect();
    files.sort();
    if files.is_empty() {
        bail!("{}: no PNG, JPEG or PPM {what} found", dir.display());
    }
    Ok(files)
}

/// A pose as 24 axis-angle triples and a translation.
pub(super) type Pose = (Vec<[f32; 3]>, [f32; 3]);

/// Poses read from a file: one per frame, or — a JSON list whose entries all carry `t_us` — at
/// their own times (µs, the recording's clock), for the importer to interpolate.
pub(super) struct Poses {
    /// The poses, in file order.
    pub list: Vec<Pose>,
    /// Each pose's time (µs), when the file gives them.
    pub times_us: Option<Vec<i64>>,
    /// The file's shape parameters, when it has them.
    pub betas: Option<Vec<f32>>,
    /// The first person's EasyMocap id when the folder was read for everyone (0 otherwise); a
    /// scene names it only among several people.
    pub id: u32,
    /// With an EasyMocap folder following several people and no `--person`: everyone after the
    /// first, in the folder's order.
    pub others: Vec<OtherPerson>,
}

/// A further person of an EasyMocap folder: its id, shape and pose in every frame.
pub(super) struct OtherPerson {
    pub id: u32,
    pub betas: Vec<f32>,
    pub list: Vec<Pose>,
}

impl Poses {
    /// The scene's `people` entries and frame `i`'s poses of them (format 3; empty with one
    /// person).
    pub(super) fn people(&self) -> Vec<scene::PersonSpec> {
        self.others
            .iter()
            .map(|o| scene::PersonSpec {
                id: o.id,
                betas: o.betas.clone(),
            })
            .collect()
    }

    /// Frame `i`'s poses of the people after the first.
    pub(super) fn others_at(&self, i: usize) -> Vec<scene::PersonPose> {
        self.others
            .iter()
            .map(|o| scene::PersonPose {
                id: o.id,
                pose: o.list[i].0.clone(),
                transl: o.list[i].1,
            })
            .collect()
    }
}

/// Reads `--poses` (see `import frames --help` for the layouts).
pub(super) fn read_poses(
    path: &Path,
    body: &smpl_deform::BodyModel,
    person: Option<i64>,
) -> Result<Poses> {
    let triples = |flat: &[f32]| flat.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
    if path.extension().and_then(|e| e.to_str()) == Some("json") {
        let text =
            std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        let value: serde_json::Value =
            serde_json::from_str(&text).with_context(|| format!("{}: not JSON", path.display()))?;
        let serde_json::Value::Array(list) = value else {
            bail!("{}: expected a JSON list of poses", path.display());
        };
        let mut times = Vec::new();
        let mut poses = Vec::with_capacity(list.len());
        for (k, mut v) in list.into_iter().enumerate() {
            if let Some(t) = v.as_object_mut().and_then(|o| o.remove("t_us")) {
                let t = t.as_i64().with_context(|| {
                    format!(
                        "{}: pose {k}: `t_us` {t} is not an integer (µs)",
                        path.display()
                    )
                })?;
                times.push(t);
            }
            let (pose, transl, _) = crate::poses_json::read_entry(v)
                .with_context(|| format!("{}: pose {k}", path.display()))?;
            poses.push((triples(&pose), transl));
        }
        let times_us = match times.len() {
            0 => None,
            n if n == poses.len() => {
                if let Some(k) = (1..n).find(|&k| times[k] <= times[k - 1]) {
                    bail!(
                        "{}: pose {k}: `t_us` {} is not after pose {}'s {}",
                        path.display(),
                        times[k],
                        k - 1,
                        times[k - 1]
                    );
                }
                Some(times)
            }
            n => bail!(
                "{}: {n} of {} poses have `t_us`: all or none must",
                path.display(),
                poses.len()
            ),
        };
        return Ok(Poses {
            list: poses,
            times_us,
            betas: None,
            id: 0,
            others: Vec::new(),
        });
    }
    if path.is_dir() && person.is_none() {
        return read_easymocap_everyone(path, body);
    }
    let motion = if path.is_dir() {
        read_easymocap(path, rest_root(body)?, person)
    } else {
        read_motion(path)
    }
    .with_context(|| format!("reading the poses {}", path.display()))?;
    for note in &motion.dropped {
        eprintln!("note: {}: {note}", path.display());
    }
    let poses = motion
        .poses
        .iter()
        .zip(&motion.transl)
        .map(|(p, t)| (triples(p), *t))
        .collect();
    Ok(Poses {
        list: poses,
        times_us: None,
        betas: motion.betas,
        id: 0,
        others: Vec::new(),
    })
}

/// The body's rest position of joint 0 (metres), EasyMocap's rotation centre.
fn rest_root(body: &smpl_deform::BodyModel) -> Result<[f64; 3]> {
    let shaped = body.shaped_vertices(&[])?;
    let root = body
        .rest_joints(&shaped)
        .first()
        .copied()
        .unwrap_or([0.0; 3]);
    Ok(root.map(f64::from))
}

/// An EasyMocap id as a scene's person id (a non-negative 32-bit number).
fn person_id(path: &Path, id: i64) -> Result<u32> {
    u32::try_from(id).with_context(|| {
        format!(
            "{}: person id {id}: a scene's person ids are 0 to {}",
            path.display(),
            u32::MAX
        )
    })
}

/// Every person an EasyMocap folder follows through all of its frames: the first as the scene's
/// body, the others as its `people` (a note names anyone seen in some frames only).
fn read_easymocap_everyone(path: &Path, body: &smpl_deform::BodyModel) -> Result<Poses> {
    let found = read_easymocap_people(path, rest_root(body)?)
        .with_context(|| format!("reading the poses {}", path.display()))?;
    for (id, frames) in &found.partial {
        eprintln!(
            "note: {}: person {id} is in {frames} of the frames, not all: not imported \
             (--person {id} to follow it alone)",
            path.display()
        );
    }
    let triples = |flat: &[f32]| flat.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
    let mut people = found.people.into_iter().map(|(id, motion)| {
        let list: Vec<Pose> = motion
            .poses
            .iter()
            .zip(&motion.transl)
            .map(|(p, t)| (triples(p), *t))
            .collect();
        Ok::<_, anyhow::Error>((person_id(path, id)?, motion.betas, list))
    });
    let Some(first) = people.next() else {
        bail!(
            "{}: nobody is in every frame (--person ID to follow one person through its frames)",
            path.display()
        );
    };
    let (id, betas, list) = first?;
    let others = people
        .map(|p| {
            let (id, betas, list) = p?;
            Ok(OtherPerson {
                id,
                betas: betas.unwrap_or_default(),
                list,
            })
        })
        .collect::<Result<Vec<_>>>()?;
    if !others.is_empty() {
        eprintln!(
            "{}: {} people in every frame (ids {}): a scene with several people (--person ID \
             to keep one)",
            path.display(),
            others.len() + 1,
            std::iter::once(id)
                .chain(others.iter().map(|o| o.id))
                .map(|i| i.to_string())
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    Ok(Poses {
        list,
        times_us: None,
        betas,
        id,
        others,
    })
}

/// Reads a single-channel (or any) mask image as `non-zero = human`, checked against the camera.
pub(super) fn read_mask_any(path: &Path, camera: &scene::Camera) -> Result<Vec<bool>> {
    let img = image::open(path)
        .with_context(|| format!("reading the mask {}", path.display()))?
        .to_luma16();
    if (img.width(), img.height()) != (camera.width, camera.height) {
        bail!(
            "{}: {}x{}, the camera is {}x{}",
            path.display(),
            img.width(),
            img.height(),
            camera.width,
            camera.height
        );
    }
    Ok(img.pixels().map(|p| p.0[0] > 0).collect())
}
