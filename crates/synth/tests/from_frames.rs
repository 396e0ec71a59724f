//! A scene from a user's frames (`synth::from_frames`): the blur is the mean of each window, the
//! middle frame is the sharp reference, times and exposure follow the windows, simulated events
//! land in the frame whose interval holds them, and bad settings are refused by name.

use synth::from_frames::{write_scene_from_frames, FramesToScene, InputFrame};

const W: u32 = 16;
const H: u32 = 12;

fn camera() -> scene::Camera {
    scene::Camera {
        width: W,
        height: H,
        fx: 20.0,
        fy: 20.0,
        cx: 8.0,
        cy: 6.0,
        world_to_camera: [
            [1.0, 0.0, 0.0, 0.0],
            [0.0, 1.0, 0.0, 0.0],
            [0.0, 0.0, 1.0, 3.0],
            [0.0, 0.0, 0.0, 1.0],
        ],
    }
}

fn body() -> scene::BodySpec {
    scene::BodySpec {
        id: 0,
        model: "builtin:makehuman".into(),
        betas: vec![],
    }
}

/// Input frame `i`: a bright 3×3 square moving one pixel right per frame on a dim background,
/// pose and translation encoding `i`.
fn input(i: usize) -> InputFrame {
    let n = (W * H) as usize;
    let mut rgb = vec![0.05f32; 3 * n];
    let mut mask = vec![false; n];
    for y in 4..7 {
        for x in (1 + i)..(4 + i) {
            let p = y * W as usize + x.min(W as usize - 1);
            for c in 0..3 {
                rgb[c * n + p] = 0.8;
            }
            mask[p] = true;
        }
    }
    let mut pose = vec![[0.0f32; 3]; 24];
    pose[1][0] = i as f32 * 0.01;
    InputFrame {
        rgb,
        mask: Some(mask),
        pose,
        transl: [i as f32, 0.0, 0.0],
        people: Vec::new(),
        world_to_camera: None,
    }
}

#[test]
fn windows_average_to_the_observation_around_their_sharp_middle_frame() {
    let dir = tempfile::tempdir().expect("tempdir");
    let cfg = FramesToScene {
        fps: 60.0,
        blur: 3,
        events: Some(events::EsimConfig::default()),
        ..FramesToScene::default()
    };
    let mut loaded = Vec::new();
    let report = write_scene_from_frames(
        dir.path(),
        camera(),
        body(),
        &[],
        10,
        &cfg,
        serde_json::json!({"name": "test"}),
        |i| {
            loaded.push(i);
            Ok(input(i))
        },
        None,
        |_| {},
    )
    .expect("import");
    // 10 frames in windows of 3: three output frames, frame 9 left over (and never loaded).
    assert_eq!(loaded, (0..9).collect::<Vec<_>>());
    assert_eq!((report.frames, report.dropped_frames), (3, 1));
    let s = scene::load(dir.path()).expect("valid scene");
    assert_eq!(s.frames.len(), 3);
    assert!((s.fps - 20.0).abs() < 1e-12);
    assert!((s.exposure_s - 3.0 / 60.0).abs() < 1e-12);
    let n = (W * H) as usize;
    for (j, f) in s.frames.iter().enumerate() {
        let centre = 3 * j + 1;
        assert!((f.time_s - centre as f64 / 60.0).abs() < 1e-6, "frame {j}");
        assert_eq!(f.transl, [centre as f32, 0.0, 0.0]);
        let sharp = scene::read_rgb(&dir.path().join(f.sharp.as_ref().expect("sharp")), s.images)
            .expect("sharp");
        let image = scene::read_rgb(&dir.path().join(&f.image), s.images).expect("image");
        let expected_sharp = input(centre).rgb;
        let expected_mean: Vec<f32> = (0..3 * n)
            .map(|p| (0..3).map(|d| input(3 * j + d).rgb[p]).sum::<f32>() / 3.0)
            .collect();
        // 16-bit sRGB storage: within 1e-4 of the linear values.
        for p in 0..3 * n {
            assert!(
                (sharp.data[p] - expected_sharp[p]).abs() < 1e-4,
                "sharp {j} {p}"
            );
            assert!(
                (image.data[p] - expected_mean[p]).abs() < 1e-4,
                "mean {j} {p}"
            );
        }
        let (_, _, mask) =
            scene::read_mask(&dir.path().join(f.mask.as_ref().expect("mask"))).expect("mask");
        assert_eq!(mask, input(centre).mask.expect("mask"));
        assert_eq!(f.split, scene::Split::Train);
    }
    // Events: each file holds only events of its frame's interval, and the moving square made some.
    let mut total = 0;
    for (j, f) in s.frames.iter().enumerate() {
        let ev = events::read_events(dir.path().join(f.events.as_ref().expect("events")))
            .expect("events");
        let from = (f.time_s * 1e6).round() as i64;
        let to = s
            .frames
            .get(j + 1)
            .map_or(i64::MAX, |g| (g.time_s * 1e6).round() as i64);
        assert!(ev.t.iter().all(|&t| t >= from && t < to), "frame {j}");
        total += ev.len();
    }
    assert!(total > 0, "the moving square made no events");
    assert_eq!(total, report.events);
    assert!(report.events_before_first_frame > 0);
}

