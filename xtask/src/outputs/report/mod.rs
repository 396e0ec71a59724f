//! `report.html`: one page a person reads in a browser, written beside `metrics.json` by
//! `reconstruct`, `eval` and `ablate`.
//!
//! The page is self-contained apart from images, which it references relatively (so the folder can be
//! moved or served as is): the summary table (render and blurred input, each against the sharp
//! reference: PSNR, SSIM, LPIPS, full frame and human box, mask IoU), the training curves
//! (`curves.svg`, from `log.jsonl`), PSNR per test frame (`per_frame.svg`), the comparison strips
//! (`eval/strip_*.png`, whose last panel is the learned human probability, i.e. the semantic mask)
//! and any event or flow pictures the run wrote (`eval/events_*.png`, `eval/flow_*.png`). Plots are
//! SVG drawn with `plotters`. The page is a pure function of the folder's files, so it can be
//! rewritten at any time (`write_run_report`).

use anyhow::{anyhow, Context, Result};
use plotters::prelude::*;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

mod tables;
use tables::summary_table;

/// Escapes text for HTML.
fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

const STYLE: &str =
    "body{font-family:system-ui,sans-serif;margin:24px;max-width:1200px;color:#222}\
table{border-collapse:collapse;margin:8px 0 16px}td,th{border:1px solid #ccc;padding:4px 10px;\
text-align:right}th{background:#f3f3f3}td:first-child,th:first-child{text-align:left}\
img{max-width:100%;image-rendering:pixelated}figure{margin:12px 0}figcaption{color:#555;\
font-size:90%}code{background:#f3f3f3;padding:0 3px}.note{color:#555;font-size:90%}";

fn page(title: &str, body: &str) -> String {
    format!(
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<title>{t}</title>\n\
         <style>{STYLE}</style>\n</head>\n<body>\n<h1>{t}</h1>\n{body}</body>\n</html>\n",
        t = esc(title)
    )
}

fn number(v: &serde_json::Value, key: &str) -> Option<f64> {
    v.get(key)
        .and_then(serde_json::Value::as_f64)
        .filter(|x| x.is_finite())
}

fn cell(v: Option<f64>, digits: usize) -> String {
    v.map_or_else(|| "—".to_string(), |x| format!("{x:.digits$}"))
}

/// A generator setting as a reader wants it: a number stored from an `f32` (2.5999999046325684)
/// is written as the `f32` it was (2.6); strings without quotes.
fn setting_text(v: &serde_json::Value) -> String {
    match v {
        serde_json::Value::Number(n) if n.is_f64() => {
            let x = n.as_f64().unwrap_or(f64::NAN);
            let narrow = x as f32;
            // A few f64 ulps of slack: some writers print the f32's value to 17 digits, which
            // parses back one ulp away from it.
            if (f64::from(narrow) - x).abs() <= 4.0 * f64::EPSILON * x.abs() {
                format!("{narrow}")
            } else {
                format!("{x}")
            }
        }
        serde_json::Value::String(s) => s.clone(),
        other => other.to_string(),
    }
}

/// `(step, value)` series of `log.jsonl` field `key`, averaged into at most `buckets` buckets.
fn bucketed(rows: &[serde_json::Value], key: &str, buckets: usize) -> Vec<(f64, f64)> {
    let points: Vec<(f64, f64)> = rows
        .iter()
        .filter_map(|r| Some((number(r, "step")?, number(r, key)?)))
        .collect();
    let per = points.len().div_ceil(buckets.max(1)).max(1);
    points
        .chunks(per)
        .map(|c| {
            let n = c.len() as f64;
            (
                c.iter().map(|p| p.0).sum::<f64>() / n,
                c.iter().map(|p| p.1).sum::<f64>() / n,
            )
        })
        .collect()
}

fn plot_err(e: impl std::fmt::Display) -> anyhow::Error {
    anyhow!("drawing a plot: {e}")
}

const SERIES_COLOURS: [RGBColor; 6] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
];

