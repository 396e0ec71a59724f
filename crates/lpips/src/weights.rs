//! Reading the LPIPS AlexNet weights from safetensors (names and layout in the crate docs). Every
//! tensor's presence, dtype and shape is checked against [`ALEXNET_CHANNELS`] and the offending
//! tensor is named in the error; nothing is allocated from an unchecked size.

use crate::net::{ALEXNET_CHANNELS, KERNELS};
use crate::{Lpips, LpipsError};
use safetensors::SafeTensors;
use std::path::Path;

/// Parses safetensors bytes into the AlexNet LPIPS network (f32).
pub fn read_safetensors(bytes: &[u8]) -> Result<Lpips<f32>, LpipsError> {
    let st = SafeTensors::deserialize(bytes)?;
    let read = |name: String, shape: Vec<usize>| -> Result<Vec<f32>, LpipsError> {
        Ok(nn::tensors::read_f32(&st, &name, &shape)?)
    };
    let mut weights: [Vec<f32>; 5] = Default::default();
    let mut biases: [Vec<f32>; 5] = Default::default();
    let mut heads: [Vec<f32>; 5] = Default::default();
    for i in 0..5 {
        let c_out = ALEXNET_CHANNELS[i];
        let c_in = if i == 0 { 3 } else { ALEXNET_CHANNELS[i - 1] };
        let k = KERNELS[i];
        weights[i] = read(format!("conv{i}.weight"), vec![c_out, c_in, k, k])?;
        biases[i] = read(format!("conv{i}.bias"), vec![c_out])?;
        heads[i] = read(format!("lin{i}.weight"), vec![1, c_out, 1, 1])?;
    }
    Lpips::from_parts(weights, biases, heads)
}

/// Reads the AlexNet LPIPS network from a safetensors file.
pub fn load_safetensors(path: &Path) -> Result<Lpips<f32>, LpipsError> {
    let bytes = std::fs::read(path).map_err(|source| LpipsError::Io {
        path: path.display().to_string(),
        source,
    })?;
    read_safetensors(&bytes)
}
