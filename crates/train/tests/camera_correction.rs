//! Learned camera correction on the tiny fixture: a correction that cannot move leaves the run's
//! bits alone, a learning one moves the cameras (the change over the exposure too) whatever the
//! thread count, resumes bit for bit, and held-out frames are rendered from the camera
//! interpolated between their neighbours' corrections; the scale prior keeps the corrections
//! from following the given camera path.
#![allow(clippy::unwrap_used)]

use train::config::{CameraCorrectionBasis, CameraGauge, TrainConfig};
use train::pose::camera_correction::{CAMERA_CORRECTION_VALUES, TWIST_VALUES};
use train::trainer::Trainer;

mod common;
use common::*;

#[test]
fn a_correction_that_cannot_move_changes_no_bit() {
    let ctx = context();
    let run = |config: TrainConfig| {
        let mut t = Trainer::new(&ctx, config).unwrap();
        t.run(&ctx, 8, |_, _| Ok(())).unwrap();
        let mut b = bits(&t);
        b.truncate(b.len() - t.model.camera_corrections.len());
        (b, t.model.camera_corrections.clone())
    };
    let (off, none) = run(tiny_config(8));
    assert!(none.is_empty());
    let (frozen, corrections) = run(TrainConfig {
        camera_correction: true,
        camera_correction_from: 2,
        lr_camera_rotation: 0.0,
        lr_camera_translation: 0.0,
        ..tiny_config(8)
    });
    assert_eq!(
        corrections.len(),
        ctx.frames.len() * CAMERA_CORRECTION_VALUES
    );
    assert!(corrections.iter().all(|&v| v == 0.0));
    assert_same_bits(&off, &frozen);
}

#[test]
fn a_learning_correction_moves_the_trained_frames_cameras_whatever_the_thread_count() {
    let config = camera_config(12);
    let ctx = exposure_context(&config);
    let one = trained_alike_on_one_and_two_threads(&ctx, &config, 12);
    let c = &one.model.camera_corrections;
    assert!(c.iter().all(|v| v.is_finite()));
    let moved: Vec<bool> = c
        .chunks(CAMERA_CORRECTION_VALUES)
        .map(|row| row.iter().any(|&v| v != 0.0))
        .collect();
    // Steps 2..12 train ten frames (of the fixture's training frames): those moved, from the
    // mid-exposure twist to its change over the exposure.
    assert!(moved.iter().filter(|&&m| m).count() >= 2, "{moved:?}");
    assert!(c
        .chunks(CAMERA_CORRECTION_VALUES)
        .any(|row| row[TWIST_VALUES..].iter().any(|&v| v != 0.0)));
    // With one part off, only the other moves: (config, the part that stays zero).
    let only_part_moves = |config: TrainConfig, frozen: std::ops::Range<usize>| {
        let mut t = Trainer::new(&ctx, config).unwrap();
        t.run(&ctx, 12, |_, _| Ok(())).unwrap();
        let rows = t.model.camera_corrections.chunks(CAMERA_CORRECTION_VALUES);
        assert!(rows
            .clone()
            .all(|row| row[frozen.clone()].iter().all(|&v| v == 0.0)));
        assert!(rows.clone().any(|row| row.iter().any(|&v| v != 0.0)));
    };
    // Without the change: only the mid-exposure twists move.
    only_part_moves(
        TrainConfig {
            camera_correction_change: false,
            ..config.clone()
        },
        TWIST_VALUES..CAMERA_CORRECTION_VALUES,
    );
    // Without the mid-exposure twist: only the change over the exposure moves.
    only_part_moves(
        TrainConfig {
            camera_correction_mid: false,
            ..config.clone()
        },
        0..TWIST_VALUES,
    );
    let nothing = TrainConfig {
        camera_correction_mid: false,
        camera_correction_change: false,
        ..config
    };
    let refused = nothing.validate().unwrap_err().to_string();
    assert!(refused.contains("camera_correction_mid"), "{refused}");
}

#[test]
fn camera_correction_resumes_bit_identically() {
    let config = camera_config(16);
    resume_is_bit_identical(&exposure_context(&config), config);
}

/// The clip-wide twist set by the person (`--camera-gauge person`).
fn gauge_config(steps: usize) -> TrainConfig {
    TrainConfig {
        camera_gauge: CameraGauge::Person,
        ..camera_config(steps)
    }
}