/// One line chart into `area`: `series` as `(name, points)`, a log y axis when `log`.
fn line_chart<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    title: &str,
    x_desc: &str,
    series: &[(&str, Vec<(f64, f64)>)],
    log: bool,
) -> Result<()> {
    let all = series.iter().flat_map(|(_, p)| p.iter());
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for &(x, y) in all {
        if log && y <= 0.0 {
            continue;
        }
        x0 = x0.min(x);
        x1 = x1.max(x);
        y0 = y0.min(y);
        y1 = y1.max(y);
    }
    if x0 > x1 {
        return Ok(());
    }
    if x1 <= x0 {
        x1 = x0 + 1.0;
    }
    if y1 <= y0 {
        y1 = y0 + 1.0;
    }
    let mut builder = ChartBuilder::on(area);
    builder
        .caption(title, ("sans-serif", 16))
        .margin(10)
        .x_label_area_size(32)
        .y_label_area_size(56);
    let style = |k: usize| SERIES_COLOURS[k % SERIES_COLOURS.len()];
    macro_rules! draw {
        ($chart:expr) => {{
            let mut chart = $chart;
            chart
                .configure_mesh()
                .x_desc(x_desc)
                .x_label_formatter(&|x| format!("{x:.0}"))
                .light_line_style(RGBColor(235, 235, 235))
                .draw()
                .map_err(plot_err)?;
            for (k, (name, points)) in series.iter().enumerate() {
                let colour = style(k);
                let kept: Vec<(f64, f64)> = points
                    .iter()
                    .copied()
                    .filter(|&(_, y)| !log || y > 0.0)
                    .collect();
                chart
                    .draw_series(LineSeries::new(kept, colour.stroke_width(2)))
                    .map_err(plot_err)?
                    .label(*name)
                    .legend(move |(x, y)| {
                        PathElement::new(vec![(x, y), (x + 14, y)], colour.stroke_width(2))
                    });
            }
            chart
                .configure_series_labels()
                .background_style(WHITE.mix(0.85))
                .border_style(RGBColor(200, 200, 200))
                .draw()
                .map_err(plot_err)?;
        }};
    }
    if log {
        let pad = (y1 / y0).powf(0.05);
        draw!(builder
            .build_cartesian_2d(x0..x1, ((y0 / pad)..(y1 * pad)).log_scale())
            .map_err(plot_err)?);
    } else {
        let pad = 0.05 * (y1 - y0);
        draw!(builder
            .build_cartesian_2d(x0..x1, (y0 - pad)..(y1 + pad))
            .map_err(plot_err)?);
    }
    Ok(())
}

/// The loss terms plotted, in order (those that are zero throughout are left out).
const LOSS_TERMS: [(&str, &str); 6] = [
    ("loss", "total"),
    ("l1", "L1"),
    ("event", "event"),
    ("flow", "flow"),
    ("lpips", "LPIPS"),
    ("sharpness", "size / opacity priors"),
];

/// The JSON lines of the file at `path` that parse (a torn last line is skipped).
fn json_lines(path: &Path) -> Result<Vec<serde_json::Value>> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    Ok(text
        .lines()
        .filter(|l| !l.trim().is_empty())
        .filter_map(|l| serde_json::from_str(l).ok())
        .collect())
}

