//! Optical-flow files and the flow colour code.
//!
//! In memory a flow field is `(2, H, W)` f32 planar (u plane then v plane), in pixels, forward from
//! frame k to frame k+1 (DESIGN.md §3). On disk: Middlebury `.flo`, DSEC and KITTI 16-bit PNG,
//! `.npy` `(2, H, W)` or `(H, W, 2)`, and OpenEXR. Readers check every header value against the
//! file's actual length (or a hard cap) before allocating; none of them panics on bad input.

use std::fs::File;
use std::io::{BufReader, BufWriter, Read, Write};
use std::path::Path;

use crate::error::{EventsError, Result};

/// Largest flow field any reader accepts (pixels): 2^28 (16384 x 16384).
pub const MAX_FLOW_PIXELS: usize = 1 << 28;

/// A dense flow field `(2, H, W)` f32 planar, in pixels, forward (`x_{k+1} = x_k + F(x_k)`).
#[derive(Clone, Debug, PartialEq)]
pub struct Flow {
    /// Width (pixels).
    pub width: usize,
    /// Height (pixels).
    pub height: usize,
    /// `2 * H * W` values: the u (x, rightwards) plane, then the v (y, downwards) plane, row-major.
    pub data: Vec<f32>,
}

impl Flow {
    /// An all-zero flow field.
    pub fn zeros(width: usize, height: usize) -> Self {
        Self {
            width,
            height,
            data: vec![0.0; 2 * width * height],
        }
    }

    /// A flow field from planar data; errors when the length is not `2 * W * H`.
    pub fn from_planar(width: usize, height: usize, data: Vec<f32>) -> Result<Self> {
        if data.len() != 2 * width * height {
            return Err(EventsError::arg(
                "data",
                format!("length {} is not 2*{width}*{height}", data.len()),
            ));
        }
        Ok(Self {
            width,
            height,
            data,
        })
    }

    /// The u (horizontal, pixels, positive rightwards) plane.
    pub fn u(&self) -> &[f32] {
        &self.data[..self.width * self.height]
    }

    /// The v (vertical, pixels, positive downwards) plane.
    pub fn v(&self) -> &[f32] {
        &self.data[self.width * self.height..]
    }

    /// `(u, v)` at pixel (x, y).
    pub fn at(&self, x: usize, y: usize) -> (f32, f32) {
        let i = y * self.width + x;
        (self.data[i], self.data[self.width * self.height + i])
    }

    /// Sets `(u, v)` at pixel (x, y).
    pub fn set(&mut self, x: usize, y: usize, u: f32, v: f32) {
        let n = self.width * self.height;
        let i = y * self.width + x;
        self.data[i] = u;
        self.data[n + i] = v;
    }
}

fn check_dims(path: &Path, w: i64, h: i64) -> Result<(usize, usize)> {
    if w <= 0 || h <= 0 || (w as u128) * (h as u128) > MAX_FLOW_PIXELS as u128 {
        return Err(EventsError::format(
            path,
            format!("flow size {w}x{h} is empty or exceeds {MAX_FLOW_PIXELS} pixels"),
        ));
    }
    Ok((w as usize, h as usize))
}

/// Middlebury `.flo` magic: the float 202021.25, i.e. the bytes `PIEH`.
const FLO_MAGIC: &[u8; 4] = b"PIEH";

/// Parses a Middlebury `.flo` file held in memory (`path` only names it in errors).
pub fn decode_flo(bytes: &[u8], path: &Path) -> Result<Flow> {
    if bytes.len() < 12 {
        return Err(EventsError::format(
            path,
            format!("truncated .flo header ({} bytes)", bytes.len()),
        ));
    }
    if &bytes[0..4] != FLO_MAGIC {
        return Err(EventsError::format(
            path,
            format!("magic {:?} is not PIEH", &bytes[0..4]),
        ));
    }
    let le_i32 =
        |o: usize| i32::from_le_bytes([bytes[o], bytes[o + 1], bytes[o + 2], bytes[o + 3]]);
    let (w, h) = check_dims(path, le_i32(4) as i64, le_i32(8) as i64)?;
    let expected = 12 + 8 * w * h;
    if bytes.len() != expected {
        return Err(EventsError::format(
            path,
            format!(
                "file has {} bytes but header {w}x{h} needs {expected}",
                bytes.len()
            ),
        ));
    }
    let n = w * h;
    let mut data = vec![0.0f32; 2 * n];
    for (i, c) in bytes[12..].chunks_exact(8).enumerate() {
        data[i] = f32::from_le_bytes([c[0], c[1], c[2], c[3]]);
        data[n + i] = f32::from_le_bytes([c[4], c[5], c[6], c[7]]);
    }
    Ok(Flow {
        width: w,
        height: h,
        data,
    })
}

