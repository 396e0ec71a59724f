//! Export the two flow test sets of the flow issue as raw arrays, so that other estimators (the
//! classical baselines of `docs/scripts/classical_flow_baselines.py`) can be scored on exactly the
//! pairs and targets the project's own network is scored on.
//!
//! `export_flow_pairs OUT [BENCHMARK_DIR]` writes
//! - `OUT/heldout/NNN_{img1,img2,flow,matched}.f32`: the `train-flow` held-out set (40 pairs of the
//!   default generator, seed 1000003), 64×64;
//! - with a benchmark directory, `OUT/bench/NNN_…`: every consecutive pair with ground-truth flow,
//!   resized to 1/4 exactly as the flow loss resizes renders (`sharp1/2`, `blur1/2`, the loss's
//!   target `flow` and mask `mask`, every valid pixel `valid`), plus the full-resolution sharp
//!   frames `full1/2` and ground-truth flow `fullflow`;
//! - `OUT/pairs.json`: the sizes.
//!
//! Every `.f32` file is little-endian `f32`, planar (channel, row, column): images 3 planes in
//! `[0, 1]`, flows 2 planes (u, v) in pixels of their own resolution, masks 1 plane of 0 / 1.

use nn::resize_bilinear_forward;
use std::path::{Path, PathBuf};
use train::data::sharp_flow_pairs;

/// Seed and size of the `train-flow` held-out set (`xtask train-flow --eval-seed`, `--eval-pairs`).
const HELD_OUT_SEED: u64 = 1_000_003;
const HELD_OUT_PAIRS: u64 = 40;
/// The flow loss's default mask threshold τ, pixels at 1/4 resolution.
const TAU: f32 = 0.25;

type Error = Box<dyn std::error::Error>;

fn write_f32(dir: &Path, name: String, values: &[f32]) -> Result<(), Error> {
    let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
    let path = dir.join(name);
    std::fs::write(&path, bytes).map_err(|e| format!("{}: {e}", path.display()).into())
}

fn as_f32(mask: &[bool]) -> Vec<f32> {
    mask.iter().map(|&m| f32::from(u8::from(m))).collect()
}

fn main() -> Result<(), Error> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let out = PathBuf::from(
        args.first()
            .ok_or("usage: export_flow_pairs OUT [BENCHMARK_DIR]")?,
    );
    let cfg = flow::synthetic::PairConfig::default();
    let held_out = out.join("heldout");
    std::fs::create_dir_all(&held_out)?;
    for k in 0..HELD_OUT_PAIRS {
        let p = flow::synthetic::generate_pair(HELD_OUT_SEED, k, &cfg);
        let matched = flow::synthetic::matched_pixels(HELD_OUT_SEED, k, &cfg);
        write_f32(&held_out, format!("{k:03}_img1.f32"), &p.img1)?;
        write_f32(&held_out, format!("{k:03}_img2.f32"), &p.img2)?;
        write_f32(&held_out, format!("{k:03}_flow.f32"), &p.flow)?;
        write_f32(&held_out, format!("{k:03}_matched.f32"), &as_f32(&matched))?;
    }
    let mut sizes = serde_json::json!({ "heldout": { "pairs": HELD_OUT_PAIRS, "size": cfg.size } });
    if let Some(dir) = args.get(1).map(PathBuf::from) {
        let bench = out.join("bench");
        std::fs::create_dir_all(&bench)?;
        let data = train::data::load_dataset(&dir)?;
        let (w, h) = (data.camera.width as usize, data.camera.height as usize);
        let (wo, ho) = (w / 4, h / 4);
        let mut n = 0usize;
        for pair in sharp_flow_pairs(&data, (ho, wo), TAU)? {
            let (a, b) = pair.frames;
            let (sharp_a, sharp_b) = pair.sharp;
            let target = &pair.target;
            for (tag, img_a, img_b) in [("sharp", sharp_a, sharp_b), ("blur", &a.image, &b.image)] {
                for (j, img) in [img_a, img_b].into_iter().enumerate() {
                    let mut small = vec![0.0f32; 3 * ho * wo];
                    resize_bilinear_forward(3, h, w, img, ho, wo, true, &mut small)?;
                    write_f32(&bench, format!("{n:03}_{tag}{}.f32", j + 1), &small)?;
                }
            }
            write_f32(&bench, format!("{n:03}_full1.f32"), sharp_a)?;
            write_f32(&bench, format!("{n:03}_full2.f32"), sharp_b)?;
            write_f32(&bench, format!("{n:03}_fullflow.f32"), &pair.flow)?;
            write_f32(&bench, format!("{n:03}_flow.f32"), &target.flow)?;
            write_f32(&bench, format!("{n:03}_mask.f32"), &as_f32(&target.mask))?;
            write_f32(&bench, format!("{n:03}_valid.f32"), &as_f32(&pair.all.mask))?;
            n += 1;
        }
        sizes["bench"] = serde_json::json!({
            "pairs": n, "height": ho, "width": wo, "full_height": h, "full_width": w, "tau": TAU
        });
    }
    let index = out.join("pairs.json");
    std::fs::write(&index, serde_json::to_string_pretty(&sizes)?)
        .map_err(|e| format!("{}: {e}", index.display()))?;
    println!("{}", serde_json::to_string(&sizes)?);
    Ok(())
}
