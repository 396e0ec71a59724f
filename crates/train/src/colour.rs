//! The colour networks of E-Sem3DGS: a per-Gaussian MLP decoding colour from a learned feature and the
//! SH basis of the view direction, optionally with extra per-Gaussian inputs and a per-frame latent.
//!
//! - Scene-colour MLP (paper §4.3): feature 32 ⊕ degree-3 SH basis (16) of the world view direction →
//!   64 → RGB (sigmoid).
//! - Human colour MLP (3DGS-Avatar): feature 32 ⊕ degree-3 SH basis without DC (15) of the view direction
//!   rotated into canonical space ⊕ non-rigid feature 16 ⊕ per-frame latent 16 → 64 → 64 → RGB (sigmoid).
//!
//! Gradients reach the network weights, the features, the extra inputs, the latent and the (unnormalised)
//! view directions, through the SH encoding and the normalisation, as colour gradients reach the means
//! through the view direction in 3DGS.

use gaussians::sh::{num_sh_coeffs, sh_basis, sh_basis_backward, MAX_SH_COEFFS};
use nn::mlp::{Activation, Mlp, MlpCache};
use nn::{NnError, Real};
use rayon::prelude::*;

/// Shape of a colour network's input and hidden layers.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ColourNetConfig {
    /// Per-Gaussian feature length.
    pub feature_dim: usize,
    /// SH degree of the direction encoding.
    pub sh_degree: usize,
    /// Whether the constant (DC) basis function is part of the encoding.
    pub include_dc: bool,
    /// Length of the extra per-Gaussian input (e.g. the non-rigid network's feature; 0 for none).
    pub extra_dim: usize,
    /// Length of the per-frame latent (0 for none).
    pub latent_dim: usize,
    /// Hidden layer widths.
    pub hidden: Vec<usize>,
}

impl ColourNetConfig {
    /// The scene-colour MLP of the paper: feature 32, SH degree 3 with DC, one hidden layer of 64.
    pub fn scene() -> Self {
        Self {
            feature_dim: 32,
            sh_degree: 3,
            include_dc: true,
            extra_dim: 0,
            latent_dim: 0,
            hidden: vec![64],
        }
    }

    /// The human colour MLP of 3DGS-Avatar: feature 32, SH degree 3 without DC, non-rigid feature 16,
    /// frame latent 16, two hidden layers of 64.
    pub fn human() -> Self {
        Self {
            feature_dim: 32,
            sh_degree: 3,
            include_dc: false,
            extra_dim: 16,
            latent_dim: 16,
            hidden: vec![64, 64],
        }
    }

    fn sh_dim(&self) -> usize {
        num_sh_coeffs(self.sh_degree) - usize::from(!self.include_dc)
    }

    /// Input width of the MLP.
    pub fn input_dim(&self) -> usize {
        self.feature_dim + self.sh_dim() + self.extra_dim + self.latent_dim
    }
}

/// Per-Gaussian inputs of one evaluation over N Gaussians.
#[derive(Clone, Copy, Debug)]
pub struct ColourInputs<'a, T> {
    /// Features, N × feature_dim.
    pub features: &'a [T],
    /// View directions (any length; normalised here), N.
    pub directions: &'a [[T; 3]],
    /// Extra inputs, N × extra_dim (empty when extra_dim = 0).
    pub extra: &'a [T],
    /// Per-frame latent, latent_dim values shared by all N (empty when latent_dim = 0).
    pub latent: &'a [T],
}

/// Gradients of one evaluation.
#[derive(Clone, Debug, PartialEq)]
pub struct ColourGradients<T> {
    /// dL/d network parameters (flat, as `ColourNet::mlp.params`).
    pub params: Vec<T>,
    /// dL/d features, N × feature_dim.
    pub features: Vec<T>,
    /// dL/d extra inputs, N × extra_dim.
    pub extra: Vec<T>,
    /// dL/d latent (summed over the N Gaussians).
    pub latent: Vec<T>,
    /// dL/d view directions (unnormalised, as passed in), N.
    pub directions: Vec<[T; 3]>,
}

