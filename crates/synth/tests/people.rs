#![allow(clippy::unwrap_used)]
//! Several people (`--people N`): the scene is format version 3 with a pose per person and frame,
//! the id images agree with the human masks, every person is seen, and a person crossing in front
//! of the first one hides it.

use synth::body::capsule_body;
use synth::{generate_with_body, Preset, Speed, SynthConfig};

fn small(people: u32) -> SynthConfig {
    SynthConfig {
        frames: 9,
        width: 64,
        height: 48,
        subframes: 2,
        supersample: 1,
        speed: Speed::Fast,
        event_flow: false,
        people,
        ..SynthConfig::preset(Preset::Tiny)
    }
}

/// Pixel (column, row) of world point `p` in `camera`.
fn project(camera: &scene::Camera, p: [f64; 3]) -> (usize, usize) {
    let m = camera.world_to_camera;
    let c: Vec<f64> = (0..3)
        .map(|i| m[i][0] * p[0] + m[i][1] * p[1] + m[i][2] * p[2] + m[i][3])
        .collect();
    let u = camera.fx * c[0] / c[2] + camera.cx;
    let v = camera.fy * c[1] / c[2] + camera.cy;
    (u as usize, v as usize)
}

#[test]
fn three_people_are_posed_masked_and_occlude_each_other() {
    let dir = tempfile::tempdir().unwrap();
    let stats = generate_with_body(&small(3), capsule_body(), dir.path(), &mut |_, _| {}).unwrap();
    // Each person's own box is blurred: finite PSNRs below the cap.
    assert_eq!(stats.person_box_db.len(), 3);
    assert!(
        stats.person_box_db.iter().all(|&db| db > 5.0 && db < 60.0),
        "{:?}",
        stats.person_box_db
    );
    let s = scene::load(dir.path()).unwrap();
    assert_eq!(s.format_version, scene::FORMAT_VERSION_PEOPLE);
    assert_eq!(s.person_ids(), vec![0, 1, 2]);
    let mut seen = [0usize; 4];
    for f in &s.frames {
        let (w, h, ids) =
            scene::read_person_ids(&dir.path().join(f.person_ids.as_ref().unwrap())).unwrap();
        let (_, _, mask) = scene::read_mask(&dir.path().join(f.mask.as_ref().unwrap())).unwrap();
        assert_eq!((w, h), (64, 48));
        for (&id, &m) in ids.iter().zip(&mask) {
            assert_eq!(id != 0, m, "the id image and the human mask agree");
            seen[usize::from(id.min(3))] += 1;
        }
    }
    assert!(
        seen[1..].iter().all(|&n| n > 0),
        "every person is seen: {seen:?}"
    );
    // The people walk: person 1 crosses from one side to the other.
    let x_of = |k: usize| s.frames[k].pose_of(1).unwrap().1[0];
    assert!(x_of(8) - x_of(0) > 1.0, "{} -> {}", x_of(0), x_of(8));
    // In the middle of the clip person 1 (nearer the camera) stands in front of the first person:
    // the pixel of the first person's pelvis shows person 1.
    let mid = &s.frames[4];
    let t = mid.transl;
    let (u, v) = project(
        &s.camera,
        [f64::from(t[0]), f64::from(t[1]), f64::from(t[2])],
    );
    let (_, _, ids) =
        scene::read_person_ids(&dir.path().join(mid.person_ids.as_ref().unwrap())).unwrap();
    assert_eq!(
        ids[v * 64 + u],
        2,
        "person 1 hides the first person at ({u}, {v})"
    );
}

#[test]
fn several_people_refuse_a_simulated_pose_error_and_more_than_four() {
    let mut cfg = small(5);
    let err = cfg.validate().unwrap_err().to_string();
    assert!(err.contains("people") && err.contains("1..=4"), "{err}");
    cfg = SynthConfig {
        people: 2,
        ..SynthConfig::preset(Preset::Realistic)
    };
    let err = cfg.validate().unwrap_err().to_string();
    assert!(err.contains("pose error"), "{err}");
}
