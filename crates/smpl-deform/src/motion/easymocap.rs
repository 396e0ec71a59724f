//! EasyMocap's per-frame `smpl/*.json` files (see the parent module's documentation for the
//! layout and the root-convention conversion).

use std::path::Path;

use glam::{DQuat, DVec3};

use super::{axis_angle_of, Motion, MotionLayout, MAX_MOTION_FRAMES};
use crate::error::{Result, SmplDeformError};
use crate::skeleton::NUM_JOINTS;

/// Largest EasyMocap frame file read (bytes).
const MAX_JSON_BYTES: u64 = 1 << 20;

/// One person of an EasyMocap frame file (other fields are ignored).
#[derive(serde::Deserialize)]
struct EasyMocapPerson {
    #[serde(default)]
    id: i64,
    #[serde(rename = "Rh")]
    rh: Vec<Vec<f64>>,
    #[serde(rename = "Th")]
    th: Vec<Vec<f64>>,
    poses: Vec<Vec<f64>>,
    #[serde(default)]
    shapes: Vec<Vec<f64>>,
}

/// A frame file: a list of people, or one person.
#[derive(serde::Deserialize)]
#[serde(untagged)]
enum EasyMocapFrame {
    People(Vec<EasyMocapPerson>),
    One(EasyMocapPerson),
}

fn json_err(path: &Path, field: &str, reason: impl Into<String>) -> SmplDeformError {
    SmplDeformError::InvalidParams {
        field: format!("{}: `{field}`", path.display()),
        reason: reason.into(),
    }
}

/// The single row of a `[[...]]` field with `width` finite values.
fn one_row<'a>(
    path: &Path,
    field: &str,
    rows: &'a [Vec<f64>],
    widths: &[usize],
) -> Result<&'a [f64]> {
    match rows {
        [row] if widths.contains(&row.len()) && row.iter().all(|v| v.is_finite()) => Ok(row),
        [row] if widths.contains(&row.len()) => Err(json_err(path, field, "holds NaN or ∞")),
        _ => Err(json_err(
            path,
            field,
            format!(
                "expected one row of {} values, found {} rows of {:?}",
                widths
                    .iter()
                    .map(usize::to_string)
                    .collect::<Vec<_>>()
                    .join(" or "),
                rows.len(),
                rows.iter().map(Vec::len).collect::<Vec<_>>()
            ),
        )),
    }
}

/// Reads an EasyMocap `smpl/` folder (every `*.json`, in name order, one frame each) for person
/// `person` (default: the first person of the first file), converting to SMPL's root convention with
/// `root_rest`, the body's rest position of joint 0 (metres; see the module docs).
pub fn read_easymocap(dir: &Path, root_rest: [f64; 3], person: Option<i64>) -> Result<Motion> {
    let frames = read_frames(dir)?;
    let id = match person {
        Some(id) => id,
        None => frames
            .first()
            .and_then(|(_, f)| f.first())
            .map_or(0, |p| p.id),
    };
    person_motion(&frames, id, DVec3::from_array(root_rest))
}

/// Everyone an EasyMocap folder follows through all of its frames.
#[derive(Clone, Debug)]
pub struct EasyMocapPeople {
    /// Each person seen in every frame (by `id`, in the first frame's order) with its motion.
    pub people: Vec<(i64, Motion)>,
    /// The people seen in some frames only: `(id, frames that show it)`, by id.
    pub partial: Vec<(i64, usize)>,
}

/// Reads an EasyMocap `smpl/` folder for every person it follows through all of its frames, as
/// [`read_easymocap`] reads one.
pub fn read_easymocap_people(dir: &Path, root_rest: [f64; 3]) -> Result<EasyMocapPeople> {
    let frames = read_frames(dir)?;
    let mut seen: std::collections::BTreeMap<i64, usize> = std::collections::BTreeMap::new();
    for (_, people) in &frames {
        let ids: std::collections::BTreeSet<i64> = people.iter().map(|p| p.id).collect();
        for id in ids {
            *seen.entry(id).or_default() += 1;
        }
    }
    let everywhere = |id: &i64| seen.get(id) == Some(&frames.len());
    let mut ids: Vec<i64> = Vec::new();
    for p in frames.first().map_or(&[][..], |(_, f)| f) {
        if everywhere(&p.id) && !ids.contains(&p.id) {
            ids.push(p.id);
        }
    }
    let j0 = DVec3::from_array(root_rest);
    let people = ids
        .iter()
        .map(|&id| Ok((id, person_motion(&frames, id, j0)?)))
        .collect::<Result<Vec<_>>>()?;
    let partial = seen
        .iter()
        .filter(|&(_, &count)| count < frames.len())
        .map(|(&id, &count)| (id, count))
        .collect();
    Ok(EasyMocapPeople { people, partial })
}

