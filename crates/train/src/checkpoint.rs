//! Single-file training checkpoints: named float32 tensors in a safetensors file plus a JSON metadata
//! string, written atomically (temporary sibling + rename), and the (de)serialisation of the pieces every
//! trainer shares — a `GaussianSet`, its Adam moments, density statistics and a ChaCha RNG position.

use crate::TrainError;
use gaussians::adam::{AdamState, GaussianAdam};
use gaussians::density::DensityStats;
use gaussians::GaussianSet;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use safetensors::tensor::{Dtype, TensorView};
use safetensors::SafeTensors;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// Tensors and metadata to be written as one checkpoint.
#[derive(Debug, Default)]
pub struct CheckpointWriter {
    tensors: Vec<(String, Vec<f32>)>,
}

impl CheckpointWriter {
    /// Adds a flat float32 tensor.
    pub fn push(&mut self, name: impl Into<String>, values: Vec<f32>) {
        self.tensors.push((name.into(), values));
    }

    /// Adds every array of `set` under `prefix.`.
    pub fn push_set(&mut self, prefix: &str, s: &GaussianSet) {
        self.push(format!("{prefix}.means"), s.means.as_flattened().to_vec());
        self.push(
            format!("{prefix}.log_scales"),
            s.log_scales.as_flattened().to_vec(),
        );
        self.push(format!("{prefix}.quats"), s.quats.as_flattened().to_vec());
        self.push(format!("{prefix}.opacity_logits"), s.opacity_logits.clone());
        self.push(format!("{prefix}.sh"), s.sh.clone());
        self.push(format!("{prefix}.features"), s.features.clone());
        self.push(
            format!("{prefix}.semantic_logits"),
            s.semantic_logits.clone(),
        );
    }

    /// Adds the moments of every group of `adam` under `prefix.<group>.{m,v}`; returns the step counts.
    pub fn push_gaussian_adam(&mut self, prefix: &str, adam: &GaussianAdam) -> Vec<u64> {
        adam_groups(adam)
            .iter()
            .map(|(name, g)| {
                self.push(format!("{prefix}.{name}.m"), g.m.clone());
                self.push(format!("{prefix}.{name}.v"), g.v.clone());
                g.step
            })
            .collect()
    }

    /// Adds the moments of a network optimiser; returns its step count.
    pub fn push_adam(&mut self, prefix: &str, adam: &nn::Adam<f32>) -> u64 {
        let (m, v) = adam.moments();
        self.push(format!("{prefix}.m"), m.to_vec());
        self.push(format!("{prefix}.v"), v.to_vec());
        adam.steps()
    }

    /// Adds density statistics under `prefix.`.
    pub fn push_stats(&mut self, prefix: &str, stats: &DensityStats) {
        self.push(format!("{prefix}.grad_accum"), stats.grad_accum.clone());
        self.push(format!("{prefix}.max_radius"), stats.max_radius.clone());
        let counts: Vec<f32> = stats.visible_count.iter().map(|&c| c as f32).collect();
        self.push(format!("{prefix}.visible_count"), counts);
    }

    /// Serialises to `path` atomically with `metadata` stored under the key `trainer`.
    pub fn write(self, path: &Path, metadata: &str) -> Result<(), TrainError> {
        let err = |message: String| TrainError::Checkpoint {
            path: path.to_path_buf(),
            message,
        };
        let bytes: Vec<(String, Vec<u8>, Vec<usize>)> = self
            .tensors
            .into_iter()
            .map(|(name, values)| {
                let len = values.len();
                (
                    name,
                    values.iter().flat_map(|v| v.to_le_bytes()).collect(),
                    vec![len],
                )
            })
            .collect();
        let views = bytes
            .iter()
            .map(|(name, data, shape)| {
                TensorView::new(Dtype::F32, shape.clone(), data).map(|v| (name.clone(), v))
            })
            .collect::<Result<Vec<_>, _>>()
            .map_err(|e| err(e.to_string()))?;
        let mut meta = HashMap::new();
        meta.insert("trainer".to_string(), metadata.to_string());
        let file = safetensors::serialize(views, Some(meta)).map_err(|e| err(e.to_string()))?;
        gaussians::ply::write_atomically(path, &file).map_err(|e| err(e.to_string()))
    }
}

