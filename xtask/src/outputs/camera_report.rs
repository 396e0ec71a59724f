//! The camera error of a reconstruction's frames against a synthetic scene's true cameras
//! (`cameras_true.json`, which the trainer never reads): the cameras as the scene gives them and,
//! with camera correction, as corrected (held-out frames: interpolated, never fitted).

use anyhow::{Context, Result};
use scene::Split;
use synth::camera_error::{rms_error, TrueCamera, TrueCameras};
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
    /// Training frames, corrected: the scale of the corrected camera path against the true one
    /// ([`path_scale`]; 1 = the true motion, below 1 a path that moves less).
    pub train_corrected_path_scale: Option<[f64; 3]>,
}

/// Per camera axis (x right, y down, z forward), the least-squares slope of the `estimated`
/// camera centres' deviations from their mean on the `truth`'s, each in its own camera's
/// coordinates (`train::pose::camera_scale::centre_deviations`): how much of the true path's
/// motion along that axis the estimated path makes. NaN on an axis the truth does not move along.
pub fn path_scale(estimated: &[[[f64; 4]; 4]], truth: &[[[f64; 4]; 4]]) -> [f64; 3] {
    use train::pose::camera_scale::centre_deviations;
    let (a, b) = (centre_deviations(estimated), centre_deviations(truth));
    std::array::from_fn(|axis| {
        let along: f64 = a.iter().zip(&b).map(|(a, b)| a[axis] * b[axis]).sum();
        let spread: f64 = b.iter().map(|b| b[axis] * b[axis]).sum();
        along / spread
    })
}

/// The report for `data`, or `None` when the scene has no `cameras_true.json`.
pub fn camera_report(data: &Dataset, model: &Model) -> Result<Option<CameraReport>> {
    let path = TrueCameras::path(&data.dir);
    if !path.exists() {
        return Ok(None);
    }
    let truth =
        TrueCameras::read(&data.dir).with_context(|| format!("reading {}", path.display()))?;
    let errors = |split: Split| -> Result<(CameraError, CameraError, [f64; 3])> {
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
        let truth: Vec<_> = of_split.frames.iter().map(TrueCamera::matrix).collect();
        Ok((
            error(&given),
            error(&corrected),
            path_scale(&corrected, &truth),
        ))
    };
    let (train_given, train_corrected, train_scale) = errors(Split::Train)?;
    let (test_given, test_corrected, _) = errors(Split::Test)?;
    let correcting = model.config.camera_correction;
    Ok(Some(CameraReport {
        train_given,
        train_corrected: correcting.then_some(train_corrected),
        test_given,
        test_corrected: correcting.then_some(test_corrected),
        train_corrected_path_scale: correcting.then_some(train_scale),
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
             {}, held-out frames {} → {}{}",
            pair(&r.train_given),
            pair(train),
            pair(&r.test_given),
            pair(test),
            r.train_corrected_path_scale
                .map(|s| format!(
                    "; the corrected path moves {:.2} / {:.2} / {:.2} of the true one (x / y / z)",
                    s[0], s[1], s[2]
                ))
                .unwrap_or_default()
        ),
        _ => format!(
            "camera error (RMS rotation / centre, against cameras_true.json): training frames {}, \
             held-out frames {} (no camera correction)",
            pair(&r.train_given),
            pair(&r.test_given)
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(centre: [f64; 3]) -> [[f64; 4]; 4] {
        // Identity rotation: t = −c.
        [
            [1.0, 0.0, 0.0, -centre[0]],
            [0.0, 1.0, 0.0, -centre[1]],
            [0.0, 0.0, 1.0, -centre[2]],
            [0.0, 0.0, 0.0, 1.0],
        ]
    }

    #[test]
    fn a_path_that_moves_three_quarters_vertically_scales_by_three_quarters() {
        let truth: Vec<_> = [[0.0, -0.02, 0.01], [0.01, 0.0, 0.0], [0.02, 0.02, -0.01]]
            .map(at)
            .to_vec();
        let estimated: Vec<_> = [[0.0, -0.015, 0.01], [0.01, 0.0, 0.0], [0.02, 0.015, -0.01]]
            .map(|c| at([c[0] + 0.3, c[1], c[2]]))
            .to_vec();
        let s = path_scale(&estimated, &truth);
        assert!(
            (s[0] - 1.0).abs() < 1e-12 && (s[2] - 1.0).abs() < 1e-12,
            "{s:?}"
        );
        assert!((s[1] - 0.75).abs() < 1e-12, "{s:?}");
    }
}
