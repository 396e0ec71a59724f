//! The scene as training reads it: every frame decoded (images linear and planar, masks, SMPL
//! parameters, the split) and the rasterizer's camera; [`load_dataset`] converts what `scene::load`
//! validated.

use crate::TrainError;
use rasterize_cpu::Camera;
use scene::{Scene, Split};
use smpl_deform::SmplParams;
use std::path::{Path, PathBuf};

/// One decoded frame.
#[derive(Clone, Debug, PartialEq)]
pub struct TrainFrame {
    /// Frame number from `scene.json`.
    pub index: u32,
    /// Mid-exposure time (s).
    pub time_s: f64,
    /// The frame's exposure (s): its own `exposure_s` in `scene.json`, else the scene's.
    pub exposure_s: f64,
    /// Train or test.
    pub split: Split,
    /// Observed (blurred) image, planar (3, H, W) linear.
    pub image: Vec<f32>,
    /// Sharp reference, if the scene has one.
    pub sharp: Option<Vec<f32>>,
    /// Human mask (H × W), if the scene has one.
    pub mask: Option<Vec<bool>>,
    /// Which person each pixel shows (H × W; 0 = nobody, p + 1 = person p of the scene's
    /// order), if the scene has one.
    pub person_ids: Option<Vec<u8>>,
    /// SMPL parameters at mid exposure (betas from the scene's body spec).
    pub smpl: SmplParams,
    /// The other people's SMPL parameters at mid exposure (scene order, each with its own betas;
    /// empty with one person).
    pub others: Vec<SmplParams>,
    /// The camera at mid exposure: the scene camera, at the frame's own pose when it has one.
    pub camera: Camera,
}

/// A loaded dataset.
#[derive(Clone, Debug)]
pub struct Dataset {
    /// The scene directory.
    pub dir: PathBuf,
    /// The validated description.
    pub scene: Scene,
    /// The scene camera: the intrinsics of every frame and the pose of every frame without one of
    /// its own; checked for rendering (`Camera::validate`).
    pub camera: Camera,
    /// Some frame is filmed from a pose of its own ([`TrainFrame::camera`]): the camera moves.
    pub camera_moves: bool,
    /// Every frame, in time order.
    pub frames: Vec<TrainFrame>,
}

/// The body's, the other people's and (when it moves) the camera's paths through a scene's frames
/// ([`Dataset::paths`]): what the exposure model samples a frame's sub-exposure renders from.
pub struct ScenePaths {
    /// The first person's body.
    pub body: crate::pose::exposure::PoseTrack,
    /// Each other person's, in the scene's order.
    pub others: Vec<crate::pose::exposure::PoseTrack>,
    /// The camera's, `None` for a static camera.
    pub camera: Option<crate::pose::exposure::CameraTrack>,
}

impl Dataset {
    /// The paths through every frame, interpolated by `rules`, with `people` other people.
    pub fn paths(&self, rules: crate::pose::exposure::TrackRules, people: usize) -> ScenePaths {
        use crate::pose::exposure::{CameraTrack, PoseTrack};
        let keys: Vec<(f64, &SmplParams)> =
            self.frames.iter().map(|f| (f.time_s, &f.smpl)).collect();
        let others = (0..people)
            .map(|j| {
                let keys: Vec<(f64, &SmplParams)> = self
                    .frames
                    .iter()
                    .map(|f| (f.time_s, &f.others[j]))
                    .collect();
                PoseTrack::new(&keys, rules.body)
            })
            .collect();
        let camera = self.camera_moves.then(|| {
            let keys: Vec<(f64, [[f64; 4]; 4])> = self
                .frames
                .iter()
                .map(|f| (f.time_s, f.camera.world_to_camera))
                .collect();
            CameraTrack::new(&keys, rules.camera)
        });
        ScenePaths {
            body: PoseTrack::new(&keys, rules.body),
            others,
            camera,
        }
    }

    /// The body the scene names (`scene.json`'s `body`), a relative SMPL path taken relative to
    /// the scene directory.
    pub fn body(&self) -> Result<crate::pose::body::Body, TrainError> {
        let spec = &self.scene.body;
        crate::pose::body::Body::load(&spec.model, spec.betas.clone(), &self.dir)
    }

    /// The other people's bodies (`scene.json`'s `people`, in order): the first person's body
    /// model with each one's own betas. Empty with one person.
    pub fn other_bodies(&self) -> Result<Vec<crate::pose::body::Body>, TrainError> {
        let spec = &self.scene.body;
        let model = crate::pose::body::resolve_reference(&spec.model, &self.dir)?.load()?;
        self.scene
            .people
            .iter()
            .map(|p| crate::pose::body::Body::new(model.clone(), p.betas.clone()))
            .collect()
    }