/// Forward state kept for the backward.
#[derive(Clone, Debug)]
pub struct ColourCache<T> {
    n: usize,
    mlp: MlpCache<T>,
    rgb: Vec<T>,
    /// Unit directions and the norms they were divided by (0 for a zero direction).
    units: Vec<([T; 3], T)>,
}

/// A colour network (see the module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct ColourNet<T: Real> {
    /// Input layout.
    pub config: ColourNetConfig,
    /// The MLP (LeakyReLU 0.01 hidden activations, sigmoid applied to its output).
    pub mlp: Mlp<T>,
}

impl<T: Real> ColourNet<T> {
    /// A freshly initialised network (seeded).
    pub fn new(config: ColourNetConfig, seed: u64) -> Result<Self, NnError> {
        let mut sizes = vec![config.input_dim()];
        sizes.extend_from_slice(&config.hidden);
        sizes.push(3);
        let mlp = Mlp::new(&sizes, Activation::LeakyRelu(0.01), seed)?;
        Ok(Self { config, mlp })
    }

    fn check(&self, x: &ColourInputs<'_, T>) -> Result<usize, NnError> {
        let n = x.directions.len();
        let c = &self.config;
        for (name, got, want) in [
            ("colour features", x.features.len(), n * c.feature_dim),
            ("colour extra", x.extra.len(), n * c.extra_dim),
            ("colour latent", x.latent.len(), c.latent_dim),
        ] {
            if got != want {
                return Err(NnError::Length {
                    name,
                    expected: want,
                    actual: got,
                });
            }
        }
        Ok(n)
    }

    /// Linear RGB in (0, 1) for every Gaussian, N × 3, and the cache for [`ColourNet::backward`].
    pub fn forward(&self, x: &ColourInputs<'_, T>) -> Result<(Vec<T>, ColourCache<T>), NnError> {
        let n = self.check(x)?;
        let c = &self.config;
        let width = c.input_dim();
        let skip = usize::from(!c.include_dc);
        let k = num_sh_coeffs(c.sh_degree);
        // Rows in parallel: each row's arithmetic is independent of the others.
        let mut input = vec![T::zero(); n * width];
        let mut units = vec![([T::zero(); 3], T::zero()); n];
        input
            .par_chunks_mut(width.max(1))
            .zip(units.par_iter_mut())
            .enumerate()
            .for_each(|(i, (row, unit_norm))| {
                let mut basis = [T::zero(); MAX_SH_COEFFS];
                let (f, rest) = row.split_at_mut(c.feature_dim);
                f.copy_from_slice(&x.features[i * c.feature_dim..(i + 1) * c.feature_dim]);
                let d = x.directions[i];
                let norm = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
                let unit = if norm > T::zero() {
                    [d[0] / norm, d[1] / norm, d[2] / norm]
                } else {
                    [T::zero(); 3]
                };
                *unit_norm = (unit, norm);
                sh_basis(c.sh_degree, unit, &mut basis);
                let (sh, rest) = rest.split_at_mut(k - skip);
                sh.copy_from_slice(&basis[skip..k]);
                let (e, l) = rest.split_at_mut(c.extra_dim);
                e.copy_from_slice(&x.extra[i * c.extra_dim..(i + 1) * c.extra_dim]);
                l.copy_from_slice(x.latent);
            });
        let (logits, mlp_cache) = self.mlp.forward_owned(input, n)?;
        let rgb: Vec<T> = logits
            .par_iter()
            .map(|&z| T::one() / (T::one() + (-z).exp()))
            .collect();
        Ok((
            rgb.clone(),
            ColourCache {
                n,
                mlp: mlp_cache,
                rgb,
                units,
            },
        ))
    }

