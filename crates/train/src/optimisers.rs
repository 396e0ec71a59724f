//! The optimisers of a [`Model`]: Adam on every Gaussian attribute group (with per-group rates, the
//! moments following density control's splits and prunes), one Adam per shared network parameter
//! group ([`NETWORK_GROUPS`]), keyed by group name, and a lazy per-frame Adam ([`nn::RowAdam`]) for
//! the pose corrections, which only the step's frames may move; with their checkpoint form.

use crate::checkpoint::{CheckpointReader, CheckpointWriter};
use crate::config::{CameraCorrectionBasis, ExposureMotion, TrainConfig};
use crate::model::{Model, NETWORK_GROUPS};
use crate::pose::camera_basis::{apply_basis, BASIS_VALUES};
use crate::pose::camera_correction::{CAMERA_CORRECTION_VALUES, TWIST_VALUES};
use crate::pose::correction::{root_indices, CORRECTION_VALUES, POSE_VALUES};
use crate::TrainError;
use gaussians::adam::{AdamConfig, GaussianAdam, GaussianLearningRates};
use gaussians::GaussianSet;

/// Every optimiser state of a training run.
#[derive(Clone, Debug)]
pub struct Optimisers {
    /// Adam over the Gaussian set's attribute groups.
    pub gaussians: GaussianAdam,
    /// One Adam per network group, in [`NETWORK_GROUPS`] order (the pose-correction group's is
    /// unused: see `corrections`).
    networks: Vec<nn::Adam<f32>>,
    /// The pose corrections' Adam, one row per training frame with its own step count: a frame's
    /// correction moves only on the steps that train that frame.
    corrections: nn::RowAdam<f32>,
    /// The camera corrections' Adam, one row per training frame, lazy like `corrections`.
    cameras: nn::RowAdam<f32>,
    /// The clip-wide camera twist's Adam (one row; none without one).
    camera_gauge: nn::RowAdam<f32>,
    /// With `camera_correction_basis = image`: the basis P (row-major 6 × 6) in whose coordinates
    /// `cameras` steps the mid-exposure twists, ξ = P u (`crate::pose::camera_basis`).
    camera_basis: Option<[f32; BASIS_VALUES]>,
}

/// The prefix of the camera corrections' Adam tensors.
const CAMERA_ADAM: &str = "camera_correction_adam";

/// The tensor of the camera corrections' image-motion basis.
const CAMERA_BASIS: &str = "camera_correction_basis";

/// The prefix of the clip-wide camera twist's Adam tensors.
const CAMERA_GAUGE_ADAM: &str = "camera_gauge_adam";

/// The name of the pose-correction group in [`NETWORK_GROUPS`].
const CORRECTION_GROUP: &str = "pose_correction";

/// A step's schedule factors of the pose rows' rates (`train::schedule::correction_rate_scale`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PoseRateScales {
    /// Of the mid-exposure part (`lr_pose_correction_final_fraction`'s decay).
    pub mid: f32,
    /// Of the change over the exposure (`lr_exposure_motion_final_fraction`'s decay when it is
    /// learned as the in-exposure motion, else the mid part's).
    pub change: f32,
}

/// Step counts of a checkpoint's optimisers (stored in its JSON metadata).
#[derive(Clone, Debug, PartialEq)]
pub struct OptimiserSteps {
    /// Per Gaussian attribute group.
    pub gaussians: Vec<u64>,
    /// Per network group, [`NETWORK_GROUPS`] order.
    pub networks: Vec<u64>,
}

/// The learning rate of a network group.
fn network_rate(config: &TrainConfig, group: &str) -> f32 {
    match group {
        "nonrigid" => config.lr_nonrigid,
        "skinning" => config.lr_skinning,
        "human_colour" | "scene_colour" => config.lr_colour,
        "pose_correction" => config.lr_pose_correction,
        _ => config.lr_latent,
    }
}