/// A checkpoint file read back: its metadata string and its tensors by name.
pub struct CheckpointReader {
    path: PathBuf,
    /// The `trainer` metadata string.
    pub metadata: String,
    tensors: HashMap<String, Vec<f32>>,
}

impl CheckpointReader {
    /// Reads and decodes `path` (every tensor must be float32).
    pub fn open(path: &Path) -> Result<Self, TrainError> {
        let err = |message: String| TrainError::Checkpoint {
            path: path.to_path_buf(),
            message,
        };
        let bytes = std::fs::read(path).map_err(|e| err(e.to_string()))?;
        let (_, header) = SafeTensors::read_metadata(&bytes).map_err(|e| err(e.to_string()))?;
        let metadata = header
            .metadata()
            .as_ref()
            .and_then(|m| m.get("trainer"))
            .ok_or_else(|| err("missing `trainer` metadata".into()))?
            .clone();
        let st = SafeTensors::deserialize(&bytes).map_err(|e| err(e.to_string()))?;
        let mut tensors = HashMap::new();
        for (name, t) in st.tensors() {
            if t.dtype() != Dtype::F32 {
                return Err(err(format!("tensor `{name}` is not float32")));
            }
            let values = t
                .data()
                .chunks_exact(4)
                .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                .collect();
            tensors.insert(name, values);
        }
        Ok(Self {
            path: path.to_path_buf(),
            metadata,
            tensors,
        })
    }

    /// An error about this file.
    pub fn error(&self, message: impl Into<String>) -> TrainError {
        TrainError::Checkpoint {
            path: self.path.clone(),
            message: message.into(),
        }
    }

    /// Whether the file holds a tensor `name`.
    pub fn has(&self, name: &str) -> bool {
        self.tensors.contains_key(name)
    }

    /// The tensor `name`.
    pub fn get(&self, name: &str) -> Result<Vec<f32>, TrainError> {
        self.tensors
            .get(name)
            .cloned()
            .ok_or_else(|| self.error(format!("missing tensor `{name}`")))
    }

    /// The tensor `name`, which must hold exactly `len` values.
    pub fn get_len(&self, name: &str, len: usize) -> Result<Vec<f32>, TrainError> {
        let v = self.get(name)?;
        if v.len() != len {
            return Err(self.error(format!(
                "tensor `{name}` has {} values, expected {len}",
                v.len()
            )));
        }
        Ok(v)
    }

    fn rows<const D: usize>(&self, name: &str) -> Result<Vec<[f32; D]>, TrainError> {
        let v = self.get(name)?;
        if !v.len().is_multiple_of(D) {
            return Err(self.error(format!(
                "tensor `{name}` length {} is not a multiple of {D}",
                v.len()
            )));
        }
        Ok(v.chunks_exact(D)
            .map(|c| std::array::from_fn(|k| c[k]))
            .collect())
    }

    /// A `GaussianSet` stored by [`CheckpointWriter::push_set`], validated.
    pub fn set(
        &self,
        prefix: &str,
        sh_degree: usize,
        feature_dim: usize,
        semantic_classes: usize,
    ) -> Result<GaussianSet, TrainError> {
        let mut set = GaussianSet::new(sh_degree, feature_dim, semantic_classes);
        set.means = self.rows(&format!("{prefix}.means"))?;
        set.log_scales = self.rows(&format!("{prefix}.log_scales"))?;
        set.quats = self.rows(&format!("{prefix}.quats"))?;
        set.opacity_logits = self.get(&format!("{prefix}.opacity_logits"))?;
        set.sh = self.get(&format!("{prefix}.sh"))?;
        set.features = self.get(&format!("{prefix}.features"))?;
        set.semantic_logits = self.get(&format!("{prefix}.semantic_logits"))?;
        set.validate().map_err(|e| self.error(e.to_string()))?;
        Ok(set)
    }

