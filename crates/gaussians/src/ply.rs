//! Reading and writing Gaussian sets in the INRIA 3DGS PLY layout.
//!
//! Written files are binary little-endian with the vertex properties, all `float`, in the order
//! `x y z nx ny nz f_dc_0..2 f_rest_0..(3·(K−1)−1) opacity scale_0..2 rot_0..3`, followed by the extra
//! properties `semantic_0..` and `feature_0..` that other viewers ignore. Values are stored
//! pre-activation; `f_rest` is channel-major (`f_rest[c·(K−1) + k]` is coefficient k+1 of channel c).
//!
//! Reading accepts binary little/big-endian and ASCII files, any property order, unknown extra properties
//! (skipped) and other elements before or after `vertex` (skipped, scalar properties only when binary),
//! and the PlayCanvas / SuperSplat compressed layout (`crate::ply_compressed`).
//! It never trusts the header for an allocation: the claimed vertex count is checked against the bytes
//! that actually follow before anything is reserved. Every error names the file and the property.

use crate::set::GaussianSet;
use crate::sh::{num_sh_coeffs, sh_degree_from_coeffs};
use std::io::Write;
use std::path::{Path, PathBuf};

/// Errors reading or writing a 3DGS PLY file. Every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum PlyError {
    /// The file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying I/O error.
        source: std::io::Error,
    },
    /// The header is malformed (missing magic, unknown format, bad element or property line).
    #[error("{path}: header line {line}: {message}")]
    Header {
        /// The file.
        path: PathBuf,
        /// 1-based header line number.
        line: usize,
        /// What is wrong.
        message: String,
    },
    /// A property the 3DGS layout needs is absent, duplicated or out of sequence.
    #[error("{path}: property `{property}`: {message}")]
    Property {
        /// The file.
        path: PathBuf,
        /// The property name.
        property: String,
        /// What is wrong.
        message: String,
    },
    /// The header claims more data than the file holds (or an absurd count).
    #[error("{path}: element `{element}` claims {count} rows of {row_bytes} bytes but only {available} bytes follow")]
    TooLarge {
        /// The file.
        path: PathBuf,
        /// The element name.
        element: String,
        /// Claimed number of rows.
        count: u64,
        /// Bytes per row.
        row_bytes: u64,
        /// Bytes actually available.
        available: u64,
    },
    /// The data ends inside a row.
    #[error("{path}: truncated: data ends in vertex {vertex} at property `{property}`")]
    Truncated {
        /// The file.
        path: PathBuf,
        /// Index of the incomplete vertex.
        vertex: u64,
        /// The property being read.
        property: String,
    },
    /// An ASCII value does not parse as a number.
    #[error("{path}: vertex {vertex}, property `{property}`: cannot parse `{value}` as a number")]
    Parse {
        /// The file.
        path: PathBuf,
        /// Vertex index.
        vertex: u64,
        /// The property.
        property: String,
        /// The offending token.
        value: String,
    },
    /// A NaN or infinite value in a property the set uses.
    #[error("{path}: vertex {vertex}, property `{property}`: non-finite value {value}")]
    NonFinite {
        /// The file.
        path: PathBuf,
        /// Vertex index.
        vertex: u64,
        /// The property.
        property: String,
        /// The value read.
        value: f64,
    },
    /// Bytes remain after the last element.
    #[error("{path}: {bytes} unexpected bytes after the last element (wrong vertex count in the header?)")]
    TrailingData {
        /// The file.
        path: PathBuf,
        /// Number of extra bytes.
        bytes: u64,
    },
    /// The set to write is inconsistent.
    #[error("{path}: cannot write an invalid Gaussian set: {source}")]
    InvalidSet {
        /// The file.
        path: PathBuf,
        /// What is wrong with the set.
        source: crate::GaussianError,
    },
}

