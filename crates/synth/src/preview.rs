//! The contact sheet `preview.png`: one row per chosen frame, columns blurred | sharp | mask |
//! ground-truth flow (Middlebury colours, black = invalid) | events of `[t_k, t_{k+1})` (red =
//! positive, blue = negative), 8-bit sRGB, with a header naming the columns. Small images are
//! enlarged by an integer factor (nearest neighbour) so tiles are at least ~192 pixels.

use std::path::Path;

use crate::error::{Result, SynthError};
use crate::generate::PreviewRow;

const GAP: usize = 4;

/// 5×7 glyphs of the header letters (rows top to bottom, bit 4 = leftmost column).
fn glyph(c: char) -> [u8; 7] {
    match c {
        'A' => [0x0E, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11],
        'B' => [0x1E, 0x11, 0x11, 0x1E, 0x11, 0x11, 0x1E],
        'D' => [0x1E, 0x11, 0x11, 0x11, 0x11, 0x11, 0x1E],
        'E' => [0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x1F],
        'F' => [0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x10],
        'G' => [0x0E, 0x11, 0x10, 0x17, 0x11, 0x11, 0x0F],
        'H' => [0x11, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11],
        'K' => [0x11, 0x12, 0x14, 0x18, 0x14, 0x12, 0x11],
        'L' => [0x10, 0x10, 0x10, 0x10, 0x10, 0x10, 0x1F],
        'M' => [0x11, 0x1B, 0x15, 0x15, 0x11, 0x11, 0x11],
        'N' => [0x11, 0x19, 0x15, 0x13, 0x11, 0x11, 0x11],
        'O' => [0x0E, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E],
        'P' => [0x1E, 0x11, 0x11, 0x1E, 0x10, 0x10, 0x10],
        'R' => [0x1E, 0x11, 0x11, 0x1E, 0x14, 0x12, 0x11],
        'S' => [0x0F, 0x10, 0x10, 0x0E, 0x01, 0x01, 0x1E],
        'T' => [0x1F, 0x04, 0x04, 0x04, 0x04, 0x04, 0x04],
        'U' => [0x11, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E],
        'V' => [0x11, 0x11, 0x11, 0x11, 0x11, 0x0A, 0x04],
        'W' => [0x11, 0x11, 0x11, 0x15, 0x15, 0x15, 0x0A],
        _ => [0; 7],
    }
}

struct Canvas {
    w: usize,
    h: usize,
    px: Vec<u8>,
}

impl Canvas {
    fn set(&mut self, x: usize, y: usize, c: [u8; 3]) {
        if x < self.w && y < self.h {
            let i = 3 * (y * self.w + x);
            self.px[i..i + 3].copy_from_slice(&c);
        }
    }

    fn text(&mut self, x0: usize, y0: usize, s: &str, scale: usize) {
        for (k, ch) in s.chars().enumerate() {
            let g = glyph(ch);
            for (r, bits) in g.iter().enumerate() {
                for c in 0..5 {
                    if bits & (0x10 >> c) != 0 {
                        for dy in 0..scale {
                            for dx in 0..scale {
                                self.set(
                                    x0 + (6 * k + c) * scale + dx,
                                    y0 + r * scale + dy,
                                    [20, 20, 20],
                                );
                            }
                        }
                    }
                }
            }
        }
    }

    /// Draws a `w × h` tile of interleaved RGB8, enlarged by `s`.
    fn tile(&mut self, x0: usize, y0: usize, w: usize, h: usize, s: usize, rgb: &[u8]) {
        for y in 0..h * s {
            for x in 0..w * s {
                let i = 3 * ((y / s) * w + x / s);
                self.set(x0 + x, y0 + y, [rgb[i], rgb[i + 1], rgb[i + 2]]);
            }
        }
    }
}

/// Writes the contact sheet for `rows` of `w × h` frames.
pub(crate) fn write(path: &Path, rows: &[PreviewRow], w: usize, h: usize) -> Result<()> {
    let n = w * h;
    let s = (192 / w.max(h)).max(1);
    let (tw, th) = (w * s, h * s);
    let font = if tw >= 160 { 2 } else { 1 };
    let header = 7 * font + 2 * GAP;
    let cols = 5;
    let mut cv = Canvas {
        w: cols * tw + (cols + 1) * GAP,
        h: header + rows.len() * (th + GAP) + GAP,
        px: Vec::new(),
    };
    cv.px = vec![255; 3 * cv.w * cv.h];
    for (c, label) in ["BLURRED", "SHARP", "MASK", "GT FLOW", "EVENTS"]
        .iter()
        .enumerate()
    {
        cv.text(GAP + c * (tw + GAP), GAP, label, font);
    }
    // Colour scale: the 98th percentile of the valid moving pixels' flow magnitude (at least 1 px).
    let mut mags: Vec<f32> = rows
        .iter()
        .flat_map(|r| {
            (0..n)
                .filter(|&i| r.valid.get(i).copied().unwrap_or(false))
                .map(|i| r.flow[i].hypot(r.flow[n + i]))
                .filter(|m| *m > 0.1)
        })
        .collect();
    mags.sort_by(f32::total_cmp);
    let max_r = mags
        .get((mags.len() * 98) / 100)
        .copied()
        .unwrap_or(1.0)
        .max(1.0);
    for (k, r) in rows.iter().enumerate() {
        let y0 = header + k * (th + GAP);
        let x = |c: usize| GAP + c * (tw + GAP);
        cv.tile(
            x(0),
            y0,
            w,
            h,
            s,
            &scene::image_io::srgb8_interleaved(&r.blurred, n),
        );
        cv.tile(
            x(1),
            y0,
            w,
            h,
            s,
            &scene::image_io::srgb8_interleaved(&r.sharp, n),
        );
        let mask: Vec<u8> = r
            .mask
            .iter()
            .flat_map(|&m| if m { [255u8; 3] } else { [0u8; 3] })
            .collect();
        cv.tile(x(2), y0, w, h, s, &mask);
        let mut flow_rgb = vec![0u8; 3 * n];
        if r.flow.len() == 2 * n {
            let f = events::Flow {
                width: w,
                height: h,
                data: r.flow.clone(),
            };
            flow_rgb = events::flow_to_rgb(&f, Some(max_r));
            for i in 0..n {
                if !r.valid[i] {
                    flow_rgb[3 * i..3 * i + 3].copy_from_slice(&[0, 0, 0]);
                }
            }
        }
        cv.tile(x(3), y0, w, h, s, &flow_rgb);
        let mut ev = vec![255u8; 3 * n];
        if r.events.len() == 2 * n {
            for i in 0..n {
                let a_pos = (r.events[i] / 3.0).min(1.0);
                let a_neg = (r.events[n + i] / 3.0).min(1.0);
                let to8 = |v: f32| (255.0 * v).round() as u8;
                ev[3 * i] = to8(1.0 - a_neg);
                ev[3 * i + 1] = to8(1.0 - a_pos.max(a_neg));
                ev[3 * i + 2] = to8(1.0 - a_pos);
            }
        }
        cv.tile(x(4), y0, w, h, s, &ev);
    }
    image::save_buffer_with_format(
        path,
        &cv.px,
        cv.w as u32,
        cv.h as u32,
        image::ExtendedColorType::Rgb8,
        image::ImageFormat::Png,
    )
    .map_err(|e| SynthError::Image {
        path: path.to_path_buf(),
        message: e.to_string(),
    })
}
