//! `TrainingData::prepare`: the supervision a configuration asks for, the same as the separate
//! preparation steps, and a refusal naming the step when a frozen network is missing.

mod common;

use common::{context, exposure_events_config, fixture, tiny_config};
use train::config::TrainConfig;
use train::data::{load_dataset, LossNetworks};
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
    by_hand.enable_exposure(&data, config.subframes).unwrap();
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
        .enable_exposure(&data, exposure.subframes)
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
