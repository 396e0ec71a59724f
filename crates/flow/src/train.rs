//! Training the project's own SPyNet weights on [`crate::synthetic`] pairs, coarse to fine as SPyNet
//! was trained: level `l` is trained with levels `< l` frozen, on the end-point error between its
//! output and the ground-truth flow reduced to its resolution (2×2 average pooling, vectors ×½ per
//! level). Deterministic from the seed: pair `k` of a run is `generate_pair(seed, k)`.
//!
//! The loss of one pair at level `l` is [`level_epe_loss`]: the mean over the level's pixels of the
//! smoothed end-point error `√(Δu² + Δv² + ε)` with `ε = 1e-6` px². Its weight gradient is checked
//! against finite differences of the same function in `tests/gradient-checks` (test `flow`), so the
//! composition the optimiser sees (partial forward, loss, last-level backward) is covered, not only
//! the individual ops.

use crate::synthetic::{average_epe, generate_pair, PairConfig};
use crate::{FlowError, SpyNet};
use nn::{avg_pool2x2_forward, pooled_size, Adam, AdamConfig, Real};

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
    /// Adam learning rate.
    pub lr: f64,
    /// Seed of the initial weights and of the training pairs.
    pub seed: u64,
    /// `Some(n)`: cycle over the fixed set of pairs `0..n` of the seed (a small data set, e.g. for
    /// tests that must see the loss go down); `None`: every step draws fresh pairs.
    pub distinct_pairs: Option<u64>,
}

/// Network plus optimiser state of a coarse-to-fine training run.
pub struct Trainer {
    /// The network being trained.
    pub net: SpyNet<f32>,
    cfg: TrainConfig,
    adams: Vec<Vec<(Adam<f32>, Adam<f32>)>>,
    next_pair: u64,
}

/// Ground-truth flow `(2, H, W)` reduced to level `level` of an `levels`-level pyramid.
pub fn flow_at_level(flow: &[f32], h: usize, w: usize, levels: usize, level: usize) -> Vec<f32> {
    let (mut f, mut h, mut w) = (flow.to_vec(), h, w);
    for _ in level + 1..levels {
        let (ph, pw) = (pooled_size(h), pooled_size(w));
        let mut p = vec![0.0f32; 2 * ph * pw];
        // Shapes are consistent by construction; an error here would be a programming error.
        if avg_pool2x2_forward(2, h, w, &f, &mut p).is_err() {
            return p;
        }
        p.iter_mut().for_each(|v| *v *= 0.5);
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
    if truth.len() != tape.flow.len() {
        return Err(FlowError::Size(format!(
            "level {level} ground truth has {} values, expected {}",
            truth.len(),
            tape.flow.len()
        )));
    }
    let hw = truth.len() / 2;
    let inv = T::of(1.0 / hw.max(1) as f64);
    let (eps, scale) = (T::of(EPE_EPS), T::of(scale));
    let mut loss = T::zero();
    let mut g = vec![T::zero(); 2 * hw];
    for i in 0..hw {
        let du = tape.flow[i] - truth[i];
        let dv = tape.flow[hw + i] - truth[hw + i];
        let e = (du * du + dv * dv + eps).sqrt();
        loss = loss + e;
        g[i] = du / e * inv * scale;
        g[hw + i] = dv / e * inv * scale;
    }
    if let Some(grads) = weight_grads {
        net.backward_last_level_weights(&tape, &g, grads)?;
    }
    Ok((loss * inv).as_f64())
}

impl Trainer {
    /// A fresh network (`SpyNet::random(levels, seed)`) and zeroed Adam moments.
    pub fn new(cfg: TrainConfig) -> Self {
        let net = SpyNet::random(cfg.levels, cfg.seed);
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
        Self {
            net,
            cfg,
            adams,
            next_pair: 0,
        }
    }

    /// One Adam step on level `level` over a batch of fresh pairs; returns the batch's mean EPE at
    /// that level's resolution (in that level's pixels).
    pub fn step(&mut self, level: usize) -> Result<f64, FlowError> {
        let mut grads = self.net.zeros_like();
        let mut epe = 0.0;
        let n = self.cfg.pairs.size;
        let scale = 1.0 / self.cfg.batch.max(1) as f64;
        for _ in 0..self.cfg.batch {
            let index = match self.cfg.distinct_pairs {
                Some(d) => self.next_pair % d.max(1),
                None => self.next_pair,
            };
            let pair = generate_pair(self.cfg.seed, index, &self.cfg.pairs);
            self.next_pair += 1;
            let truth = flow_at_level(&pair.flow, n, n, self.cfg.levels, level);
            epe += level_epe_loss(
                &self.net,
                &pair.img1,
                &pair.img2,
                n,
                n,
                level,
                &truth,
                Some(&mut grads),
                scale,
            )?;
        }
        for (i, conv) in self.net.levels[level].iter_mut().enumerate() {
            let (aw, ab) = &mut self.adams[level][i];
            aw.step(&mut conv.weight, &grads.levels[level][i].weight)?;
            ab.step(&mut conv.bias, &grads.levels[level][i].bias)?;
        }
        Ok(epe * scale)
    }
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
