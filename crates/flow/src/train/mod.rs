//! Training the project's own SPyNet weights on [`crate::synthetic`] pairs, coarse to fine as SPyNet
//! was trained: level `l` is trained with levels `< l` frozen, on the end-point error between its
//! output and the ground-truth flow reduced to its resolution (2×2 average pooling, vectors ×½ per
//! level). Deterministic from the seed: pair `k` of a run is `generate_pair(seed, k)`, or one of a
//! fixed set of extra pairs chosen by a hash of the seed and `k` ([`ExtraPairs`]).
//!
//! The loss of one pair at level `l` is [`level_epe_loss`]: the mean over the level's pixels of the
//! smoothed end-point error `√(Δu² + Δv² + ε)` with `ε = 1e-6` px². Its weight gradient is checked
//! against finite differences of the same function in `tests/gradient-checks` (test `flow`), so the
//! composition the optimiser sees (partial forward, loss, last-level backward) is covered, not only
//! the individual ops.

pub mod recipe;

use crate::synthetic::{average_epe, generate_pair, Pair, PairConfig};
use crate::{FlowError, SpyNet};
use nn::{avg_pool2x2_forward, pooled_size, Adam, AdamConfig, Real};
use std::sync::Arc;

/// Per-pixel loss of a level's flow against its ground truth.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Loss {
    /// Smoothed end-point error `√(Δu² + Δv² + ε)` (SPyNet's training loss). Its gradient has unit
    /// norm per pixel whatever the error, so on a noisy batch it pulls towards the median flow (≈ 0).
    Epe,
    /// Half the squared end-point error `(Δu² + Δv²)/2`: the gradient is proportional to the error and
    /// the optimum is the conditional mean, which makes the zero-flow attractor weaker at the start.
    Mse,
}

/// Optimiser of a training run.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Optimizer {
    /// Adam with PyTorch's defaults apart from the learning rate.
    Adam,
    /// Plain SGD with (heavy-ball) momentum `v ← μv + g`, `p ← p − lr·v`: steps proportional to the
    /// gradient, so pure-noise directions are not amplified to learning-rate-sized steps.
    Sgd {
        /// Momentum `μ` (0.9 is the usual value).
        momentum: f64,
    },
}

/// Smoothing `ε` (px²) of the end-point-error loss `√(Δu² + Δv² + ε)`: keeps the loss differentiable
/// where the prediction is exact, far below the EPE values of interest (≥ 0.01 px).
pub const EPE_EPS: f64 = 1e-6;

/// Knobs of a training run.
#[derive(Clone, Debug)]
pub struct TrainConfig {
    /// Number of pyramid levels of the network.
    pub levels: usize,
    /// Pair generator settings (image size must be a multiple of `2^(levels−1)`).
    pub pairs: PairConfig,
    /// Pairs per optimiser step.
    pub batch: usize,
    /// Peak learning rate of the optimiser.
    pub lr: f64,
    /// Optimiser.
    pub optimizer: Optimizer,
    /// Steps of linear learning-rate warm-up at the start of every level (0 = none).
    pub warmup_steps: usize,
    /// Scale of the output convolution's initial weights relative to He-uniform (see
    /// [`SpyNet::random_with_output_gain`]; 0.1 was the original initialisation).
    pub output_init_gain: f64,
    /// Motion-aware first-layer initialisation (see [`SpyNet::random_init`]): every first-layer
    /// filter mixes a zero-mean appearance filter and an amplified temporal-difference filter.
    pub paired_input_init: bool,
    /// Steps at the start of every level trained on [`Loss::Mse`] before switching to [`Loss::Epe`]
    /// (0 = EPE throughout, `usize::MAX` = MSE throughout).
    pub mse_steps: usize,
    /// Seed of the initial weights and of the training pairs.
    pub seed: u64,
    /// `Some(n)`: cycle over the fixed set of pairs `0..n` of the seed (a small data set, e.g. for
    /// tests that must see the loss go down); `None`: every step draws fresh pairs.
    pub distinct_pairs: Option<u64>,
    /// Steps of a cosine learning-rate decay from the peak to zero, counted from a level's (or the
    /// joint phase's) first step; later steps keep a rate of zero (0 = constant peak rate).
    pub decay_steps: usize,
    /// Fixed pairs from elsewhere (e.g. frames rendered by the synthetic benchmark's generator
    /// with other seeds) mixed into the procedural ones; `None` = procedural pairs only.
    pub extra_pairs: Option<ExtraPairs>,
}

