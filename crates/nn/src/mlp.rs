//! Multi-layer perceptrons on batches: a stack of dense layers with one hidden activation, no output
//! activation (the caller applies sigmoid/softmax as its loss needs). Parameters live in one flat vector
//! (per layer: weight `(outputs, inputs)` row-major, then bias) so an optimiser and a weights file see
//! a single tensor per network. Forward keeps the activations needed by the backward pass.
//!
//! Used by the deformation networks (`smpl-deform`) and the colour networks (`train`); it must not know
//! what its inputs mean.

use crate::{check_len, dense_backward, dense_forward, DenseShape, NnError, Real};
use rand::{Rng, SeedableRng};
use rayon::prelude::*;

/// Hidden-layer activation of an [`Mlp`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Activation {
    /// max(0, x).
    Relu,
    /// x if x > 0, else slope·x (PyTorch's default slope is 0.01).
    LeakyRelu(f64),
}

impl Activation {
    #[inline]
    fn apply<T: Real>(self, x: T) -> T {
        match self {
            Self::Relu => x.max(T::zero()),
            Self::LeakyRelu(s) => {
                if x > T::zero() {
                    x
                } else {
                    x * T::of(s)
                }
            }
        }
    }

    #[inline]
    fn derivative<T: Real>(self, x: T) -> T {
        match self {
            Self::Relu => {
                if x > T::zero() {
                    T::one()
                } else {
                    T::zero()
                }
            }
            Self::LeakyRelu(s) => {
                if x > T::zero() {
                    T::one()
                } else {
                    T::of(s)
                }
            }
        }
    }
}

/// A fully connected network `sizes[0] → sizes[1] → … → sizes[L]` with `activation` after every layer
/// but the last.
#[derive(Clone, Debug, PartialEq)]
pub struct Mlp<T: Real> {
    /// Layer widths, input first, output last (at least two entries).
    pub sizes: Vec<usize>,
    /// Activation after each hidden layer.
    pub activation: Activation,
    /// All weights and biases, flattened layer by layer (weight `(out, in)` row-major, then bias `(out)`).
    pub params: Vec<T>,
}

/// Activations of one forward pass, needed by [`Mlp::backward`].
#[derive(Clone, Debug, Default)]
pub struct MlpCache<T> {
    batch: usize,
    /// Input of each layer (`inputs[0]` is the network input).
    inputs: Vec<Vec<T>>,
    /// Pre-activation output of each hidden layer.
    pre_activations: Vec<Vec<T>>,
}

impl<T: Real> Mlp<T> {
    /// A network with PyTorch's default `nn.Linear` initialisation (weights and biases uniform in
    /// ±1/√fan_in), drawn from a ChaCha8 stream seeded with `seed`.
    pub fn new(sizes: &[usize], activation: Activation, seed: u64) -> Result<Self, NnError> {
        if sizes.len() < 2 || sizes.contains(&0) {
            return Err(NnError::Shape(format!(
                "an MLP needs at least two non-zero layer sizes, got {sizes:?}"
            )));
        }
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let mut params = Vec::new();
        for l in 0..sizes.len() - 1 {
            let (fan_in, fan_out) = (sizes[l], sizes[l + 1]);
            let bound = 1.0 / (fan_in as f64).sqrt();
            for _ in 0..fan_out * fan_in + fan_out {
                params.push(T::of(rng.gen_range(-bound..bound)));
            }
        }
        Ok(Self {
            sizes: sizes.to_vec(),
            activation,
            params,
        })
    }

    /// Number of layers (dense maps).
    pub fn layers(&self) -> usize {
        self.sizes.len() - 1
    }

    /// Input width.
    pub fn input_dim(&self) -> usize {
        self.sizes[0]
    }

    /// Output width.
    pub fn output_dim(&self) -> usize {
        self.sizes[self.sizes.len() - 1]
    }

    /// Total number of parameters.
    pub fn num_params(&self) -> usize {
        (0..self.layers())
            .map(|l| self.sizes[l + 1] * (self.sizes[l] + 1))
            .sum()
    }

    /// Offset of layer `l`'s weight in `params` (its bias follows the weight).
    fn layer_offset(&self, l: usize) -> usize {
        (0..l)
            .map(|k| self.sizes[k + 1] * (self.sizes[k] + 1))
            .sum()
    }

    /// Names and ranges of every weight and bias in `params` (`layer{l}.weight`, `layer{l}.bias`), for
    /// writing weights files.
    pub fn named_ranges(&self) -> Vec<(String, std::ops::Range<usize>, Vec<usize>)> {
        let mut out = Vec::new();
        for l in 0..self.layers() {
            let o = self.layer_offset(l);
            let (i_dim, o_dim) = (self.sizes[l], self.sizes[l + 1]);
            out.push((
                format!("layer{l}.weight"),
                o..o + o_dim * i_dim,
                vec![o_dim, i_dim],
            ));
            out.push((
                format!("layer{l}.bias"),
                o + o_dim * i_dim..o + o_dim * (i_dim + 1),
                vec![o_dim],
            ));
        }
        out
    }

