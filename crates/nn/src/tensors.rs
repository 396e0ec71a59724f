//! Checked f32 tensors out of a parsed safetensors container: the one reader the weight loaders of
//! the networks built on this crate share (`flow`'s SpyNet, `lpips`' AlexNet). It reads bytes
//! already in memory, never files; every tensor's presence, element type and shape is checked and
//! the tensor named in the error, so nothing is allocated from an unchecked size.

use safetensors::tensor::Dtype;
use safetensors::SafeTensors;

/// Why a tensor could not be read.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum TensorError {
    /// The tensor is absent.
    #[error("missing tensor {name}")]
    Missing {
        /// Tensor name.
        name: String,
    },
    /// The tensor is not F32.
    #[error("tensor {name}: unsupported dtype {dtype} (expected F32)")]
    WrongDtype {
        /// Tensor name.
        name: String,
        /// Element type found.
        dtype: String,
    },
    /// The tensor has another shape.
    #[error("tensor {name}: expected shape {expected:?}, found {actual:?}")]
    WrongShape {
        /// Tensor name.
        name: String,
        /// Shape required.
        expected: Vec<usize>,
        /// Shape found.
        actual: Vec<usize>,
    },
}

/// The F32 tensor `name` of `st`, which must have exactly `shape`, as little-endian-decoded values
/// in row-major order.
pub fn read_f32(
    st: &SafeTensors<'_>,
    name: &str,
    shape: &[usize],
) -> Result<Vec<f32>, TensorError> {
    let t = st.tensor(name).map_err(|_| TensorError::Missing {
        name: name.to_string(),
    })?;
    if t.dtype() != Dtype::F32 {
        return Err(TensorError::WrongDtype {
            name: name.to_string(),
            dtype: format!("{:?}", t.dtype()),
        });
    }
    if t.shape() != shape {
        return Err(TensorError::WrongShape {
            name: name.to_string(),
            expected: shape.to_vec(),
            actual: t.shape().to_vec(),
        });
    }
    // The container has checked that the data spans exactly the shape's F32 values.
    Ok(t.data()
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect())
}
