//! Writing AEDAT 4: the IOHeader, event packets, their compression, and whole files.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

use super::header::{Compression, MAGIC};
use crate::error::{EventsError, Result};
use crate::stream::{EventStream, SensorSize};

pub(in crate::io) fn ioheader_bytes(compression: Compression, description: &str) -> Vec<u8> {
    let mut b = Vec::new();
    b.extend_from_slice(&24u32.to_le_bytes()); // root table at 24
    b.extend_from_slice(b"IOHE");
    for v in [10u16, 20, 4, 8, 16] {
        b.extend_from_slice(&v.to_le_bytes()); // vtable at 8: size, table size, 3 field offsets
    }
    b.resize(24, 0);
    b.extend_from_slice(&16i32.to_le_bytes()); // table - vtable
    b.extend_from_slice(&(compression as i32).to_le_bytes());
    b.extend_from_slice(&(-1i64).to_le_bytes());
    b.extend_from_slice(&4u32.to_le_bytes()); // string at 40 + 4 = 44
    b.extend_from_slice(&(description.len() as u32).to_le_bytes());
    b.extend_from_slice(description.as_bytes());
    b.push(0);
    while b.len() % 4 != 0 {
        b.push(0);
    }
    b
}

pub(in crate::io) fn event_packet_bytes(
    ev: &EventStream,
    range: std::ops::Range<usize>,
) -> Vec<u8> {
    let n = range.len();
    let mut b = Vec::with_capacity(32 + 16 * n);
    b.extend_from_slice(&((28 + 16 * n) as u32).to_le_bytes()); // size prefix
    b.extend_from_slice(&16u32.to_le_bytes()); // root table at 4 + 16 = 20
    b.extend_from_slice(b"EVTS");
    for v in [6u16, 8, 4] {
        b.extend_from_slice(&v.to_le_bytes()); // vtable at 12
    }
    b.extend_from_slice(&[0, 0]);
    b.extend_from_slice(&8i32.to_le_bytes()); // table at 20, vtable at 12
    b.extend_from_slice(&4u32.to_le_bytes()); // vector at 24 + 4 = 28
    b.extend_from_slice(&(n as u32).to_le_bytes());
    for i in range {
        b.extend_from_slice(&ev.t[i].to_le_bytes());
        b.extend_from_slice(&(ev.x[i] as i16).to_le_bytes());
        b.extend_from_slice(&(ev.y[i] as i16).to_le_bytes());
        b.extend_from_slice(&[u8::from(ev.p[i] > 0), 0, 0, 0]);
    }
    b
}

/// A packet payload compressed as the file says (`path` names the file in errors).
pub(in crate::io) fn compress(
    compression: Compression,
    raw: Vec<u8>,
    path: &Path,
) -> Result<Vec<u8>> {
    let io = |e: std::io::Error| EventsError::io(path, e);
    Ok(match compression {
        Compression::None => raw,
        Compression::Lz4 | Compression::Lz4High => {
            let mut enc = lz4_flex::frame::FrameEncoder::new(Vec::new());
            enc.write_all(&raw).map_err(io)?;
            enc.finish()
                .map_err(|e| EventsError::format(path, format!("LZ4 encode: {e}")))?
        }
        Compression::Zstd | Compression::ZstdHigh => {
            let level = if compression == Compression::ZstdHigh {
                19
            } else {
                3
            };
            // One-shot compression: the frame header states the decompressed size, which lets
            // readers decode it in one call.
            zstd::bulk::compress(&raw, level).map_err(io)?
        }
    })
}

/// Writes an AEDAT 4 file with one EVTS stream (id 0), packets of up to 8192 events, the given
/// compression, and the sensor size in the description (the stream's, else the events' bounding
/// box). Coordinates must fit i16.
pub fn write_aedat4(
    path: impl AsRef<Path>,
    events: &EventStream,
    compression: Compression,
) -> Result<()> {
    let path = path.as_ref();
    let io = |e: std::io::Error| EventsError::io(path, e);
    if let Some(i) =
        (0..events.len()).find(|&i| events.x[i] > i16::MAX as u16 || events.y[i] > i16::MAX as u16)
    {
        return Err(EventsError::arg(
            "events",
            format!(
                "event {i} at ({}, {}) does not fit AEDAT 4 i16 coordinates",
                events.x[i], events.y[i]
            ),
        ));
    }
    let size = events
        .sensor
        .or_else(|| events.bounding_sensor())
        .unwrap_or(SensorSize::new(1, 1));
    let name = compression.name();
    let desc = format!(
        "<dv version=\"2.0\"><node name=\"outInfo\" path=\"/mainloop/Recorder/outInfo/\">\
         <node name=\"0\" path=\"/mainloop/Recorder/outInfo/0/\">\
         <attr key=\"compression\" type=\"string\">{name}</attr>\
         <attr key=\"originalModuleName\" type=\"string\">events</attr>\
         <attr key=\"originalOutputName\" type=\"string\">events</attr>\
         <attr key=\"typeDescription\" type=\"string\">Array of events (polarity ON/OFF).</attr>\
         <attr key=\"typeIdentifier\" type=\"string\">EVTS</attr>\
         <node name=\"info\" path=\"/mainloop/Recorder/outInfo/0/info/\">\
         <attr key=\"sizeX\" type=\"int\">{}</attr><attr key=\"sizeY\" type=\"int\">{}</attr>\
         <attr key=\"source\" type=\"string\">events crate</attr></node></node></node></dv>",
        size.width, size.height
    );
    let f = File::create(path).map_err(io)?;
    let mut w = BufWriter::with_capacity(1 << 20, f);
    w.write_all(MAGIC).map_err(io)?;
    let h = ioheader_bytes(compression, &desc);
    w.write_all(&(h.len() as u32).to_le_bytes()).map_err(io)?;
    w.write_all(&h).map_err(io)?;
    let mut start = 0;
    while start < events.len() {
        let end = (start + 8192).min(events.len());
        let raw = event_packet_bytes(events, start..end);
        let payload = compress(compression, raw, path)?;
        w.write_all(&0u32.to_le_bytes()).map_err(io)?;
        w.write_all(&(payload.len() as u32).to_le_bytes())
            .map_err(io)?;
        w.write_all(&payload).map_err(io)?;
        start = end;
    }
    w.flush().map_err(io)
}
