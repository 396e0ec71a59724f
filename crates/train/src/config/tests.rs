//! The configuration's presets, files and options, merged and validated.

use super::*;

#[test]
fn a_file_overrides_only_its_keys_and_unknown_keys_are_rejected() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("c.toml");
    std::fs::write(
        &p,
        "steps = 7\nsemantic = \"scalar\"\ninit = \"smpl+cube\"\n",
    )
    .unwrap();
    let base = TrainConfig::preset(Preset::Full);
    let c = TrainConfig::load_over(&p, &base).unwrap();
    assert_eq!(c.steps, 7);
    assert_eq!(c.semantic, SemanticMode::Scalar);
    assert_eq!(c.scene_gaussians, base.scene_gaussians);
    std::fs::write(&p, "stpes = 7\n").unwrap();
    let e = TrainConfig::load_over(&p, &base).unwrap_err().to_string();
    assert!(e.contains("stpes"), "{e}");
    let j = dir.path().join("c.json");
    std::fs::write(&j, "{\"ssim_weight\": 2.0}").unwrap();
    let e = TrainConfig::load_over(&j, &base).unwrap_err().to_string();
    assert!(e.contains("ssim_weight"), "{e}");
}

#[test]
fn options_override_the_file_which_overrides_the_preset() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("c.toml");
    std::fs::write(&p, "steps = 7\nevent_weight = 2.0\n").unwrap();
    let options = TrainOptions {
        steps: Some(9),
        semantic: Some(SemanticMode::Scalar),
        ..TrainOptions::default()
    };
    let c = TrainConfig::resolve(Preset::Full, Some(&p), &options).unwrap();
    assert_eq!(
        (c.steps, c.semantic, c.event_weight),
        (9, SemanticMode::Scalar, 2.0)
    );
    assert_eq!(
        c.scene_gaussians,
        TrainConfig::preset(Preset::Full).scene_gaussians
    );
    let bad = TrainOptions {
        ssim_weight: Some(3.0),
        ..TrainOptions::default()
    };
    let e = TrainConfig::resolve(Preset::Quick, None, &bad)
        .unwrap_err()
        .to_string();
    assert!(e.contains("ssim_weight"), "{e}");
    // A later set of options wins field by field.
    let merged = options.overridden_by(&TrainOptions {
        steps: Some(3),
        event_loss: Some(true),
        ..TrainOptions::default()
    });
    assert_eq!(
        (merged.steps, merged.semantic, merged.event_loss),
        (Some(3), Some(SemanticMode::Scalar), Some(true))
    );
}

#[test]
fn every_option_is_a_flag_with_the_fields_name() {
    use clap::{CommandFactory, FromArgMatches};
    #[derive(clap::Parser)]
    struct Cli {
        #[command(flatten)]
        options: TrainOptions,
    }
    let cli = Cli::command();
    let config = serde_json::to_value(TrainConfig::default()).unwrap();
    for field in config.as_object().unwrap().keys() {
        let flag = field.replace('_', "-");
        assert!(
            cli.get_arguments()
                .any(|a| a.get_long() == Some(flag.as_str())),
            "no --{flag}"
        );
    }
    let m = Cli::command()
        .try_get_matches_from([
            "x",
            "--event-loss",
            "on",
            "--flow-source",
            "gt",
            "--init",
            "smpl+cube",
            "--background",
            "0.1,0.2,0.3",
        ])
        .unwrap();
    let o = Cli::from_arg_matches(&m).unwrap().options;
    assert_eq!(o.event_loss, Some(true));
    assert_eq!(o.flow_source, Some(FlowSource::GroundTruth));
    assert_eq!(o.init, Some(InitMode::SmplCube));
    assert_eq!(o.background, Some([0.1, 0.2, 0.3]));
    assert!(Cli::command()
        .try_get_matches_from(["x", "--event-loss", "yes"])
        .is_err());
}

#[test]
fn a_rate_fraction_must_be_positive() {
    for (field, v) in [
        ("lr_means_final_fraction", 0.0),
        ("lr_pose_correction_final_fraction", -0.1),
        ("lr_pose_correction_final_fraction", f32::NAN),
    ] {
        let mut c = TrainConfig::default();
        if field == "lr_means_final_fraction" {
            c.lr_means_final_fraction = v;
        } else {
            c.lr_pose_correction_final_fraction = v;
        }
        let e = c.validate().unwrap_err().to_string();
        assert!(e.contains(field), "{e}");
    }
}

#[test]
fn presets_are_valid_and_round_trip_through_json() {
    for p in [Preset::Quick, Preset::Full] {
        let c = TrainConfig::preset(p);
        c.validate().unwrap();
        let back: TrainConfig = serde_json::from_str(&serde_json::to_string(&c).unwrap()).unwrap();
        assert_eq!(back, c);
    }
}

#[test]
fn both_presets_let_the_event_weight_fall_to_a_tenth_after_densification() {
    for preset in [Preset::Quick, Preset::Full] {
        let c = TrainConfig::preset(preset);
        assert_eq!(c.event_weight_decay_from, c.densify_until, "{preset:?}");
        let w = c.event_weight;
        assert_eq!(crate::schedule::event_weight_at(&c, c.densify_until), w);
        let last = crate::schedule::event_weight_at(&c, c.steps);
        assert!((last - 0.1 * w).abs() < 1e-6 * w, "{preset:?}: {last}");
    }
}

#[test]
fn the_refractory_reading_of_silence_is_refused_outside_its_range_and_between_frames() {
    for v in [-1.0, f32::NAN, 2e5] {
        let c = TrainConfig {
            event_refractory_us: v,
            ..TrainConfig::default()
        };
        let e = c.validate().unwrap_err().to_string();
        assert!(e.contains("event_refractory_us"), "{v}: {e}");
    }
    let between_frames = TrainConfig {
        event_refractory_us: 1000.0,
        event_pairs: super::EventPairs::Frames,
        ..TrainConfig::default()
    };
    let e = between_frames.validate().unwrap_err().to_string();
    assert!(e.contains("event_pairs = exposure"), "{e}");
    TrainConfig {
        event_refractory_us: 1000.0,
        ..TrainConfig::default()
    }
    .validate()
    .unwrap();
}

#[test]
fn the_bound_margin_reaches_what_a_refractory_sensor_guarantees_and_no_further() {
    // n events of one polarity on a sensor with a refractory period guarantee a change beyond
    // (n − 2) thresholds, so m = 2 is the widest reading with a meaning.
    for (m, ok) in [
        (0.0, true),
        (2.0, true),
        (2.01, false),
        (-0.1, false),
        (f32::NAN, false),
    ] {
        let c = TrainConfig {
            event_bound_margin: m,
            ..TrainConfig::default()
        };
        match c.validate() {
            Ok(()) => assert!(ok, "{m} accepted"),
            Err(e) => {
                assert!(!ok, "{m}: {e}");
                assert!(e.to_string().contains("event_bound_margin"), "{e}");
            }
        }
    }
}