/// A fixed set of training pairs mixed into a run's procedural pairs: pair `k` of the run is, with
/// probability `fraction` (decided by a hash of the seed and `k`), one of `pairs` picked by another
/// hash and mirrored left–right with probability ½ (image columns reversed, horizontal flow negated);
/// otherwise the procedural pair `k`. Deterministic like the rest of the run.
#[derive(Clone)]
pub struct ExtraPairs {
    /// The pairs, all of the run's image size.
    pub pairs: Arc<Vec<Pair>>,
    /// Probability in `[0, 1]` that a training pair is drawn from `pairs`.
    pub fraction: f32,
}

impl std::fmt::Debug for ExtraPairs {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ExtraPairs")
            .field("pairs", &self.pairs.len())
            .field("fraction", &self.fraction)
            .finish()
    }
}

/// A well-mixed 64-bit hash of `x`: the first output of SplitMix64 seeded with `x`.
fn mix64(x: u64) -> u64 {
    crate::synthetic::Rng(x).next_u64()
}

/// `pair` mirrored left–right: columns reversed in both images and the flow, horizontal flow negated.
pub fn mirror_pair(pair: &Pair) -> Pair {
    let (h, w) = (pair.height, pair.width);
    let mirror = |data: &[f32], channels: usize, negate_first: bool| -> Vec<f32> {
        let mut out = vec![0.0f32; data.len()];
        for c in 0..channels {
            let sign = if negate_first && c == 0 { -1.0 } else { 1.0 };
            for y in 0..h {
                let row = (c * h + y) * w;
                for x in 0..w {
                    out[row + x] = sign * data[row + w - 1 - x];
                }
            }
        }
        out
    };
    Pair {
        height: h,
        width: w,
        img1: mirror(&pair.img1, 3, false),
        img2: mirror(&pair.img2, 3, false),
        flow: mirror(&pair.flow, 2, true),
        weight: pair.weight.as_ref().map(|w| mirror(w, 1, false)),
    }
}

impl TrainConfig {
    /// Pair `index` of the run's training data: procedural, or from [`TrainConfig::extra_pairs`].
    pub fn training_pair(&self, index: u64) -> Pair {
        if let Some(extra) = &self.extra_pairs {
            let h = mix64(self.seed ^ mix64(index ^ 0x005E_ED0F_E77A));
            let draw = (h >> 40) as f32 / (1u64 << 24) as f32;
            if !extra.pairs.is_empty() && draw < extra.fraction {
                let h2 = mix64(h);
                let pick = &extra.pairs[(h2 >> 1) as usize % extra.pairs.len()];
                return if h2 & 1 == 1 {
                    mirror_pair(pick)
                } else {
                    pick.clone()
                };
            }
        }
        generate_pair(self.seed, index, &self.pairs)
    }
}

/// Network plus optimiser state of a coarse-to-fine training run.
pub struct Trainer {
    /// The network being trained.
    pub net: SpyNet<f32>,
    cfg: TrainConfig,
    adams: Vec<Vec<(Adam<f32>, Adam<f32>)>>,
    /// SGD momentum buffers, same layout as `net` (used with [`Optimizer::Sgd`]).
    velocity: SpyNet<f32>,
    /// Steps taken so far per level (for the warm-up and loss schedules).
    level_steps: Vec<usize>,
    next_pair: u64,
}

/// Result of one [`Trainer::step`].
#[derive(Clone, Debug)]
pub struct StepReport {
    /// Batch mean EPE at the level's resolution (level pixels).
    pub epe: f64,
    /// Batch mean of the loss that was optimised.
    pub loss: f64,
    /// Fraction of positive outputs of the level's four ReLU layers on the batch's first pair.
    pub live_relu: Vec<f64>,
}

/// Ground-truth flow `(2, H, W)` reduced to level `level` of an `levels`-level pyramid.
pub fn flow_at_level(flow: &[f32], h: usize, w: usize, levels: usize, level: usize) -> Vec<f32> {
    pool_to_level(flow, 2, 0.5, h, w, levels, level)
}

/// A per-pixel loss weight `(h, w)` reduced to pyramid level `level` of `levels` by repeated 2×2
/// average pooling (values unchanged in scale, unlike the flow's).
pub fn weight_at_level(
    weight: &[f32],
    h: usize,
    w: usize,
    levels: usize,
    level: usize,
) -> Vec<f32> {
    pool_to_level(weight, 1, 1.0, h, w, levels, level)
}

