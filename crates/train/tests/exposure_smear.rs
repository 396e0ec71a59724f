//! The smeared sub-exposure renders (`TrainConfig::exposure_smear`) on the tiny fixture: with the
//! learned in-exposure motion and events they train to finite values, ignore the thread count,
//! resume bit for bit, and are not the same function as point-in-time renders.
#![allow(clippy::unwrap_used)]

use train::config::{ExposureMotion, TrainConfig};
use train::trainer::Trainer;

mod common;
use common::*;

fn smear_config(steps: usize, smear: bool) -> TrainConfig {
    TrainConfig {
        exposure_smear: smear,
        exposure_motion: ExposureMotion::Learned,
        pose_correction_from: 2,
        ..exposure_events_config(steps)
    }
}

#[test]
fn smeared_renders_train_ignore_the_thread_count_and_resume_bit_for_bit() {
    let config = smear_config(8, true);
    let ctx = exposure_context(&config);
    let run = |config: &TrainConfig, threads: usize| {
        with_threads(threads, || {
            let mut t = Trainer::new(&ctx, config.clone()).unwrap();
            t.run(&ctx, 8, |_, r| {
                assert!(r.loss.is_finite());
                Ok(())
            })
            .unwrap();
            bits(&t)
        })
    };
    let smeared = run(&config, 1);
    assert_same_bits(&smeared, &run(&config, 2));
    assert_ne!(smeared, run(&smear_config(8, false), 1));
    resume_is_bit_identical(&ctx, config);
}
