//! Training experiment: `flow_experiment SIZE LEVELS STEPS BATCH LR MAX_T LAYERS [ROT SCALE]`,
//! trains every level in turn for STEPS steps and prints held-out EPE ratios.
#![allow(clippy::unwrap_used, missing_docs)]
use flow::synthetic::PairConfig;
use flow::train::{evaluate, TrainConfig, Trainer};

fn main() {
    let a: Vec<String> = std::env::args().collect();
    if a.get(1).map(String::as_str) == Some("check") {
        check_data();
        return;
    }
    let p = |i: usize, d: &str| a.get(i).cloned().unwrap_or(d.into());
    let size: usize = p(1, "16").parse().unwrap();
    let levels: usize = p(2, "1").parse().unwrap();
    let steps: usize = p(3, "300").parse().unwrap();
    let batch: usize = p(4, "8").parse().unwrap();
    let lr: f64 = p(5, "1e-4").parse().unwrap();
    let max_t: f32 = p(6, "0.06").parse().unwrap();
    let layers: usize = p(7, "0").parse().unwrap();
    let rot: f32 = p(8, "0").parse().unwrap();
    let scale: f32 = p(9, "0").parse().unwrap();
    let pairs = PairConfig {
        size,
        max_translation: max_t,
        max_rotation: rot,
        max_scale: scale,
        max_foreground_layers: layers,
    };
    let mut t = Trainer::new(TrainConfig {
        levels,
        pairs,
        batch,
        lr,
        seed: 1,
        distinct_pairs: None,
    });
    let start = std::time::Instant::now();
    for level in 0..levels {
        let mut acc = 0.0;
        for s in 0..steps {
            acc += t.step(level).unwrap();
            if (s + 1) % 50 == 0 {
                println!(
                    "level {level} step {} train epe {:.4} ({:.0} s)",
                    s + 1,
                    acc / 50.0,
                    start.elapsed().as_secs_f64()
                );
                acc = 0.0;
            }
        }
        if level + 1 == levels {
            let (e, z) = evaluate(&t.net, 999, 20, &pairs).unwrap();
            println!("held-out epe {e:.4} zero {z:.4} ratio {:.3}", e / z);
        }
    }
}

#[allow(dead_code)]
pub fn check_data() {
    for (size, layers) in [(16usize, 0usize), (64, 0), (64, 3)] {
        let cfg = PairConfig {
            size,
            max_foreground_layers: layers,
            max_rotation: if layers == 0 { 0.0 } else { 0.15 },
            max_scale: if layers == 0 { 0.0 } else { 0.1 },
            max_translation: 0.06,
        };
        let (mut e_w, mut e_0) = (0.0, 0.0);
        for k in 0..10 {
            let p = flow::synthetic::generate_pair(7, k, &cfg);
            let mut w = vec![0.0f32; p.img1.len()];
            nn::warp_forward(1, 3, size, size, &p.img2, &p.flow, &mut w).unwrap();
            let m = 4; // ignore borders
            for c in 0..3 {
                for y in m..size - m {
                    for x in m..size - m {
                        let i = c * size * size + y * size + x;
                        e_w += (p.img1[i] - w[i]).abs() as f64;
                        e_0 += (p.img1[i] - p.img2[i]).abs() as f64;
                    }
                }
            }
        }
        println!("size {size} layers {layers}: warped err {e_w:.1} vs unwarped {e_0:.1}");
    }
}
