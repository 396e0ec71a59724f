//! `SpyNet::forward_with_level_flow`: substituting a level's output for the finer levels to refine.

use flow::{FlowError, SpyNet};

fn pair(h: usize, w: usize) -> (Vec<f32>, Vec<f32>) {
    let img1 = (0..3 * h * w)
        .map(|i| ((i * 7919) % 101) as f32 / 100.0)
        .collect();
    let img2 = (0..3 * h * w)
        .map(|i| ((i * 104_729) % 97) as f32 / 96.0)
        .collect();
    (img1, img2)
}

#[test]
fn substituting_a_levels_own_output_reproduces_the_forward_pass() {
    let net = SpyNet::<f32>::random(3, 11);
    let (h, w) = (16, 24);
    let (img1, img2) = pair(h, w);
    let tape = net.forward(&img1, &img2, h, w).expect("forward");
    for level in 0..2 {
        let own = tape.level_flow(level).expect("level output");
        let (outputs, flow) = net
            .forward_with_level_flow(&img1, &img2, h, w, level, own)
            .expect("substituted forward");
        assert_eq!(flow, tape.flow, "level {level}");
        assert_eq!(outputs.len(), 3);
        for (l, out) in outputs.iter().enumerate() {
            if l <= level {
                assert!(out.is_empty(), "level {l} was not run");
            } else {
                assert_eq!(Some(out.as_slice()), tape.level_flow(l), "level {l}");
            }
        }
        // A different coarse flow changes the result: the substitution takes effect.
        let shifted: Vec<f32> = own.iter().map(|v| v + 0.75).collect();
        let (_, other) = net
            .forward_with_level_flow(&img1, &img2, h, w, level, &shifted)
            .expect("substituted forward");
        assert_ne!(other, tape.flow, "level {level}");
        assert!(other.iter().all(|v| v.is_finite()));
    }
}

#[test]
fn bad_level_flows_are_rejected() {
    let net = SpyNet::<f32>::random(3, 11);
    let (h, w) = (16, 24);
    let (img1, img2) = pair(h, w);
    let level0 = vec![0.0f32; 2 * 4 * 6];
    assert!(net
        .forward_with_level_flow(&img1, &img2, h, w, 0, &level0)
        .is_ok());
    for (level, flow, (hh, ww)) in [
        (0, &level0[1..], (h, w)),
        (1, &level0[..], (h, w)),
        (3, &level0[..], (h, w)),
        (0, &level0[..], (18, 24)),
    ] {
        let (a, b) = pair(hh, ww);
        match net.forward_with_level_flow(&a, &b, hh, ww, level, flow) {
            Err(FlowError::Size(msg)) => assert!(msg.contains("forward_with_level_flow"), "{msg}"),
            other => panic!("level {level}, {hh}x{ww}: expected a size error, got {other:?}"),
        }
    }
}
