//! Training experiment: `flow_experiment [key=value ...]` trains every level in turn and prints the
//! training EPE, the live-ReLU fractions and the held-out EPE ratio every `every` steps.
//! Keys (defaults): size=16 levels=1 steps=300 batch=8 lr=1e-3 opt=adam|sgd mom=0.9 warmup=0 mse=0
//! maxt=0.06 layers=0 rot=0 scale=0 cyc=0.25 ss=3 jit=1 every=100 evaln=20 ogain=0 seed=1 out=PATH;
//! `flow_experiment check` runs the data check.
#![allow(clippy::unwrap_used, missing_docs)]
use flow::synthetic::PairConfig;
use flow::train::{evaluate, Optimizer, TrainConfig, Trainer};
use std::collections::HashMap;

fn main() {
    let a: Vec<String> = std::env::args().collect();
    if a.get(1).map(String::as_str) == Some("check") {
        check_data();
        return;
    }
    if a.get(1).map(String::as_str) == Some("rep") {
        // rep WEIGHTS LEVELS SIZE: level 0 of WEIGHTS copied into every level, held-out ratio on the
        // full generator with and without brightness jitter.
        let src = flow::load_safetensors(std::path::Path::new(&a[2])).unwrap();
        let levels: usize = a[3].parse().unwrap();
        let size: usize = a[4].parse().unwrap();
        let net = flow::train::replicate_level(&src, 0, levels);
        for jit in [1.0, 0.0] {
            let pairs = PairConfig {
                size,
                brightness_jitter: jit,
                ..PairConfig::default()
            };
            let (e, z) = evaluate(&net, 1_000_003, 20, &pairs).unwrap();
            println!(
                "rep {levels} levels {size}px jit {jit}: held-out {e:.4} zero {z:.4} ratio {:.3}",
                e / z
            );
        }
        return;
    }
    if a.get(1).map(String::as_str) == Some("lk") {
        lk_oracle(
            a[2].parse().unwrap(),
            a[3].parse().unwrap(),
            a[4].parse().unwrap(),
            a[5].parse().unwrap(),
        );
        return;
    }
    let kv: HashMap<String, String> = a[1..]
        .iter()
        .filter_map(|s| {
            s.split_once('=')
                .map(|(k, v)| (k.to_string(), v.to_string()))
        })
        .collect();
    let g = |k: &str, d: &str| kv.get(k).cloned().unwrap_or(d.into());
    let f = |k: &str, d: &str| g(k, d).parse::<f64>().unwrap();
    let u = |k: &str, d: &str| g(k, d).parse::<usize>().unwrap();
    let size = u("size", "16");
    let levels = u("levels", "1");
    let steps = u("steps", "300");
    let every = u("every", "100");
    let pairs = PairConfig {
        size,
        max_translation: f("maxt", "0.06") as f32,
        max_rotation: f("rot", "0") as f32,
        max_scale: f("scale", "0") as f32,
        max_foreground_layers: u("layers", "0"),
        max_cycles_per_pixel: f("cyc", "0.25") as f32,
        supersampling: u("ss", "3"),
        brightness_jitter: f("jit", "1") as f32,
        static_background: f("static", "0") as f32,
    };
    let optimizer = match g("opt", "adam").as_str() {
        "sgd" => Optimizer::Sgd {
            momentum: f("mom", "0.9"),
        },
        _ => Optimizer::Adam,
    };
    let mse = g("mse", "0");
    let mut t = Trainer::new(TrainConfig {
        levels,
        pairs,
        batch: u("batch", "8"),
        lr: f("lr", "1e-3"),
        optimizer,
        warmup_steps: u("warmup", "0"),
        mse_steps: if mse == "all" {
            usize::MAX
        } else {
            mse.parse().unwrap()
        },
        output_init_gain: f("ogain", "0"),
        paired_input_init: u("paired", "1") == 1,
        seed: u("seed", "1") as u64,
        distinct_pairs: None,
        decay_steps: 0,
        extra_pairs: None,
    });
    let evaln = u("evaln", "20") as u64;
    println!("{kv:?}");
    let start = std::time::Instant::now();
    for level in 0..levels {
        let (mut acc, mut accl, mut cnt) = (0.0, 0.0, 0);
        for s in 0..steps {
            let r = t.step_report(level).unwrap();
            acc += r.epe;
            accl += r.loss;
            cnt += 1;
            if (s + 1) % every == 0 || s + 1 == steps {
                let live: Vec<String> = r.live_relu.iter().map(|v| format!("{v:.2}")).collect();
                let mut line = format!(
                    "level {level} step {} train epe {:.4} loss {:.4} live [{}] ({:.0} s)",
                    s + 1,
                    acc / cnt as f64,
                    accl / cnt as f64,
                    live.join(" "),
                    start.elapsed().as_secs_f64()
                );
                if level + 1 == levels {
                    let (e, z) = evaluate(&t.net, 999, evaln, &pairs).unwrap();
                    line += &format!(" held-out {e:.4} zero {z:.4} ratio {:.3}", e / z);
                }
                println!("{line}");
                if let Some(out) = kv.get("out") {
                    let path = format!("{out}.level{level}.safetensors");
                    flow::save_safetensors(&t.net, std::path::Path::new(&path)).unwrap();
                }
                (acc, accl, cnt) = (0.0, 0.0, 0);
            }
        }
        if let Some(out) = kv.get("out") {
            flow::save_safetensors(
                &t.net,
                std::path::Path::new(&format!("{out}.level{level}.safetensors")),
            )
            .unwrap();
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
            ..PairConfig::original(size)
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

/// Global Lucas–Kanade translation estimate on pure-translation pairs: an upper bound on what the
/// data say about the flow at this size (`lk SIZE CYC SS`).
pub fn lk_oracle(size: usize, cyc: f32, ss: usize, jit: f32) {
    let cfg = PairConfig {
        max_translation: 0.06,
        max_rotation: 0.0,
        max_scale: 0.0,
        max_foreground_layers: 0,
        max_cycles_per_pixel: cyc,
        supersampling: ss,
        brightness_jitter: jit,
        ..PairConfig::original(size)
    };
    let (mut e, mut z) = (0.0, 0.0);
    let n = size;
    for k in 0..50 {
        let p = flow::synthetic::generate_pair(999, k, &cfg);
        let g = |img: &[f32], y: usize, x: usize| {
            (0..3).map(|c| img[c * n * n + y * n + x]).sum::<f32>() as f64
        };
        let (mut a, mut b, mut c, mut d, mut f) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for y in 1..n - 1 {
            for x in 1..n - 1 {
                let m = |y: usize, x: usize| 0.5 * (g(&p.img1, y, x) + g(&p.img2, y, x));
                let ix = 0.5 * (m(y, x + 1) - m(y, x - 1));
                let iy = 0.5 * (m(y + 1, x) - m(y - 1, x));
                let it = g(&p.img2, y, x) - g(&p.img1, y, x);
                a += ix * ix;
                b += ix * iy;
                c += iy * iy;
                d += ix * it;
                f += iy * it;
            }
        }
        let det = a * c - b * b + 1e-9;
        let u = -(c * d - b * f) / det;
        let v = -(a * f - b * d) / det;
        let (tu, tv) = (p.flow[0] as f64, p.flow[n * n] as f64);
        e += ((u - tu).powi(2) + (v - tv).powi(2)).sqrt();
        z += (tu * tu + tv * tv).sqrt();
    }
    println!(
        "LK size {size} cyc {cyc} ss {ss} jit {jit}: epe {:.4} zero {:.4} ratio {:.3}",
        e / 50.0,
        z / 50.0,
        e / z
    );
}
