//! The loss / PSNR training curve as a PNG (two panels: total loss — photometric plus the weighted
//! skinning and AIAP terms, so it drops where the skinning loss ends — on a log scale, training PSNR in
//! dB, both against the step), drawn directly with the `image` crate and a 3×5 pixel font for the
//! axis labels, so no plotting dependency is needed.

use anyhow::{Context, Result};
use image::{Rgb, RgbImage};
use std::io::BufRead;
use std::path::Path;

const W: u32 = 960;
const H: u32 = 360;
const PANEL_W: u32 = W / 2;
const MARGIN_L: u32 = 56;
const MARGIN_R: u32 = 14;
const MARGIN_T: u32 = 26;
const MARGIN_B: u32 = 30;

/// 3×5 glyphs, rows top to bottom, 3 bits per row (MSB left).
fn glyph(c: char) -> Option<[u8; 5]> {
    Some(match c {
        '0' => [7, 5, 5, 5, 7],
        '1' => [2, 6, 2, 2, 7],
        '2' => [7, 1, 7, 4, 7],
        '3' => [7, 1, 7, 1, 7],
        '4' => [5, 5, 7, 1, 1],
        '5' => [7, 4, 7, 1, 7],
        '6' => [7, 4, 7, 5, 7],
        '7' => [7, 1, 1, 1, 1],
        '8' => [7, 5, 7, 5, 7],
        '9' => [7, 5, 7, 1, 7],
        '.' => [0, 0, 0, 0, 2],
        '-' => [0, 0, 7, 0, 0],
        'e' => [0, 7, 7, 4, 7],
        'g' => [0, 7, 5, 7, 1],
        'l' => [6, 2, 2, 2, 7],
        'o' => [0, 7, 5, 5, 7],
        's' => [0, 7, 6, 1, 7],
        't' => [2, 7, 2, 2, 3],
        'p' => [0, 7, 5, 7, 4],
        'd' => [1, 7, 5, 5, 7],
        'B' => [6, 5, 6, 5, 6],
        'P' => [7, 5, 7, 4, 4],
        'S' => [7, 4, 7, 1, 7],
        'N' => [5, 7, 7, 7, 5],
        'R' => [6, 5, 6, 5, 5],
        '(' => [1, 2, 2, 2, 1],
        ')' => [4, 2, 2, 2, 4],
        ' ' => [0; 5],
        _ => return None,
    })
}

/// Draws `s` with the 3×5 font at twice its size (unknown characters are skipped).
pub fn text(img: &mut RgbImage, x: u32, y: u32, s: &str, colour: Rgb<u8>) {
    const SCALE: u32 = 2;
    for (k, c) in s.chars().enumerate() {
        let Some(g) = glyph(c) else { continue };
        for (row, bits) in g.iter().enumerate() {
            for col in 0..3 {
                if bits & (4 >> col) != 0 {
                    for dy in 0..SCALE {
                        for dx in 0..SCALE {
                            let px = x + (k as u32 * 4 + col) * SCALE + dx;
                            let py = y + row as u32 * SCALE + dy;
                            if px < img.width() && py < img.height() {
                                img.put_pixel(px, py, colour);
                            }
                        }
                    }
                }
            }
        }
    }
}

fn line(img: &mut RgbImage, (x0, y0): (f64, f64), (x1, y1): (f64, f64), colour: Rgb<u8>) {
    let n = ((x1 - x0).abs().max((y1 - y0).abs()).ceil() as usize).max(1);
    for i in 0..=n {
        let t = i as f64 / n as f64;
        let (x, y) = (x0 + t * (x1 - x0), y0 + t * (y1 - y0));
        if x >= 0.0 && y >= 0.0 && (x as u32) < img.width() && (y as u32) < img.height() {
            img.put_pixel(x as u32, y as u32, colour);
        }
    }
}

fn label(v: f64) -> String {
    if v.abs() >= 100.0 || v == 0.0 {
        format!("{v:.0}")
    } else if v.abs() >= 1.0 {
        format!("{v:.1}")
    } else {
        format!("{v:.3}")
    }
}