    /// Forward on a `(batch, input_dim)` row-major input; returns `(batch, output_dim)` and the cache.
    pub fn forward(&self, x: &[T], batch: usize) -> Result<(Vec<T>, MlpCache<T>), NnError> {
        self.forward_owned(x.to_vec(), batch)
    }

    /// [`Mlp::forward`] on an input the cache may keep (no copy of it).
    pub fn forward_owned(&self, x: Vec<T>, batch: usize) -> Result<(Vec<T>, MlpCache<T>), NnError> {
        check_len("mlp input", batch * self.input_dim(), x.len())?;
        check_len("mlp params", self.num_params(), self.params.len())?;
        let mut cache = MlpCache {
            batch,
            inputs: Vec::with_capacity(self.layers()),
            pre_activations: Vec::with_capacity(self.layers()),
        };
        let mut current = x;
        for l in 0..self.layers() {
            let (i_dim, o_dim) = (self.sizes[l], self.sizes[l + 1]);
            let o = self.layer_offset(l);
            let w = &self.params[o..o + o_dim * i_dim];
            let b = &self.params[o + o_dim * i_dim..o + o_dim * (i_dim + 1)];
            let mut y = vec![T::zero(); batch * o_dim];
            let shape = DenseShape {
                batch,
                inputs: i_dim,
                outputs: o_dim,
            };
            dense_forward(shape, &current, w, Some(b), &mut y)?;
            cache.inputs.push(current);
            if l + 1 < self.layers() {
                // Element-wise: in parallel, with the bits of a serial loop.
                let post: Vec<T> = y.par_iter().map(|&v| self.activation.apply(v)).collect();
                cache.pre_activations.push(y);
                current = post;
            } else {
                current = y;
            }
        }
        Ok((current, cache))
    }

    /// Backward from `d_out` (`(batch, output_dim)`): **accumulates** parameter gradients into
    /// `d_params` (length `num_params()`) and, if given, **overwrites** `d_input` (`(batch, input_dim)`).
    pub fn backward(
        &self,
        cache: &MlpCache<T>,
        d_out: &[T],
        d_params: &mut [T],
        d_input: Option<&mut [T]>,
    ) -> Result<(), NnError> {
        let batch = cache.batch;
        check_len("mlp d_out", batch * self.output_dim(), d_out.len())?;
        check_len("mlp d_params", self.num_params(), d_params.len())?;
        // The gradient at layer l's output: `d_out` itself for the last layer, then owned.
        let mut owned: Option<Vec<T>> = None;
        let mut d_input = d_input;
        for l in (0..self.layers()).rev() {
            let (i_dim, o_dim) = (self.sizes[l], self.sizes[l + 1]);
            let o = self.layer_offset(l);
            let w = &self.params[o..o + o_dim * i_dim];
            let shape = DenseShape {
                batch,
                inputs: i_dim,
                outputs: o_dim,
            };
            let (dw, db) = d_params[o..o + o_dim * (i_dim + 1)].split_at_mut(o_dim * i_dim);
            let grad = owned.as_deref().unwrap_or(d_out);
            if l == 0 {
                // The first layer's input gradient goes straight to `d_input`, if asked for
                // (`dense_backward` overwrites it).
                let dx = match d_input.as_deref_mut() {
                    Some(di) => {
                        check_len("mlp d_input", batch * i_dim, di.len())?;
                        Some(di)
                    }
                    None => None,
                };
                dense_backward(shape, &cache.inputs[l], w, grad, dx, Some(dw), Some(db))?;
                continue;
            }
            let mut dx = vec![T::zero(); batch * i_dim];
            dense_backward(
                shape,
                &cache.inputs[l],
                w,
                grad,
                Some(&mut dx),
                Some(dw),
                Some(db),
            )?;
            // Through the activation of layer l − 1 (element-wise, in parallel).
            let pre = &cache.pre_activations[l - 1];
            dx.par_iter_mut()
                .zip(pre)
                .for_each(|(g, &z)| *g = *g * self.activation.derivative(z));
            owned = Some(dx);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shapes_and_init_are_as_documented() {
        let mlp = Mlp::<f32>::new(&[3, 8, 2], Activation::LeakyRelu(0.01), 1).unwrap();
        assert_eq!(mlp.num_params(), 8 * 4 + 2 * 9);
        assert!(mlp.params[..24]
            .iter()
            .all(|w| w.abs() <= 1.0 / 3f32.sqrt()));
        let (y, _) = mlp.forward(&[0.1, 0.2, 0.3, -1.0, 0.0, 1.0], 2).unwrap();
        assert_eq!(y.len(), 4);
        assert_eq!(
            Mlp::<f32>::new(&[3, 8, 2], Activation::Relu, 1)
                .unwrap()
                .params,
            mlp.params
        );
        assert!(Mlp::<f32>::new(&[3], Activation::Relu, 1).is_err());
        let names: Vec<String> = mlp.named_ranges().into_iter().map(|r| r.0).collect();
        assert_eq!(
            names,
            [
                "layer0.weight",
                "layer0.bias",
                "layer1.weight",
                "layer1.bias"
            ]
        );
    }
}
