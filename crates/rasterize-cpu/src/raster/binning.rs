//! Tile binning: every visible Gaussian is listed once per 16×16 tile of its screen rectangle, and
//! each tile's list is sorted by (view depth, input index), the order of INRIA's stable radix sort.
//! Parallel and deterministic: the lists are the same for any chunking and thread count.

use rayon::prelude::*;

use super::kernels::pixel_span;
use crate::project::Projected;
use crate::{lit, Real, TILE_SIZE};

/// Visible Gaussians per binning job of [`bin_and_sort`]: at least this many.
const BIN_CHUNK: usize = 4096;
/// Upper bound on the number of binning jobs.
const MAX_BIN_JOBS: usize = 32;
/// Upper bound on the per-tile counters of all binning jobs together (each job holds one per
/// tile), so that huge images get fewer jobs rather than large count arrays.
const BIN_COUNTER_BUDGET: usize = 1 << 20;

/// One binning job's entries (depth keys, see [`Real::depth_key`]) grouped by tile, and where each
/// tile's group starts (n_tiles + 1 offsets).
type BinJob<K> = (Vec<usize>, Vec<K>);

/// Shrinks `p.rect` (INRIA's 3σ rectangle) to the tiles where the tile kernels can blend some pixel
/// of `p`: those whose pixel span within `p.extent` (the opacity-aware box where alpha can reach
/// 1/255) is non-empty in x and in y, by the kernels' own rule. A tile dropped here is one the
/// kernels would skip for this Gaussian, so images and gradients keep their bits; it only saves
/// listing, sorting, gathering and replaying the pair. `width` × `height` is the image size.
pub(super) fn trim_rect<T: Real>(p: &mut Projected<T>, width: usize, height: usize) {
    let axis = |mean: T, half: T, lo: u32, hi: u32, len: usize| -> (u32, u32) {
        let live = |tile: u32| {
            let origin = tile as usize * TILE_SIZE;
            let size = TILE_SIZE.min(len.saturating_sub(origin));
            let (a, b) = pixel_span(mean, half, lit(origin as f64), size);
            a < b
        };
        let (mut lo, mut hi) = (lo, hi);
        while lo < hi && !live(lo) {
            lo += 1;
        }
        while hi > lo && !live(hi - 1) {
            hi -= 1;
        }
        (lo, hi)
    };
    let (x0, x1) = axis(p.mean2d[0], p.extent[0], p.rect[0], p.rect[2], width);
    let (y0, y1) = axis(p.mean2d[1], p.extent[1], p.rect[1], p.rect[3], height);
    p.rect = [x0, y0, x1, y1];
}