/// Training curves from `log.jsonl` as an SVG string (loss terms on a log scale; training PSNR,
/// and the held-out frames' PSNR when `eval_curve.jsonl` lies beside the log).
fn curves_svg(log: &Path) -> Result<String> {
    let rows = json_lines(log)?;
    let losses: Vec<(&str, Vec<(f64, f64)>)> = LOSS_TERMS
        .iter()
        .map(|&(key, name)| (name, bucketed(&rows, key, 300)))
        .filter(|(_, p)| p.iter().any(|&(_, y)| y > 0.0))
        .collect();
    let mut psnr = vec![("training frame", bucketed(&rows, "psnr", 300))];
    let curve = log.with_file_name("eval_curve.jsonl");
    if curve.exists() {
        let points = json_lines(&curve)?;
        psnr.push((
            "held-out, full frame",
            bucketed(&points, "test_psnr_full", usize::MAX),
        ));
        psnr.push((
            "held-out, human box",
            bucketed(&points, "test_psnr_human_box", usize::MAX),
        ));
    }
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (1000, 340)).into_drawing_area();
        root.fill(&WHITE).map_err(plot_err)?;
        let (left, right) = root.split_horizontally(500);
        line_chart(&left, "loss (log scale)", "step", &losses, true)?;
        line_chart(&right, "PSNR (dB)", "step", &psnr, false)?;
        root.present().map_err(plot_err)?;
    }
    Ok(svg)
}

/// PSNR per test frame (render and blurred input, full frame and human box) as an SVG string.
fn per_frame_svg(m: &serde_json::Value) -> Result<Option<String>> {
    let Some(frames) = m.get("per_frame").and_then(serde_json::Value::as_array) else {
        return Ok(None);
    };
    let series_of = |key: &str| -> Vec<(f64, f64)> {
        frames
            .iter()
            .filter_map(|f| Some((number(f, "index")?, number(f.get("metrics")?, key)?)))
            .collect()
    };
    let series = vec![
        ("render, full frame", series_of("psnr_full")),
        ("blurred input, full frame", series_of("blurred_psnr_full")),
        ("render, human box", series_of("psnr_human_box")),
        (
            "blurred input, human box",
            series_of("blurred_psnr_human_box"),
        ),
    ];
    if series.iter().all(|(_, p)| p.is_empty()) {
        return Ok(None);
    }
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (1000, 320)).into_drawing_area();
        root.fill(&WHITE).map_err(plot_err)?;
        line_chart(&root, "PSNR per test frame (dB)", "frame", &series, false)?;
        root.present().map_err(plot_err)?;
    }
    Ok(Some(svg))
}

/// PNG files of `dir/eval` whose names start with `prefix`, sorted, as paths relative to `dir`.
fn pictures(dir: &Path, prefix: &str) -> Vec<String> {
    let Ok(entries) = std::fs::read_dir(dir.join("eval")) else {
        return Vec::new();
    };
    let mut names: Vec<String> = entries
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with(prefix) && n.ends_with(".png"))
        .collect();
    names.sort();
    names.into_iter().map(|n| format!("eval/{n}")).collect()
}

/// What the run was trained on: the scene's frames, size, channels, exposure and events, and —
/// for an imported scene — the import command and its settings (`generator` in `scene.json`).
/// Empty when the scene cannot be read.
fn data_section(m: &serde_json::Value) -> String {
    let Some(dir) = m.get("data").and_then(|d| d.as_str()) else {
        return String::new();
    };
    let Ok(text) = std::fs::read_to_string(Path::new(dir).join(scene::SCENE_FILE)) else {
        return String::new();
    };
    let Ok(s) = serde_json::from_str::<serde_json::Value>(&text) else {
        return String::new();
    };
    let frames = s["frames"].as_array().map_or(0, Vec::len);
    let count = |pred: &dyn Fn(&serde_json::Value) -> bool| {
        s["frames"]
            .as_array()
            .map_or(0, |a| a.iter().filter(|f| pred(f)).count())
    };
    let own_exposure = count(&|f| f.get("exposure_s").is_some());
    let with_events = count(&|f| f.get("events").is_some());
    let with_sharp = count(&|f| f.get("sharp").is_some());
    let grey = s["images"]["channels"].as_u64() == Some(1);
    let mut rows = vec![
        ("scene".to_string(), dir.to_string()),
        (
            "frames".into(),
            format!(
                "{frames} ({}×{}, {}, {}-bit {})",
                s["camera"]["width"],
                s["camera"]["height"],
                if grey { "grey" } else { "RGB" },
                s["images"]["bit_depth"],
                s["images"]["transfer"].as_str().unwrap_or("?")
            ),
        ),
        (
            "frame rate, exposure".into(),
            format!(
                "{:.3} fps, {:.2} ms{}",
                s["fps"].as_f64().unwrap_or(f64::NAN),
                1e3 * s["exposure_s"].as_f64().unwrap_or(f64::NAN),
                if own_exposure > 0 {
                    format!(" ({own_exposure} frames with their own exposure)")
                } else {
                    String::new()
                }
            ),
        ),
        (
            "events, sharp references".into(),
            format!("{with_events} frames with events, {with_sharp} with sharp references"),
        ),
    ];
    if let Some(g) = s.get("generator") {
        rows.push((
            "made by".into(),
            g["name"].as_str().unwrap_or("(unnamed)").to_string(),
        ));
        if let Some(cfg) = g.get("config").and_then(|c| c.as_object()) {
            let settings: Vec<String> = cfg
                .iter()
                .filter(|(_, v)| !v.is_object() && !v.is_array())
                .map(|(k, v)| format!("{k} = {}", setting_text(v)))
                .collect();
            rows.push(("settings".into(), settings.join(", ")));
        }
    }
    let mut html = String::from("<h2>Data</h2>\n<table>\n");
    for (k, v) in rows {
        html += &format!("<tr><th>{}</th><td>{}</td></tr>\n", esc(&k), esc(&v));
    }
    html + "</table>\n"
}