/// Longest header accepted (bytes); real 3DGS headers are a few kilobytes.
const MAX_HEADER_BYTES: usize = 1 << 20;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Format {
    Ascii,
    BinaryLe,
    BinaryBe,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(name: &str) -> Option<Self> {
        Some(match name {
            "char" | "int8" => Self::I8,
            "uchar" | "uint8" => Self::U8,
            "short" | "int16" => Self::I16,
            "ushort" | "uint16" => Self::U16,
            "int" | "int32" => Self::I32,
            "uint" | "uint32" => Self::U32,
            "float" | "float32" => Self::F32,
            "double" | "float64" => Self::F64,
            _ => return None,
        })
    }

    pub(crate) fn size(self) -> usize {
        match self {
            Self::I8 | Self::U8 => 1,
            Self::I16 | Self::U16 => 2,
            Self::I32 | Self::U32 | Self::F32 => 4,
            Self::F64 => 8,
        }
    }

    pub(crate) fn is_float(self) -> bool {
        matches!(self, Self::F32 | Self::F64)
    }

    /// Decodes one value (only float types are ever decoded; others are skipped).
    fn read(self, bytes: &[u8], format: Format) -> f64 {
        let mut b4 = [0u8; 4];
        let mut b8 = [0u8; 8];
        match self {
            Self::F32 => {
                b4.copy_from_slice(&bytes[..4]);
                f64::from(if format == Format::BinaryBe {
                    f32::from_be_bytes(b4)
                } else {
                    f32::from_le_bytes(b4)
                })
            }
            Self::F64 => {
                b8.copy_from_slice(&bytes[..8]);
                if format == Format::BinaryBe {
                    f64::from_be_bytes(b8)
                } else {
                    f64::from_le_bytes(b8)
                }
            }
            _ => 0.0,
        }
    }

    /// Decodes one f32 exactly (no round trip through f64 for f32 data).
    pub(crate) fn read_f32(self, bytes: &[u8], format: Format) -> f32 {
        if self == Self::F32 {
            let mut b4 = [0u8; 4];
            b4.copy_from_slice(&bytes[..4]);
            if format == Format::BinaryBe {
                f32::from_be_bytes(b4)
            } else {
                f32::from_le_bytes(b4)
            }
        } else {
            self.read(bytes, format) as f32
        }
    }
}

#[derive(Clone, Debug)]
pub(crate) enum PropertyKind {
    Scalar(Scalar),
    /// A list property (skipped; only ASCII bodies can skip lists).
    List,
}

#[derive(Clone, Debug)]
pub(crate) struct Property {
    pub(crate) name: String,
    pub(crate) kind: PropertyKind,
}

#[derive(Clone, Debug)]
pub(crate) struct Element {
    pub(crate) name: String,
    pub(crate) count: u64,
    pub(crate) properties: Vec<Property>,
}

pub(crate) struct Header {
    pub(crate) format: Format,
    pub(crate) elements: Vec<Element>,
    pub(crate) data_offset: usize,
}

