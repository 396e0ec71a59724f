//! `TrainingData::prepare`: the supervision a configuration asks for, the same as the separate
//! preparation steps, and a refusal naming the step when a frozen network is missing; the EDI
//! warm-up it prepares.

mod common;

use common::{assert_same_bits, bits, context, exposure_events_config, fixture, tiny_config};
use train::config::TrainConfig;
use train::data::{load_dataset, LossNetworks};
use train::pose::exposure::TrackRules;
use train::trainer::Trainer;
use train::TrainError;

#[test]
fn prepare_equals_the_separate_steps_and_reports_them() {
    let data = load_dataset(&fixture()).unwrap();
    let config = exposure_events_config(4);
    let mut prepared = context();
    let done = prepared
        .prepare(&data, &config, LossNetworks::default())
        .unwrap();
    let mut by_hand = context();
    by_hand
        .enable_exposure(&data, config.subframes, TrackRules::of(&config))
        .unwrap();
    by_hand.enable_exposure_events(&data, &config).unwrap();
    assert_eq!(
        format!("{:?}", prepared.exposure_poses),
        format!("{:?}", by_hand.exposure_poses)
    );
    assert_eq!(
        format!("{:?}", prepared.exposure_events),
        format!("{:?}", by_hand.exposure_events)
    );
    let pairs = by_hand.exposure_events.iter().flatten().flatten().count();
    assert!(pairs > 0);
    assert_eq!(done.event_pairs, Some(pairs));
    let exposure = data.frames[0].exposure_s;
    assert_eq!(done.exposure_s, Some((exposure, exposure)));
    assert_eq!(
        (done.flow_pairs, done.lpips, done.edi_deblurred),
        (None, false, None)
    );
    // One render per frame without events or flow: nothing to prepare.
    let mut bare = context();
    let nothing = bare
        .prepare(&data, &tiny_config(4), LossNetworks::default())
        .unwrap();
    assert_eq!(nothing, train::data::Preparation::default());
}

#[test]
fn a_missing_network_is_refused_naming_its_loss() {
    let data = load_dataset(&fixture()).unwrap();
    for (config, loss) in [
        (
            TrainConfig {
                flow_loss: true,
                ..tiny_config(4)
            },
            "the flow loss",
        ),
        (
            TrainConfig {
                lpips_weight: 0.1,
                ..tiny_config(4)
            },
            "the perceptual (LPIPS) loss",
        ),
    ] {
        let err = context()
            .prepare(&data, &config, LossNetworks::default())
            .unwrap_err();
        assert!(
            matches!(&err, TrainError::Prepare { what, .. } if *what == loss),
            "{err}"
        );
        assert!(err.to_string().contains("network was not given"), "{err}");
    }
}

#[test]
fn a_step_on_data_not_prepared_for_its_configuration_is_refused() {
    let data = load_dataset(&fixture()).unwrap();
    let exposure = exposure_events_config(4);
    let mut poses_only = context();
    poses_only
        .enable_exposure(&data, exposure.subframes, TrackRules::of(&exposure))
        .unwrap();
    let lpips = TrainConfig {
        lpips_weight: 0.1,
        ..tiny_config(4)
    };
    for (ctx, config, missing) in [
        (context(), exposure.clone(), "no sub-exposure poses"),
        (poses_only, exposure, "no events inside exposures"),
        (context(), lpips, "no LPIPS network"),
    ] {
        let mut trainer = Trainer::new(&ctx, config).unwrap();
        let err = trainer.step(&ctx).unwrap_err();
        assert!(
            matches!(err, TrainError::Config(_)) && err.to_string().contains(missing),
            "{err}"
        );
        assert_eq!(trainer.step, 0, "a refused step takes no step");
    }
}

/// The EDI warm-up's steps are the 2-D cascade's steps (`train_on = edi`, one render, no event
/// term), bit for bit; after it the exposure model, its events and the observed frames take over.
#[test]
fn the_edi_warmup_steps_are_the_cascade_steps_then_the_exposure_model_takes_over() {
    let data = load_dataset(&fixture()).unwrap();
    let warm = TrainConfig {
        edi_warmup: 2,
        event_modulation: true,
        ..exposure_events_config(6)
    };
    let cascade = TrainConfig {
        train_on: train::config::TrainOn::Edi,
        blur_model: train::config::BlurModel::None,
        event_loss: false,
        event_modulation: false,
        edi_warmup: 0,
        ..warm.clone()
    };
    let mut warm_ctx = context();
    let done = warm_ctx
        .prepare(&data, &warm, LossNetworks::default())
        .unwrap();
    let mut cascade_ctx = context();
    let cascaded = cascade_ctx
        .prepare(&data, &cascade, LossNetworks::default())
        .unwrap();
    assert!(done.edi_warmup.is_some_and(|n| n > 0), "{done:?}");
    assert_eq!(done.edi_warmup, cascaded.edi_deblurred);
    assert!(done.modulated_slices.is_some() && done.event_pairs.is_some());
    // The observed frames stay the frames; the warm-up images are the cascade's.
    for (slot, frame) in warm_ctx.frames.iter().enumerate() {
        assert_eq!(warm_ctx.target_image(slot, false), frame.image.as_slice());
        assert_eq!(
            warm_ctx.target_image(slot, true),
            cascade_ctx.frames[slot].image.as_slice()
        );
    }
    let mut a = Trainer::new(&warm_ctx, warm).unwrap();
    let mut b = Trainer::new(&cascade_ctx, cascade).unwrap();
    for _ in 0..2 {
        let (ra, rb) = (a.step(&warm_ctx).unwrap(), b.step(&cascade_ctx).unwrap());
        assert_eq!(ra.loss.to_bits(), rb.loss.to_bits());
        assert_eq!((ra.event, rb.event), (0.0, 0.0));
    }
    assert_same_bits(&bits(&a), &bits(&b));
    let (ra, rb) = (a.step(&warm_ctx).unwrap(), b.step(&cascade_ctx).unwrap());
    assert!(ra.event > 0.0, "the event term is on after the warm-up");
    assert_ne!(ra.loss.to_bits(), rb.loss.to_bits());
}

#[test]
fn an_edi_warmup_is_refused_with_other_images_or_as_long_as_the_run() {
    for (config, why) in [
        (
            TrainConfig {
                edi_warmup: 2,
                train_on: train::config::TrainOn::Sharp,
                ..tiny_config(6)
            },
            "train_on = blurred",
        ),
        (
            TrainConfig {
                edi_warmup: 6,
                ..tiny_config(6)
            },
            "fewer than `steps`",
        ),
    ] {
        let err = config.validate().unwrap_err().to_string();
        assert!(err.contains("edi_warmup") && err.contains(why), "{err}");
    }
}