fn figure(src: &str, caption: &str) -> String {
    format!(
        "<figure><img src=\"{}\" alt=\"{c}\"><figcaption>{c}</figcaption></figure>\n",
        esc(src),
        c = esc(caption)
    )
}

/// Writes `dir/report.html` (and its plots `curves.svg`, `per_frame.svg`) for the run whose
/// `metrics.json` is in `dir`; `title` heads the page. Returns the page's path.
pub fn write_run_report(dir: &Path, title: &str) -> Result<PathBuf> {
    let metrics_path = dir.join("metrics.json");
    let m: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(&metrics_path)
            .with_context(|| format!("reading {}", metrics_path.display()))?,
    )
    .with_context(|| format!("{}: not JSON", metrics_path.display()))?;
    let mut body = String::new();
    body += "<h2>Summary</h2>\n";
    body += &summary_table(&m);
    body += &data_section(&m);
    let log = dir.join("log.jsonl");
    if log.exists() {
        let svg = curves_svg(&log)?;
        write(&dir.join("curves.svg"), &svg)?;
        body += "<h2>Training</h2>\n";
        body += &figure(
            "curves.svg",
            "Loss terms and training PSNR against the step (means over buckets of steps).",
        );
    }
    if let Some(svg) = per_frame_svg(&m)? {
        write(&dir.join("per_frame.svg"), &svg)?;
        body += "<h2>Test frames</h2>\n";
        body += &figure(
            "per_frame.svg",
            "PSNR of every held-out test frame against its sharp reference.",
        );
    }
    let strips = pictures(dir, "strip_");
    if !strips.is_empty() {
        body += "<h2>Comparison strips</h2>\n<p class=\"note\">Each strip: blurred input | render | \
                 sharp reference | learned human probability (the semantic mask, white = human).</p>\n";
        for s in &strips {
            body += &figure(
                s,
                s.trim_start_matches("eval/strip_").trim_end_matches(".png"),
            );
        }
    }
    let events = pictures(dir, "events_");
    if !events.is_empty() {
        body += "<h2>Events</h2>\n";
        for s in &events {
            body += &figure(s, "Events during the frame's exposure, summed per pixel (red positive, blue negative).");
        }
    }
    let flows = pictures(dir, "flow_");
    if !flows.is_empty() {
        body += "<h2>Optical flow</h2>\n";
        for s in &flows {
            body += &figure(s, "Flow to the next frame (Middlebury colour wheel; hue = direction, saturation = magnitude).");
        }
    }
    let path = dir.join("report.html");
    write(&path, &page(title, &body))?;
    Ok(path)
}