/// `adam` with the pose rows' rates: the mid-exposure part at `lr_pose_correction` for the body
/// joints and `lr_pose_correction_root` for the root's orientation and translation when pose
/// correction learns it (on, with `pose_correction_mid`), else 0; the change over the exposure at
/// `lr_exposure_motion` / `lr_exposure_motion_root` with `exposure_motion = learned`, else at the
/// pose correction's rates with `pose_correction_change`, else 0.
fn correction_adam(adam: nn::RowAdam<f32>, config: &TrainConfig) -> nn::RowAdam<f32> {
    let part = |joints: f32, root: f32| {
        let mut rates = vec![f64::from(joints); POSE_VALUES];
        for k in root_indices().filter(|&k| k < POSE_VALUES) {
            rates[k] = f64::from(root);
        }
        rates
    };
    let fitter = part(config.lr_pose_correction, config.lr_pose_correction_root);
    let off = vec![0.0; POSE_VALUES];
    let mid = if config.pose_correction && config.pose_correction_mid {
        fitter.clone()
    } else {
        off.clone()
    };
    let change = if config.exposure_motion == ExposureMotion::Learned {
        part(config.lr_exposure_motion, config.lr_exposure_motion_root)
    } else if config.pose_correction && config.pose_correction_change {
        fitter
    } else {
        off
    };
    // One rate per column of the rows (`CORRECTION_VALUES`): this cannot fail.
    adam.with_column_rates([mid, change].concat())
        .unwrap_or_else(|e| unreachable!("{e}"))
}

/// The camera corrections' per-frame Adam for `rows` frames: `lr_camera_rotation` for the
/// twists' rotations, `lr_camera_translation` for their shifts.
/// With `whitened`, the mid-exposure twists' columns step at `lr_camera_pixels` (the image-motion
/// basis' coordinates).
fn camera_adam(rows: usize, config: &TrainConfig, whitened: bool) -> nn::RowAdam<f32> {
    camera_rates(
        nn::RowAdam::new(
            rows,
            CAMERA_CORRECTION_VALUES,
            adam_config(config.lr_camera_rotation),
        ),
        config,
        whitened,
    )
}

/// `adam` with the camera corrections' column rates (the mid-exposure twist's at
/// `lr_camera_pixels` when `whitened`).
fn camera_rates(adam: nn::RowAdam<f32>, config: &TrainConfig, whitened: bool) -> nn::RowAdam<f32> {
    let (rotation, shift) = (
        f64::from(config.lr_camera_rotation),
        f64::from(config.lr_camera_translation),
    );
    let twist = [rotation, rotation, rotation, shift, shift, shift];
    let mid = if whitened {
        [f64::from(config.lr_camera_pixels); TWIST_VALUES]
    } else {
        twist
    };
    let rates = [mid, twist].concat();
    // One rate per column of the rows (`CAMERA_CORRECTION_VALUES`): this cannot fail.
    adam.with_column_rates(rates)
        .unwrap_or_else(|e| unreachable!("{e}"))
}

