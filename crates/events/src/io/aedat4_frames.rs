//! Intensity frames of an AEDAT 4 file: the `FRME` stream a DAVIS camera records beside its events
//! (APS frames). A packet's payload is (after decompression) a size-prefixed FlatBuffers `Frame`
//! table with file identifier `FRME`, fields in schema order: `t` (µs, exposure midpoint),
//! `begin_t`, `end_t` (readout), `exposure_begin_t`, `exposure_end_t` (all i64 µs), `format` (i8,
//! OpenCV type code: 0 grey 8-bit, 2 grey 16-bit, 16 BGR, 24 BGRA; default 0), `width`, `height`,
//! `offset_x`, `offset_y` (i16) and `pixels` (`[uint8]`, row-major, top row first, 16-bit samples
//! little-endian).
//!
//! Every offset is bounds-checked, the pixel vector's length must equal what the header's size and
//! format imply, and no buffer is sized by a header value before it is checked against the bytes
//! present. Frames are kept in their stored form ([`ApsFrame::pixels`]) and converted one at a time
//! ([`ApsFrame::to_planar`]).

use std::fs::File;
use std::io::{BufReader, BufWriter, Read, Write};
use std::path::Path;

use super::aedat4::{
    compress, decompress, find_stream, ioheader_bytes, read_header, Compression, Fb, MAGIC,
    MAX_PACKET,
};
use crate::error::{EventsError, Result};
use crate::stream::{EventStream, SensorSize};

/// Pixel layout of a frame (the schema's `FrameFormat`, an OpenCV type code).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FrameFormat {
    /// One 8-bit channel (code 0).
    Gray,
    /// One 16-bit little-endian channel (code 2).
    Gray16,
    /// Blue, green, red, 8 bits each (code 16).
    Bgr,
    /// Blue, green, red, alpha, 8 bits each (code 24; alpha ignored).
    Bgra,
}

impl FrameFormat {
    fn from_code(code: i8) -> Option<Self> {
        Some(match code {
            0 => Self::Gray,
            2 => Self::Gray16,
            16 => Self::Bgr,
            24 => Self::Bgra,
            _ => return None,
        })
    }

    fn code(self) -> i8 {
        match self {
            Self::Gray => 0,
            Self::Gray16 => 2,
            Self::Bgr => 16,
            Self::Bgra => 24,
        }
    }

    /// Bytes per pixel.
    pub fn bytes_per_pixel(self) -> usize {
        match self {
            Self::Gray => 1,
            Self::Gray16 => 2,
            Self::Bgr => 3,
            Self::Bgra => 4,
        }
    }

    /// Colour channels of the converted image: 1 (grey) or 3 (RGB).
    pub fn channels(self) -> usize {
        match self {
            Self::Gray | Self::Gray16 => 1,
            Self::Bgr | Self::Bgra => 3,
        }
    }
}

/// One frame of a `FRME` stream.
#[derive(Clone, Debug, PartialEq)]
pub struct ApsFrame {
    /// Exposure midpoint (µs, the file's clock).
    pub t_us: i64,
    /// Start of the exposure (µs).
    pub exposure_begin_us: i64,
    /// End of the exposure (µs).
    pub exposure_end_us: i64,
    /// Pixel layout of [`ApsFrame::pixels`].
    pub format: FrameFormat,
    /// Width (pixels).
    pub width: u32,
    /// Height (pixels).
    pub height: u32,
    /// Position of the frame's left column on the sensor (a region of interest when non-zero).
    pub offset_x: u32,
    /// Position of the frame's top row on the sensor.
    pub offset_y: u32,
    /// The stored samples, row-major, top row first (`width · height · bytes_per_pixel` bytes).
    pub pixels: Vec<u8>,
}

impl ApsFrame {
    /// The frame as planar `(channels, H, W)` values in `[0, 1]` (code / 255 or / 65535), RGB
    /// order for colour frames.
    pub fn to_planar(&self) -> Vec<f32> {
        let n = self.width as usize * self.height as usize;
        let bpp = self.format.bytes_per_pixel();
        let mut out = vec![0.0f32; self.format.channels() * n];
        for (i, px) in self.pixels.chunks_exact(bpp).take(n).enumerate() {
            match self.format {
                FrameFormat::Gray => out[i] = f32::from(px[0]) / 255.0,
                FrameFormat::Gray16 => {
                    out[i] = f32::from(u16::from_le_bytes([px[0], px[1]])) / 65535.0;
                }
                FrameFormat::Bgr | FrameFormat::Bgra => {
                    for c in 0..3 {
                        out[c * n + i] = f32::from(px[2 - c]) / 255.0;
                    }
                }
            }
        }
        out
    }
}