#[test]
fn a_person_gauge_moves_every_camera_and_keeps_the_frames_twists_centred() {
    let config = gauge_config(12);
    let ctx = exposure_context(&config);
    let one = trained_alike_on_one_and_two_threads(&ctx, &config, 12);
    let (gauge, rows) = (&one.model.camera_gauge, &one.model.camera_corrections);
    assert_eq!(gauge.len(), CAMERA_CORRECTION_VALUES);
    // The person's Gaussians pull on the clip-wide twist; its change half never moves.
    assert!(gauge[..TWIST_VALUES].iter().any(|&v| v != 0.0), "{gauge:?}");
    assert!(gauge[TWIST_VALUES..].iter().all(|&v| v == 0.0));
    // The frames' own twists moved, and their clip mean is zero (to f32 rounding of values of
    // order 1e-3: the mean is removed in f64 and each row rounded once).
    assert!(rows.iter().any(|&v| v != 0.0));
    let frames = rows.len() / CAMERA_CORRECTION_VALUES;
    for k in 0..TWIST_VALUES {
        let mean: f64 = rows
            .chunks(CAMERA_CORRECTION_VALUES)
            .map(|row| f64::from(row[k]))
            .sum::<f64>()
            / frames as f64;
        assert!(mean.abs() < 1e-8, "component {k}: clip mean {mean}");
    }
    // Every frame's camera, held-out ones too, carries the clip-wide twist.
    let given = ctx.camera.clone();
    let mut centred = one.model.clone();
    centred.camera_gauge.fill(0.0);
    for &index in &[one.model.frame_indices[0], one.model.frame_indices[0] + 1] {
        assert_ne!(
            one.model.corrected_camera(index, &given).world_to_camera,
            centred.corrected_camera(index, &given).world_to_camera
        );
    }
    // The free gauge trains other bits.
    let mut free = Trainer::new(&ctx, camera_config(12)).unwrap();
    free.run(&ctx, 12, |_, _| Ok(())).unwrap();
    assert!(free.model.camera_gauge.is_empty());
    assert_ne!(&free.model.camera_corrections, rows);
}

#[test]
fn smoothed_corrections_move_the_neighbours_of_the_trained_frames_and_resume() {
    let config = TrainConfig {
        camera_correction_smoothing: 1.0,
        ..camera_config(12)
    };
    let ctx = exposure_context(&config);
    let one = trained_alike_on_one_and_two_threads(&ctx, &config, 12);
    let mut sharp = Trainer::new(&ctx, camera_config(12)).unwrap();
    sharp.run(&ctx, 12, |_, _| Ok(())).unwrap();
    let moved = |t: &Trainer| {
        t.model
            .camera_corrections
            .chunks(CAMERA_CORRECTION_VALUES)
            .filter(|row| row.iter().any(|&v| v != 0.0))
            .count()
    };
    // Every stored value within 3σ of a trained frame learns, so more rows move than frames
    // trained; each frame's camera takes the smoothed twist.
    assert!(
        moved(&one) > moved(&sharp),
        "{} vs {}",
        moved(&one),
        moved(&sharp)
    );
    let n = CAMERA_CORRECTION_VALUES;
    let slot = 1;
    let taken = one.model.training_camera_correction(slot);
    assert_ne!(
        &taken[..],
        &one.model.camera_corrections[slot * n..(slot + 1) * n]
    );
    resume_is_bit_identical(&ctx, config);
}

#[test]
fn smoothing_the_mid_exposure_twist_alone_keeps_each_frames_own_change() {
    let config = TrainConfig {
        camera_correction_smoothing: 1.0,
        camera_correction_smooth_change: false,
        ..camera_config(12)
    };
    let ctx = exposure_context(&config);
    let one = trained_alike_on_one_and_two_threads(&ctx, &config, 12);
    let n = CAMERA_CORRECTION_VALUES;
    let mut moved_change = 0;
    for slot in 0..ctx.frames.len() {
        let taken = one.model.training_camera_correction(slot);
        let stored = &one.model.camera_corrections[slot * n..(slot + 1) * n];
        // The change over the exposure is the frame's own; the mid-exposure twist is smoothed.
        assert_eq!(
            &taken[TWIST_VALUES..],
            &stored[TWIST_VALUES..],
            "slot {slot}"
        );
        moved_change += usize::from(stored[TWIST_VALUES..].iter().any(|&v| v != 0.0));
    }
    assert!(moved_change >= 2, "{moved_change}");
    let smoothed_twist = (0..ctx.frames.len()).any(|slot| {
        one.model.training_camera_correction(slot)[..TWIST_VALUES]
            != one.model.camera_corrections[slot * n..slot * n + TWIST_VALUES]
    });
    assert!(smoothed_twist);
    resume_is_bit_identical(&ctx, config);
}

