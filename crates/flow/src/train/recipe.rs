//! The recipe of the project's SPyNet weights (`cargo xtask train-flow`), deterministic from the
//! seed, in three phases:
//!
//! 1. **Pre-training** of a single level on small pairs of pure background translation (no
//!    brightness jitter, textures resolved at that size) with a squared-error loss, from the
//!    motion-aware initialisation ([`SpyNet::random_init`]): the phase that leaves the zero-flow
//!    plateau every earlier recipe stayed on. Skipped when the run starts from given weights.
//! 2. The pre-trained level copied into every level ([`replicate_level`]) and each level fine-tuned
//!    coarse to fine (lower levels frozen); a level whose validation EPE does not improve keeps
//!    its weights from before.
//! 3. **Joint** training of all levels on the multi-scale loss ([`Trainer::step_joint`]); the
//!    weights are validated every `report_every` steps and the best ones kept.
//!
//! Validation is on `validation_set` when given (e.g. frame pairs of rendered scenes, weighted by
//! the flow loss's mask), else on `validation_pairs` procedural pairs of seed `eval_seed + 1`.
//! What a run shows and where it writes its weights is the caller's: it watches through a
//! [`RecipeObserver`].

use super::{
    evaluate, evaluate_pairs, replicate_level, ExtraPairs, Optimizer, TrainConfig, Trainer,
};
use crate::synthetic::{Pair, PairConfig};
use crate::{FlowError, SpyNet};
use std::time::Instant;

/// The pre-training phase: one level on small pure-translation pairs (`steps = 0`: none).
#[derive(Clone, Debug)]
pub struct Pretraining {
    /// Optimiser steps.
    pub steps: usize,
    /// Image side of its pairs (pixels).
    pub size: usize,
    /// Largest background translation, as a fraction of `size`.
    pub max_translation: f32,
    /// Pairs per step.
    pub batch: usize,
    /// Peak learning rate.
    pub lr: f64,
}

/// The joint phase: every level trained together (`steps = 0`: none).
#[derive(Clone, Debug)]
pub struct JointPhase {
    /// Optimiser steps.
    pub steps: usize,
    /// Pairs per step.
    pub batch: usize,
    /// Peak learning rate.
    pub lr: f64,
    /// Decay the rate to zero along a cosine over `steps` (else constant after the warm-up).
    pub cosine: bool,
}

/// Every setting of the recipe.
#[derive(Clone, Debug)]
pub struct Recipe {
    /// Pyramid levels.
    pub levels: usize,
    /// Image side of the fine-tuning and joint pairs (pixels; a multiple of `2^(levels−1)`).
    pub size: usize,
    /// Phase 1.
    pub pretraining: Pretraining,
    /// Phase 2: fine-tuning steps per level, coarsest first (one value per level).
    pub level_steps: Vec<usize>,
    /// Phase 2: pairs per step.
    pub batch: usize,
    /// Phase 2: peak learning rate.
    pub lr: f64,
    /// Phase 3.
    pub joint: JointPhase,
    /// Optimiser of every phase.
    pub optimizer: Optimizer,
    /// Linear warm-up steps at the start of every phase and level.
    pub warmup_steps: usize,
    /// Steps on the squared error before the end-point error, per phase and level.
    pub mse_steps: usize,
    /// Scale of the output convolution's initial weights relative to He-uniform.
    pub output_init_gain: f64,
    /// Motion-aware first-layer initialisation ([`SpyNet::random_init`]).
    pub paired_input_init: bool,
    /// Seed of the initial weights and of the training pairs.
    pub seed: u64,
    /// Probability that a phase-2/3 pair has a static background.
    pub static_background: f32,
    /// Fixed pairs mixed into the procedural ones.
    pub extra_pairs: Option<ExtraPairs>,
    /// Report (and, in the joint phase, validate) every this many steps (0 = pre-training never
    /// reports; the joint phase still validates at its end).
    pub report_every: usize,
    /// Seed of the held-out pairs; validation pairs use `eval_seed + 1`.
    pub eval_seed: u64,
    /// Procedural validation pairs (0 = always keep the latest weights).
    pub validation_pairs: u64,
    /// Validation pairs replacing the procedural ones when not empty.
    pub validation_set: Vec<Pair>,
}

