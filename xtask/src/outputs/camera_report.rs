//! The camera error of a reconstruction's frames against a synthetic scene's true cameras
//! (`cameras_true.json`, which the trainer never reads): the cameras as the scene gives them and,
//! with camera correction, as corrected (held-out frames: interpolated, never fitted).

use anyhow::{Context, Result};
use scene::Split;
use synth::camera_error::{rms_error, TrueCameras};
use train::data::Dataset;
use train::model::Model;

/// RMS errors of one set of camera poses against the truth.
#[derive(Clone, Copy, Debug, serde::Serialize)]
pub struct CameraError {
    /// RMS rotation error (degrees).
    pub rotation_rms_deg: f64,
    /// RMS camera-centre error (cm).
    pub centre_rms_cm: f64,
}

/// Camera errors of the training and held-out frames, given and (with camera correction)
/// corrected at mid exposure.
#[derive(Clone, Debug, serde::Serialize)]
pub struct CameraReport {
    /// Training frames, the scene's cameras.
    pub train_given: CameraError,
    /// Training frames, corrected.
    pub train_corrected: Option<CameraError>,
    /// Held-out frames, the scene's cameras.
    pub test_given: CameraError,
    /// Held-out frames, corrected (interpolated corrections).
    pub test_corrected: Option<CameraError>,
}

/// The report for `data`, or `None` when the scene has no `cameras_true.json`.
pub fn camera_report(data: &Dataset, model: &Model) -> Result<Option<CameraReport>> {
    let path = TrueCameras::path(&data.dir);
    if !path.exists() {
        return Ok(None);
    }
    let truth =
        TrueCameras::read(&data.dir).with_context(|| format!("reading {}", path.display()))?;
    let errors = |split: Split| -> Result<(CameraError, CameraError)> {
        let mut true_frames = Vec::new();
        let (mut given, mut corrected) = (Vec::new(), Vec::new());
        for f in data.frames.iter().filter(|f| f.split == split) {
            let t = truth
                .frames
                .iter()
                .find(|t| t.index == f.index)
                .with_context(|| format!("{}: no frame {}", path.display(), f.index))?;
            true_frames.push(t.clone());
            given.push(f.camera.world_to_camera);
            corrected.push(model.corrected_camera(f.index, &f.camera).world_to_camera);
        }
        let of_split = TrueCameras {
            format_version: truth.format_version,
            frames: true_frames,
        };
        let error = |estimates: &[[[f64; 4]; 4]]| {
            let (rotation_rms_deg, centre_rms_cm) = rms_error(estimates, &of_split);
            CameraError {
                rotation_rms_deg,
                centre_rms_cm,
            }
        };
        Ok((error(&given), error(&corrected)))
    };
    let (train_given, train_corrected) = errors(Split::Train)?;
    let (test_given, test_corrected) = errors(Split::Test)?;
    let correcting = model.config.camera_correction;
    Ok(Some(CameraReport {
        train_given,
        train_corrected: correcting.then_some(train_corrected),
        test_given,
        test_corrected: correcting.then_some(test_corrected),
    }))
}

/// The RMS error of the cameras `aligned` (frame index, world-to-camera; the held-out frames'
/// cameras after test-time alignment) against the truth, or `None` without `cameras_true.json`.
pub fn aligned_error(
    data: &Dataset,
    aligned: &[(u32, [[f64; 4]; 4])],
) -> Result<Option<CameraError>> {
    let path = TrueCameras::path(&data.dir);
    if !path.exists() || aligned.is_empty() {
        return Ok(None);
    }
    let truth =
        TrueCameras::read(&data.dir).with_context(|| format!("reading {}", path.display()))?;
    let mut frames = Vec::with_capacity(aligned.len());
    for (index, _) in aligned {
        let t = truth
            .frames
            .iter()
            .find(|t| t.index == *index)
            .with_context(|| format!("{}: no frame {index}", path.display()))?;
        frames.push(t.clone());
    }
    let estimates: Vec<_> = aligned.iter().map(|(_, m)| *m).collect();
    let (rotation_rms_deg, centre_rms_cm) = rms_error(
        &estimates,
        &TrueCameras {
            format_version: truth.format_version,
            frames,
        },
    );
    Ok(Some(CameraError {
        rotation_rms_deg,
        centre_rms_cm,
    }))
}

/// One line for the terminal: the RMS camera errors, given → corrected.
pub fn summary_line(r: &CameraReport) -> String {
    let pair = |e: &CameraError| format!("{:.3}° / {:.2} cm", e.rotation_rms_deg, e.centre_rms_cm);
    match (&r.train_corrected, &r.test_corrected) {
        (Some(train), Some(test)) => format!(
            "camera error (RMS rotation / centre, against cameras_true.json): training frames {} → \
             {}, held-out frames {} → {}",
            pair(&r.train_given),
            pair(train),
            pair(&r.test_given),
            pair(test)
        ),
        _ => format!(
            "camera error (RMS rotation / centre, against cameras_true.json): training frames {}, \
             held-out frames {} (no camera correction)",
            pair(&r.train_given),
            pair(&r.test_given)
        ),
    }
}