/// One lazy Adam step of the camera corrections' rows `slots` in the coordinates u of the
/// image-motion basis `basis` (ξ = P u, `crate::pose::camera_basis`) for their mid-exposure
/// twists: the twists' gradients as u's (Pᵀ g), Adam's step of u from zero (its step does not
/// depend on the values it moves), then ξ += P Δu; the change over the exposure steps as itself.
fn whitened_camera_step(
    adam: &mut nn::RowAdam<f32>,
    basis: &[f32; BASIS_VALUES],
    corrections: &mut [f32],
    grads: &[f32],
    slots: &[usize],
    rate_scale: f32,
) -> Result<(), TrainError> {
    let n = CAMERA_CORRECTION_VALUES;
    if grads.len() != corrections.len() || slots.iter().any(|&s| (s + 1) * n > grads.len()) {
        return Err(TrainError::Config(format!(
            "camera correction step: {} gradients for {} values, slots {slots:?}",
            grads.len(),
            corrections.len()
        )));
    }
    // A slot named twice steps once (as `RowAdam` does).
    let mut slots = slots.to_vec();
    slots.sort_unstable();
    slots.dedup();
    let to_f64 = |x: &[f32]| x.iter().map(|&v| f64::from(v)).collect::<Vec<_>>();
    let mut coordinate_grads = grads.to_vec();
    for &slot in &slots {
        let span = slot * n..slot * n + TWIST_VALUES;
        let gu = apply_basis(basis, &to_f64(&grads[span.clone()]), true);
        for (d, v) in coordinate_grads[span].iter_mut().zip(gu) {
            *d = v as f32;
        }
    }
    let mut steps = vec![0.0f32; corrections.len()];
    adam.step_rows_scaled(&mut steps, &coordinate_grads, &slots, f64::from(rate_scale))?;
    for &slot in &slots {
        let (row, steps) = (
            &mut corrections[slot * n..(slot + 1) * n],
            &steps[slot * n..(slot + 1) * n],
        );
        let dxi = apply_basis(basis, &to_f64(&steps[..TWIST_VALUES]), false);
        let (mid, change) = row.split_at_mut(TWIST_VALUES);
        for (x, d) in mid.iter_mut().zip(dxi) {
            *x = (f64::from(*x) + d) as f32;
        }
        for (x, &d) in change.iter_mut().zip(&steps[TWIST_VALUES..]) {
            *x += d;
        }
    }
    Ok(())
}

/// Adam's defaults with the learning rate `lr`.
pub fn adam_config(lr: f32) -> nn::AdamConfig {
    nn::AdamConfig {
        lr: f64::from(lr),
        ..nn::AdamConfig::default()
    }
}

/// The index of the network group `group` in [`NETWORK_GROUPS`].
fn group_index(group: &str) -> Result<usize, TrainError> {
    NETWORK_GROUPS
        .iter()
        .position(|(name, _)| *name == group)
        .ok_or_else(|| TrainError::Config(format!("no network parameter group `{group}`")))
}

impl Optimisers {
    /// Fresh optimiser state (zero moments) for `model` at the rates of `config`.
    /// `camera_basis`: the image-motion basis of the camera corrections' steps, with
    /// `camera_correction_basis = image` (`crate::pose::camera_basis`).
    pub fn new(
        model: &Model,
        config: &TrainConfig,
        camera_basis: Option<[f32; BASIS_VALUES]>,
    ) -> Self {
        let networks = NETWORK_GROUPS
            .iter()
            .zip(model.network_groups())
            .map(|((name, _), params)| {
                let len = if *name == CORRECTION_GROUP {
                    0
                } else {
                    params.len()
                };
                nn::Adam::new(len, adam_config(network_rate(config, name)))
            })
            .collect();
        Self {
            gaussians: GaussianAdam::new(&model.set, AdamConfig::default()),
            networks,
            corrections: correction_adam(
                nn::RowAdam::new(
                    model.pose_corrections.len() / CORRECTION_VALUES,
                    CORRECTION_VALUES,
                    adam_config(config.lr_pose_correction),
                ),
                config,
            ),
            cameras: camera_adam(
                model.camera_corrections.len() / CAMERA_CORRECTION_VALUES,
                config,
                camera_basis.is_some(),
            ),
            camera_gauge: camera_adam(
                model.camera_gauge.len() / CAMERA_CORRECTION_VALUES,
                config,
                false,
            ),
            camera_basis,
        }
    }

    /// One Adam step of the Gaussian attribute groups at the rates `rates`.
    pub fn step_gaussians(
        &mut self,
        set: &mut GaussianSet,
        grads: &GaussianSet,
        rates: &GaussianLearningRates,
    ) -> Result<(), TrainError> {
        self.gaussians
            .step(set, grads, rates)
            .map_err(|e| TrainError::Config(e.to_string()))
    }

    /// One Adam step of the network group `group` (a name of [`NETWORK_GROUPS`]).
    pub fn step_network(
        &mut self,
        group: &str,
        params: &mut [f32],
        grads: &[f32],
    ) -> Result<(), TrainError> {
        if group == CORRECTION_GROUP {
            return Err(TrainError::Config(
                "the pose corrections step by frame: `step_pose_corrections`".into(),
            ));
        }
        let k = group_index(group)?;
        Ok(self.networks[k].step(params, grads)?)
    }

