#![allow(clippy::unwrap_used)]
//! Round trip of a small scene and the validator's report on a broken one.

use std::path::Path;

use scene::{
    read_mask, read_rgb, write_mask, write_rgb, BodySpec, Camera, FlowKind, FlowRef, Frame,
    ImageEncoding, PersonPose, PersonSpec, Rgb, Scene, SceneError, Split, Transfer, FORMAT_VERSION,
    FORMAT_VERSION_MOVING_CAMERA, FORMAT_VERSION_PEOPLE,
};

const W: u32 = 6;
const H: u32 = 4;

fn write_flo(path: &Path, w: u32, h: u32) {
    let mut b = Vec::new();
    b.extend_from_slice(&202_021.25f32.to_le_bytes());
    b.extend_from_slice(&(w as i32).to_le_bytes());
    b.extend_from_slice(&(h as i32).to_le_bytes());
    b.resize(12 + 8 * (w * h) as usize, 0);
    std::fs::write(path, b).unwrap();
}

fn make_scene(dir: &Path, frames: usize) -> Scene {
    let enc = ImageEncoding::rgb(16, Transfer::Srgb);
    for sub in ["images", "masks", "flow"] {
        std::fs::create_dir_all(dir.join(sub)).unwrap();
    }
    let n = (W * H) as usize;
    let mut out = Vec::new();
    for k in 0..frames {
        let img = Rgb {
            width: W,
            height: H,
            data: (0..3 * n)
                .map(|i| (i + k) as f32 / (3 * n + frames) as f32)
                .collect(),
        };
        let image = format!("images/{k:06}.png");
        write_rgb(&dir.join(&image), &img, enc).unwrap();
        let mask = format!("masks/{k:06}.png");
        write_mask(&dir.join(&mask), W, H, &vec![k % 2 == 0; n]).unwrap();
        let mut flow_to_next = Vec::new();
        if k + 1 < frames {
            let p = format!("flow/{k:06}.flo");
            write_flo(&dir.join(&p), W, H);
            flow_to_next.push(FlowRef {
                kind: FlowKind::GroundTruth,
                path: p,
                valid_mask: Some(mask.clone()),
            });
        }
        out.push(Frame {
            people: Vec::new(),
            person_ids: None,
            index: k as u32,
            time_s: k as f64 / 30.0,
            exposure_s: None,
            world_to_camera: None,
            image,
            sharp: None,
            mask: Some(mask),
            pose: vec![[0.1, -0.2, 0.3]; 24],
            transl: [0.0, 0.9, 0.0],
            flow_to_next,
            events: None,
            split: if k % 10 < 7 {
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
        format_version: FORMAT_VERSION,
        camera: Camera {
            width: W,
            height: H,
            fx: 10.0,
            fy: 10.0,
            cx: 3.0,
            cy: 2.0,
            world_to_camera: [
                [1.0, 0.0, 0.0, 0.0],
                [0.0, -1.0, 0.0, 1.0],
                [0.0, 0.0, -1.0, 3.0],
                [0.0, 0.0, 0.0, 1.0],
            ],
        },
        body: BodySpec {
            id: 0,
            model: "builtin:makehuman".into(),
            betas: vec![0.0; 10],
        },
        fps: 30.0,
        exposure_s: 1.0 / 30.0,
        images: enc,
        frames: out,
        generator: None,
    };
    s.write(dir).unwrap();
    s
}

#[test]
fn round_trip_and_pixels() {
    let tmp = tempfile::tempdir().unwrap();
    let s = make_scene(tmp.path(), 3);
    let back = scene::load(tmp.path()).unwrap();
    assert_eq!(back, s);
    assert_eq!(back.split_indices(Split::Train), vec![0, 1, 2]);
    assert!(back.frames[0].flow(FlowKind::GroundTruth).is_some());
    assert!(back.frames[2].flow(FlowKind::GroundTruth).is_none());
    // 16-bit sRGB: the round trip error is below 1e-4 in linear intensity.
    let img = read_rgb(&tmp.path().join(&s.frames[1].image), s.images).unwrap();
    let n = (W * H) as usize;
    for (i, v) in img.data.iter().enumerate() {
        let want = (i + 1) as f32 / (3 * n + 3) as f32;
        assert!((v - want).abs() < 1e-4, "pixel {i}: {v} vs {want}");
    }
    let (w, h, m) = read_mask(&tmp.path().join("masks/000000.png")).unwrap();
    assert_eq!((w, h), (W, H));
    assert!(m.iter().all(|&x| x));
}

#[test]
fn every_problem_is_reported() {
    let tmp = tempfile::tempdir().unwrap();
    make_scene(tmp.path(), 3);
    let path = tmp.path().join("scene.json");
    let mut v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    let f = v["frames"].as_array_mut().unwrap();
    f[0]["pose"][5][1] = serde_json::Value::Null; // a NaN written by a JSON writer
    f[1]["time_s"] = serde_json::json!(-1.0); // time goes back
    f[1]["split"] = serde_json::json!("validation");
    f[2]["image"] = serde_json::json!("images/missing.png");
    f[2]["shapr"] = serde_json::json!("sharp/000002.png");
    f[0]["flow_to_next"][0]["kind"] = serde_json::json!("raft");
    std::fs::write(&path, serde_json::to_string(&v).unwrap()).unwrap();
    // A mask of the wrong size and a truncated flow.
    write_mask(
        &tmp.path().join("masks/000001.png"),
        W + 1,
        H,
        &vec![true; ((W + 1) * H) as usize],
    )
    .unwrap();
    std::fs::write(tmp.path().join("flow/000001.flo"), b"PIEH").unwrap();

    let err = scene::load(tmp.path()).unwrap_err();
    let SceneError::Invalid { problems, .. } = &err else {
        panic!("expected Invalid, got {err}");
    };
    let text = err.to_string();
    let expect = [
        ("frames[0].pose[5][1]", "null"),
        ("frames[1].time_s", "not after"),
        ("frames[1].split", "validation"),
        ("frames[2].image", "does not exist"),
        ("frames[2].shapr", "unknown key"),
        ("frames[0].flow_to_next[0].kind", "raft"),
        ("frames[1].mask", "7x4"),
        ("frames[1].flow_to_next[0].path", "header"),
    ];
    let mut missing = Vec::new();
    for (p, m) in expect {
        if !problems
            .iter()
            .any(|q| q.path == p && q.message.contains(m))
        {
            missing.push(format!("{p} ({m})"));
        }
    }
    assert!(
        missing.is_empty(),
        "not reported: {missing:?}\nreport:\n{text}"
    );
    // The report names the description's file, each problem its frame and field.
    assert!(text.starts_with(&path.display().to_string()), "{text}");
    // The valid mask of frame 0's flow is the same file as frame 1's mask: reported there too.
    assert_eq!(problems.len(), expect.len() + 1, "report:\n{text}");
}

#[test]
fn writer_refuses_bad_values() {
    let tmp = tempfile::tempdir().unwrap();
    let mut s = make_scene(tmp.path(), 2);
    s.frames[1].pose[0][0] = f32::NAN;
    s.frames[1].split = Split::Test;
    s.frames[0].split = Split::Test;
    let err = s.write(tmp.path()).unwrap_err().to_string();
    assert!(err.contains("frames[1].pose[0][0]"), "{err}");
    assert!(err.contains("no frame has split"), "{err}");
}

#[test]
fn grey_frames_and_per_frame_exposures_round_trip_and_are_checked() {
    let tmp = tempfile::tempdir().unwrap();
    let mut s = make_scene(tmp.path(), 3);
    let grey = ImageEncoding {
        channels: 1,
        ..ImageEncoding::rgb(8, Transfer::Linear)
    };
    let n = (W * H) as usize;
    let img = Rgb {
        width: W,
        height: H,
        data: (0..3 * n).map(|i| (i % n) as f32 / n as f32).collect(),
    };
    for f in &s.frames {
        write_rgb(&tmp.path().join(&f.image), &img, grey).unwrap();
    }
    s.images = grey;
    s.frames[1].exposure_s = Some(0.01);
    s.write(tmp.path()).unwrap();
    let text = std::fs::read_to_string(tmp.path().join("scene.json")).unwrap();
    assert!(text.contains("\"channels\": 1"), "{text}");
    let back = scene::load(tmp.path()).unwrap();
    assert_eq!(back, s);
    assert_eq!(back.exposure_of(0), 1.0 / 30.0);
    assert_eq!(back.exposure_of(1), 0.01);
    // A grey frame reads as three equal planes holding the stored luminance (of three equal
    // planes: the value itself, to the 8-bit step).
    let read = read_rgb(&tmp.path().join(&s.frames[0].image), grey).unwrap();
    for i in 0..n {
        let want = i as f32 / n as f32;
        assert!(
            (read.data[i] - want).abs() <= 0.5 / 255.0 + 1e-6,
            "pixel {i}"
        );
        for c in 1..3 {
            assert_eq!(read.data[c * n + i], read.data[i], "pixel {i} plane {c}");
        }
    }
    // An RGB scene's files read as grey are refused, and the reverse; bad values name the field.
    assert!(read_rgb(
        &tmp.path().join(&s.frames[0].image),
        ImageEncoding::rgb(8, Transfer::Linear)
    )
    .is_err());
    let mut value: serde_json::Value = serde_json::from_str(&text).unwrap();
    value["images"]["channels"] = serde_json::json!(2);
    value["frames"][2]["exposure_s"] = serde_json::json!(0.5);
    std::fs::write(tmp.path().join("scene.json"), value.to_string()).unwrap();
    let msg = scene::load(tmp.path()).unwrap_err().to_string();
    assert!(
        msg.contains("images.channels: 2 is not 1 (grey) or 3 (RGB)"),
        "{msg}"
    );
    assert!(
        msg.contains("frames[2].exposure_s: 0.5 s is longer"),
        "{msg}"
    );
    // A grey scene whose frame is an RGB file is refused naming the frame.
    value["images"]["channels"] = serde_json::json!(1);
    value["frames"][2]["exposure_s"] = serde_json::json!(0.02);
    std::fs::write(tmp.path().join("scene.json"), value.to_string()).unwrap();
    write_rgb(
        &tmp.path().join(&s.frames[2].image),
        &img,
        ImageEncoding::rgb(8, Transfer::Linear),
    )
    .unwrap();
    let msg = scene::load(tmp.path()).unwrap_err().to_string();
    assert!(
        msg.contains("frames[2].image") && msg.contains("single channel"),
        "{msg}"
    );
}

#[test]
fn event_files_span_from_their_frame_to_the_next_and_the_last_to_the_end() {
    let tmp = tempfile::tempdir().unwrap();
    let mut s = make_scene(tmp.path(), 3);
    let t = |k: usize| s.frames[k].time_s;
    assert_eq!(s.event_file_span(0), (t(0), t(1)));
    assert_eq!(s.event_file_span(2), (t(2), f64::INFINITY));
    assert_eq!(s.event_evidence_span(2), Some((t(2), f64::INFINITY)));
    // A recording's events between 0.01 s and 0.05 s: frame 0's evidence starts at its first
    // event, frame 2's (from 0.0667 s) is empty, and the written scene keeps the span.
    s.events_recorded_s = Some([0.01, 0.05]);
    assert_eq!(s.event_evidence_span(0), Some((0.01, t(1))));
    assert_eq!(s.event_evidence_span(1), Some((t(1), 0.05)));
    assert_eq!(s.event_evidence_span(2), None);
    s.write(tmp.path()).unwrap();
    assert_eq!(
        scene::load(tmp.path()).unwrap().events_recorded_s,
        Some([0.01, 0.05])
    );
    // A span that runs backwards is refused, naming the field.
    s.events_recorded_s = Some([0.05, 0.01]);
    let err = s.write(tmp.path()).unwrap_err().to_string();
    assert!(
        err.contains("events_recorded_s") && err.contains("after the last"),
        "{err}"
    );
}

/// Format version 2: frames at their own camera poses round-trip, a version-1 scene reads as
/// before, and a per-frame pose is refused in version 1 or when it is not a rotation.
#[test]
fn per_frame_camera_poses_need_version_2_and_a_rotation() {
    let tmp = tempfile::tempdir().unwrap();
    let mut s = make_scene(tmp.path(), 3);
    assert!(!s.camera_moves());
    assert_eq!(s.format_version_needed(), FORMAT_VERSION);
    assert_eq!(s.camera_of(1), s.camera);
    let mut moved = s.camera.world_to_camera;
    moved[0][3] += 0.05; // 5 cm to the side
    s.frames[1].world_to_camera = Some(moved);
    assert!(s.camera_moves());
    assert_eq!(s.format_version_needed(), FORMAT_VERSION_MOVING_CAMERA);
    assert_eq!(s.camera_of(1).world_to_camera, moved);
    assert_eq!(s.camera_of(2), s.camera);
    let err = s.write(tmp.path()).unwrap_err().to_string();
    assert!(
        err.contains("frames[1].world_to_camera") && err.contains("format_version 2"),
        "{err}"
    );
    s.format_version = FORMAT_VERSION_MOVING_CAMERA;
    s.write(tmp.path()).unwrap();
    assert_eq!(scene::load(tmp.path()).unwrap(), s);
    let text = std::fs::read_to_string(tmp.path().join("scene.json")).unwrap();
    assert_eq!(
        text.matches("world_to_camera").count(),
        2,
        "the scene's and frame 1's"
    );
    // Not a rotation; and an unknown version.
    let path = tmp.path().join("scene.json");
    let mut v: serde_json::Value = serde_json::from_str(&text).unwrap();
    v["frames"][1]["world_to_camera"][0][0] = serde_json::json!(2.0);
    v["format_version"] = serde_json::json!(4);
    std::fs::write(&path, serde_json::to_string(&v).unwrap()).unwrap();
    let err = scene::load(tmp.path()).unwrap_err().to_string();
    assert!(err.contains("format_version: 4 is not supported"), "{err}");
    v["format_version"] = serde_json::json!(2);
    std::fs::write(&path, serde_json::to_string(&v).unwrap()).unwrap();
    let err = scene::load(tmp.path()).unwrap_err().to_string();
    assert!(
        err.contains("frames[1].world_to_camera") && err.contains("not a rotation"),
        "{err}"
    );
}

/// Format version 3: a scene with two people (ids 4 and 9, their own betas, a pose each per frame,
/// an id image) round-trips; a one-person scene keeps its bytes; every refusal names its field.
#[test]
fn several_people_need_version_3_a_pose_per_frame_and_unique_ids() {
    let tmp = tempfile::tempdir().unwrap();
    let mut s = make_scene(tmp.path(), 3);
    s.write(tmp.path()).unwrap();
    let one_person = std::fs::read_to_string(tmp.path().join("scene.json")).unwrap();
    assert!(!one_person.contains("people") && !one_person.contains("\"id\""));
    assert_eq!((s.person_count(), s.person_ids()), (1, vec![0]));
    s.body.id = 4;
    s.people = vec![PersonSpec {
        id: 9,
        betas: vec![0.5; 10],
    }];
    for (k, f) in s.frames.iter_mut().enumerate() {
        f.people = vec![PersonPose {
            id: 9,
            pose: vec![[0.0, 0.1 * k as f32, 0.0]; 24],
            transl: [1.0, 0.9, k as f32],
        }];
        f.person_ids = f.mask.clone();
    }
    assert_eq!(s.format_version_needed(), FORMAT_VERSION_PEOPLE);
    let err = s.write(tmp.path()).unwrap_err().to_string();
    assert!(
        err.contains("people: several people need format_version 3")
            && err.contains("frames[0].people")
            && err.contains("body.id"),
        "{err}"
    );
    s.format_version = FORMAT_VERSION_PEOPLE;
    s.write(tmp.path()).unwrap();
    let read = scene::load(tmp.path()).unwrap();
    assert_eq!(read, s);
    assert_eq!((read.person_count(), read.person_ids()), (2, vec![4, 9]));
    assert_eq!(read.betas_of(1), Some(&[0.5f32; 10][..]));
    assert_eq!(read.frames[2].pose_of(1).unwrap().1, [1.0, 0.9, 2.0]);
    assert_eq!(read.frames[2].pose_of(0).unwrap().1, [0.0, 0.9, 0.0]);
    assert!(read.frames[2].pose_of(2).is_none());

    let path = tmp.path().join("scene.json");
    let text = std::fs::read_to_string(&path).unwrap();
    let refused = |edit: &dyn Fn(&mut serde_json::Value)| {
        let mut v: serde_json::Value = serde_json::from_str(&text).unwrap();
        edit(&mut v);
        std::fs::write(&path, serde_json::to_string(&v).unwrap()).unwrap();
        scene::load(tmp.path()).unwrap_err().to_string()
    };
    let err = refused(&|v| v["people"][0]["id"] = serde_json::json!(4));
    assert!(err.contains("people[0].id: 4 is already"), "{err}");
    let err = refused(&|v| v["frames"][1]["people"] = serde_json::json!([]));
    assert!(err.contains("frames[1].people: 0 entries"), "{err}");
    let err = refused(&|v| {
        v["frames"][1].as_object_mut().unwrap().remove("people");
    });
    assert!(
        err.contains("frames[1]: missing required key \"people\""),
        "{err}"
    );
    let err = refused(&|v| v["frames"][2]["people"][0]["id"] = serde_json::json!(5));
    assert!(err.contains("frames[2].people[0].id: 5"), "{err}");
    let err = refused(&|v| v["frames"][0]["people"][0]["pose"] = serde_json::json!([[0, 0, 0]]));
    assert!(
        err.contains("frames[0].people[0].pose: expected 24"),
        "{err}"
    );
    let err = refused(&|v| v["frames"][0]["person_ids"] = serde_json::json!("masks/none.png"));
    assert!(
        err.contains("frames[0].person_ids") && err.contains("does not exist"),
        "{err}"
    );
    let err = refused(&|v| v["format_version"] = serde_json::json!(2));
    assert!(
        err.contains("people: several people need format_version 3"),
        "{err}"
    );
}