fn parse_header(path: &Path, bytes: &[u8]) -> Result<Header, PlyError> {
    let herr = |line: usize, message: String| PlyError::Header {
        path: path.to_path_buf(),
        line,
        message,
    };
    if !bytes.starts_with(b"ply\n") && !bytes.starts_with(b"ply\r\n") {
        return Err(herr(1, "missing `ply` magic: not a PLY file".into()));
    }
    let limit = bytes.len().min(MAX_HEADER_BYTES);
    let end_marker = b"end_header";
    let mut pos = 0usize;
    let mut line_no = 0usize;
    let mut format = None;
    let mut elements: Vec<Element> = Vec::new();
    loop {
        let rest = &bytes[pos..limit];
        let Some(nl) = rest.iter().position(|&b| b == b'\n') else {
            return Err(herr(
                line_no + 1,
                format!("no `end_header` line within the first {limit} bytes"),
            ));
        };
        line_no += 1;
        let raw = &rest[..nl];
        pos += nl + 1;
        let line = std::str::from_utf8(raw)
            .map_err(|_| herr(line_no, "header is not valid UTF-8/ASCII".into()))?
            .trim_end_matches('\r')
            .trim();
        if line_no == 1 {
            continue; // "ply"
        }
        if line.as_bytes() == end_marker {
            break;
        }
        let words: Vec<&str> = line.split_whitespace().collect();
        match words.as_slice() {
            [] => {}
            ["comment", ..] | ["obj_info", ..] => {}
            ["format", f, version] => {
                if *version != "1.0" {
                    return Err(herr(
                        line_no,
                        format!("unsupported PLY version `{version}`"),
                    ));
                }
                format = Some(match *f {
                    "ascii" => Format::Ascii,
                    "binary_little_endian" => Format::BinaryLe,
                    "binary_big_endian" => Format::BinaryBe,
                    other => return Err(herr(line_no, format!("unknown format `{other}`"))),
                });
            }
            ["element", name, count] => {
                let count: u64 = count
                    .parse()
                    .map_err(|_| herr(line_no, format!("element `{name}`: bad count `{count}`")))?;
                elements.push(Element {
                    name: (*name).to_string(),
                    count,
                    properties: Vec::new(),
                });
            }
            ["property", "list", ct, it, name] => {
                let element = elements
                    .last_mut()
                    .ok_or_else(|| herr(line_no, "property before any element".into()))?;
                for ty in [ct, it] {
                    Scalar::parse(ty).ok_or_else(|| {
                        herr(line_no, format!("property `{name}`: unknown type `{ty}`"))
                    })?;
                }
                element.properties.push(Property {
                    name: (*name).to_string(),
                    kind: PropertyKind::List,
                });
            }
            ["property", ty, name] => {
                let element = elements
                    .last_mut()
                    .ok_or_else(|| herr(line_no, "property before any element".into()))?;
                let scalar = Scalar::parse(ty).ok_or_else(|| {
                    herr(line_no, format!("property `{name}`: unknown type `{ty}`"))
                })?;
                if element.properties.iter().any(|p| p.name == *name) {
                    return Err(PlyError::Property {
                        path: path.to_path_buf(),
                        property: (*name).to_string(),
                        message: format!("declared twice in element `{}`", element.name),
                    });
                }
                element.properties.push(Property {
                    name: (*name).to_string(),
                    kind: PropertyKind::Scalar(scalar),
                });
            }
            _ => return Err(herr(line_no, format!("cannot parse `{line}`"))),
        }
    }
    let format = format.ok_or_else(|| herr(2, "missing `format` line".into()))?;
    Ok(Header {
        format,
        elements,
        data_offset: pos,
    })
}

/// Where a vertex property goes in the set.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Target {
    Mean(usize),
    Dc(usize),
    Rest(usize),
    Opacity,
    Scale(usize),
    Rot(usize),
    Semantic(usize),
    Feature(usize),
    Ignore,
}

fn indexed(name: &str, prefix: &str) -> Option<usize> {
    name.strip_prefix(prefix)?.parse().ok()
}

/// The vertex layout resolved against the 3DGS properties.
pub(crate) struct Layout {
    pub(crate) targets: Vec<Target>,
    pub(crate) sh_degree: usize,
    pub(crate) feature_dim: usize,
    pub(crate) semantic_classes: usize,
}

