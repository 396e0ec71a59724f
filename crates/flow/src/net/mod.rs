//! The SPyNet pyramid: forward pass recording a [`Tape`], and the backward pass from `∂L/∂flow` to
//! `∂L/∂img1`, `∂L/∂img2` and (optionally) the weight gradients.
//!
//! The backward pass is the exact adjoint of the forward pass (including the warp's dependence on the
//! upsampled flow and the pyramid's pooling); it must never approximate or skip a term, because its
//! output is the gradient that reaches the Gaussians through the frozen network.

use crate::FlowError;
use nn::{
    avg_pool2x2_backward, avg_pool2x2_forward, conv2d_backward_input, conv2d_backward_weight,
    conv2d_forward, pooled_size, resize_bilinear_backward, resize_bilinear_forward, warp_backward,
    warp_forward, Conv2dShape, Real,
};

mod backward;

/// Convolution kernel side (pixels); padding is `KERNEL / 2`.
pub const KERNEL: usize = 7;
/// `(c_in, c_out)` of the five convolutions of every level.
pub const LAYER_CHANNELS: [(usize, usize); 5] = [(8, 32), (32, 64), (64, 32), (32, 16), (16, 2)];
/// Scale of the temporal-difference filters relative to the appearance filters in the first
/// convolution of [`SpyNet::random_init`] with `paired_input`.
pub const PAIRED_DIFF_GAIN: f64 = 3.0;
/// ImageNet channel means (RGB) subtracted from the `[0, 1]` input images.
pub const IMAGENET_MEAN: [f64; 3] = [0.485, 0.456, 0.406];
/// ImageNet channel standard deviations (RGB) dividing the centred input images.
pub const IMAGENET_STD: [f64; 3] = [0.229, 0.224, 0.225];

/// Weights and bias of one 7×7 convolution: `weight` `(c_out, c_in, 7, 7)`, `bias` `(c_out)`.
#[derive(Clone, Debug, PartialEq)]
pub struct Conv<T> {
    /// Kernel weights, PyTorch layout `(c_out, c_in, k, k)`.
    pub weight: Vec<T>,
    /// Bias per output channel.
    pub bias: Vec<T>,
}

/// How many pyramid levels a pass runs at a given (resized) image size.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum PyramidDepth {
    /// Every level the weights hold, whatever the image size. The project's own weights were
    /// trained this way (four levels at the flow loss's 64×64, coarsest 8×8).
    #[default]
    AllLevels,
    /// The reference SPyNet rule (the authors' code and the public PyTorch port): halve the image
    /// while a side exceeds `n` pixels (32 in the reference, [`PyramidDepth::REFERENCE`]), at most
    /// `L − 1` times. The coarsest weights run on the coarsest image built, so on a small image the
    /// finest weights go unused (e.g. 5 of 6 levels at 512×384).
    HalveWhileAbove(usize),
}

impl PyramidDepth {
    /// The rule of the original SPyNet weights: [`PyramidDepth::HalveWhileAbove`]`(32)`.
    pub const REFERENCE: Self = Self::HalveWhileAbove(32);

    /// Levels run on a `h × w` image (already resized to a multiple of `2^(levels−1)`) by a network
    /// of `levels` levels: between 1 and `levels`.
    pub fn levels_run(self, levels: usize, h: usize, w: usize) -> usize {
        match self {
            Self::AllLevels => levels,
            Self::HalveWhileAbove(side) => {
                let (mut h, mut w, mut run) = (h, w, 1);
                while run < levels && (h > side || w > side) {
                    (h, w) = (pooled_size(h), pooled_size(w));
                    run += 1;
                }
                run
            }
        }
    }
}

/// A SPyNet-style network: `levels[l][i]` is convolution `i` (0..5) of level `l` (0 = coarsest).
/// Also used, zero-initialised, as the container for weight gradients.
#[derive(Clone, Debug, PartialEq)]
pub struct SpyNet<T> {
    /// Per level, the five convolutions (shapes from [`LAYER_CHANNELS`]).
    pub levels: Vec<Vec<Conv<T>>>,
    /// Which levels a pass runs ([`PyramidDepth::AllLevels`] unless the weights say otherwise).
    pub depth: PyramidDepth,
}