/// Reads every frame of the first `FRME` stream of an AEDAT 4 file, in file order, with the sensor
/// size the stream's description states (if any). A file without a `FRME` stream is an error
/// naming the file.
pub fn read_aedat4_frames(path: impl AsRef<Path>) -> Result<(Vec<ApsFrame>, Option<SensorSize>)> {
    let path = path.as_ref();
    let f = File::open(path).map_err(|e| EventsError::io(path, e))?;
    let file_len = f.metadata().map_err(|e| EventsError::io(path, e))?.len();
    let mut reader = BufReader::with_capacity(1 << 20, f);
    let (header, mut position) = read_header(&mut reader, file_len, path)?;
    let (stream_id, sensor) = find_stream(&header.description, "FRME").ok_or_else(|| {
        EventsError::format(
            path,
            "the description has no FRME (frames) stream: the recording holds no intensity frames",
        )
    })?;
    let mut zstd = zstd::zstd_safe::DCtx::try_create();
    let (mut raw, mut payload) = (Vec::new(), Vec::new());
    let mut frames = Vec::new();
    loop {
        if header.data_table_position >= 0 && position >= header.data_table_position as u64 {
            break;
        }
        let mut hdr = [0u8; 8];
        match super::read_full(&mut reader, &mut hdr) {
            Ok(0) => break,
            Ok(8) => {}
            Ok(n) => {
                return Err(EventsError::format(
                    path,
                    format!("truncated packet header at byte {position} ({n} of 8 bytes)"),
                ))
            }
            Err(e) => return Err(EventsError::io(path, e)),
        }
        let id = u32::from_le_bytes([hdr[0], hdr[1], hdr[2], hdr[3]]);
        let size = u64::from(u32::from_le_bytes([hdr[4], hdr[5], hdr[6], hdr[7]]));
        let remaining = file_len.saturating_sub(position + 8);
        if size > remaining || size > MAX_PACKET {
            return Err(EventsError::format(
                path,
                format!("packet at byte {position} claims {size} bytes, only {remaining} remain"),
            ));
        }
        raw.resize(size as usize, 0);
        reader.read_exact(&mut raw).map_err(|_| {
            EventsError::format(path, format!("truncated packet at byte {position}"))
        })?;
        let at = position;
        position += 8 + size;
        if id != stream_id {
            continue;
        }
        decompress(
            header.compression,
            &raw,
            zstd.as_mut(),
            MAX_PACKET,
            &mut payload,
        )
        .map_err(|e| {
            EventsError::format(path, format!("packet at byte {at}: decompression: {e}"))
        })?;
        let frame = parse_frame(&payload)
            .map_err(|m| EventsError::format(path, format!("frame packet at byte {at}: {m}")))?;
        frames.push(frame);
    }
    Ok((frames, sensor))
}

fn parse_frame(buf: &[u8]) -> std::result::Result<ApsFrame, String> {
    let fb = Fb(buf);
    if fb.bytes(8, 4) != Some(b"FRME") {
        return Err("identifier is not FRME".into());
    }
    let table = fb.deref(4).ok_or("root offset out of bounds")?;
    let field = |i| fb.field(table, i).ok_or("table or vtable out of bounds");
    let i64_of = |i| -> std::result::Result<i64, String> {
        match field(i)? {
            Some(p) => fb.i64(p).ok_or_else(|| format!("field {i} out of bounds")),
            None => Ok(0),
        }
    };
    let i16_of = |i| -> std::result::Result<i16, String> {
        match field(i)? {
            Some(p) => fb
                .u16(p)
                .map(|v| v as i16)
                .ok_or_else(|| format!("field {i} out of bounds")),
            None => Ok(0),
        }
    };
    let t_us = i64_of(0)?;
    let exposure_begin_us = i64_of(3)?;
    let exposure_end_us = i64_of(4)?;
    let code = match field(5)? {
        Some(p) => fb.bytes(p, 1).ok_or("format out of bounds")?[0] as i8,
        None => 0,
    };
    let format = FrameFormat::from_code(code).ok_or_else(|| {
        format!("pixel format {code} (OpenCV type code) is not grey (0), grey 16-bit (2), BGR (16) or BGRA (24)")
    })?;
    let (width, height) = (i16_of(6)?, i16_of(7)?);
    let (offset_x, offset_y) = (i16_of(8)?, i16_of(9)?);
    if width <= 0 || height <= 0 || offset_x < 0 || offset_y < 0 {
        return Err(format!(
            "size {width}x{height} at ({offset_x}, {offset_y}) is not a positive size at a non-negative position"
        ));
    }
    let expected = width as usize * height as usize * format.bytes_per_pixel();
    let pixels = match field(10)? {
        Some(p) => {
            let s = fb.deref(p).ok_or("pixels offset out of bounds")?;
            let n = fb.u32(s).ok_or("pixels length out of bounds")? as usize;
            if n != expected {
                return Err(format!(
                    "{n} pixel bytes, a {width}x{height} {format:?} frame has {expected}"
                ));
            }
            fb.bytes(s + 4, n)
                .ok_or_else(|| format!("pixel bytes ({n}) out of bounds"))?
                .to_vec()
        }
        None => return Err("no pixels".into()),
    };
    Ok(ApsFrame {
        t_us,
        exposure_begin_us,
        exposure_end_us,
        format,
        width: width as u32,
        height: height as u32,
        offset_x: offset_x as u32,
        offset_y: offset_y as u32,
        pixels,
    })
}