/// Serialises a flow field as Middlebury `.flo` bytes (interleaved little-endian f32 u, v).
pub fn encode_flo(flow: &Flow) -> Vec<u8> {
    let n = flow.width * flow.height;
    let mut out = Vec::with_capacity(12 + 8 * n);
    out.extend_from_slice(FLO_MAGIC);
    out.extend_from_slice(&(flow.width as i32).to_le_bytes());
    out.extend_from_slice(&(flow.height as i32).to_le_bytes());
    for i in 0..n {
        out.extend_from_slice(&flow.data[i].to_le_bytes());
        out.extend_from_slice(&flow.data[n + i].to_le_bytes());
    }
    out
}

fn read_bounded(path: &Path, cap: u64) -> Result<Vec<u8>> {
    let f = File::open(path).map_err(|e| EventsError::io(path, e))?;
    let len = f.metadata().map_err(|e| EventsError::io(path, e))?.len();
    if len > cap {
        return Err(EventsError::format(
            path,
            format!("file of {len} bytes exceeds the {cap}-byte cap"),
        ));
    }
    let mut buf = Vec::with_capacity(len as usize);
    BufReader::new(f)
        .take(cap)
        .read_to_end(&mut buf)
        .map_err(|e| EventsError::io(path, e))?;
    Ok(buf)
}

/// Reads a Middlebury `.flo` file.
pub fn read_flo(path: impl AsRef<Path>) -> Result<Flow> {
    let path = path.as_ref();
    let bytes = read_bounded(path, 12 + 8 * MAX_FLOW_PIXELS as u64)?;
    decode_flo(&bytes, path)
}

/// Writes a Middlebury `.flo` file.
pub fn write_flo(path: impl AsRef<Path>, flow: &Flow) -> Result<()> {
    let path = path.as_ref();
    std::fs::write(path, encode_flo(flow)).map_err(|e| EventsError::io(path, e))
}

/// The 16-bit PNG flow encodings: `u = (R − 2^15) / scale`, `v = (G − 2^15) / scale`, B = valid.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FlowPngKind {
    /// DSEC: scale 128.
    Dsec,
    /// KITTI 2012/2015: scale 64.
    Kitti,
}

impl FlowPngKind {
    /// Pixels-to-code scale factor.
    pub fn scale(self) -> f32 {
        match self {
            Self::Dsec => 128.0,
            Self::Kitti => 64.0,
        }
    }
}

/// Reads a DSEC/KITTI 16-bit flow PNG; returns the flow and the per-pixel validity (B ≠ 0).
pub fn read_flow_png(path: impl AsRef<Path>, kind: FlowPngKind) -> Result<(Flow, Vec<bool>)> {
    let path = path.as_ref();
    let img = image::ImageReader::open(path)
        .map_err(|e| EventsError::io(path, e))?
        .with_guessed_format()
        .map_err(|e| EventsError::io(path, e))?
        .decode()
        .map_err(|e| EventsError::format(path, format!("PNG decode: {e}")))?;
    let image::DynamicImage::ImageRgb16(rgb) = img else {
        return Err(EventsError::format(
            path,
            format!("colour type {:?} is not 16-bit RGB", img.color()),
        ));
    };
    let (w, h) = (rgb.width() as usize, rgb.height() as usize);
    let n = w * h;
    let s = kind.scale();
    let mut flow = Flow::zeros(w, h);
    let mut valid = vec![false; n];
    for (i, px) in rgb.pixels().enumerate() {
        flow.data[i] = (px.0[0] as f32 - 32768.0) / s;
        flow.data[n + i] = (px.0[1] as f32 - 32768.0) / s;
        valid[i] = px.0[2] != 0;
    }
    Ok((flow, valid))
}