#[test]
fn without_blur_the_frames_are_the_observations() {
    let dir = tempfile::tempdir().expect("tempdir");
    let cfg = FramesToScene {
        fps: 30.0,
        exposure_s: Some(0.01),
        ..FramesToScene::default()
    };
    write_scene_from_frames(
        dir.path(),
        camera(),
        body(),
        &[],
        12,
        &cfg,
        serde_json::json!({}),
        |i| Ok(input(i)),
        None,
        |_| {},
    )
    .expect("import");
    let s = scene::load(dir.path()).expect("valid scene");
    assert_eq!(s.frames.len(), 12);
    assert!((s.exposure_s - 0.01).abs() < 1e-12);
    assert!(s
        .frames
        .iter()
        .all(|f| f.sharp.is_none() && f.events.is_none()));
    // The benchmark's interleaved 7/3 split.
    let test: Vec<u32> = s
        .frames
        .iter()
        .filter(|f| f.split == scene::Split::Test)
        .map(|f| f.index)
        .collect();
    assert_eq!(test, vec![7, 8, 9]);
}

#[test]
fn bad_settings_are_refused_by_name() {
    for (cfg, count, knob) in [
        (
            FramesToScene {
                blur: 2,
                ..FramesToScene::default()
            },
            10,
            "blur",
        ),
        (
            FramesToScene {
                blur: 5,
                ..FramesToScene::default()
            },
            4,
            "blur",
        ),
        (
            FramesToScene {
                fps: 0.0,
                ..FramesToScene::default()
            },
            10,
            "fps",
        ),
        (
            FramesToScene {
                exposure_s: Some(0.5),
                ..FramesToScene::default()
            },
            10,
            "exposure_s",
        ),
        (
            FramesToScene {
                blur: 3,
                exposure_s: Some(0.01),
                ..FramesToScene::default()
            },
            10,
            "exposure_s",
        ),
    ] {
        let msg = cfg.check(count).expect_err("refused").to_string();
        assert!(msg.contains(knob), "{msg}");
    }
    // A frame of the wrong size is refused naming the frame.
    let dir = tempfile::tempdir().expect("tempdir");
    let err = write_scene_from_frames(
        dir.path(),
        camera(),
        body(),
        &[],
        3,
        &FramesToScene::default(),
        serde_json::json!({}),
        |i| {
            let mut f = input(i);
            if i == 2 {
                f.rgb.pop();
            }
            Ok(f)
        },
        None,
        |_| {},
    )
    .expect_err("refused");
    assert!(err.to_string().contains("frame = 2"), "{err}");
}

#[test]
fn in_between_frames_join_the_windows_and_the_events() {
    let dir = tempfile::tempdir().expect("tempdir");
    let cfg = FramesToScene {
        fps: 60.0,
        blur: 3,
        in_between: 2,
        events: Some(events::EsimConfig::default()),
        ..FramesToScene::default()
    };
    // A stand-in interpolator: the linear blend, recording the times it was asked for.
    let mut asked = Vec::new();
    let mut blend = |a: &[f32], b: &[f32], ts: &[f32]| -> synth::Result<Vec<Vec<f32>>> {
        asked.push(ts.to_vec());
        Ok(ts
            .iter()
            .map(|&t| {
                a.iter()
                    .zip(b)
                    .map(|(&x, &y)| (1.0 - t) * x + t * y)
                    .collect()
            })
            .collect())
    };
    write_scene_from_frames(
        dir.path(),
        camera(),
        body(),
        &[],
        6,
        &cfg,
        serde_json::json!({}),
        |i| Ok(input(i)),
        Some(&mut blend),
        |_| {},
    )
    .expect("import");
    // Five pairs of consecutive frames, two in-betweens each at 1/3 and 2/3.
    assert_eq!(asked.len(), 5);
    assert!(asked.iter().all(|ts| ts == &[1.0 / 3.0, 2.0 / 3.0]));
    let s = scene::load(dir.path()).expect("valid scene");
    let n = (W * H) as usize;
    // Window 0: frames 0, 1, 2 and the four in-betweens of its two gaps: 7 samples.
    let image = scene::read_rgb(&dir.path().join(&s.frames[0].image), s.images).expect("image");
    let lerp = |p: usize, a: usize, t: f32| (1.0 - t) * input(a).rgb[p] + t * input(a + 1).rgb[p];
    for p in 0..3 * n {
        let want = (input(0).rgb[p]
            + lerp(p, 0, 1.0 / 3.0)
            + lerp(p, 0, 2.0 / 3.0)
            + input(1).rgb[p]
            + lerp(p, 1, 1.0 / 3.0)
            + lerp(p, 1, 2.0 / 3.0)
            + input(2).rgb[p])
            / 7.0;
        assert!((image.data[p] - want).abs() < 1e-4, "pixel {p}");
    }
    // Without an interpolation function, in-between frames are refused by name.
    let msg = write_scene_from_frames(
        dir.path(),
        camera(),
        body(),
        &[],
        6,
        &cfg,
        serde_json::json!({}),
        |i| Ok(input(i)),
        None,
        |_| {},
    )
    .expect_err("refused")
    .to_string();
    assert!(msg.contains("in_between"), "{msg}");
}