/// Writes `dir/report.html` for an ablation: its table (`ablation.json`), its image grid and a link
/// to every run's own report. Returns the page's path.
pub fn write_ablation_report(
    dir: &Path,
    title: &str,
    table_markdown: &str,
    runs: &[String],
) -> Result<PathBuf> {
    let mut body = String::new();
    body += "<h2>Runs</h2>\n";
    body += &markdown_table_to_html(table_markdown);
    if dir.join("ablation_grid.png").exists() {
        body += &figure("ablation_grid.png", "The first test frame of every run, one row per run, numbered as in the table (blurred | render | sharp | human probability).");
    }
    body += "<h2>Each run</h2>\n<ul>\n";
    for run in runs {
        if dir.join(run).join("report.html").exists() {
            let _ = writeln!(
                body,
                "<li><a href=\"{r}/report.html\">{r}</a></li>",
                r = esc(run)
            );
        }
    }
    body += "</ul>\n";
    let path = dir.join("report.html");
    write(&path, &page(title, &body))?;
    Ok(path)
}

/// The first Markdown table in `md` as an HTML table (other lines become paragraphs).
fn markdown_table_to_html(md: &str) -> String {
    let mut out = String::new();
    let mut in_table = false;
    for line in md.lines() {
        let t = line.trim();
        if t.starts_with('|') {
            let cells: Vec<&str> = t.trim_matches('|').split('|').map(str::trim).collect();
            if cells
                .iter()
                .all(|c| c.chars().all(|ch| matches!(ch, '-' | ':' | ' ')))
            {
                continue;
            }
            let tag = if in_table { "td" } else { "th" };
            if !in_table {
                out += "<table>\n";
                in_table = true;
            }
            out += "<tr>";
            for c in cells {
                let _ = write!(out, "<{tag}>{}</{tag}>", esc(&c.replace('`', "")));
            }
            out += "</tr>\n";
        } else {
            if in_table {
                out += "</table>\n";
                in_table = false;
            }
            if !t.is_empty() && !t.starts_with('#') {
                let _ = writeln!(out, "<p class=\"note\">{}</p>", esc(&t.replace('`', "")));
            }
        }
    }
    if in_table {
        out += "</table>\n";
    }
    out
}

fn write(path: &Path, text: &str) -> Result<()> {
    std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))
}

