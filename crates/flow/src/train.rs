//! Training the project's own SPyNet weights on [`crate::synthetic`] pairs, coarse to fine as SPyNet
//! was trained: level `l` is trained with levels `< l` frozen, on the end-point error between its
//! output and the ground-truth flow reduced to its resolution (2×2 average pooling, vectors ×½ per
//! level). Deterministic from the seed: pair `k` of a run is `generate_pair(seed, k)`.

use crate::synthetic::{average_epe, generate_pair, PairConfig};
use crate::{FlowError, SpyNet};
use nn::{avg_pool2x2_forward, pooled_size, Adam, AdamConfig};

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
        for _ in 0..self.cfg.batch {
            let pair = generate_pair(self.cfg.seed, self.next_pair, &self.cfg.pairs);
            self.next_pair += 1;
            let tape = self
                .net
                .forward_to_level(&pair.img1, &pair.img2, n, n, level)?;
            let truth = flow_at_level(&pair.flow, n, n, self.cfg.levels, level);
            let hw = truth.len() / 2;
            let scale = 1.0 / (hw as f32 * self.cfg.batch as f32);
            let mut g = vec![0.0f32; 2 * hw];
            for i in 0..hw {
                let du = tape.flow[i] - truth[i];
                let dv = tape.flow[hw + i] - truth[hw + i];
                let e = (du * du + dv * dv + 1e-6).sqrt();
                epe += e as f64 / hw as f64;
                g[i] = du / e * scale;
                g[hw + i] = dv / e * scale;
            }
            self.net
                .backward_last_level_weights(&tape, &g, &mut grads)?;
        }
        for (i, conv) in self.net.levels[level].iter_mut().enumerate() {
            let (aw, ab) = &mut self.adams[level][i];
            aw.step(&mut conv.weight, &grads.levels[level][i].weight)?;
            ab.step(&mut conv.bias, &grads.levels[level][i].bias)?;
        }
        Ok(epe / self.cfg.batch as f64)
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