/// Everything the backward pass needs from one forward pass, plus its result.
#[derive(Clone, Debug)]
pub struct Tape<T> {
    /// Size of the input images (H, W).
    pub size: (usize, usize),
    /// Size the network ran at (multiples of `2^(L−1)`).
    pub work_size: (usize, usize),
    /// Pyramid level sizes, index 0 = coarsest; as many as the pass's [`PyramidDepth`] runs
    /// (weights level `l` ran on `level_sizes[l]`).
    pub level_sizes: Vec<(usize, usize)>,
    /// Normalised image-2 pyramid (for the warp's backward pass), per level `(3, h, w)`.
    pyr2: Vec<Vec<T>>,
    /// Per level run: the upsampled flow `U_l` `(2, h, w)` and the inputs of the five convolutions.
    levels: Vec<LevelTape<T>>,
    /// The output flow: `(2, H, W)` for a full pass, `(2, h_l, w_l)` for a partial one.
    pub flow: Vec<T>,
}

impl<T: Real> Tape<T> {
    /// Fraction of positive outputs of each of the four ReLU layers of level `level` (training
    /// diagnostics: a layer whose fraction falls to ~0 is dead). Empty if the level was not run.
    pub fn live_relu_fractions(&self, level: usize) -> Vec<f64> {
        self.levels.get(level).map_or_else(Vec::new, |lt| {
            lt.acts[1..]
                .iter()
                .map(|a| {
                    a.iter().filter(|&&v| v > T::zero()).count() as f64 / a.len().max(1) as f64
                })
                .collect()
        })
    }

    /// Output flow `(2, h_l, w_l)` of pyramid level `level` (0 = coarsest), in that level's pixels,
    /// before any resize back to the input size; `None` if the level was not run.
    pub fn level_flow(&self, level: usize) -> Option<&[T]> {
        self.levels.get(level).map(|lt| lt.out.as_slice())
    }

    /// Fingerprint of the piecewise-smooth region the forward pass ran in: the sign pattern of every
    /// ReLU, and for every warp sample its bilinear cell and whether it was clamped at the border.
    /// Two passes with equal signatures are evaluations of the same smooth branch of the network;
    /// finite-difference checks use this to discard probes that straddle a kink.
    pub fn region_signature(&self) -> u64 {
        let mut hsh = 0xcbf2_9ce4_8422_2325u64;
        let mut mix = |v: u64| {
            hsh ^= v;
            hsh = hsh.wrapping_mul(0x0000_0100_0000_01B3);
        };
        for (l, lt) in self.levels.iter().enumerate() {
            for a in &lt.acts[1..] {
                for chunk in a.chunks(64) {
                    let mut bits = 0u64;
                    for (i, &v) in chunk.iter().enumerate() {
                        if v > T::zero() {
                            bits |= 1 << i;
                        }
                    }
                    mix(bits);
                }
            }
            let (h, w) = self.level_sizes[l];
            let hw = h * w;
            for y in 0..h {
                for x in 0..w {
                    let p = y * w + x;
                    for (pos, n) in [
                        (T::of(x as f64) + lt.up[p], w),
                        (T::of(y as f64) + lt.up[hw + p], h),
                    ] {
                        let max = T::of((n - 1) as f64);
                        let code = if pos <= T::zero() {
                            u64::MAX
                        } else if pos >= max {
                            u64::MAX - 1
                        } else {
                            pos.floor().to_u64().unwrap_or(0)
                        };
                        mix(code);
                    }
                }
            }
        }
        hsh
    }
}

#[derive(Clone, Debug)]
struct LevelTape<T> {
    up: Vec<T>,
    acts: Vec<Vec<T>>,
    /// The level's output flow `(2, h_l, w_l)` (level pixels).
    out: Vec<T>,
}

fn conv_shape(i: usize, h: usize, w: usize) -> Conv2dShape {
    Conv2dShape {
        batch: 1,
        c_in: LAYER_CHANNELS[i].0,
        c_out: LAYER_CHANNELS[i].1,
        height: h,
        width: w,
        kernel: KERNEL,
        stride: 1,
        pad: KERNEL / 2,
    }
}

