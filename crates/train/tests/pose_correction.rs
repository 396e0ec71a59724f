//! Learned pose correction on the tiny fixture: the differentiable pose preparation gives the same
//! bits as the plain one, a correction that cannot move leaves the run's bits alone, a learning one
//! moves the poses and ignores the thread count, resumes bit for bit, held-out frames are
//! rendered with interpolated corrections (and exported with them), decaying rates shrink the
//! later steps, and corrections on knots every few frames step only the knots of the trained
//! frames.
#![allow(clippy::unwrap_used)]

use train::config::{BlurModel, TrainConfig};
use train::data::{load_dataset, TrainingData};
use train::pose::correction::{KnotSpan, CORRECTION_VALUES, POSE_VALUES};
use train::trainer::Trainer;

mod common;
use common::*;

/// Pose correction from step 2, one correction per training frame (the knots' layout has its own
/// test below).
fn correction_config(steps: usize) -> TrainConfig {
    TrainConfig {
        pose_correction: true,
        pose_correction_from: 2,
        pose_correction_knot_every: 1,
        ..tiny_config(steps)
    }
}

#[test]
fn the_differentiable_pose_preparation_gives_the_plain_bits() {
    let data = load_dataset(&fixture()).unwrap();
    let ctx = context();
    for f in &data.frames {
        let plain = ctx.body.prepare(&f.smpl).unwrap();
        let (differentiable, _) = ctx.body.prepare_differentiable(&f.smpl).unwrap();
        assert_eq!(plain, differentiable, "frame {}", f.index);
    }
    let mut bad = data.frames[0].smpl.clone();
    bad.pose[5] = f32::NAN;
    assert!(ctx.body.prepare_differentiable(&bad).is_err());
    bad.pose.pop();
    assert!(ctx.body.prepare_differentiable(&bad).is_err());
}

#[test]
fn a_correction_that_cannot_move_changes_no_bit() {
    let ctx = context();
    let run = |config: TrainConfig| {
        let mut t = Trainer::new(&ctx, config).unwrap();
        t.run(&ctx, 8, |_, _| Ok(())).unwrap();
        let mut b = bits(&t);
        b.truncate(b.len() - t.model.pose_corrections.len());
        (b, t.model.pose_corrections.clone())
    };
    let (off, none) = run(tiny_config(8));
    assert!(none.is_empty());
    let (frozen, corrections) = run(TrainConfig {
        lr_pose_correction: 0.0,
        lr_pose_correction_root: 0.0,
        ..correction_config(8)
    });
    assert!(corrections.iter().all(|&v| v == 0.0));
    assert_same_bits(&off, &frozen);
}

#[test]
fn decaying_rates_take_the_first_step_whole_and_the_later_ones_smaller() {
    let ctx = context();
    let run = |fraction: f32, steps: usize| {
        let mut t = Trainer::new(
            &ctx,
            TrainConfig {
                lr_pose_correction_final_fraction: fraction,
                ..correction_config(8)
            },
        )
        .unwrap();
        t.run(&ctx, steps, |_, _| Ok(())).unwrap();
        t.model.pose_corrections.clone()
    };
    // The corrections start at step 2: its step is at the full rate whatever the fraction.
    let after_first = run(1.0, 3);
    assert_eq!(after_first, run(1e-3, 3));
    assert!(after_first.iter().any(|&v| v != 0.0));
    // After it, the decayed rates (0.32, 0.10, ... of the first) move the corrections far less
    // than the constant ones (1, 1, ...); unwired, the two runs would give the same bits.
    let (constant, decayed) = (run(1.0, 8), run(1e-3, 8));
    let moved = |c: &[f32]| {
        c.iter()
            .zip(&after_first)
            .map(|(a, b)| (a - b).abs())
            .sum::<f32>()
    };
    assert!(
        moved(&decayed) < 0.5 * moved(&constant),
        "{} {}",
        moved(&decayed),
        moved(&constant)
    );
}