/// Writes a DSEC/KITTI 16-bit flow PNG. Values are rounded to the 1/scale grid and clamped to the
/// representable range (±256 px for DSEC, ±512 px for KITTI); `valid` (or all-valid) goes to B.
pub fn write_flow_png(
    path: impl AsRef<Path>,
    flow: &Flow,
    valid: Option<&[bool]>,
    kind: FlowPngKind,
) -> Result<()> {
    let path = path.as_ref();
    let n = flow.width * flow.height;
    if let Some(v) = valid {
        if v.len() != n {
            return Err(EventsError::arg(
                "valid",
                format!("length {} is not {n}", v.len()),
            ));
        }
    }
    let s = kind.scale();
    let code = |f: f32| (f * s + 32768.0).round().clamp(0.0, 65535.0) as u16;
    let mut buf = Vec::with_capacity(3 * n);
    for i in 0..n {
        buf.push(code(flow.data[i]));
        buf.push(code(flow.data[n + i]));
        buf.push(u16::from(valid.is_none_or(|v| v[i])));
    }
    let img = image::ImageBuffer::<image::Rgb<u16>, _>::from_raw(
        flow.width as u32,
        flow.height as u32,
        buf,
    )
    .ok_or_else(|| EventsError::arg("flow", "buffer size mismatch".to_string()))?;
    img.save_with_format(path, image::ImageFormat::Png)
        .map_err(|e| EventsError::format(path, format!("PNG encode: {e}")))
}

/// Reads a flow `.npy` of f32 (or f64) with shape `(2, H, W)` or `(H, W, 2)` (the first is preferred
/// when both match).
pub fn read_flow_npy(path: impl AsRef<Path>) -> Result<Flow> {
    let path = path.as_ref();
    let f = File::open(path).map_err(|e| EventsError::io(path, e))?;
    let file_len = f.metadata().map_err(|e| EventsError::io(path, e))?.len();
    let npy = npyz::NpyFile::new(BufReader::new(f))
        .map_err(|e| EventsError::format(path, format!("npy header: {e}")))?;
    let shape = npy.shape().to_vec();
    if shape.len() != 3 {
        return Err(EventsError::format(
            path,
            format!("shape {shape:?} is not 3-dimensional"),
        ));
    }
    let planar = shape[0] == 2;
    if !planar && shape[2] != 2 {
        return Err(EventsError::format(
            path,
            format!("shape {shape:?} is neither (2,H,W) nor (H,W,2)"),
        ));
    }
    let (h, w) = if planar {
        (shape[1], shape[2])
    } else {
        (shape[0], shape[1])
    };
    let (w, h) = check_dims(
        path,
        w.min(i64::MAX as u64) as i64,
        h.min(i64::MAX as u64) as i64,
    )?;
    let n = w * h;
    let item = match npy.dtype() {
        npyz::DType::Plain(ts) => ts.num_bytes().unwrap_or(0),
        other => {
            return Err(EventsError::format(
                path,
                format!("dtype {} is not a float", other.descr()),
            ));
        }
    };
    if (2 * n * item) as u64 > file_len {
        return Err(EventsError::format(
            path,
            format!(
                "shape {shape:?} needs {} bytes but the file has {file_len}",
                2 * n * item
            ),
        ));
    }
    if npy.order() != npyz::Order::C {
        return Err(EventsError::format(
            path,
            "Fortran-order arrays are not supported".to_string(),
        ));
    }
    let descr = npy.dtype().descr().trim_matches('\'').to_string();
    let values: Vec<f32> = if descr.ends_with("f4") {
        npy.into_vec::<f32>()
    } else if descr.ends_with("f8") {
        npy.into_vec::<f64>()
            .map(|v| v.into_iter().map(|x| x as f32).collect())
    } else {
        return Err(EventsError::format(
            path,
            format!("dtype {descr} is not f4 or f8"),
        ));
    }
    .map_err(|e| EventsError::format(path, format!("npy data: {e}")))?;
    if values.len() != 2 * n {
        return Err(EventsError::format(
            path,
            format!("read {} values, expected {}", values.len(), 2 * n),
        ));
    }
    if planar {
        return Ok(Flow {
            width: w,
            height: h,
            data: values,
        });
    }
    let mut flow = Flow::zeros(w, h);
    for i in 0..n {
        flow.data[i] = values[2 * i];
        flow.data[n + i] = values[2 * i + 1];
    }
    Ok(flow)
}

