//! The pyramid rule ([`PyramidDepth`]): how many levels a pass runs, that a pass under the reference
//! rule is exactly the pass of the weights it uses, and that the rule survives the weights file.

use flow::{read_safetensors, write_safetensors, FlowError, PyramidDepth, SpyNet, PYRAMID_KEY};

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
fn the_reference_rule_counts_levels_as_the_reference_port_does() {
    let r = PyramidDepth::REFERENCE;
    // 512x384 with the 6-level original weights: 512x384 → … → 32x24, five images.
    assert_eq!(r.levels_run(6, 384, 512), 5);
    // FlyingChairs pairs are resized to 512x384 as well; 1024x448 (a multiple of 32) uses all six.
    assert_eq!(r.levels_run(6, 448, 1024), 6);
    // Never more than the weights hold, never fewer than one.
    assert_eq!(r.levels_run(6, 4096, 4096), 6);
    assert_eq!(r.levels_run(6, 32, 32), 1);
    // The project's 4-level weights at the flow loss's 64x64 would run 2 levels under it.
    assert_eq!(r.levels_run(4, 64, 64), 2);
    assert_eq!(PyramidDepth::AllLevels.levels_run(4, 64, 64), 4);
}

#[test]
fn a_reference_pass_is_the_pass_of_the_coarse_weights_alone() {
    // 3 levels, halving while a side exceeds 6: 12x12 → 6x6, so weights levels 0 and 1 run and
    // level 2 (the finest) is unused. The same as a 2-level network of those weights on 12x12.
    let net = SpyNet::<f32>::random(3, 21).with_depth(PyramidDepth::HalveWhileAbove(6));
    let coarse = SpyNet {
        levels: net.levels[..2].to_vec(),
        depth: PyramidDepth::AllLevels,
    };
    let (h, w) = (12, 12);
    let (img1, img2) = pair(h, w);
    assert_eq!(net.levels_run(h, w), 2);
    let tape = net.forward(&img1, &img2, h, w).expect("forward");
    let expected = coarse.forward(&img1, &img2, h, w).expect("forward");
    assert_eq!(tape.level_sizes, vec![(6, 6), (12, 12)]);
    assert_eq!(tape.flow, expected.flow);
    assert!(tape.level_flow(2).is_none(), "the finest level did not run");
    // Backward: the same input gradients, and no gradient for the unused weights.
    let g: Vec<f32> = (0..2 * h * w)
        .map(|i| ((i % 7) as f32 - 3.0) / 3.0)
        .collect();
    let mut grads = net.zeros_like();
    let (d1, d2) = net.backward(&tape, &g, Some(&mut grads)).expect("backward");
    let mut coarse_grads = coarse.zeros_like();
    let (e1, e2) = coarse
        .backward(&expected, &g, Some(&mut coarse_grads))
        .expect("backward");
    assert_eq!((d1, d2), (e1, e2));
    assert_eq!(grads.levels[..2], coarse_grads.levels[..]);
    assert!(grads.levels[2]
        .iter()
        .all(|c| c.weight.iter().chain(&c.bias).all(|&v| v == 0.0)));
    assert!(grads.levels[1][0].weight.iter().any(|&v| v != 0.0));
    // All levels on the same input differ: the rule takes effect.
    let all = net.clone().with_depth(PyramidDepth::AllLevels);
    assert_ne!(
        all.forward(&img1, &img2, h, w).expect("forward").flow,
        tape.flow
    );
}

#[test]
fn the_rule_is_recorded_in_the_weights_file() {
    let net = SpyNet::<f32>::random(2, 3);
    // All levels: no metadata entry, so files written before the rule existed read unchanged.
    let bytes = write_safetensors(&net).expect("write");
    assert!(!String::from_utf8_lossy(&bytes[..200]).contains(PYRAMID_KEY));
    assert_eq!(read_safetensors(&bytes).expect("read"), net);
    let reference = net.clone().with_depth(PyramidDepth::REFERENCE);
    let bytes = write_safetensors(&reference).expect("write");
    assert_eq!(read_safetensors(&bytes).expect("read"), reference);
    // An unknown value is refused by key and value.
    let (from, to) = (b"halve-while-above:32", b"halve-while-above:x0");
    let at = bytes
        .windows(from.len())
        .position(|w| w == from)
        .expect("entry");
    let mut bad = bytes.clone();
    bad[at..at + to.len()].copy_from_slice(to);
    match read_safetensors(&bad) {
        Err(FlowError::Metadata { key, value, .. }) => {
            assert_eq!(
                (key.as_str(), value.as_str()),
                (PYRAMID_KEY, "halve-while-above:x0")
            );
        }
        other => panic!("expected a metadata error, got {other:?}"),
    }
}

#[test]
fn the_shipped_weights_run_all_their_levels() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../data-fixtures/flow/spynet-synthetic.safetensors");
    let net = flow::load_safetensors(&path).expect("shipped weights");
    assert_eq!(net.depth, PyramidDepth::AllLevels);
    assert_eq!(net.levels_run(64, 64), 4);
}
