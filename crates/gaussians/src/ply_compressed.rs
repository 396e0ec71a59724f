//! Reading the PlayCanvas / SuperSplat compressed PLY layout (what SuperSplat exports as
//! `.compressed.ply` and `splat-transform` writes).
//!
//! The file is binary little-endian with three elements: `chunk` (one row per 256 Gaussians, float
//! bounds `min_x … max_z`, `min_scale_x … max_scale_z` and optionally `min_r … max_b`), `vertex`
//! (four `uint` words per Gaussian: `packed_position`, `packed_rotation`, `packed_scale`,
//! `packed_color`) and optionally `sh` (`uchar f_rest_0 …`, 9, 24 or 45 per Gaussian). Decoding, as
//! the format's reference reader does it:
//! - position and log-scale: 11 / 10 / 11 bits (x in the top bits), each a fraction of its chunk's
//!   `[min, max]`;
//! - rotation: the quaternion `(rot_0, rot_1, rot_2, rot_3)` with its largest component dropped —
//!   the top 2 bits say which — and the other three in 10 bits each over `[−1/√2, 1/√2]`;
//! - colour: 8 bits each of r, g, b (a fraction of the chunk's colour bounds when present) and
//!   opacity; `f_dc = (colour − 0.5) / C0` with `C0` the degree-0 SH constant, the opacity logit
//!   `ln(a / (1 − a))`, clamped to ±20 where the byte is 0 or 255 (the reference gives ±∞);
//! - `f_rest`: a byte `b` is `0` → 0, `255` → 1, else `(b + 0.5) / 256`, then `(value − 0.5) · 8`.
//!
//! Sizes are checked against the file before anything is allocated, and every error names the file
//! and the element or property.

use crate::ply::{check_fits, Element, Format, Header, PlyError, PropertyKind, Scalar};
use crate::set::GaussianSet;
use crate::sh::num_sh_coeffs;
use std::path::Path;

/// Gaussians per `chunk` row.
const CHUNK: u64 = 256;
/// The degree-0 SH basis constant, 1 / (2√π).
const SH_C0: f32 = 0.282_094_8;
/// The packed vertex words, in the order they are decoded.
const PACKED: [&str; 4] = [
    "packed_position",
    "packed_rotation",
    "packed_scale",
    "packed_color",
];
/// The chunk bounds that must be present.
const BOUNDS: [&str; 12] = [
    "min_x",
    "min_y",
    "min_z",
    "max_x",
    "max_y",
    "max_z",
    "min_scale_x",
    "min_scale_y",
    "min_scale_z",
    "max_scale_x",
    "max_scale_y",
    "max_scale_z",
];
/// The optional colour bounds.
const COLOUR_BOUNDS: [&str; 6] = ["min_r", "min_g", "min_b", "max_r", "max_g", "max_b"];

/// True when `header` is the compressed layout: a `chunk` element and a `vertex` element with
/// `packed_position`.
pub(crate) fn is_compressed(header: &Header) -> bool {
    header.elements.iter().any(|e| e.name == "chunk")
        && header
            .elements
            .iter()
            .any(|e| e.name == "vertex" && e.properties.iter().any(|p| p.name == "packed_position"))
}

fn property_error(path: &Path, property: &str, message: impl Into<String>) -> PlyError {
    PlyError::Property {
        path: path.to_path_buf(),
        property: property.to_string(),
        message: message.into(),
    }
}

/// Byte offset and scalar type of each property of `element` (all scalar), and the row size.
fn columns(path: &Path, element: &Element) -> Result<(Vec<(usize, Scalar)>, usize), PlyError> {
    let mut out = Vec::with_capacity(element.properties.len());
    let mut offset = 0usize;
    for p in &element.properties {
        let PropertyKind::Scalar(s) = p.kind else {
            return Err(property_error(
                path,
                &p.name,
                format!("a list in element `{}` of a compressed PLY", element.name),
            ));
        };
        out.push((offset, s));
        offset += s.size();
    }
    Ok((out, offset))
}

/// The column of property `name` of `element`, which must have type `want` (`None`: any float).
fn column(
    path: &Path,
    element: &Element,
    cols: &[(usize, Scalar)],
    name: &str,
    want: Option<Scalar>,
) -> Result<Option<(usize, Scalar)>, PlyError> {
    let Some(k) = element.properties.iter().position(|p| p.name == name) else {
        return Ok(None);
    };
    let (offset, s) = cols[k];
    let ok = match want {
        Some(w) => s == w,
        None => s.is_float(),
    };
    if !ok {
        return Err(property_error(
            path,
            name,
            format!(
                "has type {s:?} in element `{}`; the compressed layout stores {}",
                element.name,
                want.map_or("float".to_string(), |w| format!("{w:?}"))
            ),
        ));
    }
    Ok(Some((offset, s)))
}

