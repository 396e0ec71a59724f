//! The generated scene's `scene.json`: one frame entry per rendered frame (its files, every
//! person's SMPL parameters at its time, the camera when it moves) and the scene itself, with the
//! estimated poses and cameras of a pose or camera error (the truth to its side files).

use std::path::Path;

use crate::camera::PinholeCamera;
use crate::cast::Person;
use crate::config::SynthConfig;
use crate::error::Result;
use crate::pose_metrics::PoseErrorStats;

/// The files of frame k, relative to the scene directory.
pub(super) struct FrameFiles {
    /// The blurred frame.
    pub(super) image: String,
    /// The sharp mid-exposure reference.
    pub(super) sharp: String,
    /// The human mask.
    pub(super) mask: String,
    /// The person-id image (several people only).
    pub(super) person_ids: Option<String>,
}

/// The events file of frame k (`[t_k, t_{k+1})`), relative to the scene directory.
pub(super) fn event_path(k: usize) -> String {
    format!("events/{k:06}.npz")
}

/// Frame k's entry: its files, the flows to the next frame, every person's pose at `t_k`
/// (the first person's as the frame's own, the others' in `people`), and `world_to_camera` when
/// the camera moves; every tenth frame's last three are held out.
pub(super) fn frame_entry(
    cfg: &SynthConfig,
    k: usize,
    people: &[Person],
    world_to_camera: Option<[[f64; 4]; 4]>,
    files: FrameFiles,
) -> scene::Frame {
    let frames = cfg.frames as usize;
    let tk = k as f64 / cfg.fps;
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
    scene::Frame {
        people: others,
        person_ids: files.person_ids,
        index: k as u32,
        time_s: tk,
        exposure_s: None,
        world_to_camera,
        image: files.image,
        sharp: Some(files.sharp),
        mask: Some(files.mask),
        pose: pose.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
        transl,
        flow_to_next,
        events: Some(event_path(k)),
        split: if k % 10 < 7 {
            scene::Split::Train
        } else {
            scene::Split::Test
        },
    }
}

/// Writes `scene.json` of the rendered frames (`frames`, with the true poses and cameras so far):
/// with a pose or camera error the estimates replace them and the truth goes to its side file;
/// returns the realised pose error.
pub(super) fn write_scene(
    cfg: &SynthConfig,
    out: &Path,
    people: &[Person],
    cam: &PinholeCamera,
    mut scene_frames: Vec<scene::Frame>,
) -> Result<Option<PoseErrorStats>> {
    // The scene's SMPL parameters so far are the true ones; with a pose error they become an
    // estimate and the truth goes to its own file (everything rendered above is unchanged).
    let mut pose_error = None;
    let mut generator = serde_json::json!({
        "name": "synth",
        "config": cfg,
    });
    if cfg.pose_error.is_off() {
        // A truth file left by an earlier generation into `out` would not be this scene's.
        crate::true_poses::TruePoses::remove(out)?;
    } else {
        pose_error = Some(crate::pose_error::apply(
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
            betas: people[0].body.betas.clone(),
        },
        fps: cfg.fps,
        exposure_s: cfg.exposure_fraction / cfg.fps,
        images: scene::ImageEncoding::rgb(16, scene::Transfer::Srgb),
        frames: scene_frames,
        generator: Some(generator),
    };
    sc.format_version = sc.format_version_needed();
    sc.write(out)?;
    Ok(pose_error)
}