#[test]
fn pose_correction_learns_ignores_the_thread_count_and_resumes_bit_for_bit() {
    // With the change over the exposure learned too: every column keeps its rate across a resume.
    let config = TrainConfig {
        blur_model: BlurModel::Exposure,
        subframes: 3,
        pose_correction_change: true,
        ..correction_config(8)
    };
    let ctx = exposure_context(&config);
    let run = |threads: usize| {
        with_threads(threads, || {
            let mut t = Trainer::new(&ctx, config.clone()).unwrap();
            let mut prior = 0.0f32;
            t.run(&ctx, 8, |_, r| {
                assert!(r.loss.is_finite());
                prior += r.pose_prior;
                Ok(())
            })
            .unwrap();
            (t, prior)
        })
    };
    let (one, prior) = run(1);
    let c = &one.model.pose_corrections;
    assert_eq!(c.len(), ctx.frames.len() * CORRECTION_VALUES);
    assert!(c.iter().all(|v| v.is_finite()));
    // Both the mid-exposure values and their change over the exposure moved, and the prior saw them.
    assert!(c
        .iter()
        .take(POSE_VALUES)
        .chain(&c[CORRECTION_VALUES..CORRECTION_VALUES + POSE_VALUES])
        .any(|&v| v != 0.0));
    assert!(c
        .chunks(CORRECTION_VALUES)
        .any(|s| s[POSE_VALUES..].iter().any(|&v| v != 0.0)));
    assert!(prior > 0.0);
    assert_same_bits(&bits(&one), &bits(&run(2).0));
    resume_is_bit_identical(&ctx, config.clone());
}

#[test]
fn held_out_frames_are_rendered_with_interpolated_corrections() {
    let data = load_dataset(&fixture()).unwrap();
    let ctx = context();
    let mut t = Trainer::new(&ctx, correction_config(4)).unwrap();
    t.run(&ctx, 4, |_, _| Ok(())).unwrap();
    let model = &mut t.model;
    // A known correction: the root translated 5 cm along x on every training frame.
    for slot in model.pose_corrections.chunks_mut(CORRECTION_VALUES) {
        slot.fill(0.0);
        slot[72] = 0.05;
    }
    let held_out = data
        .frames
        .iter()
        .find(|f| !model.frame_indices.contains(&f.index))
        .expect("the fixture holds out a frame");
    let corrected = model.corrected_params(held_out.index, &held_out.smpl);
    assert!((corrected.transl[0] - held_out.smpl.transl[0] - 0.05).abs() < 1e-6);
    assert_eq!(corrected.pose, held_out.smpl.pose);
    // The exported poses: every frame, the held-out one with its interpolated correction, and
    // the file reads back to the same values.
    let dir = tempfile::tempdir().unwrap();
    train::export::write_corrected_poses(dir.path(), model, &data).unwrap();
    let text =
        std::fs::read_to_string(dir.path().join(train::export::CORRECTED_POSES_FILE)).unwrap();
    let file: train::export::CorrectedPoses = serde_json::from_str(&text).unwrap();
    assert_eq!(file, train::export::corrected_poses(model, &data));
    assert_eq!(file.frames.len(), data.frames.len());
    let entry = file
        .frames
        .iter()
        .find(|f| f.index == held_out.index)
        .unwrap();
    assert_eq!(entry.split, scene::Split::Test);
    assert_eq!(entry.transl, corrected.transl);
    let flat: Vec<f32> = entry.pose.iter().flatten().copied().collect();
    assert_eq!(flat, corrected.pose);
    // Off: the parameters as given.
    let plain = Trainer::new(&ctx, tiny_config(4)).unwrap();
    assert_eq!(
        plain.model.corrected_params(held_out.index, &held_out.smpl),
        held_out.smpl
    );
}

#[test]
fn without_the_root_only_the_body_joints_are_corrected() {
    let ctx = context();
    let mut t = Trainer::new(
        &ctx,
        TrainConfig {
            pose_correction_root: false,
            ..correction_config(8)
        },
    )
    .unwrap();
    t.run(&ctx, 8, |_, _| Ok(())).unwrap();
    let c = &t.model.pose_corrections;
    for slot in c.chunks(CORRECTION_VALUES) {
        for k in train::pose::correction::root_indices() {
            assert_eq!(slot[k], 0.0, "root value {k}");
        }
    }
    assert!(c.iter().any(|&v| v != 0.0));
}

/// Runs steps 2..10 of `t` and asserts that each changes only the correction rows (frames or knots)
/// that `rows_of(slot)` names for the slots it trains: its frame's and the next one's (trained too
/// when the step renders it: flow or frame-pair events). Returns how many of those rows moved.
fn steps_move_only_their_rows(
    t: &mut Trainer,
    ctx: &TrainingData,
    rows_of: impl Fn(usize) -> Vec<usize>,
) -> usize {
    t.run(ctx, 2, |_, _| Ok(())).unwrap();
    let mut moved = 0usize;
    for _ in 2..10 {
        let before = t.model.pose_corrections.clone();
        let r = t.step(ctx).unwrap();
        let frames = &t.model.frame_indices;
        let slot = frames.iter().position(|&i| i == r.frame).unwrap();
        let allowed: Vec<usize> = [slot, (slot + 1).min(frames.len() - 1)]
            .into_iter()
            .flat_map(&rows_of)
            .collect();
        for (k, (a, b)) in before
            .chunks(CORRECTION_VALUES)
            .zip(t.model.pose_corrections.chunks(CORRECTION_VALUES))
            .enumerate()
        {
            if allowed.contains(&k) {
                moved += usize::from(a != b);
            } else {
                assert_eq!(a, b, "row {k} moved on a step that trained slot {slot}");
            }
        }
    }
    moved
}