/// The size-prefixed `FRME` payload of one frame (see the module documentation for the layout).
fn frame_packet_bytes(f: &ApsFrame) -> Vec<u8> {
    // [0] size prefix, [4] root offset, [8] "FRME", [12] vtable (26 bytes, padded to 28),
    // [40] table (64 bytes: soffset, pad, 5 × i64, 4 × i16, format, pad, pixels offset),
    // [104] pixel vector.
    let mut b = Vec::with_capacity(108 + f.pixels.len());
    b.extend_from_slice(&0u32.to_le_bytes());
    b.extend_from_slice(&36u32.to_le_bytes()); // table at 4 + 36 = 40
    b.extend_from_slice(b"FRME");
    let offsets: [u16; 11] = [8, 16, 24, 32, 40, 56, 48, 50, 52, 54, 60];
    b.extend_from_slice(&26u16.to_le_bytes());
    b.extend_from_slice(&64u16.to_le_bytes());
    for o in offsets {
        b.extend_from_slice(&o.to_le_bytes());
    }
    b.resize(40, 0);
    b.extend_from_slice(&28i32.to_le_bytes()); // table 40 − vtable 12
    b.extend_from_slice(&[0; 4]);
    for t in [
        f.t_us,
        f.exposure_begin_us,
        f.exposure_end_us,
        f.exposure_begin_us,
        f.exposure_end_us,
    ] {
        b.extend_from_slice(&t.to_le_bytes());
    }
    for v in [f.width, f.height, f.offset_x, f.offset_y] {
        b.extend_from_slice(&(v as i16).to_le_bytes());
    }
    b.push(f.format.code() as u8);
    b.extend_from_slice(&[0; 3]);
    b.extend_from_slice(&4u32.to_le_bytes()); // vector at 100 + 4 = 104
    b.extend_from_slice(&(f.pixels.len() as u32).to_le_bytes());
    b.extend_from_slice(&f.pixels);
    let size = (b.len() - 4) as u32;
    b[..4].copy_from_slice(&size.to_le_bytes());
    b
}

/// Writes an AEDAT 4 file with an `EVTS` stream (id 0) holding `events` and a `FRME` stream (id 1)
/// holding `frames` (the readout times are written as the exposure's), both of size `sensor`:
/// what a DAVIS recording holds, for tests and for users converting their data.
pub fn write_aedat4_with_frames(
    path: impl AsRef<Path>,
    events: &EventStream,
    frames: &[ApsFrame],
    sensor: SensorSize,
    compression: Compression,
) -> Result<()> {
    let path = path.as_ref();
    let io = |e: std::io::Error| EventsError::io(path, e);
    let stream = |id: u32, kind: &str| {
        format!(
            "<node name=\"{id}\" path=\"/mainloop/Recorder/outInfo/{id}/\">\
             <attr key=\"compression\" type=\"string\">{}</attr>\
             <attr key=\"typeIdentifier\" type=\"string\">{kind}</attr>\
             <node name=\"info\" path=\"/mainloop/Recorder/outInfo/{id}/info/\">\
             <attr key=\"sizeX\" type=\"int\">{}</attr><attr key=\"sizeY\" type=\"int\">{}</attr>\
             </node></node>",
            compression.name(),
            sensor.width,
            sensor.height
        )
    };
    let desc = format!(
        "<dv version=\"2.0\"><node name=\"outInfo\" path=\"/mainloop/Recorder/outInfo/\">{}{}</node></dv>",
        stream(0, "EVTS"),
        stream(1, "FRME")
    );
    let mut w = BufWriter::new(File::create(path).map_err(io)?);
    w.write_all(MAGIC).map_err(io)?;
    let h = ioheader_bytes(compression, &desc);
    w.write_all(&(h.len() as u32).to_le_bytes()).map_err(io)?;
    w.write_all(&h).map_err(io)?;
    let packet = |id: u32, raw: Vec<u8>, w: &mut BufWriter<File>| -> Result<()> {
        let payload = compress(compression, raw, path)?;
        w.write_all(&id.to_le_bytes()).map_err(io)?;
        w.write_all(&(payload.len() as u32).to_le_bytes())
            .map_err(io)?;
        w.write_all(&payload).map_err(io)
    };
    let mut start = 0;
    while start < events.len() {
        let end = (start + 8192).min(events.len());
        packet(
            0,
            super::aedat4::event_packet_bytes(events, start..end),
            &mut w,
        )?;
        start = end;
    }
    for f in frames {
        packet(1, frame_packet_bytes(f), &mut w)?;
    }
    w.flush().map_err(io)
}