fn resolve_layout(path: &Path, vertex: &Element) -> Result<Layout, PlyError> {
    let perr = |property: &str, message: String| PlyError::Property {
        path: path.to_path_buf(),
        property: property.to_string(),
        message,
    };
    let mut targets = Vec::with_capacity(vertex.properties.len());
    let (mut rest, mut semantic, mut feature) = (Vec::new(), Vec::new(), Vec::new());
    for p in &vertex.properties {
        let name = p.name.as_str();
        let target = match name {
            "x" => Target::Mean(0),
            "y" => Target::Mean(1),
            "z" => Target::Mean(2),
            "opacity" => Target::Opacity,
            _ => {
                if let Some(i) = indexed(name, "f_dc_").filter(|&i| i < 3) {
                    Target::Dc(i)
                } else if let Some(i) = indexed(name, "f_rest_") {
                    rest.push(i);
                    Target::Rest(i)
                } else if let Some(i) = indexed(name, "scale_").filter(|&i| i < 3) {
                    Target::Scale(i)
                } else if let Some(i) = indexed(name, "rot_").filter(|&i| i < 4) {
                    Target::Rot(i)
                } else if let Some(i) = indexed(name, "semantic_") {
                    semantic.push(i);
                    Target::Semantic(i)
                } else if let Some(i) = indexed(name, "feature_") {
                    feature.push(i);
                    Target::Feature(i)
                } else {
                    Target::Ignore
                }
            }
        };
        if !matches!(target, Target::Ignore) {
            match p.kind {
                PropertyKind::Scalar(s) if s.is_float() => {}
                PropertyKind::Scalar(s) => {
                    return Err(perr(
                        name,
                        format!(
                            "has type {s:?}; the 3DGS layout stores float32 (float64 accepted)"
                        ),
                    ))
                }
                PropertyKind::List => {
                    return Err(perr(name, "is a list; a float scalar is required".into()))
                }
            }
        }
        targets.push(target);
    }
    for required in [
        "x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0", "scale_1", "scale_2",
        "rot_0", "rot_1", "rot_2", "rot_3",
    ] {
        if !vertex.properties.iter().any(|p| p.name == required) {
            return Err(perr(required, "missing from element `vertex`".into()));
        }
    }
    let contiguous = |indices: &mut Vec<usize>, prefix: &str| -> Result<usize, PlyError> {
        indices.sort_unstable();
        for (want, &got) in indices.iter().enumerate() {
            if got != want {
                return Err(perr(
                    &format!("{prefix}{want}"),
                    format!("missing: `{prefix}*` indices must run 0..{}", indices.len()),
                ));
            }
        }
        Ok(indices.len())
    };
    let rest_count = contiguous(&mut rest, "f_rest_")?;
    let semantic_classes = contiguous(&mut semantic, "semantic_")?;
    let feature_dim = contiguous(&mut feature, "feature_")?;
    let sh_degree = if rest_count % 3 == 0 {
        sh_degree_from_coeffs(rest_count / 3 + 1)
    } else {
        None
    }
    .ok_or_else(|| {
        perr(
            "f_rest_",
            format!("{rest_count} f_rest properties; expected 0, 9, 24 or 45 (SH degree 0 to 3)"),
        )
    })?;
    Ok(Layout {
        targets,
        sh_degree,
        feature_dim,
        semantic_classes,
    })
}

/// Stores one decoded value into row `i` of `set`.
#[inline]
pub(crate) fn store(set: &mut GaussianSet, layout: &Layout, i: usize, target: Target, v: f32) {
    let k = num_sh_coeffs(layout.sh_degree);
    match target {
        Target::Mean(a) => set.means[i][a] = v,
        Target::Dc(c) => set.sh[i * k * 3 + c] = v,
        Target::Rest(j) => {
            // f_rest is channel-major in the file: j = c·(K−1) + (coefficient − 1).
            let (c, coeff) = (j / (k - 1), j % (k - 1) + 1);
            set.sh[(i * k + coeff) * 3 + c] = v;
        }
        Target::Opacity => set.opacity_logits[i] = v,
        Target::Scale(a) => set.log_scales[i][a] = v,
        Target::Rot(a) => set.quats[i][a] = v,
        Target::Semantic(j) => set.semantic_logits[i * layout.semantic_classes + j] = v,
        Target::Feature(j) => set.features[i * layout.feature_dim + j] = v,
        Target::Ignore => {}
    }
}