    /// One lazy Adam step of the pose rows' knots `slots` (those of the step's frames; one per
    /// training slot by default), the mid-exposure part at `scales.mid` times its rates and the
    /// change over the exposure at `scales.change` times its; every other knot keeps its values
    /// and moments.
    pub fn step_pose_corrections(
        &mut self,
        corrections: &mut [f32],
        grads: &[f32],
        slots: &[usize],
        scales: PoseRateScales,
    ) -> Result<(), TrainError> {
        let (mid, change) = (f64::from(scales.mid), f64::from(scales.change));
        Ok(self
            .corrections
            .step_rows_column_scaled(corrections, grads, slots, |j| {
                if j < POSE_VALUES {
                    mid
                } else {
                    change
                }
            })?)
    }

    /// One lazy Adam step of the camera corrections of the training slots `slots` at `rate_scale`
    /// times their rates; every other frame keeps its correction and moments.
    pub fn step_camera_corrections(
        &mut self,
        corrections: &mut [f32],
        grads: &[f32],
        slots: &[usize],
        rate_scale: f32,
    ) -> Result<(), TrainError> {
        let Some(basis) = &self.camera_basis else {
            return Ok(self.cameras.step_rows_scaled(
                corrections,
                grads,
                slots,
                f64::from(rate_scale),
            )?);
        };
        whitened_camera_step(
            &mut self.cameras,
            basis,
            corrections,
            grads,
            slots,
            rate_scale,
        )
    }

    /// One Adam step of the clip-wide camera twist at `rate_scale` times the camera rates.
    pub fn step_camera_gauge(
        &mut self,
        gauge: &mut [f32],
        grads: &[f32],
        rate_scale: f32,
    ) -> Result<(), TrainError> {
        if gauge.is_empty() {
            return Ok(());
        }
        Ok(self
            .camera_gauge
            .step_rows_scaled(gauge, grads, &[0], f64::from(rate_scale))?)
    }

    /// Adds every moment to `w` (`adam.<group>.{m,v}` and `<group>_adam.{m,v}`; an empty group's
    /// are not stored); returns the step counts for the metadata.
    pub fn save(&self, w: &mut CheckpointWriter) -> OptimiserSteps {
        let gaussians = w.push_gaussian_adam("adam", &self.gaussians);
        let networks = NETWORK_GROUPS
            .iter()
            .zip(&self.networks)
            .map(|((name, _), adam)| {
                if *name == CORRECTION_GROUP {
                    let rows = &self.corrections;
                    let (m, v) = rows.moments();
                    if !m.is_empty() {
                        w.push(format!("{name}_adam.m"), m.to_vec());
                        w.push(format!("{name}_adam.v"), v.to_vec());
                        let steps = rows.row_steps().iter().map(|&t| t as f32).collect();
                        w.push(format!("{name}_adam.row_steps"), steps);
                    }
                    rows.row_steps().iter().sum()
                } else if adam.moments().0.is_empty() {
                    adam.steps()
                } else {
                    w.push_adam(&format!("{name}_adam"), adam)
                }
            })
            .collect();
        if let Some(basis) = &self.camera_basis {
            w.push(CAMERA_BASIS, basis.to_vec());
        }
        for (prefix, adam) in [
            (CAMERA_ADAM, &self.cameras),
            (CAMERA_GAUGE_ADAM, &self.camera_gauge),
        ] {
            let (m, v) = adam.moments();
            if !m.is_empty() {
                w.push(format!("{prefix}.m"), m.to_vec());
                w.push(format!("{prefix}.v"), v.to_vec());
                let steps = adam.row_steps().iter().map(|&t| t as f32).collect();
                w.push(format!("{prefix}.row_steps"), steps);
            }
        }
        OptimiserSteps {
            gaussians,
            networks,
        }
    }