/// Writes a flow `.npy` of little-endian f32 with shape `(2, H, W)`.
pub fn write_flow_npy(path: impl AsRef<Path>, flow: &Flow) -> Result<()> {
    use npyz::WriterBuilder;
    let path = path.as_ref();
    let f = File::create(path).map_err(|e| EventsError::io(path, e))?;
    let mut bw = BufWriter::new(f);
    let mut w = npyz::WriteOptions::<f32>::new()
        .default_dtype()
        .shape(&[2, flow.height as u64, flow.width as u64])
        .writer(&mut bw)
        .begin_nd()
        .map_err(|e| EventsError::io(path, e))?;
    w.extend(flow.data.iter().copied())
        .map_err(|e| EventsError::io(path, e))?;
    w.finish().map_err(|e| EventsError::io(path, e))?;
    bw.flush().map_err(|e| EventsError::io(path, e))
}

/// Reads a flow EXR: channels `u`/`v` if present, else `R`/`G` (first valid layer, f16/f32).
pub fn read_flow_exr(path: impl AsRef<Path>) -> Result<Flow> {
    let path = path.as_ref();
    let img = exr::prelude::read_first_flat_layer_from_file(path)
        .map_err(|e| EventsError::format(path, format!("EXR: {e}")))?;
    let layer = img.layer_data;
    let (w, h) = (layer.size.0, layer.size.1);
    let (w, h) = check_dims(path, w as i64, h as i64)?;
    let find = |names: [&str; 2]| {
        let get = |nm: &str| layer.channel_data.list.iter().find(|c| c.name.eq(nm));
        Some((get(names[0])?, get(names[1])?))
    };
    let (cu, cv) = find(["u", "v"])
        .or_else(|| find(["R", "G"]))
        .ok_or_else(|| {
            EventsError::format(path, "EXR has neither channels u,v nor R,G".to_string())
        })?;
    let mut data = Vec::with_capacity(2 * w * h);
    data.extend(cu.sample_data.values_as_f32());
    data.extend(cv.sample_data.values_as_f32());
    if data.len() != 2 * w * h {
        return Err(EventsError::format(
            path,
            format!(
                "EXR channels hold {} values, expected {}",
                data.len(),
                2 * w * h
            ),
        ));
    }
    Ok(Flow {
        width: w,
        height: h,
        data,
    })
}

/// Writes a flow EXR with two f32 channels `u` and `v` (lossless ZIP compression).
pub fn write_flow_exr(path: impl AsRef<Path>, flow: &Flow) -> Result<()> {
    use exr::prelude::*;
    let path = path.as_ref();
    let n = flow.width * flow.height;
    let channels = AnyChannels::sort(SmallVec::from_vec(vec![
        AnyChannel::new("u", FlatSamples::F32(flow.data[..n].to_vec())),
        AnyChannel::new("v", FlatSamples::F32(flow.data[n..].to_vec())),
    ]));
    let layer = Layer::new(
        (flow.width, flow.height),
        LayerAttributes::named("flow"),
        Encoding::SMALL_LOSSLESS,
        channels,
    );
    Image::from_layer(layer)
        .write()
        .to_file(path)
        .map_err(|e| EventsError::format(path, format!("EXR write: {e}")))
}

/// Reads a flow file, choosing the format by extension: `.flo`, `.npy`, `.exr`, `.png` (DSEC
/// encoding; use [`read_flow_png`] for KITTI).
pub fn read_flow(path: impl AsRef<Path>) -> Result<Flow> {
    let path = path.as_ref();
    match extension(path).as_str() {
        "flo" => read_flo(path),
        "npy" => read_flow_npy(path),
        "exr" => read_flow_exr(path),
        "png" => read_flow_png(path, FlowPngKind::Dsec).map(|(f, _)| f),
        other => Err(EventsError::format(
            path,
            format!("unknown flow extension {other:?}"),
        )),
    }
}

