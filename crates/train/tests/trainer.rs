//! The full E-Sem3DGS loop on the tiny checked-in fixture: it learns, resumes bit for bit from a
//! checkpoint, and gives identical bits with 1 and 2 threads.
#![allow(clippy::unwrap_used)]

use train::config::TrainConfig;
use train::data::load_dataset;
use train::data::TrainingData;
use train::pose::exposure::TrackRules;
use train::trainer::Trainer;

mod common;
use common::*;

#[test]
fn training_reduces_the_loss_on_the_tiny_fixture() {
    let ctx = context();
    let mut t = Trainer::new(&ctx, tiny_config(60)).unwrap();
    let mut losses = Vec::new();
    t.run(&ctx, 60, |_, r| {
        assert!(r.loss.is_finite());
        losses.push(r.loss);
        Ok(())
    })
    .unwrap();
    let first: f32 = losses[..10].iter().sum::<f32>() / 10.0;
    let last: f32 = losses[50..].iter().sum::<f32>() / 10.0;
    assert!(last < 0.8 * first, "loss {first} → {last}");
    // Densification ran and kept the semantic classes.
    assert!(t.model.set.len() != 1200, "density control changed nothing");
    assert!(t.model.human_count() > 0);
}

#[test]
fn resume_from_a_checkpoint_is_bit_identical() {
    resume_is_bit_identical(&context(), tiny_config(16));
}

#[test]
fn resume_with_the_exposure_model_and_events_is_bit_identical() {
    let config = exposure_events_config(16);
    resume_is_bit_identical(&exposure_context(&config), config);
}

#[test]
fn one_and_two_threads_give_identical_bits() {
    let ctx = context();
    let run = |threads: usize| {
        with_threads(threads, || {
            let mut t = Trainer::new(&ctx, tiny_config(8)).unwrap();
            t.run(&ctx, 8, |_, _| Ok(())).unwrap();
            bits(&t)
        })
    };
    assert_same_bits(&run(1), &run(2));
}

/// A context with the flow loss on (ground-truth flow of the fixture, a random 2-level network).
fn flow_context(config: &TrainConfig) -> TrainingData {
    let data = load_dataset(&fixture()).unwrap();
    let mut ctx = context();
    ctx.enable_flow(&data, config, flow::SpyNet::random(2, 7))
        .unwrap();
    ctx
}

#[test]
fn the_flow_loss_trains_pairs_of_consecutive_training_frames() {
    let config = TrainConfig {
        flow_loss: true,
        flow_source: train::config::FlowSource::GroundTruth,
        flow_tau: 0.0,
        ..tiny_config(8)
    };
    let ctx = flow_context(&config);
    // The fixture's split is 7 train / 3 test per block of 10: pairs exist, and a frame followed by a
    // test frame has none.
    let pairs = ctx.flow_pairs.iter().filter(|p| p.is_some()).count();
    assert!(pairs > 0 && pairs < ctx.frames.len(), "{pairs} pairs");
    for (slot, p) in ctx.flow_pairs.iter().enumerate() {
        if let Some(p) = p {
            assert_eq!(p.next_slot, slot + 1);
            assert_eq!((p.target.height, p.target.width), (16, 16));
        }
    }
    let run = |threads: usize| {
        with_threads(threads, || {
            let mut t = Trainer::new(&ctx, config.clone()).unwrap();
            let mut flow_steps = 0;
            t.run(&ctx, 8, |_, r| {
                assert!(r.flow.is_finite() && r.flow >= 0.0);
                flow_steps += usize::from(r.flow > 0.0);
                Ok(())
            })
            .unwrap();
            (bits(&t), flow_steps)
        })
    };
    let (one, flow_steps) = run(1);
    assert!(flow_steps > 0, "no step had a flow pair");
    assert_same_bits(&one, &run(2).0);
    // The same run without the flow loss ends elsewhere: the term changes the parameters.
    let mut off = Trainer::new(
        &ctx,
        TrainConfig {
            flow_loss: false,
            ..config.clone()
        },
    )
    .unwrap();
    off.run(&ctx, 8, |_, _| Ok(())).unwrap();
    assert_ne!(bits(&off), one);
}