/// `(channels, h, w)` data 2×2-average-pooled from the finest level down to `level`, multiplied by
/// `scale` at each halving.
fn pool_to_level(
    data: &[f32],
    channels: usize,
    scale: f32,
    h: usize,
    w: usize,
    levels: usize,
    level: usize,
) -> Vec<f32> {
    let (mut f, mut h, mut w) = (data.to_vec(), h, w);
    for _ in level + 1..levels {
        let (ph, pw) = (pooled_size(h), pooled_size(w));
        let mut p = vec![0.0f32; channels * ph * pw];
        // Shapes are consistent by construction; an error here would be a programming error.
        if avg_pool2x2_forward(channels, h, w, &f, &mut p).is_err() {
            return p;
        }
        if scale != 1.0 {
            p.iter_mut().for_each(|v| *v *= scale);
        }
        (f, h, w) = (p, ph, pw);
    }
    f
}

/// Mean smoothed end-point-error loss of one pair at level `level` (see the module doc), in that
/// level's pixels, and — if `weight_grads` is given — **accumulates** `scale · ∂loss/∂weights` of
/// level `level` into it (lower levels are frozen). `truth` is the ground-truth flow already reduced
/// to the level ([`flow_at_level`]); `h`, `w` are the full image size (multiples of
/// [`SpyNet::size_multiple`]).
pub fn level_epe_loss<T: Real>(
    net: &SpyNet<T>,
    img1: &[T],
    img2: &[T],
    h: usize,
    w: usize,
    level: usize,
    truth: &[T],
    weight_grads: Option<&mut SpyNet<T>>,
    scale: f64,
) -> Result<f64, FlowError> {
    let tape = net.forward_to_level(img1, img2, h, w, level)?;
    Ok(level_loss_on_tape(net, &tape, truth, Loss::Epe, weight_grads, scale)?.0)
}

/// [`level_epe_loss`] for any [`Loss`], on an existing partial-forward tape of `net` (from
/// [`SpyNet::forward_to_level`]); returns `(loss, mean EPE)`, both in the level's pixels.
pub fn level_loss_on_tape<T: Real>(
    net: &SpyNet<T>,
    tape: &crate::Tape<T>,
    truth: &[T],
    kind: Loss,
    weight_grads: Option<&mut SpyNet<T>>,
    scale: f64,
) -> Result<(f64, f64), FlowError> {
    let (loss, epe, g) = pixel_loss(&tape.flow, truth, None, kind, scale)?;
    if let Some(grads) = weight_grads {
        net.backward_last_level_weights(tape, &g, grads)?;
    }
    Ok((loss, epe))
}

impl Trainer {
    /// A fresh network ([`SpyNet::random_init`]) and zeroed optimiser state.
    pub fn new(cfg: TrainConfig) -> Self {
        let net = SpyNet::random_init(
            cfg.levels,
            cfg.seed,
            cfg.output_init_gain,
            cfg.paired_input_init,
        );
        Self::from_net(net, cfg)
    }

    /// Continues training an existing network.
    pub fn from_net(net: SpyNet<f32>, cfg: TrainConfig) -> Self {
        let adam = AdamConfig {
            lr: cfg.lr,
            ..AdamConfig::default()
        };
        let adams = net
            .levels
            .iter()
            .map(|l| {
                l.iter()
                    .map(|c| {
                        (
                            Adam::new(c.weight.len(), adam),
                            Adam::new(c.bias.len(), adam),
                        )
                    })
                    .collect()
            })
            .collect();
        let velocity = net.zeros_like();
        let level_steps = vec![0; net.num_levels()];
        Self {
            net,
            cfg,
            adams,
            velocity,
            level_steps,
            next_pair: 0,
        }
    }

    /// Loss and learning rate of a level's step `t` (counted from 0): [`Loss::Mse`] for the first
    /// `mse_steps`, then [`Loss::Epe`]; the rate ramps linearly over `warmup_steps`
    /// and, with `decay_steps`, follows a cosine from the peak to zero.
    fn schedule(&self, t: usize) -> (Loss, f64) {
        let kind = if t < self.cfg.mse_steps {
            Loss::Mse
        } else {
            Loss::Epe
        };
        let warm = if self.cfg.warmup_steps > 0 {
            ((t + 1) as f64 / self.cfg.warmup_steps as f64).min(1.0)
        } else {
            1.0
        };
        let decay = if self.cfg.decay_steps > 0 {
            let progress = (t as f64 / self.cfg.decay_steps as f64).min(1.0);
            0.5 * (1.0 + (std::f64::consts::PI * progress).cos())
        } else {
            1.0
        };
        (kind, self.cfg.lr * warm * decay)
    }

