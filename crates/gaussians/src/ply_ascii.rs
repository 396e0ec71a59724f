//! The ASCII body of a 3DGS PLY (`format ascii 1.0`): rows parsed line by line into a set, nothing
//! reserved from the header's count; see [`crate::ply`] for the layout and the errors.

use crate::ply::{empty_set, store, Header, Layout, PlyError, PropertyKind, Target};
use crate::set::GaussianSet;
use crate::sh::num_sh_coeffs;
use std::path::Path;

/// Reads the vertex rows of an ASCII body (`data`, after the header); `vertex_pos` is the vertex
/// element's index in `header.elements`.
pub(crate) fn read_ascii(
    path: &Path,
    data: &[u8],
    header: &Header,
    vertex_pos: usize,
    layout: &Layout,
) -> Result<GaussianSet, PlyError> {
    let text = std::str::from_utf8(data).map_err(|_| PlyError::Header {
        path: path.to_path_buf(),
        line: 0,
        message: "ASCII body is not valid UTF-8".into(),
    })?;
    let mut lines = text.lines().filter(|l| !l.trim().is_empty());
    for element in &header.elements[..vertex_pos] {
        for _ in 0..element.count {
            if lines.next().is_none() {
                return Err(PlyError::Truncated {
                    path: path.to_path_buf(),
                    vertex: 0,
                    property: format!("element {}", element.name),
                });
            }
        }
    }
    let vertex = &header.elements[vertex_pos];
    let sh_stride = num_sh_coeffs(layout.sh_degree) * 3;
    // Rows are appended as they are parsed: nothing is reserved from the header's claim.
    let mut set = empty_set(layout);
    let row_zero = GaussianSet::zeros(
        1,
        layout.sh_degree,
        layout.feature_dim,
        layout.semantic_classes,
    );
    for i in 0..vertex.count {
        let first_prop = vertex
            .properties
            .first()
            .map_or("vertex", |p| p.name.as_str());
        let line = lines.next().ok_or_else(|| PlyError::Truncated {
            path: path.to_path_buf(),
            vertex: i,
            property: first_prop.to_string(),
        })?;
        set.append(&row_zero)
            .map_err(|source| PlyError::InvalidSet {
                path: path.to_path_buf(),
                source,
            })?;
        let idx = set.len() - 1;
        debug_assert_eq!(set.sh.len(), set.len() * sh_stride);
        let mut tokens = line.split_whitespace();
        for (p, &t) in vertex.properties.iter().zip(&layout.targets) {
            let mut next = || {
                tokens.next().ok_or_else(|| PlyError::Truncated {
                    path: path.to_path_buf(),
                    vertex: i,
                    property: p.name.clone(),
                })
            };
            let parse = |tok: &str| {
                tok.parse::<f64>().map_err(|_| PlyError::Parse {
                    path: path.to_path_buf(),
                    vertex: i,
                    property: p.name.clone(),
                    value: tok.to_string(),
                })
            };
            match p.kind {
                PropertyKind::Scalar(_) => {
                    let tok = next()?;
                    if matches!(t, Target::Ignore) {
                        continue;
                    }
                    let v = parse(tok)?;
                    if !v.is_finite() {
                        return Err(PlyError::NonFinite {
                            path: path.to_path_buf(),
                            vertex: i,
                            property: p.name.clone(),
                            value: v,
                        });
                    }
                    store(&mut set, layout, idx, t, v as f32);
                }
                PropertyKind::List => {
                    let count = parse(next()?)?;
                    if !(0.0..=1e6).contains(&count) || count.fract() != 0.0 {
                        return Err(PlyError::Parse {
                            path: path.to_path_buf(),
                            vertex: i,
                            property: p.name.clone(),
                            value: count.to_string(),
                        });
                    }
                    for _ in 0..count as usize {
                        next()?;
                    }
                }
            }
        }
    }
    Ok(set)
}