/// The appearance parameters of a trainer (colour features, opacities, colour networks) as bits.
fn appearance_bits(t: &Trainer) -> Vec<u32> {
    let s = &t.model.set;
    s.features
        .iter()
        .chain(&s.opacity_logits)
        .chain(&t.model.nets.human_colour.mlp.params)
        .chain(&t.model.nets.scene_colour.mlp.params)
        .map(|v| v.to_bits())
        .collect()
}

/// The means of a trainer's Gaussians as bits.
fn mean_bits(t: &Trainer) -> Vec<u32> {
    t.model
        .set
        .means
        .iter()
        .flatten()
        .map(|v| v.to_bits())
        .collect()
}

/// The shapes (log-scales and rotations) of a trainer's Gaussians as bits.
fn shape_bits(t: &Trainer) -> Vec<u32> {
    let s = &t.model.set;
    let scales = s.log_scales.iter().flatten();
    scales
        .chain(s.quats.iter().flatten())
        .map(|v| v.to_bits())
        .collect()
}

#[test]
fn a_geometric_flow_gradient_moves_the_means_and_leaves_appearance_alone() {
    use train::config::FlowGradient;
    let config = TrainConfig {
        flow_loss: true,
        flow_source: train::config::FlowSource::GroundTruth,
        flow_tau: 0.0,
        flow_weight: 10.0,
        ..tiny_config(8)
    };
    let ctx = flow_context(&config);
    // One step from the same start under three settings; the step's frame must have a flow pair.
    let one_step = |config: TrainConfig| {
        let mut t = Trainer::new(&ctx, config).unwrap();
        let report = t.step(&ctx).unwrap();
        (t, report)
    };
    // The first seed whose first frame has a next frame.
    let config = (0..64)
        .map(|seed| TrainConfig {
            seed,
            ..config.clone()
        })
        .find(|c| one_step(c.clone()).1.flow > 0.0)
        .expect("no seed starts with a flow pair");
    let (geometry, _) = one_step(TrainConfig {
        flow_gradient: FlowGradient::Geometry,
        ..config.clone()
    });
    let (all, _) = one_step(config.clone());
    let (off, _) = one_step(TrainConfig {
        flow_loss: false,
        ..config.clone()
    });
    // The flow loss reaches appearance with `All` (so the comparison below can fail) but not with
    // `Geometry`, where appearance takes exactly the step it takes without the flow loss.
    assert_ne!(appearance_bits(&all), appearance_bits(&off));
    assert_same_bits(&appearance_bits(&geometry), &appearance_bits(&off));
    // The means and the shapes (through the covariances) still feel the flow loss.
    assert_ne!(mean_bits(&geometry), mean_bits(&off));
    assert_ne!(shape_bits(&geometry), shape_bits(&off));
}

#[test]
fn a_flow_source_the_scene_lacks_is_refused_at_load_time() {
    let data = load_dataset(&fixture()).unwrap();
    let mut ctx = context();
    // The tiny fixture has no event-only flow.
    let config = TrainConfig {
        flow_loss: true,
        flow_source: train::config::FlowSource::Events,
        ..tiny_config(8)
    };
    let err = ctx
        .enable_flow(&data, &config, flow::SpyNet::random(2, 7))
        .unwrap_err()
        .to_string();
    assert!(err.contains("events_cm") && err.contains("frame"), "{err}");
}