#[test]
fn a_person_gauge_resumes_bit_identically() {
    let config = gauge_config(16);
    resume_is_bit_identical(&exposure_context(&config), config);
}

/// Steps in the image-motion basis (`--camera-correction-basis image`).
fn basis_config(steps: usize) -> TrainConfig {
    TrainConfig {
        camera_correction_basis: CameraCorrectionBasis::Image,
        ..gauge_config(steps)
    }
}

#[test]
fn the_image_basis_moves_the_cameras_otherwise_alike_on_any_thread_count_and_resumes() {
    let config = basis_config(12);
    let ctx = exposure_context(&config);
    let whitened = trained_alike_on_one_and_two_threads(&ctx, &config, 12);
    let twist = trained_alike_on_one_and_two_threads(&ctx, &gauge_config(12), 12);
    let (a, b) = (
        &whitened.model.camera_corrections,
        &twist.model.camera_corrections,
    );
    assert!(a.iter().all(|v| v.is_finite()));
    assert!(a.iter().any(|&v| v != 0.0));
    assert_ne!(a, b, "the basis changed no step");
    resume_is_bit_identical(&ctx, basis_config(16));
}

#[test]
fn held_out_frames_take_the_camera_fitted_to_the_training_frames() {
    let ctx = context();
    let mut t = Trainer::new(&ctx, camera_config(4)).unwrap();
    let n = CAMERA_CORRECTION_VALUES;
    for (slot, row) in t.model.camera_corrections.chunks_mut(n).enumerate() {
        row[3] = 0.01 * slot as f32; // mid-exposure shift along x (m)
        row[TWIST_VALUES + 3] = 5.0; // a change over the exposure: never applied to a held-out frame
    }
    let frames = t.model.frame_indices.clone();
    let (a, b) = (frames[0], frames[1]);
    let given = ctx.camera.clone();
    let at = |index: u32| t.model.corrected_camera(index, &given).world_to_camera[0][3];
    let shift = |index: u32| at(index) - given.world_to_camera[0][3];
    assert!((shift(a) - 0.0).abs() < 1e-7);
    assert!((shift(b) - 0.01).abs() < 1e-7, "{}", shift(b));
    if b > a + 1 {
        let between = a + (b - a) / 2;
        let u = f64::from(between - a) / f64::from(b - a);
        assert!((shift(between) - 0.01 * u).abs() < 1e-6);
    }
    // Rendering a frame applies its correction: a shifted camera renders another image.
    let pose = ctx.body.prepare(&ctx.frames[1].pose.params).unwrap();
    let latent = t.model.latent(1).to_vec();
    let corrected = t.model.render_frame(b, &given, &pose, &latent).unwrap();
    let plain = t.model.render(&given, &pose, &latent).unwrap();
    assert_ne!(corrected.rgb, plain.rgb);
    t.model.camera_corrections.fill(0.0);
    let zero = t.model.render_frame(b, &given, &pose, &latent).unwrap();
    assert_eq!(zero.rgb, plain.rgb);
}

#[test]
fn the_scale_prior_keeps_the_corrections_off_the_given_path() {
    use train::pose::camera_scale::{centre_deviations, scale_prior_terms};
    let config = gauge_config(12);
    let mut ctx = exposure_context(&config);
    // The fixture's camera is bolted down: give each frame's camera a vertical path for the
    // prior to see (the renders keep their cameras).
    let frames = ctx.frames.len();
    for (k, f) in ctx.frames.iter_mut().enumerate() {
        f.camera.world_to_camera[1][3] += 0.02 * (k as f64 - 0.5 * frames as f64);
    }
    let trained = |weight: f32| {
        let config = TrainConfig {
            camera_scale_prior_weight: weight,
            ..config.clone()
        };
        trained_alike_on_one_and_two_threads(&ctx, &config, 12)
    };
    let given: Vec<_> = ctx
        .frames
        .iter()
        .map(|f| f.camera.world_to_camera)
        .collect();
    let deviations = centre_deviations(&given);
    let along_the_path = |t: &Trainer| {
        let rows: Vec<f64> = t
            .model
            .camera_corrections
            .iter()
            .map(|&v| f64::from(v))
            .collect();
        scale_prior_terms(&rows, &deviations, (1.0, 0.01), &mut vec![0.0; rows.len()])
    };
    let (free, held) = (along_the_path(&trained(0.0)), along_the_path(&trained(1e3)));
    assert!(free > 0.0, "the free corrections follow no path: {free}");
    assert!(held < 0.5 * free, "held {held} against free {free}");
}
