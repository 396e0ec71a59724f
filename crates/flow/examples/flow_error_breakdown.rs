//! Diagnostic: where does a flow network's error on the held-out procedural set come from?
//! `flow_error_breakdown [WEIGHTS] [PAIRS] [SEED]` (defaults: the shipped weights, 40 pairs, seed
//! 1000003 — the `train-flow` held-out set, default generator) splits the end-point error of the
//! network and of zero flow by pixel kind and by true motion. The kinds are matched pixels (the
//! point is visible in both frames) and unmatched ones (it leaves the frame or is occluded; see
//! `flow::synthetic::matched_pixels`). The printout also gives what the held-out ratio would be if
//! either kind were predicted perfectly, which bounds what improving that kind alone can achieve.
//!
//! It then splits the error by pyramid level (each level's output against the truth pooled to its
//! resolution), and asks how much the finer levels depend on the coarse ones: level `k`'s output is
//! replaced by the pooled truth scaled by `1 − a` (a = 0 is a perfect level; a > 0 an estimate
//! that is right in direction but a fraction `a` short, whose level EPE ratio is `a`) and the held-out
//! ratio of the final flow is reported ([`flow::SpyNet::forward_with_level_flow`]).

use flow::synthetic::{generate_pair, matched_pixels, PairConfig};
use std::path::{Path, PathBuf};

/// Upper edges (pixels) of the true-motion bins; the last bin is open.
const MOTION_BINS: [f64; 4] = [1.0, 3.0, 6.0, 10.0];

/// Shortfalls `a` of the substituted coarse flow (level ratio `a`): 0 = the pooled truth.
const SHORTFALLS: [f32; 4] = [0.0, 0.3, 0.5, 0.7];

/// Sums of the network's and zero flow's EPE over a set of pixels, and their count.
#[derive(Clone, Copy, Default)]
struct Tally {
    net: f64,
    zero: f64,
    pixels: usize,
}