    /// The optimisers [`Optimisers::save`] wrote, for `model` (which fixes every length) at the rates
    /// of `config`. A
    /// checkpoint from before the pose-correction group (one step count fewer) loads when the model
    /// has no pose corrections.
    pub fn load(
        r: &CheckpointReader,
        model: &Model,
        config: &TrainConfig,
        steps: &OptimiserSteps,
    ) -> Result<Self, TrainError> {
        let mut gaussians = GaussianAdam::new(&model.set, AdamConfig::default());
        r.gaussian_adam("adam", &mut gaussians, &steps.gaussians)?;
        let mut counts = steps.networks.clone();
        if counts.len() + 1 == NETWORK_GROUPS.len() && model.pose_corrections.is_empty() {
            counts.push(0);
        }
        if counts.len() != NETWORK_GROUPS.len() {
            return Err(r.error(format!(
                "expected {} network optimiser step counts",
                NETWORK_GROUPS.len()
            )));
        }
        let networks = NETWORK_GROUPS
            .iter()
            .zip(model.network_groups())
            .zip(&counts)
            .map(|(((name, _), params), &count)| {
                let adam = adam_config(network_rate(config, name));
                if params.is_empty() || *name == CORRECTION_GROUP {
                    return Ok(nn::Adam::new(0, adam));
                }
                r.adam(&format!("{name}_adam"), adam, params.len(), count)
            })
            .collect::<Result<_, _>>()?;
        let corrections =
            Self::load_corrections(r, model, config, counts[group_index(CORRECTION_GROUP)?])?;
        let camera_basis = if config.camera_correction_basis == CameraCorrectionBasis::Image
            && !model.camera_corrections.is_empty()
        {
            let values = r.get_len(CAMERA_BASIS, BASIS_VALUES)?;
            let basis: [f32; BASIS_VALUES] = values
                .try_into()
                .map_err(|_| r.error(format!("{CAMERA_BASIS}: expected {BASIS_VALUES} values")))?;
            if basis.iter().any(|v| !v.is_finite()) {
                return Err(r.error(format!("{CAMERA_BASIS}: a value is not finite")));
            }
            Some(basis)
        } else {
            None
        };
        let cameras = Self::load_cameras(
            r,
            CAMERA_ADAM,
            model.camera_corrections.len(),
            config,
            camera_basis.is_some(),
        )?;
        let camera_gauge = Self::load_cameras(
            r,
            CAMERA_GAUGE_ADAM,
            model.camera_gauge.len(),
            config,
            false,
        )?;
        Ok(Self {
            gaussians,
            networks,
            corrections,
            cameras,
            camera_gauge,
            camera_basis,
        })
    }

    /// A per-row camera Adam stored under `prefix` for `len` values (the camera corrections' or
    /// the clip-wide twist's; none when `len` is 0).
    fn load_cameras(
        r: &CheckpointReader,
        prefix: &str,
        len: usize,
        config: &TrainConfig,
        whitened: bool,
    ) -> Result<nn::RowAdam<f32>, TrainError> {
        let rows = len / CAMERA_CORRECTION_VALUES;
        if len == 0 {
            return Ok(camera_adam(0, config, whitened));
        }
        let m = r.get_len(&format!("{prefix}.m"), len)?;
        let v = r.get_len(&format!("{prefix}.v"), len)?;
        let steps = row_steps(r, &format!("{prefix}.row_steps"), rows)?;
        Ok(camera_rates(
            nn::RowAdam::from_parts(
                adam_config(config.lr_camera_rotation),
                CAMERA_CORRECTION_VALUES,
                m,
                v,
                steps,
            )?,
            config,
            whitened,
        ))
    }

