//! The on-disk pixel encoding of scene images and masks, in one place so the writer (`synth`) and
//! the reader (`train`) can never disagree.
//!
//! RGB images are PNG, 8 or 16 bits per channel, with a linear or sRGB transfer function as
//! declared in `scene.json` ([`ImageEncoding`]); in memory they are planar f32 `(3, H, W)`, linear
//! intensity in [0, 1] (DESIGN.md §3). Masks are 8-bit single-channel PNG, 255 = set, 0 = unset
//! (any non-zero value reads as set). Encoding is deterministic: same pixels, same bytes.

use std::io::BufWriter;
use std::path::Path;

use image::codecs::png::{CompressionType, FilterType, PngEncoder};
use image::{DynamicImage, ExtendedColorType, ImageEncoder};

use crate::error::{Result, SceneError};
use crate::types::{ImageEncoding, Transfer};

/// A planar RGB image in memory.
#[derive(Clone, Debug, PartialEq)]
pub struct Rgb {
    /// Width (pixels).
    pub width: u32,
    /// Height (pixels).
    pub height: u32,
    /// Planar `(3, H, W)` linear intensity, nominally in [0, 1].
    pub data: Vec<f32>,
}

/// sRGB OETF: linear intensity in [0, 1] to the encoded value in [0, 1].
pub fn srgb_from_linear(x: f32) -> f32 {
    let x = x.clamp(0.0, 1.0);
    if x <= 0.003_130_8 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    }
}

/// Inverse sRGB OETF: encoded value in [0, 1] to linear intensity.
pub fn linear_from_srgb(x: f32) -> f32 {
    let x = x.clamp(0.0, 1.0);
    if x <= 0.040_45 {
        x / 12.92
    } else {
        ((x + 0.055) / 1.055).powf(2.4)
    }
}

fn img_err(path: &Path, message: impl Into<String>) -> SceneError {
    SceneError::Image {
        path: path.to_path_buf(),
        message: message.into(),
    }
}

fn write_png(path: &Path, bytes: &[u8], w: u32, h: u32, color: ExtendedColorType) -> Result<()> {
    let file = std::fs::File::create(path).map_err(|source| SceneError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let enc = PngEncoder::new_with_quality(
        BufWriter::new(file),
        CompressionType::Best,
        FilterType::Adaptive,
    );
    enc.write_image(bytes, w, h, color)
        .map_err(|e| img_err(path, e.to_string()))
}

/// Planar linear RGB `(3, n)` to interleaved 8-bit sRGB bytes (`3n`, values clamped to [0, 1]): the
/// form image encoders and viewers take.
pub fn srgb8_interleaved(planar: &[f32], n: usize) -> Vec<u8> {
    let mut out = Vec::with_capacity(3 * n);
    for i in 0..n {
        for c in 0..3 {
            out.push((srgb_from_linear(planar[c * n + i]) * 255.0).round() as u8);
        }
    }
    out
}

/// How [`undistort`] samples the recorded image.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Sampling {
    /// Bilinear (images; OpenCV's `INTER_LINEAR`).
    Bilinear,
    /// Nearest pixel (masks; OpenCV's `INTER_NEAREST`).
    Nearest,
}

/// Undistorts a planar `(channels, H, W)` image recorded by `camera` (its intrinsics, in this
/// workspace's convention: pixel `i`'s centre at `i + 0.5`) through the lens model `distortion`:
/// output pixel `(i, j)` is the recorded image sampled where the lens put the ray of pixel
/// centre `(i + 0.5, j + 0.5)`, with the same intrinsics (OpenCV's `undistort` with the camera
/// matrix as the new one). Samples outside the recorded image are 0.
pub fn undistort(
    planar: &[f32],
    channels: usize,
    camera: &pinhole::Camera,
    distortion: &pinhole::Distortion,
    sampling: Sampling,
) -> Vec<f32> {
    let (w, h) = (camera.width as usize, camera.height as usize);
    let n = w * h;
    if distortion.is_identity() {
        return planar.to_vec();
    }
    let mut out = vec![0.0f32; channels * n];
    for j in 0..h {
        for i in 0..w {
            let x = (i as f64 + 0.5 - camera.cx) / camera.fx;
            let y = (j as f64 + 0.5 - camera.cy) / camera.fy;
            let (xd, yd) = distortion.distort(x, y);
            // Source position in pixel-index coordinates (pixel k's centre at k).
            let u = xd * camera.fx + camera.cx - 0.5;
            let v = yd * camera.fy + camera.cy - 0.5;
            let p = j * w + i;
            match sampling {
                Sampling::Nearest => {
                    let (ui, vi) = (u.round(), v.round());
                    if ui >= 0.0 && vi >= 0.0 && (ui as usize) < w && (vi as usize) < h {
                        let q = vi as usize * w + ui as usize;
                        for c in 0..channels {
                            out[c * n + p] = planar[c * n + q];
                        }
                    }
                }
                Sampling::Bilinear => {
                    let (u0, v0) = (u.floor(), v.floor());
                    let (fu, fv) = ((u - u0) as f32, (v - v0) as f32);
                    let at = |uu: f64, vv: f64, c: usize| -> f32 {
                        if uu < 0.0 || vv < 0.0 || uu as usize >= w || vv as usize >= h {
                            0.0
                        } else {
                            planar[c * n + vv as usize * w + uu as usize]
                        }
                    };
                    for c in 0..channels {
                        let top = at(u0, v0, c) * (1.0 - fu) + at(u0 + 1.0, v0, c) * fu;
                        let bottom =
                            at(u0, v0 + 1.0, c) * (1.0 - fu) + at(u0 + 1.0, v0 + 1.0, c) * fu;
                        out[c * n + p] = top * (1.0 - fv) + bottom * fv;
                    }
                }
            }
        }
    }
    out
}