/// What the caller sees of a run: progress, report lines and the weights worth keeping.
pub trait RecipeObserver {
    /// The caller's error (it must hold the recipe's).
    type Error: From<FlowError>;
    /// A phase of `steps` steps begins (`"pretrain"`, `"train"`, `"joint"`).
    fn phase_started(&mut self, phase: &'static str, steps: u64) -> Result<(), Self::Error>;
    /// One step is done; `status` is its running loss.
    fn stepped(&mut self, status: String);
    /// The current phase is over.
    fn phase_finished(&mut self, phase: &'static str);
    /// A report line (validation figures, elapsed seconds).
    fn report(&mut self, line: String);
    /// The best weights so far, worth writing (a stopped run then leaves them behind).
    fn weights(&mut self, net: &SpyNet<f32>) -> Result<(), Self::Error>;
}

/// Appends `value` to the window `recent`, keeps its last `len` values and returns their mean.
fn running_mean(recent: &mut Vec<f64>, value: f64, len: usize) -> f64 {
    recent.push(value);
    if recent.len() > len {
        recent.remove(0);
    }
    recent.iter().sum::<f64>() / recent.len() as f64
}

impl Recipe {
    /// The procedural pairs of phases 2 and 3.
    pub fn pairs(&self) -> PairConfig {
        PairConfig {
            size: self.size,
            static_background: self.static_background,
            ..PairConfig::default()
        }
    }

    /// One phase's training settings.
    fn config(&self, levels: usize, pairs: PairConfig, batch: usize, lr: f64) -> TrainConfig {
        TrainConfig {
            levels,
            pairs,
            batch,
            lr,
            optimizer: self.optimizer,
            warmup_steps: self.warmup_steps,
            mse_steps: self.mse_steps,
            output_init_gain: self.output_init_gain,
            paired_input_init: self.paired_input_init,
            seed: self.seed,
            distinct_pairs: None,
            decay_steps: 0,
            extra_pairs: self.extra_pairs.clone(),
        }
    }

    /// The validation EPE of `net` (px).
    fn validation(&self, net: &SpyNet<f32>) -> Result<f64, FlowError> {
        if self.validation_set.is_empty() {
            Ok(evaluate(
                net,
                self.eval_seed + 1,
                self.validation_pairs,
                &self.pairs(),
            )?
            .0)
        } else {
            Ok(evaluate_pairs(net, &self.validation_set)?.0)
        }
    }

    /// Runs the recipe from `init` (given weights: no pre-training) or from scratch, and returns
    /// the trained network.
    pub fn run<O: RecipeObserver>(
        &self,
        init: Option<SpyNet<f32>>,
        observer: &mut O,
    ) -> Result<SpyNet<f32>, O::Error> {
        let start = Instant::now();
        let net = match init {
            Some(net) => net,
            None if self.pretraining.steps > 0 => self.pretrain(start, observer)?,
            None => SpyNet::random_init(
                self.levels,
                self.seed,
                self.output_init_gain,
                self.paired_input_init,
            ),
        };
        let net = self.fine_tune_levels(net, start, observer)?;
        if self.joint.steps == 0 {
            return Ok(net);
        }
        self.joint_phase(net, start, observer)
    }

    /// Phase 1, then its level copied into every level.
    fn pretrain<O: RecipeObserver>(
        &self,
        start: Instant,
        observer: &mut O,
    ) -> Result<SpyNet<f32>, O::Error> {
        let p = &self.pretraining;
        let pairs = PairConfig {
            size: p.size,
            max_translation: p.max_translation,
            max_rotation: 0.0,
            max_scale: 0.0,
            max_foreground_layers: 0,
            brightness_jitter: 0.0,
            ..PairConfig::default()
        };
        let mut t = Trainer::new(self.config(1, pairs, p.batch, p.lr));
        observer.phase_started("pretrain", p.steps as u64)?;
        let mut recent = Vec::new();
        for s in 0..p.steps {
            let r = t.step_report(0)?;
            let mean = running_mean(&mut recent, r.epe, 50);
            observer.stepped(format!("pre-training epe {mean:.3}"));
            if self.report_every > 0 && (s + 1) % self.report_every == 0 {
                let (e, z) = evaluate(&t.net, self.eval_seed, 20, &pairs)?;
                let live: Vec<String> = r.live_relu.iter().map(|v| format!("{v:.2}")).collect();
                observer.report(format!(
                    "pre-training step {}: last-50 EPE {mean:.3}, held-out {e:.3} / zero {z:.3} = {:.3}, live ReLUs [{}], {:.0} s",
                    s + 1,
                    e / z,
                    live.join(" "),
                    start.elapsed().as_secs_f64()
                ));
                observer.weights(&replicate_level(&t.net, 0, self.levels))?;
            }
        }
        observer.phase_finished("pretrain");
        let net = replicate_level(&t.net, 0, self.levels);
        observer.weights(&net)?;
        Ok(net)
    }

    /// Phase 2: each level fine-tuned in turn, kept only if its validation EPE improves.
    fn fine_tune_levels<O: RecipeObserver>(
        &self,
        net: SpyNet<f32>,
        start: Instant,
        observer: &mut O,
    ) -> Result<SpyNet<f32>, O::Error> {
        let mut trainer = Trainer::from_net(
            net,
            self.config(self.levels, self.pairs(), self.batch, self.lr),
        );
        observer.phase_started("train", self.level_steps.iter().sum::<usize>() as u64)?;
        for (level, &n) in self.level_steps.iter().enumerate() {
            let before = if n > 0 && self.validation_pairs > 0 {
                let weights = trainer.net.levels[level].clone();
                Some((weights, self.validation(&trainer.net)?))
            } else {
                None
            };
            let mut recent = Vec::new();
            for _ in 0..n {
                let epe = trainer.step(level)?;
                let mean = running_mean(&mut recent, epe, 20);
                observer.stepped(format!("level {level} epe {mean:.3}"));
            }
            if n == 0 {
                continue;
            }
            let mut verdict = String::new();
            if let Some((old, old_epe)) = before {
                let new_epe = self.validation(&trainer.net)?;
                verdict = format!(", validation EPE {old_epe:.3} -> {new_epe:.3} px");
                if new_epe >= old_epe {
                    trainer.net.levels[level] = old;
                    verdict += " (fine-tuning discarded)";
                }
            }
            observer.weights(&trainer.net)?;
            observer.report(format!(
                "level {level}: {n} steps, last-20 mean EPE {:.3} (level pixels){verdict}, {:.0} s",
                recent.iter().sum::<f64>() / recent.len().max(1) as f64,
                start.elapsed().as_secs_f64()
            ));
        }
        observer.phase_finished("train");
        Ok(trainer.net)
    }

    /// Phase 3: all levels together, the best validated weights kept.
    fn joint_phase<O: RecipeObserver>(
        &self,
        net: SpyNet<f32>,
        start: Instant,
        observer: &mut O,
    ) -> Result<SpyNet<f32>, O::Error> {
        let j = &self.joint;
        let mut best_net = net.clone();
        let mut joint = Trainer::from_net(
            net,
            TrainConfig {
                decay_steps: if j.cosine { j.steps } else { 0 },
                ..self.config(self.levels, self.pairs(), j.batch, j.lr)
            },
        );
        observer.phase_started("joint", j.steps as u64)?;
        let mut best = self.validation(&joint.net)?;
        observer.report(format!(
            "joint phase: validation EPE {best:.3} px at the start"
        ));
        let mut recent = Vec::new();
        for s in 0..j.steps {
            let r = joint.step_joint()?;
            let mean = running_mean(&mut recent, r.epe, 50);
            observer.stepped(format!("joint epe {mean:.3}"));
            let last = s + 1 == j.steps;
            if (self.report_every > 0 && (s + 1) % self.report_every == 0) || last {
                // Without validation pairs every report keeps the latest weights.
                let v = self.validation(&joint.net)?;
                let kept = self.validation_pairs == 0 || v < best;
                if kept {
                    best = v;
                    best_net = joint.net.clone();
                    observer.weights(&best_net)?;
                }
                observer.report(format!(
                    "joint step {}: last-50 EPE {mean:.3}, validation {v:.3} px{}, {:.0} s",
                    s + 1,
                    if kept { " (best, saved)" } else { "" },
                    start.elapsed().as_secs_f64()
                ));
            }
        }
        observer.phase_finished("joint");
        Ok(best_net)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Records what a run shows.
    #[derive(Default)]
    struct Recorder {
        phases: Vec<(&'static str, u64)>,
        steps: usize,
        saved: Vec<SpyNet<f32>>,
    }

    impl RecipeObserver for Recorder {
        type Error = FlowError;
        fn phase_started(&mut self, phase: &'static str, steps: u64) -> Result<(), FlowError> {
            self.phases.push((phase, steps));
            Ok(())
        }
        fn stepped(&mut self, _: String) {
            self.steps += 1;
        }
        fn phase_finished(&mut self, _: &'static str) {}
        fn report(&mut self, _: String) {}
        fn weights(&mut self, net: &SpyNet<f32>) -> Result<(), FlowError> {
            self.saved.push(net.clone());
            Ok(())
        }
    }

    fn tiny(validation_pairs: u64) -> Recipe {
        Recipe {
            levels: 2,
            size: 16,
            pretraining: Pretraining {
                steps: 3,
                size: 16,
                max_translation: 0.06,
                batch: 2,
                lr: 2e-4,
            },
            level_steps: vec![2, 1],
            batch: 2,
            lr: 1e-4,
            joint: JointPhase {
                steps: 2,
                batch: 2,
                lr: 5e-5,
                cosine: false,
            },
            optimizer: Optimizer::Adam,
            warmup_steps: 1,
            mse_steps: usize::MAX,
            output_init_gain: 0.0,
            paired_input_init: true,
            seed: 3,
            static_background: 0.0,
            extra_pairs: None,
            report_every: 1,
            eval_seed: 11,
            validation_pairs,
            validation_set: Vec::new(),
        }
    }

    #[test]
    fn every_phase_runs_its_steps_and_the_result_is_the_last_weights_shown() {
        for validation_pairs in [0, 2] {
            let mut seen = Recorder::default();
            let net = tiny(validation_pairs).run(None, &mut seen).unwrap();
            assert_eq!(seen.phases, [("pretrain", 3), ("train", 3), ("joint", 2)]);
            assert_eq!(seen.steps, 3 + 3 + 2);
            // Without validation every joint report keeps its weights; with it, the kept ones are
            // the best validated, and the run returns exactly what it last offered to be written.
            assert!(
                seen.saved.len() >= 3 + 2,
                "{} weights shown",
                seen.saved.len()
            );
            assert_eq!(seen.saved.last(), Some(&net));
            let again = tiny(validation_pairs)
                .run(None, &mut Recorder::default())
                .unwrap();
            assert_eq!(again, net, "same seed, same weights");
        }
    }

    #[test]
    fn given_weights_skip_the_pre_training() {
        let init = SpyNet::random_init(2, 5, 0.0, true);
        let mut seen = Recorder::default();
        tiny(0).run(Some(init), &mut seen).unwrap();
        assert_eq!(seen.phases[0], ("train", 3));
    }
}