    /// How many people the scene has.
    pub fn people(&self) -> usize {
        self.scene.person_count()
    }

    /// Indices of the frames of a split.
    pub fn split(&self, split: Split) -> Vec<usize> {
        self.scene.split_indices(split)
    }

    /// A positive finite number the scene's generator recorded under `config.<key>` (e.g. the
    /// sensor's `event_threshold`), if it recorded one.
    pub fn recorded_positive(&self, key: &str) -> Option<f64> {
        self.recorded(key).filter(|c| *c > 0.0)
    }

    /// A finite number the scene's generator recorded under `config.<key>` (e.g. the sensor's
    /// `refractory_us`, which may be 0), if it recorded one.
    pub fn recorded(&self, key: &str) -> Option<f64> {
        self.scene
            .generator
            .as_ref()
            .and_then(|g| g.pointer(&format!("/config/{key}")))
            .and_then(serde_json::Value::as_f64)
            .filter(|c| c.is_finite())
    }
}

/// Loads and validates `dir` (see `scene::load`) and decodes every frame.
pub fn load_dataset(dir: &Path) -> Result<Dataset, TrainError> {
    let scene = scene::load(dir)?;
    if scene.person_count() > MAX_PEOPLE {
        return Err(TrainError::Config(format!(
            "{}: the scene has {} people (scene.json `people`, ids {:?}); the model reconstructs \
             at most {MAX_PEOPLE}",
            dir.join(scene::SCENE_FILE).display(),
            scene.person_count(),
            scene.person_ids()
        )));
    }
    scene.camera.validate()?;
    let camera = scene.camera.clone();
    let (w, h) = (scene.camera.width, scene.camera.height);
    let mut frames = Vec::with_capacity(scene.frames.len());
    for (k, f) in scene.frames.iter().enumerate() {
        let read = |rel: &str| -> Result<Vec<f32>, TrainError> {
            let path = Scene::resolve(dir, rel);
            let img = scene::read_rgb(&path, scene.images)?;
            if img.width != w || img.height != h {
                return Err(TrainError::Config(format!(
                    "{}: image is {}x{}, the camera is {w}x{h}",
                    path.display(),
                    img.width,
                    img.height
                )));
            }
            Ok(img.data)
        };
        let mask = match &f.mask {
            Some(rel) => Some(scene::read_mask(&Scene::resolve(dir, rel))?.2),
            None => None,
        };
        let person_ids = match &f.person_ids {
            Some(rel) => Some(read_person_ids(&Scene::resolve(dir, rel), w, h)?),
            None => None,
        };
        let others = (1..scene.person_count())
            .map(|p| {
                let (pose, transl) = f.pose_of(p).ok_or_else(|| {
                    TrainError::Config(format!(
                        "{}: frame {} has no pose of person {p}",
                        dir.join(scene::SCENE_FILE).display(),
                        f.index
                    ))
                })?;
                Ok(SmplParams {
                    pose: pose.iter().flatten().copied().collect(),
                    betas: scene.betas_of(p).unwrap_or_default().to_vec(),
                    transl,
                })
            })
            .collect::<Result<Vec<_>, TrainError>>()?;
        frames.push(TrainFrame {
            index: f.index,
            time_s: f.time_s,
            exposure_s: scene.exposure_of(k),
            split: f.split,
            image: read(&f.image)?,
            sharp: f.sharp.as_deref().map(read).transpose()?,
            mask,
            person_ids,
            smpl: SmplParams {
                pose: f.pose_flat(),
                betas: scene.body.betas.clone(),
                transl: f.transl,
            },
            others,
            camera: scene.camera_of(k),
        });
    }
    Ok(Dataset {
        dir: dir.to_path_buf(),
        camera_moves: scene.camera_moves(),
        scene,
        camera,
        frames,
    })
}

/// The most people a model reconstructs (the benchmark's `--people` range).
pub const MAX_PEOPLE: usize = 4;

/// A person-id image checked against the camera's `w` × `h`.
fn read_person_ids(path: &Path, w: u32, h: u32) -> Result<Vec<u8>, TrainError> {
    let (iw, ih, ids) = scene::read_person_ids(path)?;
    if (iw, ih) != (w, h) {
        return Err(TrainError::Config(format!(
            "{}: person ids are {iw}x{ih}, the camera is {w}x{h}",
            path.display()
        )));
    }
    Ok(ids)
}