#[test]
fn a_step_moves_only_the_corrections_of_the_frames_it_trains() {
    let ctx = context();
    let mut t = Trainer::new(&ctx, correction_config(10)).unwrap();
    let moved = steps_move_only_their_rows(&mut t, &ctx, |slot| vec![slot]);
    assert!(moved >= 8, "the trained frames' corrections move");
}

#[test]
fn the_change_over_the_exposure_is_learned_only_when_asked() {
    for change in [false, true] {
        let config = TrainConfig {
            blur_model: BlurModel::Exposure,
            subframes: 3,
            pose_correction_change: change,
            ..correction_config(8)
        };
        let ctx = exposure_context(&config);
        let mut t = Trainer::new(&ctx, config).unwrap();
        t.run(&ctx, 8, |_, _| Ok(())).unwrap();
        let slots = t.model.pose_corrections.chunks(CORRECTION_VALUES);
        let change_moved = slots
            .clone()
            .any(|s| s[POSE_VALUES..].iter().any(|&v| v != 0.0));
        assert_eq!(
            change_moved, change,
            "change over the exposure learned: {change}"
        );
        assert!(slots.flat_map(|s| &s[..POSE_VALUES]).any(|&v| v != 0.0));
    }
}

#[test]
fn without_the_mid_exposure_part_only_the_change_is_learned() {
    let config = TrainConfig {
        blur_model: BlurModel::Exposure,
        subframes: 3,
        pose_correction_change: true,
        pose_correction_mid: false,
        ..correction_config(8)
    };
    let ctx = exposure_context(&config);
    let mut t = Trainer::new(&ctx, config.clone()).unwrap();
    t.run(&ctx, 8, |_, _| Ok(())).unwrap();
    let slots = t.model.pose_corrections.chunks(CORRECTION_VALUES);
    assert!(
        slots
            .clone()
            .flat_map(|s| &s[..POSE_VALUES])
            .all(|&v| v == 0.0),
        "the mid-exposure corrections stay zero"
    );
    assert!(
        slots.flat_map(|s| &s[POSE_VALUES..]).any(|&v| v != 0.0),
        "the change over the exposure is learned"
    );
    let nothing = TrainConfig {
        pose_correction_change: false,
        ..config
    };
    let refused = nothing.validate().unwrap_err().to_string();
    assert!(refused.contains("pose_correction_mid"), "{refused}");
}

#[test]
fn corrections_on_knots_step_only_the_knots_of_the_trained_frames() {
    let ctx = context();
    let config = TrainConfig {
        pose_correction_knot_every: 3,
        ..correction_config(10)
    };
    let mut t = Trainer::new(&ctx, config.clone()).unwrap();
    let frames = t.model.frame_indices.len();
    let knot_frames = t.model.correction_knot_frames();
    assert_eq!(
        knot_frames.len(),
        frames.div_ceil(3) + usize::from(!(frames - 1).is_multiple_of(3))
    );
    assert_eq!(
        t.model.pose_corrections.len(),
        knot_frames.len() * CORRECTION_VALUES
    );
    let frame_indices = t.model.frame_indices.clone();
    let moved = steps_move_only_their_rows(&mut t, &ctx, |slot| {
        let span = KnotSpan::of(&knot_frames, frame_indices[slot]);
        span.weights().into_iter().map(|(k, _)| k).collect()
    });
    assert!(moved >= 8, "the trained frames' knots move");
    // A training frame between two knots is corrected by their interpolation.
    let (values, span) = t.model.training_correction(1);
    let (k0, (k1, u)) = (
        span.first,
        span.next.expect("slot 1 lies between knots 0 and 1"),
    );
    let row =
        |k: usize| &t.model.pose_corrections[k * CORRECTION_VALUES..(k + 1) * CORRECTION_VALUES];
    for ((v, a), b) in values.iter().zip(row(k0)).zip(row(k1)) {
        assert_eq!(*v, a + u * (b - a));
    }
    resume_is_bit_identical(&ctx, config);
}
