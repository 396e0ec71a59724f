//! Loading scene directories into training frames, and the errors for broken ones.

#![allow(clippy::unwrap_used)] // test helpers outside #[test] fns may panic

use scene::{BodySpec, Camera, Frame, ImageEncoding, Rgb, Scene, Split, Transfer};
use std::path::Path;

fn write_scene(dir: &Path, frames: usize) -> Scene {
    let (w, h) = (8u32, 6u32);
    let enc = ImageEncoding::rgb(16, Transfer::Srgb);
    std::fs::create_dir_all(dir.join("images")).unwrap();
    std::fs::create_dir_all(dir.join("masks")).unwrap();
    let mut list = Vec::new();
    for k in 0..frames {
        let data: Vec<f32> = (0..3 * w * h)
            .map(|i| ((i as usize + k) % 11) as f32 / 10.0)
            .collect();
        let img = Rgb {
            width: w,
            height: h,
            data,
        };
        let rel = format!("images/{k:04}.png");
        scene::write_rgb(&dir.join(&rel), &img, enc).unwrap();
        let mask: Vec<bool> = (0..w * h).map(|i| i % 3 == 0).collect();
        let mrel = format!("masks/{k:04}.png");
        scene::write_mask(&dir.join(&mrel), w, h, &mask).unwrap();
        list.push(Frame {
            people: Vec::new(),
            person_ids: None,
            index: k as u32,
            time_s: k as f64 / 30.0,
            exposure_s: None,
            world_to_camera: None,
            image: rel,
            sharp: None,
            mask: Some(mrel),
            pose: vec![[0.0, 0.1 * k as f32, 0.0]; 24],
            transl: [0.0, 0.0, 3.0],
            flow_to_next: Vec::new(),
            events: None,
            split: if k % 2 == 0 {
                Split::Train
            } else {
                Split::Test
            },
        });
    }
    let s = Scene {
        people: Vec::new(),
        events_raw_format: None,
        events_recorded_s: None,
        format_version: 1,
        camera: Camera {
            width: w,
            height: h,
            fx: 10.0,
            fy: 10.0,
            cx: 4.0,
            cy: 3.0,
            world_to_camera: [
                [1.0, 0.0, 0.0, 0.0],
                [0.0, 1.0, 0.0, 0.0],
                [0.0, 0.0, 1.0, 0.0],
                [0.0, 0.0, 0.0, 1.0],
            ],
        },
        body: BodySpec {
            id: 0,
            model: "builtin:makehuman".into(),
            betas: vec![],
        },
        fps: 30.0,
        exposure_s: 1.0 / 60.0,
        images: enc,
        frames: list,
        generator: None,
    };
    s.write(dir).unwrap();
    s
}

#[test]
fn a_written_scene_loads_with_decoded_frames() {
    let dir = tempfile::tempdir().unwrap();
    write_scene(dir.path(), 3);
    let data = train::data::load_dataset(dir.path()).unwrap();
    assert_eq!(data.frames.len(), 3);
    assert_eq!(data.split(Split::Train), vec![0, 2]);
    assert_eq!((data.camera.width, data.camera.height), (8, 6));
    let f = &data.frames[1];
    assert_eq!(f.image.len(), 3 * 8 * 6);
    // 16-bit sRGB round trip of a linear value.
    assert!((f.image[0] - 0.1).abs() < 1e-3, "{}", f.image[0]);
    assert_eq!(f.mask.as_ref().unwrap().iter().filter(|&&m| m).count(), 16);
    assert_eq!(f.smpl.pose.len(), 72);
    assert!((f.smpl.pose[1] - 0.1).abs() < 1e-7);
}

#[test]
fn a_missing_image_is_reported_with_its_path() {
    let dir = tempfile::tempdir().unwrap();
    write_scene(dir.path(), 2);
    std::fs::remove_file(dir.path().join("images/0001.png")).unwrap();
    let err = train::data::load_dataset(dir.path())
        .unwrap_err()
        .to_string();
    assert!(err.contains("0001.png"), "{err}");
}

#[test]
fn a_moving_camera_gives_every_frame_its_own_camera() {
    let dir = tempfile::tempdir().unwrap();
    let mut s = write_scene(dir.path(), 3);
    // Frame 2 at the scene camera's own pose: still a fixed camera.
    s.format_version = scene::FORMAT_VERSION_MOVING_CAMERA;
    s.frames[2].world_to_camera = Some(s.camera.world_to_camera);
    s.write(dir.path()).unwrap();
    let still = train::data::load_dataset(dir.path()).unwrap();
    assert!(!still.camera_moves);
    assert!(still.frames.iter().all(|f| f.camera == still.camera));
    let mut moved = s.camera.world_to_camera;
    moved[1][3] = 0.02;
    s.frames[1].world_to_camera = Some(moved);
    s.write(dir.path()).unwrap();
    let data = train::data::load_dataset(dir.path()).unwrap();
    assert!(data.camera_moves);
    assert_eq!(data.frames[1].camera.world_to_camera, moved);
    assert_eq!(data.frames[0].camera, data.camera);
    assert_eq!(
        (data.frames[1].camera.width, data.frames[1].camera.fx),
        (data.camera.width, data.camera.fx)
    );
}

#[test]
fn a_scene_with_several_people_loads_everyones_poses_and_more_than_four_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let mut s = write_scene(dir.path(), 2);
    s.format_version = scene::FORMAT_VERSION_PEOPLE;
    let person = |id: u32| scene::PersonSpec {
        id,
        betas: vec![0.1 * id as f32],
    };
    s.people = vec![person(3)];
    let pose_of = |id: u32, f: &scene::Frame| scene::PersonPose {
        id,
        pose: f.pose.clone(),
        transl: [0.5 * id as f32, 0.0, 0.0],
    };
    for f in &mut s.frames {
        f.people = vec![pose_of(3, f)];
    }
    s.write(dir.path()).unwrap();
    let data = train::data::load_dataset(dir.path()).unwrap();
    assert_eq!(data.people(), 2);
    for f in &data.frames {
        assert_eq!(f.others.len(), 1);
        assert_eq!(f.others[0].transl, [1.5, 0.0, 0.0]);
        assert_eq!(f.others[0].betas, vec![0.3f32]);
        assert_eq!(f.others[0].pose, f.smpl.pose);
    }
    // Five people: more than the model takes, refused naming them.
    s.people = (1..=4).map(person).collect();
    for f in &mut s.frames {
        f.people = (1..=4).map(|id| pose_of(id, f)).collect();
    }
    s.write(dir.path()).unwrap();
    let err = train::data::load_dataset(dir.path())
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("scene.json") && err.contains("5 people") && err.contains("[0, 1, 2, 3, 4]"),
        "{err}"
    );
}