/// Draws one panel: `ys` against `xs` (raw in light colour, a moving average in dark colour).
fn panel(img: &mut RgbImage, x_off: u32, title: &str, xs: &[f64], ys: &[f64], log: bool) {
    let grey = Rgb([200, 200, 200]);
    let black = Rgb([20, 20, 20]);
    let (px0, px1) = (
        f64::from(x_off + MARGIN_L),
        f64::from(x_off + PANEL_W - MARGIN_R),
    );
    let (py0, py1) = (f64::from(MARGIN_T), f64::from(H - MARGIN_B));
    let tf = |v: f64| if log { v.max(1e-12).log10() } else { v };
    let vals: Vec<f64> = ys
        .iter()
        .map(|&v| tf(v))
        .filter(|v| v.is_finite())
        .collect();
    let (mut lo, mut hi) = vals
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    if !lo.is_finite() {
        (lo, hi) = (0.0, 1.0);
    }
    if hi - lo < 1e-9 {
        hi = lo + 1.0;
    }
    let xmax = xs.last().copied().unwrap_or(1.0).max(1.0);
    let map = |x: f64, y: f64| {
        (
            px0 + (x / xmax) * (px1 - px0),
            py1 - (tf(y) - lo) / (hi - lo) * (py1 - py0),
        )
    };
    for k in 0..=4 {
        let y = py0 + (py1 - py0) * f64::from(k) / 4.0;
        line(img, (px0, y), (px1, y), grey);
        let v = hi - (hi - lo) * f64::from(k) / 4.0;
        let v = if log { 10f64.powf(v) } else { v };
        text(img, x_off + 4, y as u32 - 4, &label(v), black);
    }
    line(img, (px0, py0), (px0, py1), black);
    line(img, (px0, py1), (px1, py1), black);
    text(img, x_off + MARGIN_L, 6, title, black);
    text(img, px1 as u32 - 40, H - 16, &label(xmax), black);
    text(img, px0 as u32, H - 16, "0", black);
    text(img, ((px0 + px1) / 2.0) as u32 - 16, H - 16, "step", black);
    let light = Rgb([150, 180, 230]);
    let dark = Rgb([20, 60, 160]);
    for i in 1..xs.len() {
        line(img, map(xs[i - 1], ys[i - 1]), map(xs[i], ys[i]), light);
    }
    let win = (xs.len() / 50).max(1);
    let smooth: Vec<f64> = (0..ys.len())
        .map(|i| {
            let a = i.saturating_sub(win);
            ys[a..=i].iter().sum::<f64>() / (i - a + 1) as f64
        })
        .collect();
    for i in 1..xs.len() {
        line(
            img,
            map(xs[i - 1], smooth[i - 1]),
            map(xs[i], smooth[i]),
            dark,
        );
    }
}

/// Reads `log.jsonl` (fields `step`, `loss`, `psnr`) and writes the two-panel curve to `png`.
pub fn write_curve(log: &Path, png: &Path) -> Result<()> {
    let file = std::fs::File::open(log).with_context(|| format!("opening {}", log.display()))?;
    let (mut xs, mut loss, mut psnr) = (Vec::new(), Vec::new(), Vec::new());
    for l in std::io::BufReader::new(file).lines() {
        let l = l.with_context(|| format!("reading {}", log.display()))?;
        let v: serde_json::Value =
            serde_json::from_str(&l).with_context(|| format!("{}: bad line", log.display()))?;
        if let (Some(s), Some(a), Some(b)) =
            (v["step"].as_f64(), v["loss"].as_f64(), v["psnr"].as_f64())
        {
            xs.push(s);
            loss.push(a);
            psnr.push(b);
        }
    }
    let mut img = RgbImage::from_pixel(W, H, Rgb([255, 255, 255]));
    panel(&mut img, 0, "loss (log)", &xs, &loss, true);
    panel(&mut img, PANEL_W, "PSNR (dB)", &xs, &psnr, false);
    img.save(png)
        .with_context(|| format!("writing {}", png.display()))
}