/// Reads a 3DGS PLY file. See the module docs for what is accepted.
pub fn read_ply(path: impl AsRef<Path>) -> Result<GaussianSet, PlyError> {
    let path = path.as_ref();
    let bytes = std::fs::read(path).map_err(|source| PlyError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    read_ply_bytes(&bytes, path)
}

/// Reads a 3DGS PLY from memory; `path` is only used to name the source in errors.
pub fn read_ply_bytes(bytes: &[u8], path: impl AsRef<Path>) -> Result<GaussianSet, PlyError> {
    let path = path.as_ref();
    let header = parse_header(path, bytes)?;
    if crate::ply_compressed::is_compressed(&header) {
        return crate::ply_compressed::read_compressed(path, &bytes[header.data_offset..], &header);
    }
    let vertex_pos = header
        .elements
        .iter()
        .position(|e| e.name == "vertex")
        .ok_or_else(|| PlyError::Property {
            path: path.to_path_buf(),
            property: "element vertex".into(),
            message: "the file has no `vertex` element".into(),
        })?;
    let layout = resolve_layout(path, &header.elements[vertex_pos])?;
    let data = &bytes[header.data_offset..];
    if header.format == Format::Ascii {
        crate::ply_ascii::read_ascii(path, data, &header, vertex_pos, &layout)
    } else {
        read_binary(path, data, &header, vertex_pos, &layout)
    }
}

pub(crate) fn empty_set(layout: &Layout) -> GaussianSet {
    GaussianSet::new(
        layout.sh_degree,
        layout.feature_dim,
        layout.semantic_classes,
    )
}

fn scalar_row_bytes(path: &Path, element: &Element) -> Result<u64, PlyError> {
    element
        .properties
        .iter()
        .try_fold(0u64, |acc, p| match p.kind {
            PropertyKind::Scalar(s) => Ok(acc + s.size() as u64),
            PropertyKind::List => Err(PlyError::Property {
                path: path.to_path_buf(),
                property: p.name.clone(),
                message: format!(
                    "list property in binary element `{}` before `vertex` is not supported",
                    element.name
                ),
            }),
        })
}

pub(crate) fn check_fits(
    path: &Path,
    element: &Element,
    row_bytes: u64,
    available: u64,
) -> Result<u64, PlyError> {
    let too_large = || PlyError::TooLarge {
        path: path.to_path_buf(),
        element: element.name.clone(),
        count: element.count,
        row_bytes,
        available,
    };
    let total = element.count.checked_mul(row_bytes).ok_or_else(too_large)?;
    if total > available {
        return Err(too_large());
    }
    Ok(total)
}

fn read_binary(
    path: &Path,
    data: &[u8],
    header: &Header,
    vertex_pos: usize,
    layout: &Layout,
) -> Result<GaussianSet, PlyError> {
    let mut offset = 0u64;
    for element in &header.elements[..vertex_pos] {
        let row = scalar_row_bytes(path, element)?;
        offset += check_fits(path, element, row, data.len() as u64 - offset)?;
    }
    let vertex = &header.elements[vertex_pos];
    let row = scalar_row_bytes(path, vertex)?;
    let available = data.len() as u64 - offset;
    let total = check_fits(path, vertex, row, available)?;
    if vertex_pos + 1 == header.elements.len() && total < available {
        return Err(PlyError::TrailingData {
            path: path.to_path_buf(),
            bytes: available - total,
        });
    }
    // The claimed count is now known to fit in the file, so reserving it is safe.
    let n = vertex.count as usize;
    let mut set = GaussianSet::zeros(
        n,
        layout.sh_degree,
        layout.feature_dim,
        layout.semantic_classes,
    );
    let start = offset as usize;
    let row = row as usize;
    let mut props = Vec::with_capacity(vertex.properties.len());
    let mut col = 0usize;
    for (p, &t) in vertex.properties.iter().zip(&layout.targets) {
        let PropertyKind::Scalar(s) = p.kind else {
            unreachable!("lists rejected by scalar_row_bytes")
        };
        props.push((col, s, t, p.name.as_str()));
        col += s.size();
    }
    for i in 0..n {
        let row_bytes = &data[start + i * row..start + (i + 1) * row];
        for &(col, s, t, name) in &props {
            if matches!(t, Target::Ignore) {
                continue;
            }
            let v = s.read_f32(&row_bytes[col..], header.format);
            if !v.is_finite() {
                return Err(PlyError::NonFinite {
                    path: path.to_path_buf(),
                    vertex: i as u64,
                    property: name.to_string(),
                    value: f64::from(v),
                });
            }
            store(&mut set, layout, i, t, v);
        }
    }
    Ok(set)
}

/// Serialises a set in the INRIA layout (binary little-endian float32), with `semantic_*` and
/// `feature_*` extra properties when the set has them.
pub fn write_ply_bytes(set: &GaussianSet) -> Result<Vec<u8>, crate::GaussianError> {
    set.validate()?;
    let k = set.sh_coeffs_per_channel();
    let rest = 3 * (k - 1);
    let mut header = String::from("ply\nformat binary_little_endian 1.0\n");
    header.push_str(&format!("element vertex {}\n", set.len()));
    let mut names: Vec<String> = [
        "x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    names.extend((0..rest).map(|j| format!("f_rest_{j}")));
    names.extend(
        [
            "opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3",
        ]
        .iter()
        .map(|s| s.to_string()),
    );
    names.extend((0..set.semantic_classes).map(|j| format!("semantic_{j}")));
    names.extend((0..set.feature_dim).map(|j| format!("feature_{j}")));
    for name in &names {
        header.push_str(&format!("property float {name}\n"));
    }
    header.push_str("end_header\n");
    let mut out = Vec::with_capacity(header.len() + set.len() * names.len() * 4);
    out.extend_from_slice(header.as_bytes());
    let mut put = |v: f32| out.extend_from_slice(&v.to_le_bytes());
    for i in 0..set.len() {
        set.means[i].iter().for_each(|&v| put(v));
        (0..3).for_each(|_| put(0.0));
        let sh = set.sh_of(i);
        (0..3).for_each(|c| put(sh[c]));
        for c in 0..3 {
            for coeff in 1..k {
                put(sh[coeff * 3 + c]);
            }
        }
        put(set.opacity_logits[i]);
        set.log_scales[i].iter().for_each(|&v| put(v));
        set.quats[i].iter().for_each(|&v| put(v));
        let s = set.semantic_classes;
        set.semantic_logits[i * s..(i + 1) * s]
            .iter()
            .for_each(|&v| put(v));
        let f = set.feature_dim;
        set.features[i * f..(i + 1) * f]
            .iter()
            .for_each(|&v| put(v));
    }
    Ok(out)
}

/// Writes a set to `path` atomically (a temporary file in the same directory, then a rename), so a
/// crash never leaves a half-written model.
pub fn write_ply(path: impl AsRef<Path>, set: &GaussianSet) -> Result<(), PlyError> {
    let path = path.as_ref();
    let bytes = write_ply_bytes(set).map_err(|source| PlyError::InvalidSet {
        path: path.to_path_buf(),
        source,
    })?;
    write_atomically(path, &bytes).map_err(|source| PlyError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// Writes `bytes` to `path` through a sibling temporary file and a rename.
pub fn write_atomically(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let file_name = path.file_name().ok_or_else(|| {
        std::io::Error::new(std::io::ErrorKind::InvalidInput, "path has no file name")
    })?;
    let mut tmp_name = file_name.to_os_string();
    tmp_name.push(format!(".tmp{}", std::process::id()));
    let tmp = path.with_file_name(tmp_name);
    {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
    }
    std::fs::rename(&tmp, path)
}
