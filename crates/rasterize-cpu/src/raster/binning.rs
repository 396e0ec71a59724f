//! Tile binning: every visible Gaussian is listed once per 16×16 tile of its screen rectangle, and
//! each tile's list is sorted by (view depth, input index), the order of INRIA's stable radix sort.
//! Parallel and deterministic: the lists are the same for any chunking and thread count.

use rayon::prelude::*;

use crate::project::Projected;
use crate::Real;

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

/// Tile lists: for every tile, the indices of the visible Gaussians overlapping it sorted by
/// (view depth, index), as offsets into one list. Equals INRIA's stable radix sort on
/// (tile, depth).
///
/// Parallel: jobs over contiguous chunks of `visible` bin their Gaussians by tile (a local counting
/// sort); every tile then gathers its entries from the jobs and sorts them. The key (depth, index)
/// is a total order, so the lists are the same for any chunking and thread count.
pub(super) fn bin_and_sort<T: Real>(
    visible: &[Projected<T>],
    gx: usize,
    n_tiles: usize,
) -> (Vec<usize>, Vec<u32>) {
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
                        starts[row + tx as usize + 1] += 1;
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
                        entries[cursor[t]] = key;
                        cursor[t] += 1;
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
            let got = pool.install(|| super::bin_and_sort(&visible, gx, n_tiles));
            assert_eq!(got, expected, "{threads} threads");
        }
    }
}