/// Tile lists: for every tile, the indices of the visible Gaussians overlapping it sorted by
/// (view depth, index), as offsets into one list. Equals INRIA's stable radix sort on
/// (tile, depth).
///
/// Parallel: jobs over contiguous chunks of `visible` bin their Gaussians by tile (a local counting
/// sort); every tile then gathers its entries from the jobs and sorts them. The key (depth, index)
/// is a total order, so the lists are the same for any chunking and thread count. The tiles flagged
/// in `skip` get empty lists, and with `cut` a tile lists only the Gaussians at view depth
/// ≤ `cut[tile]` (the others' lists are unchanged).
pub(super) fn bin_and_sort<T: Real>(
    visible: &[Projected<T>],
    gx: usize,
    n_tiles: usize,
    skip: Option<&[bool]>,
    cut: Option<&[T]>,
) -> (Vec<usize>, Vec<u32>) {
    let listed =
        |t: usize, depth: T| skip.is_none_or(|s| !s[t]) && cut.is_none_or(|c| depth <= c[t]);
    let max_jobs = (BIN_COUNTER_BUDGET / (n_tiles + 1)).clamp(1, MAX_BIN_JOBS);
    let chunk = BIN_CHUNK.max(visible.len().div_ceil(max_jobs));
    // 1. Per job: its entries grouped by tile, and where each tile's group starts.
    let jobs: Vec<BinJob<T::DepthKey>> = visible
        .par_chunks(chunk)
        .enumerate()
        .map(|(job, part)| {
            let mut starts = vec![0usize; n_tiles + 1];
            for p in part {
                for ty in p.rect[1]..p.rect[3] {
                    let row = ty as usize * gx;
                    for tx in p.rect[0]..p.rect[2] {
                        let t = row + tx as usize;
                        if listed(t, p.depth) {
                            starts[t + 1] += 1;
                        }
                    }
                }
            }
            for t in 0..n_tiles {
                starts[t + 1] += starts[t];
            }
            let mut cursor = starts.clone();
            let mut entries = vec![T::DepthKey::default(); starts[n_tiles]];
            for (j, p) in part.iter().enumerate() {
                // View depth is > near > 0, so its bit pattern orders like the value.
                let key = T::depth_key(p.depth, (job * chunk + j) as u32);
                for ty in p.rect[1]..p.rect[3] {
                    let row = ty as usize * gx;
                    for tx in p.rect[0]..p.rect[2] {
                        let t = row + tx as usize;
                        if listed(t, p.depth) {
                            entries[cursor[t]] = key;
                            cursor[t] += 1;
                        }
                    }
                }
            }
            (starts, entries)
        })
        .collect();
    // 2. Tile offsets in the global list.
    let mut offsets = vec![0usize; n_tiles + 1];
    for t in 0..n_tiles {
        let count: usize = jobs
            .iter()
            .map(|(starts, _)| starts[t + 1] - starts[t])
            .sum();
        offsets[t + 1] = offsets[t] + count;
    }
    // 3. Every tile gathers its entries from the jobs and sorts them.
    let mut entries = vec![T::DepthKey::default(); offsets[n_tiles]];
    let mut slices = Vec::with_capacity(n_tiles);
    let mut rest: &mut [T::DepthKey] = &mut entries;
    for t in 0..n_tiles {
        let (head, tail) = rest.split_at_mut(offsets[t + 1] - offsets[t]);
        slices.push(head);
        rest = tail;
    }
    slices.into_par_iter().enumerate().for_each(|(t, dst)| {
        let mut at = 0;
        for (starts, part) in &jobs {
            let group = &part[starts[t]..starts[t + 1]];
            dst[at..at + group.len()].copy_from_slice(group);
            at += group.len();
        }
        dst.sort_unstable();
    });
    let list = entries.par_iter().map(|&key| T::key_index(key)).collect();
    (offsets, list)
}

#[cfg(test)]
mod tests {
    /// INRIA's order by its definition: every (tile, Gaussian) pair in input order, stably sorted
    /// by (tile, depth).
    fn bin_by_definition(
        visible: &[super::Projected<f32>],
        gx: usize,
        n_tiles: usize,
    ) -> (Vec<usize>, Vec<u32>) {
        let mut pairs = Vec::new();
        for (ci, p) in visible.iter().enumerate() {
            for ty in p.rect[1]..p.rect[3] {
                for tx in p.rect[0]..p.rect[2] {
                    pairs.push((ty as usize * gx + tx as usize, p.depth, ci as u32));
                }
            }
        }
        pairs.sort_by(|a, b| a.0.cmp(&b.0).then(a.1.total_cmp(&b.1)));
        let mut offsets = vec![0usize; n_tiles + 1];
        for &(t, _, _) in &pairs {
            offsets[t + 1] += 1;
        }
        for t in 0..n_tiles {
            offsets[t + 1] += offsets[t];
        }
        (offsets, pairs.iter().map(|p| p.2).collect())
    }