/// Rec. 601 luma weights `(R, G, B)`, applied to *linear* intensities: how a colour render is
/// compared with a grey frame (`images.channels = 1`).
pub const REC601_LUMA: [f32; 3] = [0.299, 0.587, 0.114];

/// Rec. 601 luminance of planar linear RGB `(3, n)`: `n` values.
pub fn luminance(planar: &[f32], n: usize) -> Vec<f32> {
    let [wr, wg, wb] = REC601_LUMA;
    (0..n)
        .map(|i| wr * planar[i] + wg * planar[n + i] + wb * planar[2 * n + i])
        .collect()
}

/// Writes a planar linear RGB image as PNG with the given encoding (values clamped to [0, 1]); with
/// `enc.channels = 1` the file holds the image's Rec. 601 luminance ([`luminance`]), one channel.
pub fn write_rgb(path: &Path, img: &Rgb, enc: ImageEncoding) -> Result<()> {
    let n = img.width as usize * img.height as usize;
    if img.data.len() != 3 * n {
        return Err(SceneError::Arg {
            name: "img".into(),
            message: format!(
                "{} values for a {}x{} RGB image",
                img.data.len(),
                img.width,
                img.height
            ),
        });
    }
    let code = |x: f32| match enc.transfer {
        Transfer::Linear => x.clamp(0.0, 1.0),
        Transfer::Srgb => srgb_from_linear(x),
    };
    if enc.is_grey() {
        let y = luminance(&img.data, n);
        return match enc.bit_depth {
            8 => {
                let bytes: Vec<u8> = y.iter().map(|&v| (code(v) * 255.0).round() as u8).collect();
                write_png(path, &bytes, img.width, img.height, ExtendedColorType::L8)
            }
            16 => {
                let bytes: Vec<u8> = y
                    .iter()
                    .flat_map(|&v| ((code(v) * 65535.0).round() as u16).to_ne_bytes())
                    .collect();
                write_png(path, &bytes, img.width, img.height, ExtendedColorType::L16)
            }
            b => Err(SceneError::Arg {
                name: "bit_depth".into(),
                message: format!("{b} is not 8 or 16"),
            }),
        };
    }
    match enc.bit_depth {
        8 => {
            let mut bytes = Vec::with_capacity(3 * n);
            for i in 0..n {
                for c in 0..3 {
                    bytes.push((code(img.data[c * n + i]) * 255.0).round() as u8);
                }
            }
            write_png(path, &bytes, img.width, img.height, ExtendedColorType::Rgb8)
        }
        16 => {
            let mut bytes = Vec::with_capacity(6 * n);
            for i in 0..n {
                for c in 0..3 {
                    let v = (code(img.data[c * n + i]) * 65535.0).round() as u16;
                    bytes.extend_from_slice(&v.to_ne_bytes());
                }
            }
            write_png(
                path,
                &bytes,
                img.width,
                img.height,
                ExtendedColorType::Rgb16,
            )
        }
        b => Err(SceneError::Arg {
            name: "bit_depth".into(),
            message: format!("{b} is not 8 or 16"),
        }),
    }
}

