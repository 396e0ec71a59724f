//! Reading and writing [`SpyNet`] weights as safetensors (`level{l}.conv{i}.weight|bias`, F32,
//! little-endian; names documented in the crate docs). Reading validates every tensor's presence,
//! dtype and shape and names the offending tensor in the error.

use crate::net::{Conv, KERNEL, LAYER_CHANNELS};
use crate::{FlowError, PyramidDepth, SpyNet};
use safetensors::tensor::{Dtype, TensorView};
use safetensors::SafeTensors;
use std::collections::HashMap;
use std::io::Write;
use std::path::Path;

fn tensor_name(l: usize, i: usize, what: &str) -> String {
    format!("level{l}.conv{i}.{what}")
}

/// Metadata key of the pyramid rule: `halve-while-above:N` for [`PyramidDepth::HalveWhileAbove`];
/// absent for [`PyramidDepth::AllLevels`] (so files written before the key existed read as they
/// were trained).
pub const PYRAMID_KEY: &str = "pyramid";

/// Serialises `net` to safetensors bytes (metadata: `format = spynet`, `levels = L`, and
/// [`PYRAMID_KEY`] unless the rule is [`PyramidDepth::AllLevels`]).
pub fn write_safetensors(net: &SpyNet<f32>) -> Result<Vec<u8>, FlowError> {
    let mut buffers: Vec<(String, Vec<usize>, Vec<u8>)> = Vec::new();
    for (l, level) in net.levels.iter().enumerate() {
        for (i, c) in level.iter().enumerate() {
            let (ci, co) = LAYER_CHANNELS[i];
            let bytes = |v: &[f32]| v.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<u8>>();
            buffers.push((
                tensor_name(l, i, "weight"),
                vec![co, ci, KERNEL, KERNEL],
                bytes(&c.weight),
            ));
            buffers.push((tensor_name(l, i, "bias"), vec![co], bytes(&c.bias)));
        }
    }
    let views = buffers
        .iter()
        .map(|(n, s, b)| Ok((n.clone(), TensorView::new(Dtype::F32, s.clone(), b)?)))
        .collect::<Result<Vec<_>, FlowError>>()?;
    let mut meta = HashMap::from([
        ("format".to_string(), "spynet".to_string()),
        ("levels".to_string(), net.num_levels().to_string()),
    ]);
    if let PyramidDepth::HalveWhileAbove(side) = net.depth {
        meta.insert(PYRAMID_KEY.into(), format!("halve-while-above:{side}"));
    }
    let bytes = safetensors::serialize(views, Some(meta))?;
    Ok(with_sorted_metadata(bytes))
}

/// Rewrites a safetensors file's header with its `__metadata__` entries in key order: the container
/// crate takes the metadata as a `HashMap` and writes it in that map's random iteration order, so the
/// same network would otherwise give different bytes from run to run. Returns the input unchanged if
/// its header is not the JSON object the crate writes.
fn with_sorted_metadata(bytes: Vec<u8>) -> Vec<u8> {
    let Some(len) = bytes
        .get(..8)
        .and_then(|b| <[u8; 8]>::try_from(b).ok())
        .map(u64::from_le_bytes)
        .and_then(|n| usize::try_from(n).ok())
    else {
        return bytes;
    };
    let Some(header) = bytes.get(8..8 + len) else {
        return bytes;
    };
    let Ok(serde_json::Value::Object(mut top)) = serde_json::from_slice(header) else {
        return bytes;
    };
    if let Some(serde_json::Value::Object(meta)) = top.get_mut("__metadata__") {
        let sorted: std::collections::BTreeMap<String, serde_json::Value> =
            std::mem::take(meta).into_iter().collect();
        meta.extend(sorted);
    }
    let Ok(mut text) = serde_json::to_string(&serde_json::Value::Object(top)) else {
        return bytes;
    };
    // The container pads its header with spaces to a multiple of 8 bytes.
    while text.len() % 8 != 0 {
        text.push(' ');
    }
    let mut out = Vec::with_capacity(8 + text.len() + bytes.len() - 8 - len);
    out.extend_from_slice(&(text.len() as u64).to_le_bytes());
    out.extend_from_slice(text.as_bytes());
    out.extend_from_slice(&bytes[8 + len..]);
    out
}