/// Writes a flow file, choosing the format by extension (see [`read_flow`]).
pub fn write_flow(path: impl AsRef<Path>, flow: &Flow) -> Result<()> {
    let path = path.as_ref();
    match extension(path).as_str() {
        "flo" => write_flo(path, flow),
        "npy" => write_flow_npy(path, flow),
        "exr" => write_flow_exr(path, flow),
        "png" => write_flow_png(path, flow, None, FlowPngKind::Dsec),
        other => Err(EventsError::format(
            path,
            format!("unknown flow extension {other:?}"),
        )),
    }
}

pub(crate) fn extension(path: &Path) -> String {
    path.extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase()
}

/// The Middlebury colour wheel (Baker et al. 2011): 55 hues through red, yellow, green, cyan, blue,
/// magenta, as RGB in [0, 1].
fn colour_wheel() -> Vec<[f32; 3]> {
    let (ry, yg, gc, cb, bm, mr) = (15, 6, 4, 11, 13, 6);
    let mut wheel = Vec::with_capacity(ry + yg + gc + cb + bm + mr);
    for i in 0..ry {
        wheel.push([1.0, i as f32 / ry as f32, 0.0]);
    }
    for i in 0..yg {
        wheel.push([1.0 - i as f32 / yg as f32, 1.0, 0.0]);
    }
    for i in 0..gc {
        wheel.push([0.0, 1.0, i as f32 / gc as f32]);
    }
    for i in 0..cb {
        wheel.push([0.0, 1.0 - i as f32 / cb as f32, 1.0]);
    }
    for i in 0..bm {
        wheel.push([i as f32 / bm as f32, 0.0, 1.0]);
    }
    for i in 0..mr {
        wheel.push([1.0, 0.0, 1.0 - i as f32 / mr as f32]);
    }
    wheel
}

/// Middlebury colour coding of a flow field: hue = direction, saturation = magnitude / `max_radius`
/// (pixels; `None` = the largest finite magnitude in the field). Returns interleaved 8-bit RGB,
/// `3 * W * H` bytes, row-major. Non-finite vectors are black.
pub fn flow_to_rgb(flow: &Flow, max_radius: Option<f32>) -> Vec<u8> {
    let n = flow.width * flow.height;
    let (u, v) = (flow.u(), flow.v());
    let max_r = max_radius.unwrap_or_else(|| {
        (0..n)
            .map(|i| (u[i] * u[i] + v[i] * v[i]).sqrt())
            .filter(|r| r.is_finite())
            .fold(0.0f32, f32::max)
    });
    let max_r = if max_r > 0.0 { max_r } else { 1.0 };
    let wheel = colour_wheel();
    let ncols = wheel.len();
    let mut out = vec![0u8; 3 * n];
    for i in 0..n {
        let (fu, fv) = (u[i] / max_r, v[i] / max_r);
        if !(fu.is_finite() && fv.is_finite()) {
            continue;
        }
        let rad = (fu * fu + fv * fv).sqrt();
        let a = (-fv).atan2(-fu) / std::f32::consts::PI;
        let fk = (a + 1.0) / 2.0 * (ncols - 1) as f32;
        let k0 = (fk.floor() as usize).min(ncols - 1);
        let k1 = if k0 + 1 == ncols { 0 } else { k0 + 1 };
        let f = fk - k0 as f32;
        for c in 0..3 {
            let col = (1.0 - f) * wheel[k0][c] + f * wheel[k1][c];
            let col = if rad <= 1.0 {
                1.0 - rad * (1.0 - col)
            } else {
                col * 0.75
            };
            out[3 * i + c] = (255.0 * col).round().clamp(0.0, 255.0) as u8;
        }
    }
    out
}

/// Writes the Middlebury colour coding of `flow` (see [`flow_to_rgb`]) as an 8-bit RGB PNG.
pub fn write_flow_colour_png(
    path: impl AsRef<Path>,
    flow: &Flow,
    max_radius: Option<f32>,
) -> Result<()> {
    let path = path.as_ref();
    let rgb = flow_to_rgb(flow, max_radius);
    image::save_buffer_with_format(
        path,
        &rgb,
        flow.width as u32,
        flow.height as u32,
        image::ExtendedColorType::Rgb8,
        image::ImageFormat::Png,
    )
    .map_err(|e| EventsError::format(path, format!("PNG encode: {e}")))
}