impl Tally {
    fn add(&mut self, net: f64, zero: f64) {
        self.net += net;
        self.zero += zero;
        self.pixels += 1;
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let weights = args.first().map_or_else(
        || {
            Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("../../data-fixtures/flow/spynet-synthetic.safetensors")
        },
        PathBuf::from,
    );
    let count: u64 = args.get(1).map_or(Ok(40), |s| s.parse())?;
    let seed: u64 = args.get(2).map_or(Ok(1_000_003), |s| s.parse())?;
    let net = flow::load_safetensors(&weights)?;
    let cfg = PairConfig::default();
    let (mut by_kind, mut by_motion) = ([Tally::default(); 2], [Tally::default(); 5]);
    let levels = net.levels_run(cfg.size, cfg.size);
    let mut by_level = vec![Tally::default(); levels];
    // [substituted level][shortfall] → the final flow's tally.
    let mut substituted = vec![[Tally::default(); SHORTFALLS.len()]; levels.saturating_sub(1)];
    for k in 0..count {
        let p = generate_pair(seed, k, &cfg);
        let matched = matched_pixels(seed, k, &cfg);
        let tape = net.forward(&p.img1, &p.img2, p.height, p.width)?;
        let pred = &tape.flow;
        let hw = p.height * p.width;
        let truth_at =
            |level| flow::train::flow_at_level(&p.flow, p.height, p.width, levels, level);
        for (level, tally) in by_level.iter_mut().enumerate() {
            let (Some(out), true) = (tape.level_flow(level), tape.work_size == tape.size) else {
                continue;
            };
            let scale = f64::from(1u32 << (levels - 1 - level));
            add_epe(tally, out, &truth_at(level), scale);
        }
        for (level, tallies) in substituted.iter_mut().enumerate() {
            let truth = truth_at(level);
            for (tally, &a) in tallies.iter_mut().zip(&SHORTFALLS) {
                let given: Vec<f32> = truth.iter().map(|v| v * (1.0 - a)).collect();
                let (_, out) = net
                    .forward_with_level_flow(&p.img1, &p.img2, p.height, p.width, level, &given)?;
                add_epe(tally, &out, &p.flow, 1.0);
            }
        }
        for (i, &m) in matched.iter().enumerate() {
            let (gx, gy) = (f64::from(p.flow[i]), f64::from(p.flow[hw + i]));
            let (px, py) = (f64::from(pred[i]), f64::from(pred[hw + i]));
            let net_err = (px - gx).hypot(py - gy);
            let zero_err = gx.hypot(gy);
            by_kind[usize::from(m)].add(net_err, zero_err);
            let bin = MOTION_BINS
                .iter()
                .position(|&edge| zero_err < edge)
                .unwrap_or(MOTION_BINS.len());
            by_motion[bin].add(net_err, zero_err);
        }
    }
    let total_zero = by_kind[0].zero + by_kind[1].zero;
    let total_net = by_kind[0].net + by_kind[1].net;
    let pixels = (by_kind[0].pixels + by_kind[1].pixels).max(1) as f64;
    println!(
        "{count} pairs of seed {seed}, {}: EPE net {:.3} px, zero flow {:.3} px, ratio {:.3}",
        weights.display(),
        total_net / pixels,
        total_zero / pixels,
        total_net / total_zero.max(1e-12)
    );
    let row = |name: &str, t: &Tally| {
        let n = t.pixels.max(1) as f64;
        println!(
            "{name:>16}: {:5.1} % of pixels, EPE net {:6.3} px, zero {:6.3} px, ratio {:.3}, share of the net's error {:5.1} %",
            100.0 * t.pixels as f64 / pixels,
            t.net / n,
            t.zero / n,
            t.net / t.zero.max(1e-12),
            100.0 * t.net / total_net.max(1e-12)
        );
    };
    row("matched", &by_kind[1]);
    row("unmatched", &by_kind[0]);
    println!(
        "held-out ratio with unmatched pixels perfect: {:.3}; with matched pixels perfect: {:.3}",
        by_kind[1].net / total_zero.max(1e-12),
        by_kind[0].net / total_zero.max(1e-12)
    );
    let mut lower = 0.0;
    for (bin, t) in by_motion.iter().enumerate() {
        let name = match MOTION_BINS.get(bin) {
            Some(edge) => format!("|F| {lower:.0}-{edge:.0} px"),
            None => format!("|F| >= {lower:.0} px"),
        };
        row(&name, t);
        lower = MOTION_BINS.get(bin).copied().unwrap_or(lower);
    }
    println!("per level (output against the truth pooled to the level, EPE in input pixels):");
    for (level, t) in by_level.iter().enumerate() {
        let n = t.pixels.max(1) as f64;
        println!(
            "{:>16}: EPE net {:6.3} px, zero {:6.3} px, ratio {:.3}",
            format!("level {level}"),
            t.net / n,
            t.zero / n,
            t.net / t.zero.max(1e-12)
        );
    }
    println!("held-out ratio with level k's output replaced by the pooled truth x (1 - a):");
    for (level, tallies) in substituted.iter().enumerate() {
        let ratios: Vec<String> = tallies
            .iter()
            .zip(&SHORTFALLS)
            .map(|(t, a)| format!("a {a:.1}: {:.3}", t.net / t.zero.max(1e-12)))
            .collect();
        println!("{:>16}: {}", format!("level {level}"), ratios.join(", "));
    }
    Ok(())
}

/// Adds the per-pixel EPE of `pred` against `truth` (both `(2, h, w)`) and of zero flow, times
/// `scale` (level pixels → input pixels), to `tally`.
fn add_epe(tally: &mut Tally, pred: &[f32], truth: &[f32], scale: f64) {
    let n = truth.len() / 2;
    for i in 0..n {
        let (gx, gy) = (f64::from(truth[i]), f64::from(truth[n + i]));
        let (px, py) = (f64::from(pred[i]), f64::from(pred[n + i]));
        tally.add(scale * (px - gx).hypot(py - gy), scale * gx.hypot(gy));
    }
}