/// Reads a PNG written with `enc` into planar linear f32 `(3, H, W)`. The file's bit depth must
/// match `enc.bit_depth` and its channels `enc.channels`; a grey frame is returned as three equal
/// planes.
pub fn read_rgb(path: &Path, enc: ImageEncoding) -> Result<Rgb> {
    let img = image::ImageReader::open(path)
        .map_err(|source| SceneError::Io {
            path: path.to_path_buf(),
            source,
        })?
        .decode()
        .map_err(|e| img_err(path, e.to_string()))?;
    let (w, h) = (img.width(), img.height());
    let n = w as usize * h as usize;
    let decode = |x: f32| match enc.transfer {
        Transfer::Linear => x,
        Transfer::Srgb => linear_from_srgb(x),
    };
    let mut data = vec![0.0f32; 3 * n];
    match (&img, enc.bit_depth) {
        (DynamicImage::ImageRgb8(b), 8) if !enc.is_grey() => {
            for (i, p) in b.pixels().enumerate() {
                for c in 0..3 {
                    data[c * n + i] = decode(f32::from(p.0[c]) / 255.0);
                }
            }
        }
        (DynamicImage::ImageRgb16(b), 16) if !enc.is_grey() => {
            for (i, p) in b.pixels().enumerate() {
                for c in 0..3 {
                    data[c * n + i] = decode(f32::from(p.0[c]) / 65535.0);
                }
            }
        }
        (DynamicImage::ImageLuma8(b), 8) if enc.is_grey() => {
            for (i, p) in b.pixels().enumerate() {
                let v = decode(f32::from(p.0[0]) / 255.0);
                (0..3).for_each(|c| data[c * n + i] = v);
            }
        }
        (DynamicImage::ImageLuma16(b), 16) if enc.is_grey() => {
            for (i, p) in b.pixels().enumerate() {
                let v = decode(f32::from(p.0[0]) / 65535.0);
                (0..3).for_each(|c| data[c * n + i] = v);
            }
        }
        (other, bits) => {
            return Err(img_err(
                path,
                format!(
                    "pixel format {:?}, expected {bits}-bit {}",
                    other.color(),
                    if enc.is_grey() { "grey" } else { "RGB" }
                ),
            ))
        }
    }
    Ok(Rgb {
        width: w,
        height: h,
        data,
    })
}

/// Writes a binary mask (row-major, `true` = set) as an 8-bit greyscale PNG (255 / 0).
pub fn write_mask(path: &Path, width: u32, height: u32, mask: &[bool]) -> Result<()> {
    if mask.len() != width as usize * height as usize {
        return Err(SceneError::Arg {
            name: "mask".into(),
            message: format!("{} values for a {width}x{height} mask", mask.len()),
        });
    }
    let bytes: Vec<u8> = mask.iter().map(|&m| if m { 255 } else { 0 }).collect();
    write_png(path, &bytes, width, height, ExtendedColorType::L8)
}

/// Reads a single-channel mask PNG (8 or 16 bit): `(width, height, row-major set flags)`, a pixel
/// being set when its value is non-zero.
pub fn read_mask(path: &Path) -> Result<(u32, u32, Vec<bool>)> {
    let (w, h, values) = read_grey(path)?;
    Ok((w, h, values.into_iter().map(|v| v != 0).collect()))
}

/// A single-channel PNG (8 or 16 bit) as `(width, height, row-major values)`; other pixel formats
/// are refused, naming the file.
fn read_grey(path: &Path) -> Result<(u32, u32, Vec<u16>)> {
    let img = image::ImageReader::open(path)
        .map_err(|source| SceneError::Io {
            path: path.to_path_buf(),
            source,
        })?
        .decode()
        .map_err(|e| img_err(path, e.to_string()))?;
    let (w, h) = (img.width(), img.height());
    let data = match &img {
        DynamicImage::ImageLuma8(b) => b.pixels().map(|p| u16::from(p.0[0])).collect(),
        DynamicImage::ImageLuma16(b) => b.pixels().map(|p| p.0[0]).collect(),
        other => {
            return Err(img_err(
                path,
                format!("pixel format {:?}, expected single-channel", other.color()),
            ))
        }
    };
    Ok((w, h, data))
}

/// Writes a person-id image (`frames[].person_ids`): an 8-bit single-channel PNG, row-major, 0 =
/// scene, `p + 1` = person `p`.
pub fn write_person_ids(path: &Path, width: u32, height: u32, ids: &[u8]) -> Result<()> {
    if ids.len() != width as usize * height as usize {
        return Err(SceneError::Arg {
            name: "person_ids".into(),
            message: format!("{} values for a {width}x{height} image", ids.len()),
        });
    }
    write_png(path, ids, width, height, ExtendedColorType::L8)
}

/// Reads a person-id image (8 or 16 bit single channel): `(width, height, row-major values)`, 0 =
/// scene, `p + 1` = person `p`; a value above 255 is refused, naming the file.
pub fn read_person_ids(path: &Path) -> Result<(u32, u32, Vec<u8>)> {
    let (w, h, values) = read_grey(path)?;
    let ids = values
        .into_iter()
        .map(u8::try_from)
        .collect::<std::result::Result<Vec<u8>, _>>()
        .map_err(|_| img_err(path, "a person id above 255"))?;
    Ok((w, h, ids))
}
