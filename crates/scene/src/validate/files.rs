//! The checks of the files a scene names: a relative path that exists, a PNG of the expected kind
//! and size, a `.flo` whose header and length agree.

use super::*;

impl Checker<'_> {
    /// A relative path; when a directory is known, the file must exist.
    pub(super) fn rel_file(&mut self, v: &Value, path: &str) -> Option<std::path::PathBuf> {
        let s = self.string(v, path)?;
        let p = Path::new(s);
        if s.is_empty() || p.is_absolute() || s.contains('\\') {
            self.bad(
                path,
                format!("\"{s}\" must be a non-empty relative path with / separators"),
            );
            return None;
        }
        if p.components()
            .any(|c| matches!(c, std::path::Component::ParentDir))
        {
            self.bad(
                path,
                format!("\"{s}\" must stay inside the scene directory (no ..)"),
            );
            return None;
        }
        let dir = self.dir?;
        let full = dir.join(p);
        if !full.is_file() {
            self.bad(path, format!("{s}: file does not exist"));
            return None;
        }
        Some(full)
    }

    pub(super) fn png(&mut self, v: &Value, path: &str, kind: PngKind, size: Option<(u32, u32)>) {
        let Some(full) = self.rel_file(v, path) else {
            return;
        };
        let name = v.as_str().unwrap_or_default().to_string();
        let decoder = image::ImageReader::open(&full)
            .map_err(|e| e.to_string())
            .and_then(|r| r.with_guessed_format().map_err(|e| e.to_string()))
            .and_then(|r| r.into_decoder().map_err(|e| e.to_string()));
        let d = match decoder {
            Ok(d) => d,
            Err(e) => {
                self.bad(path, format!("{name}: not a readable image: {e}"));
                return;
            }
        };
        let (w, h) = d.dimensions();
        if let Some((ew, eh)) = size {
            if (w, h) != (ew, eh) {
                self.bad(
                    path,
                    format!("{name}: image is {w}x{h}, the camera is {ew}x{eh}"),
                );
            }
        }
        let ct = d.color_type();
        let ok = match kind {
            PngKind::Rgb(8) => ct == image::ColorType::Rgb8,
            PngKind::Rgb(_) => ct == image::ColorType::Rgb16,
            PngKind::Grey(8) => ct == image::ColorType::L8,
            PngKind::Grey(_) => ct == image::ColorType::L16,
            PngKind::Mask => matches!(ct, image::ColorType::L8 | image::ColorType::L16),
        };
        if !ok {
            let want = match kind {
                PngKind::Rgb(b) => format!("{b}-bit RGB (images.bit_depth)"),
                PngKind::Grey(b) => {
                    format!("{b}-bit single channel (images.bit_depth, images.channels = 1)")
                }
                PngKind::Mask => "8- or 16-bit single channel".into(),
            };
            self.bad(
                path,
                format!("{name}: pixel format {ct:?}, expected {want}"),
            );
        }
    }

    pub(super) fn flo(&mut self, v: &Value, path: &str, size: Option<(u32, u32)>) {
        let Some(full) = self.rel_file(v, path) else {
            return;
        };
        let name = v.as_str().unwrap_or_default().to_string();
        let mut head = [0u8; 12];
        let res = std::fs::File::open(&full).and_then(|mut f| {
            f.read_exact(&mut head)?;
            f.metadata().map(|m| m.len())
        });
        let len = match res {
            Ok(len) => len,
            Err(e) => {
                self.bad(path, format!("{name}: cannot read the .flo header: {e}"));
                return;
            }
        };
        let word = |i: usize| {
            [
                head[4 * i],
                head[4 * i + 1],
                head[4 * i + 2],
                head[4 * i + 3],
            ]
        };
        let magic = f32::from_le_bytes(word(0));
        if magic != FLO_MAGIC {
            self.bad(
                path,
                format!("{name}: magic {magic} is not 202021.25 (not a .flo file)"),
            );
            return;
        }
        let (w, h) = (i32::from_le_bytes(word(1)), i32::from_le_bytes(word(2)));
        if let Some((ew, eh)) = size {
            if (i64::from(w), i64::from(h)) != (i64::from(ew), i64::from(eh)) {
                self.bad(
                    path,
                    format!("{name}: flow is {w}x{h}, the camera is {ew}x{eh}"),
                );
                return;
            }
        }
        let expect = 12 + 8 * (w.max(0) as u64) * (h.max(0) as u64);
        if len != expect {
            self.bad(
                path,
                format!("{name}: {len} bytes, a {w}x{h} .flo has {expect}"),
            );
        }
    }
}
