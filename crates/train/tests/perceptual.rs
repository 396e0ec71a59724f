//! The perceptual (LPIPS) training term on the tiny fixture: it runs with the exposure model, its
//! value is finite and positive, one and two threads give the same bits, it changes the result, and
//! with `lpips_weight = 0` the network's presence changes no bit; asking for it without the network
//! is refused.
#![allow(clippy::unwrap_used)]

use train::config::TrainConfig;
use train::trainer::Trainer;

mod common;
use common::*;

fn shipped_lpips() -> lpips::Lpips<f32> {
    lpips::load_safetensors(&fixture().join("../lpips/alexnet-lpips-v0.1.safetensors")).unwrap()
}

#[test]
fn the_perceptual_loss_trains_and_ignores_the_thread_count() {
    let config = TrainConfig {
        blur_model: train::config::BlurModel::Exposure,
        subframes: 3,
        lpips_weight: 0.2,
        ..tiny_config(6)
    };
    let mut ctx = exposure_context(&config);
    ctx.enable_lpips(shipped_lpips()).unwrap();
    let run = |config: &TrainConfig, threads: usize| {
        with_threads(threads, || {
            let mut t = Trainer::new(&ctx, config.clone()).unwrap();
            let mut lpips = Vec::new();
            t.run(&ctx, 6, |_, r| {
                assert!(r.loss.is_finite());
                lpips.push(r.lpips);
                Ok(())
            })
            .unwrap();
            (bits(&t), lpips)
        })
    };
    let (one, lpips) = run(&config, 1);
    assert!(lpips.iter().all(|&v| v > 0.0 && v.is_finite()), "{lpips:?}");
    assert_same_bits(&one, &run(&config, 2).0);
    let off = TrainConfig {
        lpips_weight: 0.0,
        ..config.clone()
    };
    let (without, zeros) = run(&off, 1);
    assert!(zeros.iter().all(|&v| v == 0.0));
    assert_ne!(without, one, "the perceptual term changed nothing");
    // With weight 0 the network's presence changes no bit.
    let plain = exposure_context(&off);
    let bare = with_threads(1, || {
        let mut t = Trainer::new(&plain, off.clone()).unwrap();
        t.run(&plain, 6, |_, _| Ok(())).unwrap();
        bits(&t)
    });
    assert_same_bits(&bare, &without);
}

#[test]
fn the_perceptual_loss_without_its_network_is_refused() {
    let ctx = context();
    let config = TrainConfig {
        lpips_weight: 0.1,
        ..tiny_config(2)
    };
    let mut t = Trainer::new(&ctx, config).unwrap();
    let e = t.step(&ctx).unwrap_err().to_string();
    assert!(e.contains("lpips_weight"), "{e}");
    let bad = TrainConfig {
        lpips_weight: -1.0,
        ..tiny_config(2)
    };
    assert!(bad
        .validate()
        .unwrap_err()
        .to_string()
        .contains("lpips_weight"));
}