    /// The pose corrections' per-frame Adam; a checkpoint from before it (one dense Adam over
    /// every frame, no `row_steps`) gives every frame that Adam's moments and step count.
    fn load_corrections(
        r: &CheckpointReader,
        model: &Model,
        rates: &TrainConfig,
        count: u64,
    ) -> Result<nn::RowAdam<f32>, TrainError> {
        let config = adam_config(rates.lr_pose_correction);
        let len = model.pose_corrections.len();
        let rows = len / CORRECTION_VALUES;
        if len == 0 {
            return Ok(correction_adam(
                nn::RowAdam::new(0, CORRECTION_VALUES, config),
                rates,
            ));
        }
        let prefix = format!("{CORRECTION_GROUP}_adam");
        let m = r.get_len(&format!("{prefix}.m"), len)?;
        let v = r.get_len(&format!("{prefix}.v"), len)?;
        let name = format!("{prefix}.row_steps");
        let steps = if r.has(&name) {
            row_steps(r, &name, rows)?
        } else {
            vec![count; rows]
        };
        Ok(correction_adam(
            nn::RowAdam::from_parts(config, CORRECTION_VALUES, m, v, steps)?,
            rates,
        ))
    }
}

/// The per-row step counts stored in tensor `name` (`rows` of them, whole numbers stored as f32).
fn row_steps(r: &CheckpointReader, name: &str, rows: usize) -> Result<Vec<u64>, TrainError> {
    r.get_len(name, rows)?
        .iter()
        .map(|&t| {
            if t >= 0.0 && t.fract() == 0.0 && t < 16_777_216.0 {
                Ok(t as u64)
            } else {
                Err(r.error(format!("tensor `{name}`: {t} is not a step count")))
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A first whitened step moves a row's mid-exposure twist by −lr · P · sign(Pᵀ g) (Adam's
    /// first step is −lr · sign per coordinate), its change by −lr · sign(g), and leaves other
    /// rows alone; P is not symmetric here, so a transposition in either direction fails.
    #[test]
    fn a_whitened_step_moves_the_twist_along_the_basis() {
        let lr = 0.25f64;
        let config = TrainConfig {
            lr_camera_pixels: lr as f32,
            lr_camera_rotation: 0.01,
            lr_camera_translation: 0.02,
            ..TrainConfig::default()
        };
        let mut adam = camera_adam(2, &config, true);
        // Upper triangular: Pᵀ g and P g differ in sign for these gradients.
        let basis: [f32; BASIS_VALUES] = std::array::from_fn(|k| {
            let (r, c) = (k / TWIST_VALUES, k % TWIST_VALUES);
            if c >= r {
                1.0 + c as f32
            } else {
                0.0
            }
        });
        let n = CAMERA_CORRECTION_VALUES;
        let mut corrections = vec![0.5f32; 2 * n];
        let grads: Vec<f32> = (0..2 * n).map(|k| (k as f32 * 0.37).sin()).collect();
        whitened_camera_step(&mut adam, &basis, &mut corrections, &grads, &[1, 1], 1.0).unwrap();
        assert!(corrections[..n].iter().all(|&v| v == 0.5), "row 0 moved");
        let g: Vec<f64> = grads[n..n + TWIST_VALUES]
            .iter()
            .map(|&v| f64::from(v))
            .collect();
        let signs: Vec<f64> = apply_basis(&basis, &g, true)
            .iter()
            .map(|v| v.signum())
            .collect();
        let want = apply_basis(&basis, &signs, false);
        for k in 0..TWIST_VALUES {
            let got = f64::from(corrections[n + k]) - 0.5;
            // Adam's ε and f32 storage: 1e-4 relative.
            let tol = 1e-4 * (lr * want[k]).abs().max(0.1);
            assert!(
                (got + lr * want[k]).abs() < tol,
                "twist {k}: {got} against {}",
                -lr * want[k]
            );
        }
        for k in 0..TWIST_VALUES {
            let rate = if k < 3 { 0.01 } else { 0.02 };
            let got = f64::from(corrections[n + TWIST_VALUES + k]) - 0.5;
            let want = -rate * f64::from(grads[n + TWIST_VALUES + k]).signum();
            assert!(
                (got - want).abs() < 1e-6,
                "change {k}: {got} against {want}"
            );
        }
        assert!(
            whitened_camera_step(&mut adam, &basis, &mut corrections, &grads, &[2], 1.0).is_err()
        );
    }
}
