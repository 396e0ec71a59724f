//! Quick timing of forward and forward+input-gradient passes (`cargo run --release -p flow --example
//! flow_timing -- [levels] [size]`); `cargo xtask bench flow` is the recorded benchmark.

use std::time::Instant;

fn main() {
    let args: Vec<usize> = std::env::args()
        .skip(1)
        .filter_map(|a| a.parse().ok())
        .collect();
    let levels = args.first().copied().unwrap_or(4);
    let size = args.get(1).copied().unwrap_or(64);
    let net = flow::SpyNet::<f32>::random(levels, 1);
    let n = 3 * size * size;
    let a: Vec<f32> = (0..n).map(|i| ((i * 31) % 17) as f32 / 16.0).collect();
    let b: Vec<f32> = (0..n).map(|i| ((i * 37) % 19) as f32 / 18.0).collect();
    // FNV-1a over the bits of the flow and both input gradients: a build that changes any bit of the
    // results prints a different fingerprint.
    let tape = net.forward(&a, &b, size, size).expect("forward");
    let g = vec![1.0f32; tape.flow.len()];
    let (g1, g2) = net.backward(&tape, &g, None).expect("backward");
    let fingerprint = tape
        .flow
        .iter()
        .chain(&g1)
        .chain(&g2)
        .fold(0xcbf2_9ce4_8422_2325u64, |h, v| {
            (h ^ u64::from(v.to_bits())).wrapping_mul(0x0000_0100_0000_01B3)
        });
    let mut fwd = Vec::new();
    let mut both = Vec::new();
    for _ in 0..7 {
        let t = Instant::now();
        let tape = net.forward(&a, &b, size, size).expect("forward");
        fwd.push(t.elapsed().as_secs_f64() * 1e3);
        let g = vec![1.0f32; tape.flow.len()];
        let t = Instant::now();
        let tape = net.forward(&a, &b, size, size).expect("forward");
        let _ = net.backward(&tape, &g, None).expect("backward");
        both.push(t.elapsed().as_secs_f64() * 1e3);
    }
    fwd.sort_by(f64::total_cmp);
    both.sort_by(f64::total_cmp);
    println!(
        "levels {levels} size {size}: fwd {:.1} ms, fwd+bwd {:.1} ms, fingerprint {fingerprint:016x}",
        fwd[3], both[3]
    );
}