#[test]
fn sharp_network_targets_make_the_sharp_frames_a_zero_of_the_flow_loss() {
    use train::config::FlowSource;
    use train::loss::optical_flow::pair_flow_loss;
    assert_eq!(
        <FlowSource as clap::ValueEnum>::from_str("sharp-net", false),
        Ok(FlowSource::SharpNetwork)
    );
    let data = load_dataset(&fixture()).unwrap();
    let net = flow::SpyNet::random(2, 7);
    let config = |flow_source| TrainConfig {
        flow_loss: true,
        flow_source,
        flow_tau: 0.05,
        ..tiny_config(8)
    };
    let mut sharp = context();
    sharp
        .enable_flow(&data, &config(FlowSource::SharpNetwork), net.clone())
        .unwrap();
    let gt = flow_context(&config(FlowSource::GroundTruth));
    let (h, w) = (sharp.camera.height as usize, sharp.camera.width as usize);
    let frame = |slot: usize| {
        let index = sharp.frames[slot].index;
        data.frames.iter().find(|f| f.index == index).unwrap()
    };
    let mut supervised = 0;
    for (slot, (p, q)) in sharp.flow_pairs.iter().zip(&gt.flow_pairs).enumerate() {
        // The same pairs as with a flow file, at the same resolution.
        assert_eq!(p.is_some(), q.is_some(), "slot {slot}");
        let Some(p) = p else { continue };
        assert_eq!((p.target.height, p.target.width), (16, 16));
        let (first, second) = (frame(slot), frame(p.next_slot));
        let (a, b) = (
            first.sharp.as_ref().unwrap(),
            second.sharp.as_ref().unwrap(),
        );
        // Zero loss (and zero gradient) at the sharp frames themselves ...
        let at_sharp = pair_flow_loss(&net, a, b, h, w, &p.target).unwrap();
        assert_eq!(at_sharp.loss, 0.0);
        assert!(at_sharp
            .d_first
            .iter()
            .chain(&at_sharp.d_second)
            .all(|&g| g == 0.0));
        // ... but not at the blurred input frames, where the network sees other images.
        let supervised_here = p.target.supervised();
        if supervised_here > 0 {
            let at_blurred = pair_flow_loss(&net, &first.image, &second.image, h, w, &p.target);
            assert!(at_blurred.unwrap().loss > 0.0, "slot {slot}");
        }
        supervised += supervised_here;
        // The mask is the predicted flow's magnitude against τ.
        let plane = 16 * 16;
        for i in 0..plane {
            let (u, v) = (p.target.flow[i], p.target.flow[plane + i]);
            assert_eq!(p.target.mask[i], (u * u + v * v).sqrt() > 0.05);
        }
    }
    assert!(supervised > 0, "no pixel supervised");
}

#[test]
fn sharp_network_targets_without_sharp_references_are_refused_at_load_time() {
    let mut data = load_dataset(&fixture()).unwrap();
    let config = TrainConfig {
        flow_loss: true,
        flow_source: train::config::FlowSource::SharpNetwork,
        ..tiny_config(8)
    };
    // Drop the sharp reference of the first frame that starts a training pair.
    let gt = flow_context(&TrainConfig {
        flow_source: train::config::FlowSource::GroundTruth,
        ..config.clone()
    });
    let slot = gt.flow_pairs.iter().position(Option::is_some).unwrap();
    let index = gt.frames[slot].index;
    let frame = data.frames.iter_mut().find(|f| f.index == index).unwrap();
    frame.sharp = None;
    let mut ctx = context();
    let err = ctx
        .enable_flow(&data, &config, flow::SpyNet::random(2, 7))
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("sharp reference") && err.contains(&format!("frame {index}")),
        "{err}"
    );
}

#[test]
fn the_event_generation_loss_trains_pairs_from_the_event_files() {
    let data = load_dataset(&fixture()).unwrap();
    let config = TrainConfig {
        event_loss: true,
        ..tiny_config(6)
    };
    let mut ctx = context();
    ctx.enable_events(&data, &config).unwrap();
    let pairs: Vec<_> = ctx.event_pairs.iter().flatten().collect();
    assert!(!pairs.is_empty());
    // The fixture's events are real: some pixels fired, in both polarities.
    let expected: Vec<f32> = pairs
        .iter()
        .flat_map(|p| p.expected.iter().copied())
        .collect();
    assert!(expected.iter().any(|&e| e > 0.0) && expected.iter().any(|&e| e < 0.0));
    let mut on = Trainer::new(&ctx, config.clone()).unwrap();
    let mut event_steps = 0;
    on.run(&ctx, 6, |_, r| {
        assert!(r.event.is_finite() && r.event >= 0.0);
        event_steps += usize::from(r.event > 0.0);
        Ok(())
    })
    .unwrap();
    assert!(event_steps > 0, "no step had an event pair");
    let mut off = Trainer::new(
        &ctx,
        TrainConfig {
            event_loss: false,
            ..config
        },
    )
    .unwrap();
    off.run(&ctx, 6, |_, _| Ok(())).unwrap();
    assert_ne!(bits(&off), bits(&on));
}