/// `(2, h, w)` flow → `(2, ht, wt)`: bilinear ×2 (`align_corners = true`), values ×2, then replicate
/// (or crop) to the target size.
fn upsample_flow<T: Real>(
    flow: &[T],
    (h, w): (usize, usize),
    (ht, wt): (usize, usize),
) -> Result<Vec<T>, FlowError> {
    let (h2, w2) = (2 * h, 2 * w);
    let mut up = vec![T::zero(); 2 * h2 * w2];
    resize_bilinear_forward(2, h, w, flow, h2, w2, true, &mut up)?;
    let two = T::of(2.0);
    let mut out = vec![T::zero(); 2 * ht * wt];
    for c in 0..2 {
        for y in 0..ht {
            let sy = y.min(h2 - 1);
            for x in 0..wt {
                out[(c * ht + y) * wt + x] = two * up[(c * h2 + sy) * w2 + x.min(w2 - 1)];
            }
        }
    }
    Ok(out)
}

/// `acc += v`, element by element.
fn add_into<T: Real>(acc: &mut [T], v: &[T]) {
    for (a, &b) in acc.iter_mut().zip(v) {
        *a = *a + b;
    }
}

impl<T: Real> SpyNet<T> {
    /// A network of `levels` levels with all weights and biases zero.
    pub fn zeros(levels: usize) -> Self {
        let level = || {
            LAYER_CHANNELS
                .iter()
                .map(|&(ci, co)| Conv {
                    weight: vec![T::zero(); co * ci * KERNEL * KERNEL],
                    bias: vec![T::zero(); co],
                })
                .collect()
        };
        Self {
            levels: (0..levels).map(|_| level()).collect(),
            depth: PyramidDepth::AllLevels,
        }
    }

    /// A freshly initialised network (He-uniform weights `U(±√(6/fan_in))`, zero biases; the last
    /// convolution of each level scaled by 0.1 so that the initial residual flow is small),
    /// deterministic from `seed`.
    pub fn random(levels: usize, seed: u64) -> Self {
        Self::random_with_output_gain(levels, seed, 0.1)
    }

    /// [`SpyNet::random`] with the output convolution's He bound scaled by `output_gain` instead of
    /// 0.1 (`0` = a zero output convolution: the untrained network predicts exactly the upsampled
    /// coarser flow, and the first gradient steps fit the read-out instead of suppressing random
    /// output noise by silencing the hidden ReLUs). Draws the same random numbers for any gain.
    pub fn random_with_output_gain(levels: usize, seed: u64, output_gain: f64) -> Self {
        Self::random_init(levels, seed, output_gain, false)
    }

    /// [`SpyNet::random_with_output_gain`], and with `paired_input` the first convolution's image
    /// weights rewritten as `w₁ = a − d`, `w₂ = a + d` (so each filter responds to `a ∗ (I₁ + I₂) +
    /// d ∗ (I₂ − I₁)`), with `a` the drawn image-1 weights minus their mean (no response to the
    /// image's DC level) and `d` the drawn image-2 weights × [`PAIRED_DIFF_GAIN`]. With independent
    /// random weights the temporal difference `I₂ − I₁` (the only part of the input that carries
    /// motion) is a small component of every feature, swamped by appearance, and the network has to
    /// discover it from a weak correlation; here every first-layer feature mixes a spatial-derivative
    /// like response and the temporal difference at comparable scales, so that the ReLUs form the
    /// `|∂I + ∂ₜI|`-type terms a motion estimate is built from.
    pub fn random_init(levels: usize, seed: u64, output_gain: f64, paired_input: bool) -> Self {
        let mut net = Self::zeros(levels);
        let mut rng = crate::synthetic::Rng(seed ^ 0x5EED_F10F);
        for level in &mut net.levels {
            for (i, conv) in level.iter_mut().enumerate() {
                let fan_in = (LAYER_CHANNELS[i].0 * KERNEL * KERNEL) as f64;
                let gain = if i == 4 { output_gain } else { 1.0 };
                let bound = gain * (6.0 / fan_in).sqrt();
                for v in &mut conv.weight {
                    *v = T::of(bound * rng.symmetric_f64());
                }
                if i == 0 && paired_input {
                    // Per output channel: the image-1 weights become a zero-mean (no DC) filter
                    // `a` of the frames' sum, the image-2 weights a filter `d` of the temporal
                    // difference with PAIRED_DIFF_GAIN× the scale; w1 = a − d, w2 = a + d.
                    let (c_in, kk) = (LAYER_CHANNELS[0].0, KERNEL * KERNEL);
                    let gain = T::of(PAIRED_DIFF_GAIN);
                    for w in conv.weight.chunks_exact_mut(c_in * kk) {
                        let (img1, rest) = w.split_at_mut(3 * kk);
                        let img2 = &mut rest[..3 * kk];
                        for (a, d) in img1.chunks_exact_mut(kk).zip(img2.chunks_exact_mut(kk)) {
                            let mean = a.iter().fold(T::zero(), |m, &v| m + v) / T::of(kk as f64);
                            for (av, dv) in a.iter_mut().zip(d.iter_mut()) {
                                let (s, t) = (*av - mean, gain * *dv);
                                *av = s - t;
                                *dv = s + t;
                            }
                        }
                    }
                }
            }
        }
        net
    }

