//! The pose error of a reconstruction's training frames against a synthetic scene's true poses
//! (`poses_true.json`, which the trainer never reads): the poses as the scene gives them and, with
//! pose correction, as corrected — in the units of `synth::pose_metrics`.

use anyhow::{Context, Result};
use scene::Split;
use synth::pose_metrics::{measure, view_error};
use synth::{FramePose, PoseErrorStats, TruePoses, ViewErrorStats};
use train::data::Dataset;
use train::model::Model;
use train::pose::body::Body;

/// Pose errors of the training frames: as given, and as corrected (when the model corrects poses);
/// and how the joints' error looks from the scene's camera, on the training and the held-out frames.
#[derive(Clone, Debug, serde::Serialize)]
pub struct PoseReport {
    /// The scene's poses against the truth.
    pub given: PoseErrorStats,
    /// The corrected poses against the truth (`None` without pose correction).
    pub corrected: Option<PoseErrorStats>,
    /// The joints' error seen from the camera, per split and pose source.
    pub view: ViewReport,
}

/// [`ViewErrorStats`] of the training frames and of the held-out frames (whose corrections are
/// interpolated, never fitted): as given and, with pose correction, as corrected.
#[derive(Clone, Debug, serde::Serialize)]
pub struct ViewReport {
    /// Training frames, the scene's poses.
    pub train_given: ViewErrorStats,
    /// Training frames, corrected.
    pub train_corrected: Option<ViewErrorStats>,
    /// Held-out frames, the scene's poses.
    pub test_given: ViewErrorStats,
    /// Held-out frames, corrected (interpolated corrections).
    pub test_corrected: Option<ViewErrorStats>,
}

/// The report for `data`, or `None` when the scene has no `poses_true.json`.
pub fn pose_report(data: &Dataset, model: &Model, body: &Body) -> Result<Option<PoseReport>> {
    if !TruePoses::path(&data.dir).exists() {
        return Ok(None);
    }
    let truth = TruePoses::read(&data.dir)
        .with_context(|| format!("reading {}", TruePoses::path(&data.dir).display()))?;
    let as_frame = |index: u32, time_s: f64, p: &smpl_deform::SmplParams| FramePose {
        index,
        time_s,
        pose: p.pose.chunks_exact(3).map(|r| [r[0], r[1], r[2]]).collect(),
        transl: p.transl,
    };
    // (truth, given, corrected) of the frames of one split.
    let frames_of = |split: Split| -> Result<[Vec<FramePose>; 3]> {
        let (mut true_frames, mut given, mut corrected) = (Vec::new(), Vec::new(), Vec::new());
        for f in data.frames.iter().filter(|f| f.split == split) {
            let t = truth
                .frames
                .iter()
                .find(|t| t.index == f.index)
                .with_context(|| format!("poses_true.json has no frame {}", f.index))?;
            true_frames.push(t.clone());
            given.push(as_frame(f.index, f.time_s, &f.smpl));
            corrected.push(as_frame(
                f.index,
                f.time_s,
                &model.corrected_params(f.index, &f.smpl),
            ));
        }
        Ok([true_frames, given, corrected])
    };
    let [train_true, train_given, train_corrected] = frames_of(Split::Train)?;
    let [test_true, test_given, test_corrected] = frames_of(Split::Test)?;
    let joints = &body.canonical.posed.joints_rest;
    let parents = &body.model.parents;
    let correcting = model.config.pose_correction;
    let view = |t: &[FramePose], e: &[FramePose]| view_error(t, e, joints, parents, &data.camera);
    Ok(Some(PoseReport {
        given: measure(&train_true, &train_given, joints, parents),
        corrected: correcting.then(|| measure(&train_true, &train_corrected, joints, parents)),
        view: ViewReport {
            train_given: view(&train_true, &train_given),
            train_corrected: correcting.then(|| view(&train_true, &train_corrected)),
            test_given: view(&test_true, &test_given),
            test_corrected: correcting.then(|| view(&test_true, &test_corrected)),
        },
    }))
}

/// One line for the terminal: mean joint, root orientation and translation errors, given → corrected.
pub fn summary_line(r: &PoseReport) -> String {
    let figures = |s: &PoseErrorStats| {
        (
            s.joint_mean_deg,
            s.root_orient_mean_deg,
            s.root_transl_mean_cm,
        )
    };
    let (j, o, t) = figures(&r.given);
    match &r.corrected {
        Some(c) => {
            let (cj, co, ct) = figures(c);
            let px = |v: &Option<ViewErrorStats>| v.map_or(f64::NAN, |v| v.image_px);
            format!(
                "pose error of the training frames (mean, against poses_true.json): joints {j:.2}° → \
                 {cj:.2}°, root orientation {o:.2}° → {co:.2}°, translation {t:.2} → {ct:.2} cm; \
                 joints on the image {:.2} → {:.2} px (held-out frames {:.2} → {:.2} px)",
                r.view.train_given.image_px,
                px(&r.view.train_corrected),
                r.view.test_given.image_px,
                px(&r.view.test_corrected),
            )
        }
        None => format!(
            "pose error of the training frames (mean, against poses_true.json): joints {j:.2}°, \
             root orientation {o:.2}°, translation {t:.2} cm (no pose correction)"
        ),
    }
}