#[test]
fn the_exposure_model_with_events_inside_exposures_trains_and_ignores_the_thread_count() {
    let config = exposure_events_config(8);
    let ctx = exposure_context(&config);
    assert_eq!(ctx.exposure_poses.len(), ctx.frames.len());
    assert!(ctx.exposure_poses.iter().all(|p| p.len() == 3));
    // The sub-exposure poses differ from each other and bracket the mid-exposure pose.
    let slot = 1;
    assert_eq!(
        ctx.exposure_poses[slot][1].prepared.pose_code,
        ctx.frames[slot].pose.prepared.pose_code
    );
    assert_ne!(
        ctx.exposure_poses[slot][0].prepared.bones,
        ctx.exposure_poses[slot][2].prepared.bones
    );
    // Frame 0's exposure starts before the first event file: its first interval is unsupervised;
    // every other interval has events.
    assert!(ctx.exposure_events[0][0].is_none());
    assert!(ctx.exposure_events[1].iter().all(Option::is_some));
    let run = |config: &TrainConfig, threads: usize| {
        with_threads(threads, || {
            let mut t = Trainer::new(&ctx, config.clone()).unwrap();
            let mut events = 0.0f32;
            t.run(&ctx, 8, |_, r| {
                assert!(r.loss.is_finite());
                events += r.event;
                Ok(())
            })
            .unwrap();
            (bits(&t), events)
        })
    };
    let (one, events) = run(&config, 1);
    assert!(events > 0.0, "the event loss never applied");
    assert_same_bits(&one, &run(&config, 2).0);
    // Networks evaluated at every sub-exposure pose: also thread-independent, and not the same
    // function as the shared evaluation.
    let per_subframe = TrainConfig {
        exposure_networks: train::config::ExposureNetworks::PerSubframe,
        ..config.clone()
    };
    let (exact, _) = run(&per_subframe, 1);
    assert_same_bits(&exact, &run(&per_subframe, 2).0);
    assert_ne!(exact, one);
    // Without the exposure model the same run ends elsewhere.
    let mut plain = Trainer::new(&ctx, tiny_config(8)).unwrap();
    plain.run(&ctx, 8, |_, _| Ok(())).unwrap();
    assert_ne!(bits(&plain), one);
}

/// The image-gradient term (`image_gradient_weight`) reaches the trainer: the same exposure run
/// with it ends elsewhere, with the same bits on one and two threads.
#[test]
fn the_image_gradient_term_trains_and_ignores_the_thread_count() {
    let config = TrainConfig {
        image_gradient_weight: 0.5,
        ..exposure_events_config(4)
    };
    let ctx = exposure_context(&config);
    let run = |config: &TrainConfig, threads: usize| {
        with_threads(threads, || {
            let mut t = Trainer::new(&ctx, config.clone()).unwrap();
            t.run(&ctx, 4, |_, r| {
                assert!(r.loss.is_finite());
                Ok(())
            })
            .unwrap();
            bits(&t)
        })
    };
    let with_term = run(&config, 1);
    assert_same_bits(&with_term, &run(&config, 2));
    let without = TrainConfig {
        image_gradient_weight: 0.0,
        ..config.clone()
    };
    assert_ne!(run(&without, 1), with_term);
}

#[test]
fn event_pairs_inside_exposures_need_the_exposure_model() {
    let config = TrainConfig {
        event_loss: true,
        event_pairs: train::config::EventPairs::Exposure,
        ..tiny_config(8)
    };
    let e = config.validate().unwrap_err().to_string();
    assert!(e.contains("event_pairs") && e.contains("blur_model"), "{e}");
}

