//! The learned in-exposure motion (`TrainConfig::exposure_motion = learned`) on the tiny fixture:
//! it is the change-only pose correction at its own rates, bit for bit; it learns the change over
//! each exposure and never the pose at mid exposure; it ignores the thread count and resumes bit
//! for bit; beside a fitter's pose correction it lives on the correction's knots at its own rates;
//! and it is refused without the exposure model.
#![allow(clippy::unwrap_used)]

use train::config::{BlurModel, ExposureMotion, TrainConfig};
use train::pose::correction::{CORRECTION_VALUES, POSE_VALUES};
use train::trainer::Trainer;

mod common;
use common::*;

/// The exposure model with events and the learned in-exposure motion from step 2.
fn motion_config(steps: usize) -> TrainConfig {
    TrainConfig {
        exposure_motion: ExposureMotion::Learned,
        pose_correction_from: 2,
        ..exposure_events_config(steps)
    }
}

/// The rows' mid-exposure parts and their changes over the exposure, each flattened.
fn parts(rows: &[f32]) -> (Vec<f32>, Vec<f32>) {
    let (mut mid, mut change) = (Vec::new(), Vec::new());
    for row in rows.chunks(CORRECTION_VALUES) {
        mid.extend_from_slice(&row[..POSE_VALUES]);
        change.extend_from_slice(&row[POSE_VALUES..]);
    }
    (mid, change)
}

#[test]
fn the_learned_motion_is_the_change_only_pose_correction_bit_for_bit() {
    let config = motion_config(8);
    let ctx = exposure_context(&config);
    let run = |config: TrainConfig| {
        let mut t = Trainer::new(&ctx, config).unwrap();
        t.run(&ctx, 8, |_, _| Ok(())).unwrap();
        t
    };
    let learned = run(config.clone());
    let (mid, change) = parts(&learned.model.pose_corrections);
    assert_eq!(
        learned.model.pose_corrections.len(),
        ctx.frames.len() * CORRECTION_VALUES,
        "one row per training frame"
    );
    assert!(
        mid.iter().all(|&v| v == 0.0),
        "the mid-exposure pose stays the given one"
    );
    assert!(
        change.iter().any(|&v| v != 0.0),
        "the change over the exposure is learned"
    );
    // The flags it replaces: pose correction with only its change, per frame, at the motion's rates.
    let flags = run(TrainConfig {
        exposure_motion: ExposureMotion::Given,
        pose_correction: true,
        pose_correction_mid: false,
        pose_correction_change: true,
        pose_correction_knot_every: 1,
        lr_pose_correction: config.lr_exposure_motion,
        lr_pose_correction_root: config.lr_exposure_motion_root,
        lr_pose_correction_final_fraction: config.lr_exposure_motion_final_fraction,
        ..config
    });
    assert_same_bits(&bits(&learned), &bits(&flags));
}

#[test]
fn the_learned_motion_ignores_the_thread_count_and_resumes_bit_for_bit() {
    let config = motion_config(8);
    let ctx = exposure_context(&config);
    let run = |threads: usize| {
        with_threads(threads, || {
            let mut t = Trainer::new(&ctx, config.clone()).unwrap();
            t.run(&ctx, 8, |_, _| Ok(())).unwrap();
            bits(&t)
        })
    };
    assert_same_bits(&run(1), &run(2));
    resume_is_bit_identical(&ctx, config);
}

#[test]
fn beside_pose_correction_the_motion_lives_on_its_knots_at_its_own_rates() {
    let config = TrainConfig {
        pose_correction: true,
        pose_correction_knot_every: 3,
        lr_exposure_motion: 0.0,
        lr_exposure_motion_root: 0.0,
        ..motion_config(8)
    };
    let ctx = exposure_context(&config);
    let mut t = Trainer::new(&ctx, config).unwrap();
    let knots = t.model.correction_knot_frames().len();
    assert!(knots < ctx.frames.len());
    assert_eq!(t.model.pose_corrections.len(), knots * CORRECTION_VALUES);
    t.run(&ctx, 8, |_, _| Ok(())).unwrap();
    let (mid, change) = parts(&t.model.pose_corrections);
    assert!(
        mid.iter().any(|&v| v != 0.0),
        "the fitter's correction learns"
    );
    assert!(
        change.iter().all(|&v| v == 0.0),
        "the change moves at the motion's rates (0 here), not the correction's"
    );
}

#[test]
fn the_learned_motion_needs_the_exposure_model() {
    let config = TrainConfig {
        blur_model: BlurModel::None,
        event_loss: false,
        ..motion_config(4)
    };
    let refused = config.validate().unwrap_err().to_string();
    assert!(refused.contains("exposure_motion"), "{refused}");
}