    /// Index in the data set of the run's `k`-th pair (cycling over `distinct_pairs` if set).
    fn pair_index(&self, k: u64) -> u64 {
        self.cfg.distinct_pairs.map_or(k, |d| k % d.max(1))
    }

    /// One optimiser update of level `level`'s parameters with the gradients in `grads`.
    fn apply(&mut self, level: usize, grads: &SpyNet<f32>, lr: f64) -> Result<(), FlowError> {
        for (i, conv) in self.net.levels[level].iter_mut().enumerate() {
            let g = &grads.levels[level][i];
            match self.cfg.optimizer {
                Optimizer::Adam => {
                    let (aw, ab) = &mut self.adams[level][i];
                    aw.config.lr = lr;
                    ab.config.lr = lr;
                    aw.step(&mut conv.weight, &g.weight)?;
                    ab.step(&mut conv.bias, &g.bias)?;
                }
                Optimizer::Sgd { momentum } => {
                    let v = &mut self.velocity.levels[level][i];
                    let (mu, lr) = (momentum as f32, lr as f32);
                    for (p, (vv, gg)) in conv.weight.iter_mut().chain(conv.bias.iter_mut()).zip(
                        v.weight
                            .iter_mut()
                            .chain(v.bias.iter_mut())
                            .zip(g.weight.iter().chain(&g.bias)),
                    ) {
                        *vv = mu * *vv + gg;
                        *p -= lr * *vv;
                    }
                }
            }
        }
        Ok(())
    }

    /// The run's settings.
    pub fn config(&self) -> &TrainConfig {
        &self.cfg
    }

    /// One optimiser step on level `level` over a batch of fresh pairs; returns the batch's mean EPE
    /// at that level's resolution (in that level's pixels).
    pub fn step(&mut self, level: usize) -> Result<f64, FlowError> {
        Ok(self.step_report(level)?.epe)
    }

    /// [`Trainer::step`] with the optimised loss and ReLU diagnostics.
    pub fn step_report(&mut self, level: usize) -> Result<StepReport, FlowError> {
        let mut grads = self.net.zeros_like();
        let (mut epe, mut loss) = (0.0, 0.0);
        let mut live_relu = Vec::new();
        let n = self.cfg.pairs.size;
        let scale = 1.0 / self.cfg.batch.max(1) as f64;
        let t = self.level_steps.get(level).copied().unwrap_or(0);
        let (kind, lr) = self.schedule(t);
        for b in 0..self.cfg.batch {
            let index = self.pair_index(self.next_pair);
            let pair = self.cfg.training_pair(index);
            self.next_pair += 1;
            let truth = flow_at_level(&pair.flow, n, n, self.cfg.levels, level);
            let tape = self
                .net
                .forward_to_level(&pair.img1, &pair.img2, n, n, level)?;
            if b == 0 {
                live_relu = tape.live_relu_fractions(level);
            }
            let weight = pair
                .weight
                .as_ref()
                .map(|w| weight_at_level(w, n, n, self.cfg.levels, level));
            let (l, e, g) = pixel_loss(&tape.flow, &truth, weight.as_deref(), kind, scale)?;
            self.net
                .backward_last_level_weights(&tape, &g, &mut grads)?;
            loss += l;
            epe += e;
        }
        if let Some(c) = self.level_steps.get_mut(level) {
            *c += 1;
        }
        self.apply(level, &grads, lr)?;
        Ok(StepReport {
            epe: epe * scale,
            loss: loss * scale,
            live_relu,
        })
    }
}