    /// Restores the moments stored by [`CheckpointWriter::push_gaussian_adam`] into `adam` (already
    /// shaped like the set) with the step counts `steps`.
    pub fn gaussian_adam(
        &self,
        prefix: &str,
        adam: &mut GaussianAdam,
        steps: &[u64],
    ) -> Result<(), TrainError> {
        if steps.len() != ADAM_GROUP_NAMES.len() {
            return Err(self.error(format!(
                "expected {} Adam step counts, found {}",
                ADAM_GROUP_NAMES.len(),
                steps.len()
            )));
        }
        for (k, name) in ADAM_GROUP_NAMES.iter().enumerate() {
            let group = adam_group_mut(adam, k);
            group.m = self.get_len(&format!("{prefix}.{name}.m"), group.m.len())?;
            group.v = self.get_len(&format!("{prefix}.{name}.v"), group.v.len())?;
            group.step = steps[k];
        }
        Ok(())
    }

    /// A network optimiser stored by [`CheckpointWriter::push_adam`] for `len` parameters.
    pub fn adam(
        &self,
        prefix: &str,
        config: nn::AdamConfig,
        len: usize,
        steps: u64,
    ) -> Result<nn::Adam<f32>, TrainError> {
        Ok(nn::Adam::from_parts(
            config,
            self.get_len(&format!("{prefix}.m"), len)?,
            self.get_len(&format!("{prefix}.v"), len)?,
            steps,
        )?)
    }

    /// Density statistics for `n` Gaussians stored by [`CheckpointWriter::push_stats`].
    pub fn stats(&self, prefix: &str, n: usize) -> Result<DensityStats, TrainError> {
        Ok(DensityStats {
            grad_accum: self.get_len(&format!("{prefix}.grad_accum"), n)?,
            max_radius: self.get_len(&format!("{prefix}.max_radius"), n)?,
            visible_count: self
                .get_len(&format!("{prefix}.visible_count"), n)?
                .iter()
                .map(|&c| c as u32)
                .collect(),
        })
    }
}

/// A ChaCha8 RNG position as text: (hex seed, word position).
pub fn rng_to_strings(rng: &ChaCha8Rng) -> (String, String) {
    (
        rng.get_seed().iter().map(|b| format!("{b:02x}")).collect(),
        rng.get_word_pos().to_string(),
    )
}

/// Inverse of [`rng_to_strings`].
pub fn rng_from_strings(seed_hex: &str, word_pos: &str) -> Result<ChaCha8Rng, String> {
    if seed_hex.len() != 64 || !seed_hex.is_ascii() {
        return Err("rng seed must be 64 hex digits".into());
    }
    let bytes: Vec<u8> = (0..32)
        .map(|i| u8::from_str_radix(&seed_hex[2 * i..2 * i + 2], 16))
        .collect::<Result<_, _>>()
        .map_err(|e| format!("rng seed: {e}"))?;
    let seed: [u8; 32] = bytes
        .try_into()
        .map_err(|_| "rng seed must be 32 bytes".to_string())?;
    let mut rng = ChaCha8Rng::from_seed(seed);
    rng.set_word_pos(word_pos.parse().map_err(|e| format!("rng position: {e}"))?);
    Ok(rng)
}

const ADAM_GROUP_NAMES: [&str; 7] = [
    "means",
    "log_scales",
    "quats",
    "opacity_logits",
    "sh",
    "features",
    "semantic_logits",
];

fn adam_groups(adam: &GaussianAdam) -> [(&'static str, &AdamState); 7] {
    [
        (ADAM_GROUP_NAMES[0], &adam.means),
        (ADAM_GROUP_NAMES[1], &adam.log_scales),
        (ADAM_GROUP_NAMES[2], &adam.quats),
        (ADAM_GROUP_NAMES[3], &adam.opacity_logits),
        (ADAM_GROUP_NAMES[4], &adam.sh),
        (ADAM_GROUP_NAMES[5], &adam.features),
        (ADAM_GROUP_NAMES[6], &adam.semantic_logits),
    ]
}

fn adam_group_mut(adam: &mut GaussianAdam, k: usize) -> &mut AdamState {
    match k {
        0 => &mut adam.means,
        1 => &mut adam.log_scales,
        2 => &mut adam.quats,
        3 => &mut adam.opacity_logits,
        4 => &mut adam.sh,
        5 => &mut adam.features,
        _ => &mut adam.semantic_logits,
    }
}
