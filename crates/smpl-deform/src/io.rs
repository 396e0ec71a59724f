//! Writing posed meshes for inspection: float32 `.npy` arrays and Wavefront OBJ. Small, dependency-
//! light helpers so the xtask stays thin; they never read user files.

use std::io::Write;
use std::path::Path;

use npyz::WriterBuilder;

use crate::error::{Result, SmplDeformError};

fn io_err(path: &Path) -> impl Fn(std::io::Error) -> SmplDeformError + '_ {
    move |source| SmplDeformError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// Writes vertices as a little-endian float32 `.npy` of shape `(V, 3)`.
pub fn write_npy_vertices(path: &Path, vertices: &[[f32; 3]]) -> Result<()> {
    let file = std::fs::File::create(path).map_err(io_err(path))?;
    let mut w = npyz::WriteOptions::new()
        .default_dtype()
        .shape(&[vertices.len() as u64, 3])
        .writer(std::io::BufWriter::new(file))
        .begin_nd()
        .map_err(io_err(path))?;
    w.extend(vertices.iter().flatten().copied())
        .map_err(io_err(path))?;
    w.finish().map_err(io_err(path))
}

/// Writes a triangle mesh as OBJ (positions and faces; 1-based indices).
pub fn write_obj(path: &Path, vertices: &[[f32; 3]], faces: &[[u32; 3]]) -> Result<()> {
    let file = std::fs::File::create(path).map_err(io_err(path))?;
    let mut w = std::io::BufWriter::new(file);
    let mut write = || -> std::io::Result<()> {
        for v in vertices {
            writeln!(w, "v {} {} {}", v[0], v[1], v[2])?;
        }
        for f in faces {
            writeln!(w, "f {} {} {}", f[0] + 1, f[1] + 1, f[2] + 1)?;
        }
        w.flush()
    };
    write().map_err(io_err(path))
}