impl Trainer {
    /// One optimiser step on **all levels at once** over a batch of fresh pairs: the loss is the sum
    /// over levels of each level's mean per-pixel loss ([`Loss`], in that level's pixels, against the
    /// ground truth reduced by [`flow_at_level`]), and its gradient reaches every level through the
    /// pyramid's warps and upsampling ([`SpyNet::backward_multiscale_weights`]). Counting every level
    /// in its own pixels weights a coarser level's errors, relative to full-resolution pixels, ½ per
    /// level with [`Loss::Epe`] and ¼ per level with [`Loss::Mse`]. The pairs of a batch run in parallel; their gradients are summed in batch order, so
    /// the result does not depend on the number of threads. Returns the batch's mean EPE of the
    /// finest level (full-resolution pixels).
    pub fn step_joint(&mut self) -> Result<StepReport, FlowError> {
        use rayon::prelude::*;
        let n = self.cfg.pairs.size;
        let levels = self.net.levels_run(n, n);
        let batch = self.cfg.batch.max(1);
        let scale = 1.0 / batch as f64;
        let t = self.level_steps.first().copied().unwrap_or(0);
        let (kind, lr) = self.schedule(t);
        let indices: Vec<u64> = (0..batch as u64)
            .map(|b| self.pair_index(self.next_pair + b))
            .collect();
        self.next_pair += batch as u64;
        let net = &self.net;
        let cfg = &self.cfg;
        let per_pair: Vec<Result<PairGradient, FlowError>> = indices
            .par_iter()
            .map(|&index| {
                let pair = cfg.training_pair(index);
                let tape = net.forward_to_level(&pair.img1, &pair.img2, n, n, levels - 1)?;
                let mut level_grads = Vec::with_capacity(levels);
                let (mut loss, mut epe) = (0.0, 0.0);
                for l in 0..levels {
                    let truth = flow_at_level(&pair.flow, n, n, levels, l);
                    let out = tape.level_flow(l).unwrap_or(&[]);
                    let weight = pair
                        .weight
                        .as_ref()
                        .map(|w| weight_at_level(w, n, n, levels, l));
                    let (lo, e, g) = pixel_loss(out, &truth, weight.as_deref(), kind, scale)?;
                    loss += lo;
                    if l + 1 == levels {
                        epe = e;
                    }
                    level_grads.push(g);
                }
                let mut grads = net.zeros_like();
                net.backward_multiscale_weights(&tape, &level_grads, &mut grads)?;
                Ok(PairGradient {
                    grads,
                    loss,
                    epe,
                    live_relu: tape.live_relu_fractions(levels - 1),
                })
            })
            .collect();
        let mut grads = self.net.zeros_like();
        let (mut loss, mut epe) = (0.0, 0.0);
        let mut live_relu = Vec::new();
        for (b, r) in per_pair.into_iter().enumerate() {
            let PairGradient {
                grads: g,
                loss: l,
                epe: e,
                live_relu: live,
            } = r?;
            grads.accumulate(&g);
            loss += l;
            epe += e;
            if b == 0 {
                live_relu = live;
            }
        }
        for c in &mut self.level_steps {
            *c += 1;
        }
        for level in 0..levels {
            self.apply(level, &grads, lr)?;
        }
        Ok(StepReport {
            epe: epe * scale,
            loss: loss * scale,
            live_relu,
        })
    }
}

/// One pair's contribution to a [`Trainer::step_joint`] batch.
struct PairGradient {
    grads: SpyNet<f32>,
    loss: f64,
    epe: f64,
    live_relu: Vec<f64>,
}

/// Weighted mean per-pixel loss of a `(2, h, w)` flow against its truth, accumulated in f64:
/// `(loss, mean EPE, scale·∂loss/∂flow)`, in the flow's pixels. With `weight` (`(h, w)`, not all
/// zero) both means are `Σ wᵢ xᵢ / Σ wᵢ`; without, uniform. The training steps' per-level loss.
pub fn pixel_loss<T: Real>(
    flow: &[T],
    truth: &[T],
    weight: Option<&[f32]>,
    kind: Loss,
    scale: f64,
) -> Result<(f64, f64, Vec<T>), FlowError> {
    if truth.len() != flow.len() {
        return Err(FlowError::Size(format!(
            "level ground truth has {} values, expected {}",
            truth.len(),
            flow.len()
        )));
    }
    let hw = truth.len() / 2;
    if let Some(wt) = weight {
        if wt.len() != hw {
            return Err(FlowError::Size(format!(
                "loss weight has {} values, expected {hw}",
                wt.len()
            )));
        }
    }
    let weight_of = |i: usize| weight.map_or(1.0, |wt| f64::from(wt[i]));
    let total: f64 = (0..hw).map(weight_of).sum();
    if !(total > 0.0) {
        return Err(FlowError::Size("loss weights sum to zero".into()));
    }
    let inv = 1.0 / total;
    let (mut loss, mut epe) = (0.0f64, 0.0f64);
    let mut g = vec![T::zero(); 2 * hw];
    for i in 0..hw {
        let wi = weight_of(i);
        let du = (flow[i] - truth[i]).as_f64();
        let dv = (flow[hw + i] - truth[hw + i]).as_f64();
        let e = (du * du + dv * dv + EPE_EPS).sqrt();
        epe += wi * e;
        let (l, gu, gv) = match kind {
            Loss::Epe => (e, du / e, dv / e),
            Loss::Mse => (0.5 * (du * du + dv * dv), du, dv),
        };
        loss += wi * l;
        g[i] = T::of(wi * gu * inv * scale);
        g[hw + i] = T::of(wi * gv * inv * scale);
    }
    Ok((loss * inv, epe * inv, g))
}