    /// Backward from dL/dRGB (N × 3).
    pub fn backward(
        &self,
        cache: &ColourCache<T>,
        d_rgb: &[T],
    ) -> Result<ColourGradients<T>, NnError> {
        let n = cache.n;
        let c = &self.config;
        if d_rgb.len() != n * 3 {
            return Err(NnError::Length {
                name: "colour d_rgb",
                expected: n * 3,
                actual: d_rgb.len(),
            });
        }
        let d_logits: Vec<T> = d_rgb
            .par_iter()
            .zip(&cache.rgb)
            .map(|(&g, &s)| g * s * (T::one() - s))
            .collect();
        let mut d_params = vec![T::zero(); self.mlp.num_params()];
        let width = c.input_dim();
        let mut d_input = vec![T::zero(); n * width];
        self.mlp
            .backward(&cache.mlp, &d_logits, &mut d_params, Some(&mut d_input))?;
        let sh_dim = c.sh_dim();
        let skip = usize::from(!c.include_dc);
        let row_len = width.max(1);
        // Rows in parallel (each row's gradients are its own); the latent's sum over the rows
        // stays serial, in row order.
        let mut directions = vec![[T::zero(); 3]; n];
        d_input
            .par_chunks_exact(row_len)
            .zip(&cache.units)
            .zip(directions.par_iter_mut())
            .for_each(|((row, &(unit, norm)), dir)| {
                let d_sh = &row[c.feature_dim..c.feature_dim + sh_dim];
                // Through the SH basis and the normalisation: dv = (g − û (û·g)) / |v|.
                let mut d_basis = [T::zero(); MAX_SH_COEFFS];
                d_basis[skip..skip + sh_dim].copy_from_slice(d_sh);
                let g = sh_basis_backward(c.sh_degree, unit, &d_basis);
                *dir = if norm > T::zero() {
                    let dot = unit[0] * g[0] + unit[1] * g[1] + unit[2] * g[2];
                    [0, 1, 2].map(|a| (g[a] - unit[a] * dot) / norm)
                } else {
                    [T::zero(); 3]
                };
            });
        // Each row's slice of the input gradient at `offset`, `len` values, gathered in row order.
        let gather = |offset: usize, len: usize| -> Vec<T> {
            let mut out = vec![T::zero(); n * len];
            if len > 0 {
                out.par_chunks_mut(len)
                    .zip(d_input.par_chunks_exact(row_len))
                    .for_each(|(dst, row)| dst.copy_from_slice(&row[offset..offset + len]));
            }
            out
        };
        let features = gather(0, c.feature_dim);
        let extra = gather(c.feature_dim + sh_dim, c.extra_dim);
        let mut latent = vec![T::zero(); c.latent_dim];
        let lat = width - c.latent_dim;
        for row in d_input.chunks_exact(row_len) {
            for (acc, &g) in latent.iter_mut().zip(&row[lat..]) {
                *acc = *acc + g;
            }
        }
        Ok(ColourGradients {
            params: d_params,
            features,
            extra,
            latent,
            directions,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn configs_have_the_documented_widths() {
        assert_eq!(ColourNetConfig::scene().input_dim(), 32 + 16);
        assert_eq!(ColourNetConfig::human().input_dim(), 32 + 15 + 16 + 16);
        let net = ColourNet::<f32>::new(ColourNetConfig::human(), 3).unwrap();
        assert_eq!(net.mlp.sizes, vec![79, 64, 64, 3]);
    }

    #[test]
    fn wrong_input_lengths_are_errors() {
        let net = ColourNet::<f32>::new(ColourNetConfig::scene(), 3).unwrap();
        let x = ColourInputs {
            features: &[0.0; 31],
            directions: &[[0.0, 0.0, 1.0]],
            extra: &[],
            latent: &[],
        };
        assert!(matches!(
            net.forward(&x),
            Err(NnError::Length {
                name: "colour features",
                ..
            })
        ));
    }
}
