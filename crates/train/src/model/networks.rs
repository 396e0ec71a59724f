//! The model's networks as parameter groups: building them, the flat vectors the optimisers
//! step, and the one writer and reader of network weights (checkpoints and model directories share
//! it), with the camera corrections beside them.

use super::{Model, ModelConfig, ModelNets};
use crate::checkpoint::{CheckpointReader, CheckpointWriter};
use crate::colour::{ColourNet, ColourNetConfig};
use crate::TrainError;
use smpl_deform::deform_net::{NonRigidNet, SkinningField};

/// Names of the model's network parameter groups, in checkpoint order, with the tensor each is
/// stored under (the per-frame latents and pose corrections are groups too; an empty group — the
/// pose corrections when `pose_correction` is off — is not stored).
pub const NETWORK_GROUPS: [(&str, &str); 6] = [
    ("nonrigid", "nonrigid"),
    ("skinning", "skinning"),
    ("human_colour", "human_colour"),
    ("scene_colour", "scene_colour"),
    ("latent", "latents"),
    ("pose_correction", "pose_corrections"),
];

/// The tensor the camera corrections are stored under (not a [`NETWORK_GROUPS`] entry: they have
/// their own per-frame optimiser, and models without them keep their bytes).
pub const CAMERA_CORRECTIONS_TENSOR: &str = "camera_corrections";

/// The tensor of the clip-wide camera twist set by the person ([`Model::camera_gauge`]).
pub const CAMERA_GAUGE_TENSOR: &str = "camera_gauge";

impl Model {
    /// Freshly initialised networks of `config` for the canonical body `vertices`.
    pub fn build_networks(
        config: &ModelConfig,
        vertices: &[[f32; 3]],
    ) -> Result<ModelNets<f32>, TrainError> {
        let mut human = ColourNetConfig::human();
        human.feature_dim = config.feature_dim;
        human.latent_dim = config.latent_dim;
        let mut scene = ColourNetConfig::scene();
        scene.feature_dim = config.feature_dim;
        Ok(ModelNets {
            nonrigid: NonRigidNet::new(vertices, config.deform_hidden, config.seed ^ 0x11)?,
            skinning: SkinningField::new(vertices, config.deform_hidden, config.seed ^ 0x22)?,
            human_colour: ColourNet::new(human, config.seed ^ 0x33)?,
            scene_colour: ColourNet::new(scene, config.seed ^ 0x44)?,
        })
    }

    /// The flat parameters of every network group ([`NETWORK_GROUPS`] order).
    pub fn network_groups(&self) -> [&Vec<f32>; 6] {
        [
            &self.nets.nonrigid.mlp.params,
            &self.nets.skinning.mlp.params,
            &self.nets.human_colour.mlp.params,
            &self.nets.scene_colour.mlp.params,
            &self.latents,
            &self.pose_corrections,
        ]
    }

    /// Mutable [`Model::network_groups`], for the optimisers and for loading.
    pub fn network_groups_mut(&mut self) -> [&mut Vec<f32>; 6] {
        [
            &mut self.nets.nonrigid.mlp.params,
            &mut self.nets.skinning.mlp.params,
            &mut self.nets.human_colour.mlp.params,
            &mut self.nets.scene_colour.mlp.params,
            &mut self.latents,
            &mut self.pose_corrections,
        ]
    }

    /// Adds every network group as a tensor, and the camera corrections (`camera_corrections`)
    /// when the model has them (the one writer of network weights: checkpoints and model
    /// directories share it).
    pub fn push_networks(&self, w: &mut CheckpointWriter) {
        for ((_, tensor), params) in NETWORK_GROUPS.iter().zip(self.network_groups()) {
            if !params.is_empty() {
                w.push(*tensor, params.clone());
            }
        }
        if !self.camera_corrections.is_empty() {
            w.push(CAMERA_CORRECTIONS_TENSOR, self.camera_corrections.clone());
        }
        if !self.camera_gauge.is_empty() {
            w.push(CAMERA_GAUGE_TENSOR, self.camera_gauge.clone());
        }
    }

    /// Replaces every network group by the tensors [`Model::push_networks`] wrote, checking each
    /// length against this model's shapes.
    pub fn read_networks(&mut self, r: &CheckpointReader) -> Result<(), TrainError> {
        for ((_, tensor), params) in NETWORK_GROUPS.iter().zip(self.network_groups_mut()) {
            if !params.is_empty() {
                *params = r.get_len(tensor, params.len())?;
            }
        }
        if !self.camera_corrections.is_empty() {
            self.camera_corrections =
                r.get_len(CAMERA_CORRECTIONS_TENSOR, self.camera_corrections.len())?;
        }
        if !self.camera_gauge.is_empty() {
            self.camera_gauge = r.get_len(CAMERA_GAUGE_TENSOR, self.camera_gauge.len())?;
        }
        Ok(())
    }
}