    /// Number of pyramid levels `L`.
    pub fn num_levels(&self) -> usize {
        self.levels.len()
    }

    /// Adds `other`'s parameters to these, element by element (summing gradient containers).
    /// Both must have the same structure (extra levels or convolutions of either are ignored).
    pub fn accumulate(&mut self, other: &SpyNet<T>) {
        for (acc, add) in self.levels.iter_mut().zip(&other.levels) {
            for (ca, cb) in acc.iter_mut().zip(add) {
                add_into(&mut ca.weight, &cb.weight);
                add_into(&mut ca.bias, &cb.bias);
            }
        }
    }

    /// The same network with all parameters zero (a gradient accumulator).
    pub fn zeros_like(&self) -> Self {
        Self {
            depth: self.depth,
            ..Self::zeros(self.num_levels())
        }
    }

    /// This network with another pyramid rule.
    pub fn with_depth(self, depth: PyramidDepth) -> Self {
        Self { depth, ..self }
    }

    /// Levels a pass on an `h × w` input runs (after the resize to [`SpyNet::size_multiple`]).
    pub fn levels_run(&self, h: usize, w: usize) -> usize {
        let m = self.size_multiple();
        self.depth
            .levels_run(self.num_levels(), h.div_ceil(m) * m, w.div_ceil(m) * m)
    }

    /// Converts the parameters to another scalar type (e.g. `f32` → `f64` for gradient checks).
    pub fn cast<U: Real>(&self) -> SpyNet<U> {
        let cv = |v: &[T]| v.iter().map(|&x| U::of(x.as_f64())).collect::<Vec<U>>();
        SpyNet {
            levels: self
                .levels
                .iter()
                .map(|l| {
                    l.iter()
                        .map(|c| Conv {
                            weight: cv(&c.weight),
                            bias: cv(&c.bias),
                        })
                        .collect()
                })
                .collect(),
            depth: self.depth,
        }
    }

    /// Total number of scalar parameters.
    pub fn num_parameters(&self) -> usize {
        self.levels
            .iter()
            .flatten()
            .map(|c| c.weight.len() + c.bias.len())
            .sum()
    }

    /// Side-length multiple the network runs at: `2^(L−1)`.
    pub fn size_multiple(&self) -> usize {
        1 << self.num_levels().saturating_sub(1)
    }

    fn check_structure(&self) -> Result<(), FlowError> {
        if self.levels.is_empty() {
            return Err(FlowError::NoLevels);
        }
        for (l, level) in self.levels.iter().enumerate() {
            if level.len() != 5 {
                return Err(FlowError::MissingTensor {
                    name: format!("level{l}.conv{}", level.len().min(4)),
                });
            }
            for (i, c) in level.iter().enumerate() {
                let (ci, co) = LAYER_CHANNELS[i];
                if c.weight.len() != co * ci * KERNEL * KERNEL {
                    return Err(FlowError::WrongShape {
                        name: format!("level{l}.conv{i}.weight"),
                        expected: vec![co, ci, KERNEL, KERNEL],
                        actual: vec![c.weight.len()],
                    });
                }
                if c.bias.len() != co {
                    return Err(FlowError::WrongShape {
                        name: format!("level{l}.conv{i}.bias"),
                        expected: vec![co],
                        actual: vec![c.bias.len()],
                    });
                }
            }
        }
        Ok(())
    }

