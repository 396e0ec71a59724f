//! `--scene-init stereo` on the tiny fixture: with a fixed camera it changes no bit; with a moving
//! one it starts scene Gaussians on the swept surfaces and trains the same bits on one and two
//! threads; the person's box it leaves out holds the person.
#![allow(clippy::unwrap_used)]

use train::config::TrainConfig;
use train::data::TrainingData;
use train::init::SceneInit;
use train::trainer::{person_box, Trainer};

mod common;
use common::*;

/// The fixture with each training frame's camera shifted sideways by 4 cm per frame: the images
/// do not follow, but the sweep needs only cameras that differ.
fn moving_context() -> TrainingData {
    let mut ctx = context();
    for (i, f) in ctx.frames.iter_mut().enumerate() {
        f.camera.world_to_camera[0][3] += 0.04 * i as f64;
    }
    ctx
}

fn stereo(steps: usize) -> TrainConfig {
    TrainConfig {
        scene_init: SceneInit::Stereo,
        ..tiny_config(steps)
    }
}

#[test]
fn a_fixed_camera_gives_the_volume_inits_bits() {
    let ctx = context();
    let run = |config: TrainConfig| {
        let mut t = Trainer::new(&ctx, config).unwrap();
        t.run(&ctx, 4, |_, _| Ok(())).unwrap();
        bits(&t)
    };
    assert_same_bits(&run(tiny_config(4)), &run(stereo(4)));
}

#[test]
fn a_moving_camera_starts_scene_gaussians_on_surfaces_whatever_the_thread_count() {
    let ctx = moving_context();
    let volume = Trainer::new(&ctx, tiny_config(6)).unwrap();
    let run = |threads: usize| {
        with_threads(threads, || {
            let t = Trainer::new(&ctx, stereo(6)).unwrap();
            let initial = t.model.set.means.clone();
            let mut t = t;
            t.run(&ctx, 6, |_, _| Ok(())).unwrap();
            (initial, bits(&t))
        })
    };
    let ((initial, one), (initial_two, two)) = (run(1), run(2));
    assert_eq!(initial, initial_two);
    assert_same_bits(&one, &two);
    assert!(one.iter().all(|&b| f32::from_bits(b).is_finite()));
    // The human samples are the volume init's; some scene samples are not.
    let human = volume.model.human_count();
    assert_eq!(initial[..human], volume.model.set.means[..human]);
    let moved = initial[human..]
        .iter()
        .zip(&volume.model.set.means[human..])
        .filter(|(a, b)| a != b)
        .count();
    assert!(moved > 0, "no scene Gaussian starts on a swept surface");
}

#[test]
fn the_box_left_out_holds_the_persons_mask() {
    let ctx = context();
    let data = train::data::load_dataset(&fixture()).unwrap();
    let w = ctx.camera.width as usize;
    let mut checked = 0;
    for f in &ctx.frames {
        let frame = data.frames.iter().find(|d| d.index == f.index).unwrap();
        let Some(mask) = &frame.mask else { continue };
        let [x0, y0, x1, y1] = person_box(&ctx, f).unwrap();
        let mut pixels = 0;
        for (i, _) in mask.iter().enumerate().filter(|(_, &m)| m) {
            let (x, y) = ((i % w) as f64 + 0.5, (i / w) as f64 + 0.5);
            assert!(
                x0 <= x && x < x1 && y0 <= y && y < y1,
                "frame {}: pixel ({x}, {y}) outside {:?}",
                f.index,
                [x0, y0, x1, y1]
            );
            pixels += 1;
        }
        // Not the whole image: the box is the person's, grown by 15 cm (the fixture's person
        // stands tall in a small image, so only its width is narrow).
        assert!(
            pixels > 0 && x1 - x0 < 0.75 * w as f64,
            "frame {}: box {:?}",
            f.index,
            [x0, y0, x1, y1]
        );
        checked += 1;
    }
    assert!(checked > 0);
}