/// The pyramid rule recorded in a file's metadata (see [`PYRAMID_KEY`]).
fn read_depth(bytes: &[u8]) -> Result<PyramidDepth, FlowError> {
    let (_, meta) = SafeTensors::read_metadata(bytes)?;
    let Some(value) = meta.metadata().as_ref().and_then(|m| m.get(PYRAMID_KEY)) else {
        return Ok(PyramidDepth::AllLevels);
    };
    let side = match value.as_str() {
        "all-levels" => return Ok(PyramidDepth::AllLevels),
        v => v
            .strip_prefix("halve-while-above:")
            .and_then(|n| n.parse::<usize>().ok())
            .filter(|&n| n > 0),
    };
    side.map(PyramidDepth::HalveWhileAbove)
        .ok_or_else(|| FlowError::Metadata {
            key: PYRAMID_KEY.into(),
            value: value.clone(),
            expected: "all-levels or halve-while-above:N (N > 0)".into(),
        })
}

/// Parses safetensors bytes into a network; the number of levels is the number of consecutive
/// `level{l}.conv0.weight` tensors present, the pyramid rule the [`PYRAMID_KEY`] metadata entry.
pub fn read_safetensors(bytes: &[u8]) -> Result<SpyNet<f32>, FlowError> {
    let st = SafeTensors::deserialize(bytes)?;
    let depth = read_depth(bytes)?;
    let names: std::collections::HashSet<String> =
        st.names().into_iter().map(str::to_string).collect();
    let mut levels = 0;
    while names.contains(&tensor_name(levels, 0, "weight")) {
        levels += 1;
    }
    if levels == 0 {
        return Err(FlowError::NoLevels);
    }
    let mut net = SpyNet::<f32>::zeros(levels);
    for l in 0..levels {
        let mut convs = Vec::with_capacity(5);
        for (i, &(ci, co)) in LAYER_CHANNELS.iter().enumerate() {
            let read = |what: &str, shape: Vec<usize>| -> Result<Vec<f32>, FlowError> {
                Ok(nn::tensors::read_f32(
                    &st,
                    &tensor_name(l, i, what),
                    &shape,
                )?)
            };
            convs.push(Conv {
                weight: read("weight", vec![co, ci, KERNEL, KERNEL])?,
                bias: read("bias", vec![co])?,
            });
        }
        net.levels[l] = convs;
    }
    Ok(net.with_depth(depth))
}

/// Writes `net` to a safetensors file atomically: to a temporary file beside `path`, synced, then
/// renamed over it, so an interrupted write leaves any previous file at `path` intact.
pub fn save_safetensors(net: &SpyNet<f32>, path: &Path) -> Result<(), FlowError> {
    let bytes = write_safetensors(net)?;
    let io = |source| FlowError::Io {
        path: path.display().to_string(),
        source,
    };
    let name = path.file_name().ok_or_else(|| {
        io(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            "the path names no file",
        ))
    })?;
    let mut tmp_name = name.to_os_string();
    tmp_name.push(format!(".partial{}", std::process::id()));
    let tmp = path.with_file_name(tmp_name);
    let written = std::fs::File::create(&tmp).and_then(|mut file| {
        file.write_all(&bytes)?;
        file.sync_all()
    });
    match written.and_then(|()| std::fs::rename(&tmp, path)) {
        Ok(()) => Ok(()),
        Err(source) => {
            // Best effort: the error to report is the write's, not the clean-up's.
            let _ = std::fs::remove_file(&tmp);
            Err(io(source))
        }
    }
}

/// Reads a network from a safetensors file.
pub fn load_safetensors(path: &Path) -> Result<SpyNet<f32>, FlowError> {
    let bytes = std::fs::read(path).map_err(|source| FlowError::Io {
        path: path.display().to_string(),
        source,
    })?;
    read_safetensors(&bytes)
}
