//! A trainer's checkpoint: one safetensors file (written atomically) holding the model's Gaussians
//! and networks, every optimiser moment, the density statistics and the AIAP neighbourhoods, with the
//! configuration, step count, frame order and RNG position as JSON metadata. Loading it resumes a run
//! bit for bit.

use super::terms::AiapNeighbours;
use super::Trainer;
use super::CHECKPOINT_FORMAT;
use crate::checkpoint::{rng_from_strings, rng_to_strings, CheckpointReader, CheckpointWriter};
use crate::config::TrainConfig;
use crate::data::TrainingData;
use crate::loss::aiap::AIAP_NEIGHBOURS;
use crate::model::{Model, ModelConfig};
use crate::optimisers::{OptimiserSteps, Optimisers};
use crate::TrainError;
use std::path::Path;

/// Non-tensor state of a checkpoint (JSON in the safetensors metadata).
#[derive(serde::Serialize, serde::Deserialize)]
struct CheckpointMeta {
    format: String,
    config: TrainConfig,
    step: usize,
    scene_extent: f32,
    sh_degree: usize,
    adam_steps: Vec<u64>,
    net_adam_steps: Vec<u64>,
    rng_seed: String,
    rng_word_pos: String,
    order: Vec<usize>,
    /// [`Trainer::person_changes`] (absent when 0, as in checkpoints from before several people).
    #[serde(default, skip_serializing_if = "is_zero")]
    person_changes: u64,
}

fn is_zero(v: &u64) -> bool {
    *v == 0
}

impl Trainer {
    /// Writes the whole state to one safetensors file atomically (temporary sibling + rename).
    pub fn save_checkpoint(&self, path: &Path) -> Result<(), TrainError> {
        let model = &self.model;
        let mut w = CheckpointWriter::default();
        w.push_set("set", &model.set);
        model.push_networks(&mut w);
        let steps = self.optimisers.save(&mut w);
        w.push_stats("stats", &self.stats);
        // Indices as float32: exact below 2^24, which `TrainConfig::validate` bounds the count by.
        w.push(
            "aiap.index",
            self.aiap.index.iter().map(|&i| i as f32).collect(),
        );
        w.push(
            "aiap.neighbours",
            self.aiap.neighbours.iter().map(|&i| i as f32).collect(),
        );
        let (rng_seed, rng_word_pos) = rng_to_strings(&self.rng);
        let meta = CheckpointMeta {
            format: CHECKPOINT_FORMAT.into(),
            config: self.config.clone(),
            step: self.step,
            scene_extent: model.scene_extent,
            sh_degree: model.set.sh_degree,
            adam_steps: steps.gaussians,
            net_adam_steps: steps.networks,
            rng_seed,
            rng_word_pos,
            order: self.order.clone(),
            person_changes: self.person_changes,
        };
        let json = serde_json::to_string(&meta).map_err(|e| TrainError::Checkpoint {
            path: path.to_path_buf(),
            message: e.to_string(),
        })?;
        w.write(path, &json)
    }

    /// Restores a trainer saved by [`Trainer::save_checkpoint`] for the training data `data` (which
    /// supplies the canonical body the networks normalise by). The stored configuration is used.
    pub fn load_checkpoint(path: &Path, data: &TrainingData) -> Result<Self, TrainError> {
        let r = CheckpointReader::open(path)?;
        let meta: CheckpointMeta =
            serde_json::from_str(&r.metadata).map_err(|e| r.error(format!("metadata: {e}")))?;
        if meta.format != CHECKPOINT_FORMAT {
            return Err(r.error(format!("unknown checkpoint format `{}`", meta.format)));
        }
        let mut config = meta.config;
        let stored: serde_json::Value =
            serde_json::from_str(&r.metadata).map_err(|e| r.error(format!("metadata: {e}")))?;
        config.pin_options_missing_from(&stored["config"]);
        config.validate()?;
        let k = config.semantic.logits_for(data.cast().len());
        let set = r.set("set", meta.sh_degree, config.feature_dim, k)?;
        let model_config = ModelConfig::from(&config);
        let nets = Model::build_networks(&model_config, &data.body.canonical.posed.vertices)?;
        let latents = vec![0.0; data.frames.len() * config.latent_dim];
        let frame_indices = data.frames.iter().map(|f| f.index).collect();
        let mut model = Model::new(
            model_config,
            set,
            nets,
            latents,
            frame_indices,
            meta.scene_extent,
        )?;
        model.read_networks(&r)?;
        let optimisers = Optimisers::load(
            &r,
            &model,
            &config,
            &OptimiserSteps {
                gaussians: meta.adam_steps,
                networks: meta.net_adam_steps,
            },
        )?;
        let stats = r.stats("stats", model.set.len())?;
        let n = model.set.len();
        let index = r.get("aiap.index")?;
        let neighbours = r.get("aiap.neighbours")?;
        let bad = |v: &f32, bound: usize| !(*v >= 0.0 && (*v as usize) < bound && v.fract() == 0.0);
        if index.iter().any(|v| bad(v, n))
            || neighbours.iter().any(|v| bad(v, index.len()))
            || neighbours.len() != index.len() * AIAP_NEIGHBOURS && !neighbours.is_empty()
        {
            return Err(r.error("AIAP neighbourhoods do not match the Gaussians"));
        }
        let aiap = AiapNeighbours {
            index: index.iter().map(|&v| v as usize).collect(),
            neighbours: neighbours.iter().map(|&v| v as u32).collect(),
        };
        Ok(Self {
            model,
            config,
            step: meta.step,
            optimisers,
            stats,
            rng: rng_from_strings(&meta.rng_seed, &meta.rng_word_pos).map_err(|e| r.error(e))?,
            order: meta.order,
            aiap,
            person_changes: meta.person_changes,
        })
    }
}