#[test]
fn an_events_file_that_does_not_cover_its_frame_is_refused_at_load_time() {
    // Frame 3 names frame 5's events file: its events lie outside [t_3, t_4).
    let dir = tempfile::tempdir().unwrap();
    copy_dir(&fixture(), dir.path());
    let scene_path = dir.path().join("scene.json");
    let mut scene: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&scene_path).unwrap()).unwrap();
    scene["frames"][3]["events"] = "events/000005.npz".into();
    std::fs::write(&scene_path, scene.to_string()).unwrap();
    let data = load_dataset(dir.path()).unwrap();
    let config = exposure_events_config(8);
    let mut ctx = context();
    ctx.enable_exposure(&data, config.subframes, TrackRules::of(&config))
        .unwrap();
    let err = ctx
        .enable_exposure_events(&data, &config)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("000005.npz") && err.contains("frame 3") && err.contains("outside"),
        "{err}"
    );
    // The pairs of frames read the same file and refuse it the same way.
    let err = ctx
        .enable_events(&data, &tiny_config(8))
        .unwrap_err()
        .to_string();
    assert!(err.contains("frame 3") && err.contains("outside"), "{err}");
}

#[test]
fn header_less_raw_event_files_need_the_scene_to_state_their_encoding() {
    // Every frame's events rewritten as Prophesee EVT 3.0 `.raw` files without a header.
    let dir = tempfile::tempdir().unwrap();
    copy_dir(&fixture(), dir.path());
    let scene_path = dir.path().join("scene.json");
    let mut scene: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&scene_path).unwrap()).unwrap();
    for frame in scene["frames"].as_array_mut().unwrap() {
        let Some(npz) = frame["events"].as_str().map(str::to_string) else {
            continue;
        };
        let stream = events::read_events(dir.path().join(&npz)).unwrap();
        let bytes =
            events::io::prophesee::encode(&stream, events::io::prophesee::PropheseeFormat::Evt3)
                .unwrap();
        let end = b"% end\n";
        let body = bytes.windows(end.len()).position(|w| w == end).unwrap() + end.len();
        let raw = npz.replace(".npz", ".raw");
        std::fs::write(dir.path().join(&raw), &bytes[body..]).unwrap();
        frame["events"] = raw.into();
    }
    std::fs::write(&scene_path, scene.to_string()).unwrap();
    let config = exposure_events_config(8);
    let load = |data: &train::data::Dataset| {
        let mut ctx = context();
        ctx.enable_exposure(data, config.subframes, TrackRules::of(&config))
            .unwrap();
        ctx.enable_exposure_events(data, &config).map(|()| ctx)
    };
    let err = load(&load_dataset(dir.path()).unwrap())
        .unwrap_err()
        .to_string();
    assert!(
        err.contains(".raw") && err.contains("events_raw_format"),
        "{err}"
    );
    // Stated in scene.json: the same counts as the original files give.
    scene["events_raw_format"] = "evt3".into();
    std::fs::write(&scene_path, scene.to_string()).unwrap();
    let from_raw = load(&load_dataset(dir.path()).unwrap()).unwrap();
    let original = exposure_context(&config);
    // Compared as text: an unconstrained pixel (both polarities) is NaN, which `==` never equals.
    assert_eq!(
        format!("{:?}", from_raw.exposure_events),
        format!("{:?}", original.exposure_events)
    );
    // An unknown encoding is refused by the scene validator, naming the field.
    scene["events_raw_format"] = "evt4".into();
    std::fs::write(&scene_path, scene.to_string()).unwrap();
    let err = format!("{:#}", load_dataset(dir.path()).unwrap_err());
    assert!(err.contains("events_raw_format"), "{err}");
}

/// Copies a directory tree.
fn copy_dir(from: &std::path::Path, to: &std::path::Path) {
    for entry in std::fs::read_dir(from).unwrap() {
        let entry = entry.unwrap();
        let target = to.join(entry.file_name());
        if entry.file_type().unwrap().is_dir() {
            std::fs::create_dir_all(&target).unwrap();
            copy_dir(&entry.path(), &target);
        } else {
            std::fs::copy(entry.path(), &target).unwrap();
        }
    }
}