    /// Flow from `img1` to `img2`, both planar RGB `(3, h, w)` in `[0, 1]`. The result is in
    /// [`Tape::flow`] as `(2, h, w)` pixels; keep the tape for [`SpyNet::backward`].
    pub fn forward(
        &self,
        img1: &[T],
        img2: &[T],
        h: usize,
        w: usize,
    ) -> Result<Tape<T>, FlowError> {
        self.forward_impl(img1, img2, h, w, None, None)
    }

    /// Runs only levels `0..=last_level` (coarse-to-fine training): [`Tape::flow`] is that level's
    /// output `(2, h_l, w_l)` at the level's own resolution. `h` and `w` must be multiples of
    /// [`SpyNet::size_multiple`], and `last_level` below [`SpyNet::levels_run`].
    pub fn forward_to_level(
        &self,
        img1: &[T],
        img2: &[T],
        h: usize,
        w: usize,
        last_level: usize,
    ) -> Result<Tape<T>, FlowError> {
        let m = self.size_multiple();
        let run = self.levels_run(h, w);
        if !h.is_multiple_of(m) || !w.is_multiple_of(m) || last_level >= run {
            return Err(FlowError::Size(format!(
                "forward_to_level needs sides that are multiples of {m} and a level < {run} (got {h}x{w}, level {last_level})"
            )));
        }
        self.forward_impl(img1, img2, h, w, Some(last_level), None)
    }

    /// Diagnostic: a full forward pass in which the output of pyramid level `level` (0 = coarsest) is
    /// replaced by `level_flow` `(2, h_l, w_l)`, in that level's pixels — e.g. the ground truth
    /// pooled to the level ([`crate::train::flow_at_level`]) — and the finer levels refine it as
    /// usual. It measures how much the finer levels' accuracy depends on the coarse estimate.
    /// Returns every level's output (empty for levels up to `level`; index 0 = coarsest) and the
    /// final flow `(2, h, w)`. There is no tape: the result is not meant to be differentiated.
    /// `h` and `w` must be multiples of [`SpyNet::size_multiple`].
    pub fn forward_with_level_flow(
        &self,
        img1: &[T],
        img2: &[T],
        h: usize,
        w: usize,
        level: usize,
        level_flow: &[T],
    ) -> Result<(Vec<Vec<T>>, Vec<T>), FlowError> {
        let m = self.size_multiple();
        let run = self.levels_run(h, w);
        let shift = run.saturating_sub(1).saturating_sub(level);
        let expected = 2 * (h >> shift) * (w >> shift);
        if !h.is_multiple_of(m)
            || !w.is_multiple_of(m)
            || level >= run
            || level_flow.len() != expected
        {
            return Err(FlowError::Size(format!(
                "forward_with_level_flow needs sides that are multiples of {m}, a level < {run} and a (2, h_l, w_l) flow of that level (got {h}x{w}, level {level}, {} values)",
                level_flow.len()
            )));
        }
        let tape = self.forward_impl(img1, img2, h, w, None, Some((level, level_flow)))?;
        let outputs = tape
            .levels
            .into_iter()
            .enumerate()
            .map(|(l, lt)| if l <= level { Vec::new() } else { lt.out })
            .collect();
        Ok((outputs, tape.flow))
    }