/// Every frame file of `dir` (`*.json`, in name order), parsed.
fn read_frames(dir: &Path) -> Result<Vec<(std::path::PathBuf, Vec<EasyMocapPerson>)>> {
    let io = |source| SmplDeformError::Io {
        path: dir.to_path_buf(),
        source,
    };
    let mut files: Vec<std::path::PathBuf> = std::fs::read_dir(dir)
        .map_err(io)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.extension()
                .is_some_and(|e| e.eq_ignore_ascii_case("json"))
        })
        .collect();
    files.sort();
    if files.is_empty() || files.len() as u64 > MAX_MOTION_FRAMES {
        return Err(json_err(
            dir,
            "*.json",
            format!(
                "expected 1 to {MAX_MOTION_FRAMES} frame files, found {}",
                files.len()
            ),
        ));
    }
    let mut frames = Vec::with_capacity(files.len());
    for path in files {
        let file_io = |source| SmplDeformError::Io {
            path: path.clone(),
            source,
        };
        let size = std::fs::metadata(&path).map_err(file_io)?.len();
        if size > MAX_JSON_BYTES {
            return Err(json_err(
                &path,
                "<file>",
                format!("{size} bytes, more than {MAX_JSON_BYTES}"),
            ));
        }
        let text = std::fs::read_to_string(&path).map_err(file_io)?;
        let people = match serde_json::from_str::<EasyMocapFrame>(&text) {
            Ok(EasyMocapFrame::People(p)) => p,
            Ok(EasyMocapFrame::One(p)) => vec![p],
            Err(e) => {
                return Err(json_err(
                    &path,
                    "<file>",
                    format!("not an EasyMocap SMPL file: {e}"),
                ))
            }
        };
        frames.push((path, people));
    }
    Ok(frames)
}

/// Person `id`'s motion through `frames`, in SMPL's root convention (`j0` the rest root joint).
fn person_motion(
    frames: &[(std::path::PathBuf, Vec<EasyMocapPerson>)],
    id: i64,
    j0: DVec3,
) -> Result<Motion> {
    let (mut poses, mut transl) = (
        Vec::with_capacity(frames.len()),
        Vec::with_capacity(frames.len()),
    );
    let mut betas = None;
    for (path, people) in frames {
        let path = path.as_path();
        let Some(p) = people.iter().find(|p| p.id == id) else {
            return Err(json_err(path, "id", format!("no person with id {id}")));
        };
        let rh = one_row(path, "Rh", &p.rh, &[3])?;
        let th = one_row(path, "Th", &p.th, &[3])?;
        let body = one_row(path, "poses", &p.poses, &[72, 69])?;
        let (root_aa, joints) = if body.len() == 72 {
            (&body[..3], &body[3..])
        } else {
            (&[0.0; 3][..], body)
        };
        // EasyMocap: x = Rh·(R₀·(v − j₀) + j₀) + Th = (Rh·R₀)·(v − j₀) + Rh·j₀ + Th.
        let rh = DQuat::from_scaled_axis(DVec3::new(rh[0], rh[1], rh[2]));
        let rotation = rh * DQuat::from_scaled_axis(DVec3::new(root_aa[0], root_aa[1], root_aa[2]));
        let t = rh * j0 + DVec3::new(th[0], th[1], th[2]) - j0;
        let mut pose = [0.0f32; 3 * NUM_JOINTS];
        pose[..3].copy_from_slice(&axis_angle_of(rotation));
        for (dst, &src) in pose[3..].iter_mut().zip(joints) {
            *dst = src as f32;
        }
        poses.push(pose);
        transl.push([t.x as f32, t.y as f32, t.z as f32]);
        if betas.is_none() {
            if let Ok(shape) = one_row(path, "shapes", &p.shapes, &[10, 16, 300]) {
                betas = Some(shape.iter().map(|&v| v as f32).collect());
            }
        }
    }
    Ok(Motion {
        layout: MotionLayout::EasyMocap,
        poses,
        transl,
        betas,
        fps: None,
        dropped: Vec::new(),
    })
}