fn u32_at(row: &[u8], offset: usize) -> u32 {
    let mut b = [0u8; 4];
    b.copy_from_slice(&row[offset..offset + 4]);
    u32::from_le_bytes(b)
}

/// `bits` low bits of `value` as a fraction of their maximum.
fn unorm(value: u32, bits: u32) -> f32 {
    let max = (1u32 << bits) - 1;
    (value & max) as f32 / max as f32
}

fn lerp(a: f32, b: f32, t: f32) -> f32 {
    a * (1.0 - t) + b * t
}

/// Reads the compressed layout from `data` (the bytes after the header).
pub(crate) fn read_compressed(
    path: &Path,
    data: &[u8],
    header: &Header,
) -> Result<GaussianSet, PlyError> {
    if header.format != Format::BinaryLe {
        return Err(property_error(
            path,
            "format",
            "a compressed (chunk + packed vertex) PLY must be binary_little_endian",
        ));
    }
    // Element offsets in header order, each checked against the bytes that follow.
    let mut offsets = Vec::with_capacity(header.elements.len());
    let mut offset = 0u64;
    for element in &header.elements {
        let (_, row) = columns(path, element)?;
        offsets.push(offset as usize);
        offset += check_fits(path, element, row as u64, data.len() as u64 - offset)?;
    }
    if offset < data.len() as u64 {
        return Err(PlyError::TrailingData {
            path: path.to_path_buf(),
            bytes: data.len() as u64 - offset,
        });
    }
    let find = |name: &str| header.elements.iter().position(|e| e.name == name);
    let (Some(ci), Some(vi)) = (find("chunk"), find("vertex")) else {
        return Err(property_error(
            path,
            "element chunk",
            "a compressed PLY needs `chunk` and `vertex`",
        ));
    };
    let (chunk, vertex) = (&header.elements[ci], &header.elements[vi]);
    let n = vertex.count;
    if chunk.count < n.div_ceil(CHUNK) {
        return Err(property_error(
            path,
            "element chunk",
            format!(
                "{} rows for {n} Gaussians; one row per {CHUNK} is needed ({})",
                chunk.count,
                n.div_ceil(CHUNK)
            ),
        ));
    }
    let (chunk_cols, chunk_row) = columns(path, chunk)?;
    let mut bounds = Vec::with_capacity(BOUNDS.len());
    for name in BOUNDS {
        match column(path, chunk, &chunk_cols, name, None)? {
            Some(c) => bounds.push(c),
            None => return Err(property_error(path, name, "missing from element `chunk`")),
        }
    }
    let mut colour_bounds = Vec::with_capacity(COLOUR_BOUNDS.len());
    for name in COLOUR_BOUNDS {
        if let Some(c) = column(path, chunk, &chunk_cols, name, None)? {
            colour_bounds.push(c);
        }
    }
    let has_colour_bounds = colour_bounds.len() == COLOUR_BOUNDS.len();
    let (vertex_cols, vertex_row) = columns(path, vertex)?;
    let mut packed = [0usize; 4];
    for (slot, name) in packed.iter_mut().zip(PACKED) {
        *slot = column(path, vertex, &vertex_cols, name, Some(Scalar::U32))?
            .ok_or_else(|| property_error(path, name, "missing from element `vertex`"))?
            .0;
    }
    // Optional SH bytes.
    let sh = match find("sh") {
        Some(si) => {
            let e = &header.elements[si];
            if e.count != n {
                return Err(property_error(
                    path,
                    "element sh",
                    format!("{} rows for {n} Gaussians", e.count),
                ));
            }
            let (cols, row) = columns(path, e)?;
            let rest = e.properties.len();
            let mut at = Vec::with_capacity(rest);
            for j in 0..rest {
                let name = format!("f_rest_{j}");
                let c = column(path, e, &cols, &name, Some(Scalar::U8))?
                    .ok_or_else(|| property_error(path, &name, "missing from element `sh`"))?;
                at.push(c.0);
            }
            Some((offsets[si], row, at))
        }
        None => None,
    };
    let rest = sh.as_ref().map_or(0, |s| s.2.len());
    let sh_degree = match rest {
        0 => 0,
        9 => 1,
        24 => 2,
        45 => 3,
        other => {
            return Err(property_error(
                path,
                "element sh",
                format!("{other} f_rest properties; expected 9, 24 or 45"),
            ))
        }
    };
    let k = num_sh_coeffs(sh_degree);
    // Every row count is now known to fit in the file, so reserving it is safe.
    let n = n as usize;
    let mut set = GaussianSet::zeros(n, sh_degree, 0, 0);
    let read_bound = |row: &[u8], (offset, s): (usize, Scalar), chunk_row: usize, name: &str| {
        let v = s.read_f32(&row[offset..], Format::BinaryLe);
        if v.is_finite() {
            Ok(v)
        } else {
            Err(PlyError::NonFinite {
                path: path.to_path_buf(),
                vertex: chunk_row as u64,
                property: format!("{name} (element `chunk`)"),
                value: f64::from(v),
            })
        }
    };
    let norm = std::f32::consts::SQRT_2;
    for c in 0..n.div_ceil(CHUNK as usize) {
        let row = &data[offsets[ci] + c * chunk_row..offsets[ci] + (c + 1) * chunk_row];
        let mut b = [0f32; 12];
        for (slot, (&col, name)) in b.iter_mut().zip(bounds.iter().zip(BOUNDS)) {
            *slot = read_bound(row, col, c, name)?;
        }
        let mut cb = [0f32; 6];
        if has_colour_bounds {
            for (slot, (&col, name)) in cb.iter_mut().zip(colour_bounds.iter().zip(COLOUR_BOUNDS)) {
                *slot = read_bound(row, col, c, name)?;
            }
        }
        for i in c * CHUNK as usize..((c + 1) * CHUNK as usize).min(n) {
            let v = &data[offsets[vi] + i * vertex_row..offsets[vi] + (i + 1) * vertex_row];
            let [pp, pr, ps, pc] = packed.map(|o| u32_at(v, o));
            set.means[i] = [
                lerp(b[0], b[3], unorm(pp >> 21, 11)),
                lerp(b[1], b[4], unorm(pp >> 11, 10)),
                lerp(b[2], b[5], unorm(pp, 11)),
            ];
            set.log_scales[i] = [
                lerp(b[6], b[9], unorm(ps >> 21, 11)),
                lerp(b[7], b[10], unorm(ps >> 11, 10)),
                lerp(b[8], b[11], unorm(ps, 11)),
            ];
            let three = [
                (unorm(pr >> 20, 10) - 0.5) * norm,
                (unorm(pr >> 10, 10) - 0.5) * norm,
                (unorm(pr, 10) - 0.5) * norm,
            ];
            let largest = (1.0 - three.iter().map(|x| x * x).sum::<f32>())
                .max(0.0)
                .sqrt();
            let which = (pr >> 30) as usize;
            let mut q = [0f32; 4];
            let mut rest_iter = three.into_iter();
            for (j, slot) in q.iter_mut().enumerate() {
                *slot = if j == which {
                    largest
                } else {
                    rest_iter.next().unwrap_or(0.0)
                };
            }
            set.quats[i] = q;
            let colour = [unorm(pc >> 24, 8), unorm(pc >> 16, 8), unorm(pc >> 8, 8)];
            for (ch, &x) in colour.iter().enumerate() {
                let x = if has_colour_bounds {
                    lerp(cb[ch], cb[3 + ch], x)
                } else {
                    x
                };
                set.sh[i * k * 3 + ch] = (x - 0.5) / SH_C0;
            }
            let alpha = unorm(pc, 8);
            set.opacity_logits[i] = (alpha / (1.0 - alpha)).ln().clamp(-20.0, 20.0);
            if let Some((sh_offset, sh_row, at)) = &sh {
                let row = &data[sh_offset + i * sh_row..sh_offset + (i + 1) * sh_row];
                for (j, &o) in at.iter().enumerate() {
                    let byte = row[o];
                    let value = match byte {
                        0 => 0.0,
                        255 => 1.0,
                        b => (f32::from(b) + 0.5) / 256.0,
                    };
                    // f_rest is channel-major: j = channel·(K−1) + (coefficient − 1).
                    let (ch, coeff) = (j / (k - 1), j % (k - 1) + 1);
                    set.sh[(i * k + coeff) * 3 + ch] = (value - 0.5) * 8.0;
                }
            }
        }
    }
    Ok(set)
}