    #[test]
    fn parallel_binning_equals_the_stable_sort_definition() {
        let mut state = 0x9E37_79B9_7F4A_7C15u64;
        let mut next = |k: u32| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 32) as u32 % k
        };
        // Enough Gaussians for several binning jobs, few distinct depths (ties must keep the
        // input order), rectangles from one tile to a third of the grid, some empty.
        let (gx, gy) = (20usize, 13usize);
        let visible: Vec<super::Projected<f32>> = (0..3 * super::BIN_CHUNK + 123)
            .map(|_| {
                let (x0, y0) = (next(gx as u32), next(gy as u32));
                let x1 = (x0 + next(7)).min(gx as u32);
                let y1 = (y0 + next(5)).min(gy as u32);
                super::Projected {
                    mean2d: [0.0; 2],
                    conic: [1.0, 0.0, 1.0],
                    depth: 0.5 + next(50) as f32 * 0.25,
                    opacity: 0.5,
                    extent: [1.0; 2],
                    rect: [x0, y0, x1, y1],
                    radius: 1,
                }
            })
            .collect();
        let n_tiles = gx * gy;
        let expected = bin_by_definition(&visible, gx, n_tiles);
        assert!(
            expected.1.len() > 4 * super::BIN_CHUNK,
            "too few pairs to test"
        );
        for threads in [1, 2, 3] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .expect("thread pool");
            let got = pool.install(|| super::bin_and_sort(&visible, gx, n_tiles, None, None));
            assert_eq!(got, expected, "{threads} threads");
        }
        // Skipped tiles get empty lists; every other tile keeps its list.
        let skip: Vec<bool> = (0..n_tiles).map(|t| t % 3 == 1).collect();
        let (offsets, list) = super::bin_and_sort(&visible, gx, n_tiles, Some(&skip), None);
        let (all_offsets, all_list) = &expected;
        for t in 0..n_tiles {
            let got = &list[offsets[t]..offsets[t + 1]];
            let full = &all_list[all_offsets[t]..all_offsets[t + 1]];
            assert_eq!(got, if skip[t] { &[][..] } else { full }, "tile {t}");
        }
        assert!(list.len() < all_list.len(), "some pairs skipped");
    }

    /// A tile leaves a Gaussian's rectangle exactly when the tile kernels would skip the pair
    /// (`splat_lanes` gives `None`), on an image whose border tiles are partial, with means and
    /// extents at the pixel-centre edges the kernels round on.
    #[test]
    fn trimmed_rectangles_keep_exactly_the_tiles_the_kernels_blend() {
        use crate::raster::kernels::{splat_lanes, PairSplat};
        use crate::{lit, TILE_SIZE};
        let mut next = crate::raster::test_uniform(0x2545_F491_4F6C_DD1D);
        let (width, height) = (83usize, 50usize);
        let (gx, gy) = (width.div_ceil(TILE_SIZE), height.div_ceil(TILE_SIZE));
        let (mut kept, mut dropped) = (0usize, 0usize);
        for _ in 0..20_000 {
            let snap = |v: f32, k: f32| if k < 0.3 { (v * 2.0).round() / 2.0 } else { v };
            let mean2d = [
                snap(next() * 120.0 - 20.0, next()),
                snap(next() * 90.0 - 20.0, next()),
            ];
            let extent = [snap(next() * 25.0, next()), snap(next() * 25.0, next())];
            // INRIA's square rectangle, at least as large as the extent box.
            let radius = extent[0].max(extent[1]) + next() * 10.0;
            let to_tile =
                |v: f32, n: usize| ((v / TILE_SIZE as f32).max(0.0) as usize).min(n) as u32;
            let rect = [
                to_tile(mean2d[0] - 0.5 - radius, gx),
                to_tile(mean2d[1] - 0.5 - radius, gy),
                to_tile(mean2d[0] - 0.5 + radius + TILE_SIZE as f32, gx),
                to_tile(mean2d[1] - 0.5 + radius + TILE_SIZE as f32, gy),
            ];
            let mut p = super::Projected {
                mean2d,
                conic: [1.0, 0.0, 1.0],
                depth: 1.0,
                opacity: 0.5,
                extent,
                rect,
                radius: 1,
            };
            super::trim_rect(&mut p, width, height);
            let pair = PairSplat {
                mean2d,
                conic: p.conic,
                opacity: p.opacity,
                depth: p.depth,
                extent,
            };
            for ty in rect[1]..rect[3] {
                for tx in rect[0]..rect[2] {
                    let origin = [tx as usize * TILE_SIZE, ty as usize * TILE_SIZE];
                    let size = [
                        TILE_SIZE.min(width - origin[0]),
                        TILE_SIZE.min(height - origin[1]),
                    ];
                    let blended =
                        splat_lanes(&pair, lit(origin[0] as f64), lit(origin[1] as f64), size)
                            .is_some();
                    let listed = (p.rect[0]..p.rect[2]).contains(&tx)
                        && (p.rect[1]..p.rect[3]).contains(&ty);
                    assert_eq!(
                        listed, blended,
                        "tile ({tx}, {ty}) of {mean2d:?} ± {extent:?}"
                    );
                    if listed {
                        kept += 1;
                    } else {
                        dropped += 1;
                    }
                }
            }
        }
        // Both outcomes are common, so the comparison is not vacuous.
        assert!(
            kept > 10_000 && dropped > 10_000,
            "{kept} kept, {dropped} dropped"
        );
    }
}