    /// The forward pass up to `last_level` (`None`: every level the [`PyramidDepth`] runs); with
    /// `given = Some((k, flow))`, levels `0..=k` are not run and level `k`'s output is `flow` (the
    /// tape of those levels is then empty, so such a tape must not reach [`SpyNet::backward`]).
    fn forward_impl(
        &self,
        img1: &[T],
        img2: &[T],
        h: usize,
        w: usize,
        last_level: Option<usize>,
        given: Option<(usize, &[T])>,
    ) -> Result<Tape<T>, FlowError> {
        self.check_structure()?;
        let n = 3 * h * w;
        if h == 0 || w == 0 || img1.len() != n || img2.len() != n {
            return Err(FlowError::Size(format!(
                "expected two RGB images of {h}x{w} ({n} values), got {} and {}",
                img1.len(),
                img2.len()
            )));
        }
        let m = self.size_multiple();
        let (hp, wp) = (h.div_ceil(m) * m, w.div_ceil(m) * m);
        let levels = self.depth.levels_run(self.num_levels(), hp, wp);
        let last_level = last_level.unwrap_or(levels - 1).min(levels - 1);
        let resized = (hp, wp) != (h, w);
        let prep = |img: &[T]| -> Result<Vec<T>, FlowError> {
            let mut v = if resized {
                let mut r = vec![T::zero(); 3 * hp * wp];
                resize_bilinear_forward(3, h, w, img, hp, wp, false, &mut r)?;
                r
            } else {
                img.to_vec()
            };
            for (c, plane) in v.chunks_exact_mut(hp * wp).enumerate() {
                let (mean, inv_std) = (T::of(IMAGENET_MEAN[c]), T::of(1.0 / IMAGENET_STD[c]));
                for p in plane {
                    *p = (*p - mean) * inv_std;
                }
            }
            Ok(v)
        };
        // Pyramids, finest last.
        let mut sizes = vec![(hp, wp)];
        let mut pyr1 = vec![prep(img1)?];
        let mut pyr2 = vec![prep(img2)?];
        for _ in 1..levels {
            let (lh, lw) = sizes[0];
            let (ph, pw) = (pooled_size(lh), pooled_size(lw));
            let mut p1 = vec![T::zero(); 3 * ph * pw];
            let mut p2 = vec![T::zero(); 3 * ph * pw];
            avg_pool2x2_forward(3, lh, lw, &pyr1[0], &mut p1)?;
            avg_pool2x2_forward(3, lh, lw, &pyr2[0], &mut p2)?;
            sizes.insert(0, (ph, pw));
            pyr1.insert(0, p1);
            pyr2.insert(0, p2);
        }
        let mut tapes = Vec::with_capacity(last_level + 1);
        let mut flow: Vec<T> = Vec::new();
        for l in 0..=last_level {
            if let Some((k, given_flow)) = given.filter(|&(k, _)| l <= k) {
                if l == k {
                    flow = given_flow.to_vec();
                }
                tapes.push(LevelTape {
                    up: Vec::new(),
                    acts: Vec::new(),
                    out: if l == k { flow.clone() } else { Vec::new() },
                });
                continue;
            }
            let (lh, lw) = sizes[l];
            let hw = lh * lw;
            let up = if l == 0 {
                vec![T::zero(); 2 * hw]
            } else {
                upsample_flow(&flow, sizes[l - 1], sizes[l])?
            };
            let mut x = vec![T::zero(); 8 * hw];
            x[..3 * hw].copy_from_slice(&pyr1[l]);
            warp_forward(1, 3, lh, lw, &pyr2[l], &up, &mut x[3 * hw..6 * hw])?;
            x[6 * hw..].copy_from_slice(&up);
            let mut acts = vec![x];
            for (i, conv) in self.levels[l].iter().enumerate() {
                let s = conv_shape(i, lh, lw);
                let mut out = vec![T::zero(); s.output_len()];
                conv2d_forward(s, &acts[i], &conv.weight, Some(&conv.bias), &mut out)?;
                if i < 4 {
                    for v in &mut out {
                        *v = v.max(T::zero());
                    }
                    acts.push(out);
                } else {
                    add_into(&mut out, &up);
                    flow = out;
                }
            }
            tapes.push(LevelTape {
                up,
                acts,
                out: flow.clone(),
            });
        }
        let full = last_level + 1 == levels;
        if full && resized {
            let mut back = vec![T::zero(); 2 * h * w];
            resize_bilinear_forward(2, hp, wp, &flow, h, w, false, &mut back)?;
            let (su, sv) = (T::of(w as f64 / wp as f64), T::of(h as f64 / hp as f64));
            let (u, v) = back.split_at_mut(h * w);
            u.iter_mut().for_each(|x| *x = *x * su);
            v.iter_mut().for_each(|x| *x = *x * sv);
            flow = back;
        }
        Ok(Tape {
            size: (h, w),
            work_size: (hp, wp),
            level_sizes: sizes,
            pyr2,
            levels: tapes,
            flow,
        })
    }
}