/// Mean EPE (full resolution, pixels) of `net` and of the zero-flow baseline over `count` pairs of
/// the data set `seed`.
pub fn evaluate(
    net: &SpyNet<f32>,
    seed: u64,
    count: u64,
    pairs: &PairConfig,
) -> Result<(f64, f64), FlowError> {
    let (mut e_net, mut e_zero) = (0.0, 0.0);
    for k in 0..count {
        let p = generate_pair(seed, k, pairs);
        let tape = net.forward(&p.img1, &p.img2, p.height, p.width)?;
        e_net += average_epe(&tape.flow, &p.flow);
        e_zero += average_epe(&vec![0.0; p.flow.len()], &p.flow);
    }
    let c = count.max(1) as f64;
    Ok((e_net / c, e_zero / c))
}

/// Mean EPE (full resolution, pixels) of `net` and of the zero-flow baseline over fixed `pairs`
/// (e.g. held-out [`ExtraPairs`]), pooled over all their pixels, each pixel counted with its
/// [`Pair::weight`] (1 without); a weight of 0 or 1 makes it the EPE over a mask.
pub fn evaluate_pairs(net: &SpyNet<f32>, pairs: &[Pair]) -> Result<(f64, f64), FlowError> {
    let (mut e_net, mut e_zero, mut total) = (0.0, 0.0, 0.0);
    for p in pairs {
        let tape = net.forward(&p.img1, &p.img2, p.height, p.width)?;
        let hw = p.height * p.width;
        if p.weight.as_ref().is_some_and(|wt| wt.len() != hw) || p.flow.len() != 2 * hw {
            return Err(FlowError::Size(format!(
                "a {}x{} pair has {} flow values and a weight of the wrong size",
                p.width,
                p.height,
                p.flow.len()
            )));
        }
        for i in 0..hw {
            let wi = p.weight.as_ref().map_or(1.0, |wt| f64::from(wt[i]));
            let (gu, gv) = (f64::from(p.flow[i]), f64::from(p.flow[hw + i]));
            let (du, dv) = (
                f64::from(tape.flow[i]) - gu,
                f64::from(tape.flow[hw + i]) - gv,
            );
            e_net += wi * (du * du + dv * dv).sqrt();
            e_zero += wi * (gu * gu + gv * gv).sqrt();
            total += wi;
        }
    }
    let c = if total > 0.0 { total } else { 1.0 };
    Ok((e_net / c, e_zero / c))
}

/// An `levels`-level network whose every level is a copy of level `src_level` of `src`, with the
/// first convolution's weights on the upsampled-flow inputs (channels 6–7) set to zero: each level
/// then estimates the residual flow from `img1` and the warped `img2` alone, which is the task a
/// single level pre-trained at zero input flow has learned (its flow-input weights never received a
/// gradient there and are still random). The starting point of coarse-to-fine fine-tuning after
/// single-level pre-training.
pub fn replicate_level(src: &SpyNet<f32>, src_level: usize, levels: usize) -> SpyNet<f32> {
    let mut level = src.levels.get(src_level).cloned().unwrap_or_default();
    if let Some(conv0) = level.first_mut() {
        let (c_in, kk) = (crate::LAYER_CHANNELS[0].0, crate::KERNEL * crate::KERNEL);
        for w in conv0.weight.chunks_exact_mut(c_in * kk) {
            w[6 * kk..].iter_mut().for_each(|v| *v = 0.0);
        }
    }
    SpyNet {
        levels: vec![level; levels],
        depth: src.depth,
    }
}
