//! Pictures of what a run was supervised with, for its report: the events of one test frame over
//! its frame interval (`eval/events_NNNNNN.png`) and the flow field of one training frame
//! (`eval/flow_NNNNNN.png`, Middlebury colours), written only when the run used them.

use anyhow::{Context, Result};
use std::path::{Path, PathBuf};

/// Draws the events of the first test frame that has an `events` file over a dimmed grey copy of
/// its observed image: red where the summed polarity is positive, blue where negative, full colour
/// at the 99th percentile of |sum|. Returns the picture's path, or `None` when no test frame has
/// events.
pub fn write_event_picture(data: &train::data::Dataset, out: &Path) -> Result<Option<PathBuf>> {
    let Some(p) = data
        .scene
        .frames
        .iter()
        .position(|f| f.split == scene::Split::Test && f.events.is_some())
    else {
        return Ok(None);
    };
    let frame = &data.scene.frames[p];
    let Some(rel) = &frame.events else {
        return Ok(None);
    };
    let path = scene::Scene::resolve(&data.dir, rel);
    let stream = events::io::read_events_with(&path, &train::data::event_read_options(data, &path))
        .with_context(|| format!("reading {}", path.display()))?;
    let (w, h) = (data.camera.width as usize, data.camera.height as usize);
    let mut sum = vec![0i32; w * h];
    for k in 0..stream.t.len() {
        let (x, y) = (usize::from(stream.x[k]), usize::from(stream.y[k]));
        if x < w && y < h {
            sum[y * w + x] += i32::from(stream.p[k]);
        }
    }
    let mut magnitudes: Vec<i32> = sum.iter().map(|s| s.abs()).filter(|&s| s > 0).collect();
    magnitudes.sort_unstable();
    let full = magnitudes
        .get(magnitudes.len() * 99 / 100)
        .copied()
        .unwrap_or(1)
        .max(1) as f32;
    let image = &data.frames[p].image;
    let n = w * h;
    let mut rgb = vec![0u8; 3 * n];
    for i in 0..n {
        let grey = scene::image_io::srgb_from_linear(
            0.299 * image[i] + 0.587 * image[n + i] + 0.114 * image[2 * n + i],
        ) * 0.35;
        let a = (sum[i].abs() as f32 / full).min(1.0);
        let colour = if sum[i] > 0 {
            [1.0, 0.15, 0.1]
        } else {
            [0.15, 0.35, 1.0]
        };
        for c in 0..3 {
            let v = grey * (1.0 - a) + colour[c] * a;
            rgb[3 * i + c] = (v * 255.0).round().clamp(0.0, 255.0) as u8;
        }
    }
    let dir = out.join("eval");
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let png = dir.join(format!("events_{:06}.png", frame.index));
    image::save_buffer(
        &png,
        &rgb,
        w as u32,
        h as u32,
        image::ExtendedColorType::Rgb8,
    )
    .with_context(|| format!("writing {}", png.display()))?;
    Ok(Some(png))
}

/// Draws the flow field of `kind` of the first frame that has one (Middlebury colours). Returns
/// the picture's path, or `None` when no frame has flow of that kind.
pub fn write_flow_picture(
    data: &train::data::Dataset,
    kind: scene::FlowKind,
    out: &Path,
) -> Result<Option<PathBuf>> {
    let Some((frame, flow_ref)) = data
        .scene
        .frames
        .iter()
        .find_map(|f| f.flow(kind).map(|r| (f, r)))
    else {
        return Ok(None);
    };
    let path = scene::Scene::resolve(&data.dir, &flow_ref.path);
    let flow =
        events::flowio::read_flow(&path).with_context(|| format!("reading {}", path.display()))?;
    let dir = out.join("eval");
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let png = dir.join(format!("flow_{:06}.png", frame.index));
    events::flowio::write_flow_colour_png(&png, &flow, None)
        .with_context(|| format!("writing {}", png.display()))?;
    Ok(Some(png))
}
