//! Where a moving camera's scene Gaussians start: the plane sweep of [`crate::init::stereo`] over
//! the training frames, each frame's people left out.

use crate::config::TrainConfig;
use crate::data::{TrainingData, TrainingFrame};
use crate::init::stereo::{self, SweepConfig, SweepView};
use crate::init::{InitMode, SceneInit};
use smpl_deform::math::affine_apply;
use smpl_deform::NUM_JOINTS;

/// Points on the static scene's surfaces for the initial scene Gaussians
/// ([`crate::init::stereo`]) when `config.scene_init` asks for them and the camera moves; empty
/// otherwise. Each frame's people are left out of its points ([`person_box`]). The sweep reaches
/// from a quarter of the nearest camera–person distance to twice the farthest (the scene cube's
/// depth).
pub(super) fn scene_surface(
    data: &TrainingData,
    config: &TrainConfig,
    roots: &[[f32; 3]],
) -> Vec<[f32; 3]> {
    let moves = data.frames.iter().any(|f| f.camera != data.camera);
    if config.scene_init != SceneInit::Stereo || !moves || config.init != InitMode::SmplCube {
        return Vec::new();
    }
    let distance = |f: &TrainingFrame, p: [f32; 3]| {
        let c = f.camera.center_world();
        (0..3)
            .map(|a| (f64::from(p[a]) - c[a]).powi(2))
            .sum::<f64>()
            .sqrt()
    };
    let (mut nearest, mut farthest) = (f64::INFINITY, 0.0f64);
    for p in roots {
        for f in &data.frames {
            nearest = nearest.min(distance(f, *p));
            farthest = farthest.max(distance(f, *p));
        }
    }
    let views: Vec<SweepView<'_>> = data
        .frames
        .iter()
        .map(|f| SweepView {
            image: &f.image,
            camera: &f.camera,
            exclude: person_box(data, f),
        })
        .collect();
    let sweep = SweepConfig {
        near: (0.25 * nearest).max(0.05),
        far: (2.0 * farthest).max(0.5 * nearest + 1.0),
        ..SweepConfig::default()
    };
    stereo::surface_points(&views, &sweep)
}

/// How far beyond its posed skeleton's vertices a person may reach in a frame (m): clothing, hair
/// and the blur of a limb's motion.
const PERSON_MARGIN_M: f64 = 0.15;

/// The pixel box (x0, y0, x1, y1) of every person of training frame `f` of `data`: the canonical
/// body vertices (every fourth) moved rigidly by the bone that weighs most on each, projected by
/// the frame's camera and grown by [`PERSON_MARGIN_M`]; what `--scene-init stereo` leaves out.
pub fn person_box(data: &TrainingData, f: &TrainingFrame) -> Option<[f64; 4]> {
    let bodies = std::iter::once(&data.body).chain(&data.others);
    let mut posed = Vec::new();
    for (person, body) in bodies.enumerate() {
        let weights = &body.model.weights;
        for (v, x) in body.canonical.posed.vertices.iter().enumerate().step_by(4) {
            let Some(row) = weights.get(v * NUM_JOINTS..(v + 1) * NUM_JOINTS) else {
                break;
            };
            let bone = (0..NUM_JOINTS)
                .max_by(|&a, &b| row[a].total_cmp(&row[b]))
                .unwrap_or(0);
            if let Some(t) = f.pose.prepared.bones.get(person * NUM_JOINTS + bone) {
                posed.push(affine_apply(t, *x));
            }
        }
    }
    stereo::pixel_box(&f.camera, posed, PERSON_MARGIN_M)
}