/// Every `src="…"` / `href="…"` of `html` (relative references only), for checks.
#[cfg(test)]
fn referenced_files(html: &str) -> Vec<String> {
    let mut out = Vec::new();
    for attr in ["src=\"", "href=\""] {
        let mut rest = html;
        while let Some(i) = rest.find(attr) {
            rest = &rest[i + attr.len()..];
            if let Some(end) = rest.find('"') {
                let r = rest[..end].replace("&amp;", "&");
                if !r.contains("://") && !r.starts_with('#') {
                    out.push(r);
                }
                rest = &rest[end..];
            }
        }
    }
    out
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    fn fake_run(dir: &Path) {
        let metrics = serde_json::json!({
            "test_frames": 2, "test_psnr_full": 33.4, "test_psnr_human_box": 28.9,
            "test_ssim_full": 0.97, "test_ssim_human_box": 0.93, "test_lpips_full": 0.06,
            "test_lpips_human_box": 0.12, "blurred_psnr_full": 29.3, "blurred_psnr_human_box": 24.7,
            "blurred_lpips_full": 0.1, "blurred_lpips_human_box": 0.25, "mask_iou": 0.97,
            "gap_to_blurred_full_db": 4.1, "gap_to_blurred_human_box_db": 4.2, "steps": 3,
            "train_seconds": 12.0, "gaussians_human": 10, "gaussians_scene": 20,
            "blur_model": "exposure", "data": "a<b",
            "per_frame": [
                {"index": 3, "metrics": {"psnr_full": 33.0, "blurred_psnr_full": 29.0, "psnr_human_box": 28.0, "blurred_psnr_human_box": 24.0}},
                {"index": 7, "metrics": {"psnr_full": 34.0, "blurred_psnr_full": 29.5, "psnr_human_box": 29.0, "blurred_psnr_human_box": 25.0}}
            ]
        });
        std::fs::write(dir.join("metrics.json"), metrics.to_string()).unwrap();
        let log: String = (0..50)
            .map(|s| {
                format!(
                    "{{\"step\":{s},\"loss\":{},\"l1\":0.1,\"event\":0.0,\"psnr\":{}}}\n",
                    1.0 / (s as f64 + 1.0),
                    20.0 + s as f64 * 0.1
                )
            })
            .collect();
        std::fs::write(dir.join("log.jsonl"), log).unwrap();
        std::fs::create_dir_all(dir.join("eval")).unwrap();
        for name in ["strip_000003.png", "strip_000007.png", "events_000003.png"] {
            image::RgbImage::new(4, 2)
                .save(dir.join("eval").join(name))
                .unwrap();
        }
    }

    #[test]
    fn the_run_report_has_its_sections_and_every_reference_exists() {
        let dir = tempfile::tempdir().unwrap();
        fake_run(dir.path());
        std::fs::write(
            dir.path().join("eval_curve.jsonl"),
            "{\"step\":2,\"test_psnr_full\":30.0,\"test_psnr_human_box\":25.0}\n\
             {\"step\":4,\"test_psnr_full\":31.0,\"test_psnr_human_box\":26.0}\n",
        )
        .unwrap();
        let path = write_run_report(dir.path(), "run <1>").unwrap();
        let html = std::fs::read_to_string(&path).unwrap();
        for needle in [
            "<h1>run &lt;1&gt;</h1>",
            "33.40",
            "28.90",
            "+4.20",
            "0.1200",
            "0.970",
            "a&lt;b",
            "Comparison strips",
            "<h2>Events</h2>",
            "curves.svg",
            "per_frame.svg",
        ] {
            assert!(html.contains(needle), "missing {needle}");
        }
        assert!(
            !html.contains("Optical flow"),
            "no flow pictures were written"
        );
        let refs = referenced_files(&html);
        assert!(refs.len() >= 5, "{refs:?}");
        for r in refs {
            assert!(dir.path().join(&r).exists(), "{r} does not exist");
        }
        let svg = std::fs::read_to_string(dir.path().join("curves.svg")).unwrap();
        assert!(
            svg.contains("<svg") && (svg.contains("<polyline") || svg.contains("<path")),
            "an SVG with lines"
        );
        assert!(
            svg.contains("total") && svg.contains("L1") && !svg.contains(">event<"),
            "zero terms are left out"
        );
        assert!(
            svg.contains("held-out, human box"),
            "the held-out curve is drawn"
        );
    }

    #[test]
    fn settings_stored_from_f32_read_as_written() {
        assert_eq!(setting_text(&serde_json::json!(2.6f32)), "2.6");
        assert_eq!(setting_text(&serde_json::json!(0.03f32)), "0.03");
        assert_eq!(
            setting_text(&serde_json::json!(0.029999999329447743)),
            "0.03"
        );
        assert_eq!(setting_text(&serde_json::json!(0.1f64)), "0.1");
        assert_eq!(setting_text(&serde_json::json!(1000)), "1000");
        assert_eq!(setting_text(&serde_json::json!("fast")), "fast");
        assert_eq!(setting_text(&serde_json::json!(true)), "true");
    }

    #[test]
    fn markdown_tables_become_html_tables() {
        let html =
            markdown_table_to_html("| run | PSNR |\n|---|---:|\n| `one-hot` | 29.2 |\nnote <x>\n");
        assert_eq!(
            html,
            "<table>\n<tr><th>run</th><th>PSNR</th></tr>\n<tr><td>one-hot</td><td>29.2</td></tr>\n</table>\n<p class=\"note\">note &lt;x&gt;</p>\n"
        );
    }
}
