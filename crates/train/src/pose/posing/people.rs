//! The human branch of a frame with several people: each active Gaussian is deformed by one
//! person's bones and pose code (its most probable person, `crate::blend::most_probable_person`),
//! so the deformation, its re-posings and their backward run once per person on that person's
//! Gaussians, and their results are merged back into the active order. A frame's bones are 24 per
//! person and its pose code 207 per person, in person order.
//!
//! With one person every call goes straight to `smpl_deform` on the whole active set (no gather,
//! no scatter): the same operations, so the same bits, as before people existed.

use super::views::{canonical_view_directions, view_directions_backward, CanonicalViews};
use nn::Real;
use smpl_deform::deform_net::{
    deform_gaussians, deform_gaussians_backward_with_moved, CanonicalGaussians, DeformCache,
    DeformGrad, MovedCotangents, NonRigidNet, PosedGaussians, ReposeCache, Reposed, SkinningCache,
    SkinningField, NR_FEATURE_DIM,
};
use smpl_deform::math::{Affine, Mat3};
use smpl_deform::{NUM_JOINTS, NUM_POSE_FEATURES};

/// The two networks a deformation evaluates.
#[derive(Clone, Copy)]
pub(crate) struct DeformNets<'a, T: Real> {
    pub nonrigid: &'a NonRigidNet<T>,
    pub skinning: &'a SkinningField<T>,
}

/// One person's share of a frame's active Gaussians.
#[derive(Clone, Debug)]
struct PersonDeform<T: Real> {
    /// Positions in the active list of the Gaussians this person deforms (ascending); `None`: the
    /// frame has one person and it deforms every active Gaussian.
    rows: Option<Vec<usize>>,
    /// The deformation of those Gaussians (`None` when the person has none).
    cache: Option<DeformCache<T>>,
}

/// The deformation of a frame's active Gaussians by their people.
#[derive(Clone, Debug)]
pub(crate) struct PeopleDeform<T: Real> {
    persons: Vec<PersonDeform<T>>,
    active: usize,
}

/// The re-posing of a [`PeopleDeform`] at other bones, per person.
#[derive(Clone, Debug)]
pub struct PeopleRepose<T>(Vec<Option<ReposeCache<T>>>);

/// Rows `idx` of `v`, `stride` values per row.
fn gather<T: Copy>(v: &[T], stride: usize, idx: &[usize]) -> Vec<T> {
    let mut out = Vec::with_capacity(idx.len() * stride);
    for &i in idx {
        out.extend_from_slice(&v[i * stride..(i + 1) * stride]);
    }
    out
}

/// Writes row `r` of `rows` to row `idx[r]` of `out`.
fn scatter<T: Copy>(out: &mut [T], rows: &[T], stride: usize, idx: &[usize]) {
    for (r, &i) in idx.iter().enumerate() {
        out[i * stride..(i + 1) * stride].copy_from_slice(&rows[r * stride..(r + 1) * stride]);
    }
}

/// Person `j`'s 24 bones of a frame's bones (24 per person).
fn bones_of<T>(bones: &[Affine<T>], j: usize) -> &[Affine<T>] {
    &bones[j * NUM_JOINTS..(j + 1) * NUM_JOINTS]
}

impl<T: Real> PeopleDeform<T> {
    /// Deforms the active Gaussians `canonical`: with `owners` (the person of each active
    /// Gaussian), each by its person's slice of `pose_code` (207 per person) and `bones` (24 per
    /// person); without, all by the one person's.
    pub(crate) fn forward(
        nets: DeformNets<'_, T>,
        canonical: &CanonicalGaussians<'_, T>,
        owners: Option<&[usize]>,
        pose_code: &[T],
        bones: &[Affine<T>],
    ) -> Result<(PosedGaussians<T>, Self), nn::NnError> {
        let active = canonical.positions.len();
        let Some(owners) = owners else {
            let (posed, cache) =
                deform_gaussians(nets.nonrigid, nets.skinning, canonical, pose_code, bones)?;
            let persons = vec![PersonDeform {
                rows: None,
                cache: Some(cache),
            }];
            return Ok((posed, Self { persons, active }));
        };
        let people = bones.len() / NUM_JOINTS;
        let mut posed = PosedGaussians {
            positions: vec![[T::zero(); 3]; active],
            log_scales: vec![[T::zero(); 3]; active],
            mats: vec![[T::zero(); 9]; active],
            features: vec![T::zero(); active * NR_FEATURE_DIM],
        };
        let mut persons = Vec::with_capacity(people);
        for j in 0..people {
            let rows: Vec<usize> = (0..active).filter(|&a| owners[a] == j).collect();
            if rows.is_empty() {
                persons.push(PersonDeform {
                    rows: Some(rows),
                    cache: None,
                });
                continue;
            }
            let (positions, log_scales, quats) = (
                gather(canonical.positions, 1, &rows),
                gather(canonical.log_scales, 1, &rows),
                gather(canonical.quats, 1, &rows),
            );
            let subset = CanonicalGaussians {
                positions: &positions,
                log_scales: &log_scales,
                quats: &quats,
            };
            let code = &pose_code[j * NUM_POSE_FEATURES..(j + 1) * NUM_POSE_FEATURES];
            let (own, cache) = deform_gaussians(
                nets.nonrigid,
                nets.skinning,
                &subset,
                code,
                bones_of(bones, j),
            )?;
            scatter(&mut posed.positions, &own.positions, 1, &rows);
            scatter(&mut posed.log_scales, &own.log_scales, 1, &rows);
            scatter(&mut posed.mats, &own.mats, 1, &rows);
            scatter(&mut posed.features, &own.features, NR_FEATURE_DIM, &rows);
            persons.push(PersonDeform {
                rows: Some(rows),
                cache: Some(cache),
            });
        }
        Ok((posed, Self { persons, active }))
    }

    /// The one person's deformation when the frame has one person, else `None`.
    fn single(&self) -> Option<&DeformCache<T>> {
        match self.persons.as_slice() {
            [PersonDeform { rows: None, cache }] => cache.as_ref(),
            _ => None,
        }
    }

    /// The deformation's own skinning pass, if it is bit for bit the skinning field at `points`
    /// (`DeformCache::skinning_at`); always `None` with several people, whose passes are cut per
    /// person.
    pub(crate) fn skinning_at(&self, points: &[[T; 3]]) -> Option<&SkinningCache<T>> {
        self.single().and_then(|c| c.skinning_at(points))
    }

    /// The deformation's own skinning weights at the moved means `x + Δx`, `(active, 24)` in active
    /// order: each person's from that person's pass.
    pub(crate) fn weights(&self) -> Vec<T> {
        if let Some(cache) = self.single() {
            return cache.skinning().weights();
        }
        let mut weights = vec![T::zero(); self.active * NUM_JOINTS];
        for person in &self.persons {
            if let (Some(rows), Some(cache)) = (&person.rows, &person.cache) {
                scatter(&mut weights, &cache.skinning().weights(), NUM_JOINTS, rows);
            }
        }
        weights
    }

    /// The skinning pass [`PeopleDeform::skinning_at`] handed out (one person only).
    pub(crate) fn reused_skinning(&self) -> Option<&SkinningCache<T>> {
        self.single().map(DeformCache::skinning)
    }

    /// The canonical view directions of the deformed `positions` (active order) seen from `c`,
    /// each with its person's bones.
    pub(super) fn views(
        &self,
        bones: &[Affine<T>],
        c: [T; 3],
        positions: &[[T; 3]],
        weights: &[T],
    ) -> CanonicalViews<T> {
        if self.persons.len() == 1 {
            return canonical_view_directions(bones, c, positions, weights);
        }
        let mut views = CanonicalViews {
            directions: vec![[T::zero(); 3]; self.active],
            world: vec![[T::zero(); 3]; self.active],
            rotations: vec![[T::zero(); 9]; self.active],
        };
        for (j, rows) in self.person_rows() {
            let own = canonical_view_directions(
                bones_of(bones, j),
                c,
                &gather(positions, 1, rows),
                &gather(weights, NUM_JOINTS, rows),
            );
            scatter(&mut views.directions, &own.directions, 1, rows);
            scatter(&mut views.world, &own.world, 1, rows);
            scatter(&mut views.rotations, &own.rotations, 1, rows);
        }
        views
    }

    /// Backward of [`PeopleDeform::views`]: ∂L/∂ the skinning weights (active order) and ∂L/∂
    /// every bone's rotation (24 per person); the positions' share is added to `d_x_def`.
    pub(super) fn views_backward(
        &self,
        bones: &[Affine<T>],
        views: &CanonicalViews<T>,
        weights: &[T],
        d_directions: &[[T; 3]],
        d_x_def: &mut [[T; 3]],
    ) -> (Vec<T>, Vec<[T; 9]>) {
        if self.persons.len() == 1 {
            return view_directions_backward(bones, views, weights, d_directions, d_x_def);
        }
        let mut d_weights = vec![T::zero(); self.active * NUM_JOINTS];
        let mut d_rotations = vec![[T::zero(); 9]; bones.len()];
        for (j, rows) in self.person_rows() {
            let own = CanonicalViews {
                directions: Vec::new(),
                world: gather(&views.world, 1, rows),
                rotations: gather(&views.rotations, 1, rows),
            };
            let mut d_x = gather(d_x_def, 1, rows);
            let (dw, dr) = view_directions_backward(
                bones_of(bones, j),
                &own,
                &gather(weights, NUM_JOINTS, rows),
                &gather(d_directions, 1, rows),
                &mut d_x,
            );
            scatter(d_x_def, &d_x, 1, rows);
            scatter(&mut d_weights, &dw, NUM_JOINTS, rows);
            d_rotations[j * NUM_JOINTS..(j + 1) * NUM_JOINTS].copy_from_slice(&dr);
        }
        (d_weights, d_rotations)
    }

    /// Backward of the deformation (and, with `moved`, of its re-posings' shared inputs): the
    /// canonical gradients in active order, ∂L/∂bones (24 per person) and ∂L/∂pose code (207 per
    /// person); the networks' gradients are added to `d_nonrigid` and `d_skinning`, person by
    /// person.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn backward(
        &self,
        nets: DeformNets<'_, T>,
        bones: &[Affine<T>],
        cot: &DeformCotangents<'_, T>,
        moved: Option<&MovedCotangents<T>>,
        d_nonrigid: &mut [T],
        d_skinning: &mut [T],
    ) -> Result<DeformGrad<T>, nn::NnError> {
        if let Some(cache) = self.single() {
            return deform_gaussians_backward_with_moved(
                nets.nonrigid,
                nets.skinning,
                bones,
                cache,
                cot.positions,
                cot.log_scales,
                cot.mats,
                cot.features,
                moved,
                d_nonrigid,
                d_skinning,
            );
        }
        let n = self.active;
        let mut out = DeformGrad {
            positions: vec![[T::zero(); 3]; n],
            log_scales: vec![[T::zero(); 3]; n],
            quats: vec![[T::zero(); 4]; n],
            bones: vec![[T::zero(); 12]; bones.len()],
            pose_code: vec![T::zero(); self.persons.len() * NUM_POSE_FEATURES],
        };
        for (j, person) in self.persons.iter().enumerate() {
            let (Some(rows), Some(cache)) = (&person.rows, &person.cache) else {
                continue;
            };
            let moved_rows = moved.map(|m| gather_moved(m, rows));
            let own = deform_gaussians_backward_with_moved(
                nets.nonrigid,
                nets.skinning,
                bones_of(bones, j),
                cache,
                &gather(cot.positions, 1, rows),
                &gather(cot.log_scales, 1, rows),
                &gather(cot.mats, 1, rows),
                &gather(cot.features, NR_FEATURE_DIM, rows),
                moved_rows.as_ref(),
                d_nonrigid,
                d_skinning,
            )?;
            scatter(&mut out.positions, &own.positions, 1, rows);
            scatter(&mut out.log_scales, &own.log_scales, 1, rows);
            scatter(&mut out.quats, &own.quats, 1, rows);
            out.bones[j * NUM_JOINTS..(j + 1) * NUM_JOINTS].copy_from_slice(&own.bones);
            out.pose_code[j * NUM_POSE_FEATURES..(j + 1) * NUM_POSE_FEATURES]
                .copy_from_slice(&own.pose_code);
        }
        Ok(out)
    }

    /// The deformation re-posed at other `bones` (24 per person): LBS only, with this
    /// deformation's non-rigid offsets and skinning weights (`DeformCache::repose`).
    pub(crate) fn repose(
        &self,
        bones: &[Affine<T>],
    ) -> Result<(Reposed<T>, PeopleRepose<T>), nn::NnError> {
        if let Some(cache) = self.single() {
            let (reposed, repose) = cache.repose(bones)?;
            return Ok((reposed, PeopleRepose(vec![Some(repose)])));
        }
        let n = self.active;
        let mut out = Reposed {
            positions: vec![[T::zero(); 3]; n],
            mats: vec![[T::zero(); 9]; n],
        };
        let mut caches = Vec::with_capacity(self.persons.len());
        for (j, person) in self.persons.iter().enumerate() {
            let (Some(rows), Some(cache)) = (&person.rows, &person.cache) else {
                caches.push(None);
                continue;
            };
            let (own, repose) = cache.repose(bones_of(bones, j))?;
            scatter(&mut out.positions, &own.positions, 1, rows);
            scatter(&mut out.mats, &own.mats, 1, rows);
            caches.push(Some(repose));
        }
        Ok((out, PeopleRepose(caches)))
    }

    /// Backward of [`PeopleDeform::repose`]: the moved Gaussians' cotangents (active order) and
    /// ∂L/∂`bones` (24 per person).
    pub(crate) fn repose_backward(
        &self,
        bones: &[Affine<T>],
        repose: &PeopleRepose<T>,
        d_positions: &[[T; 3]],
        d_mats: &[Mat3<T>],
    ) -> Result<(MovedCotangents<T>, Vec<Affine<T>>), nn::NnError> {
        if let (Some(cache), [Some(own)]) = (self.single(), repose.0.as_slice()) {
            return cache.repose_backward(bones, own, d_positions, d_mats);
        }
        let mut moved = MovedCotangents::zeros(self.active);
        let mut d_bones = vec![[T::zero(); 12]; bones.len()];
        for (j, (person, own)) in self.persons.iter().zip(&repose.0).enumerate() {
            let (Some(rows), Some(cache), Some(own)) = (&person.rows, &person.cache, own) else {
                continue;
            };
            let (m, db) = cache.repose_backward(
                bones_of(bones, j),
                own,
                &gather(d_positions, 1, rows),
                &gather(d_mats, 1, rows),
            )?;
            scatter(&mut moved.positions, &m.positions, 1, rows);
            scatter(&mut moved.quats, &m.quats, 1, rows);
            scatter(&mut moved.weights, &m.weights, NUM_JOINTS, rows);
            d_bones[j * NUM_JOINTS..(j + 1) * NUM_JOINTS].copy_from_slice(&db);
        }
        Ok((moved, d_bones))
    }

    /// Each person with Gaussians, and their positions in the active list.
    fn person_rows(&self) -> impl Iterator<Item = (usize, &[usize])> {
        self.persons
            .iter()
            .enumerate()
            .filter_map(|(j, p)| p.rows.as_deref().map(|r| (j, r)))
    }
}

/// The cotangents of a deformation's outputs (active order).
pub(crate) struct DeformCotangents<'a, T> {
    pub positions: &'a [[T; 3]],
    pub log_scales: &'a [[T; 3]],
    pub mats: &'a [Mat3<T>],
    /// Of the non-rigid features, `NR_FEATURE_DIM` per Gaussian.
    pub features: &'a [T],
}

/// Rows `idx` of moved cotangents.
fn gather_moved<T: Real>(m: &MovedCotangents<T>, idx: &[usize]) -> MovedCotangents<T> {
    MovedCotangents {
        positions: gather(&m.positions, 1, idx),
        quats: gather(&m.quats, 1, idx),
        weights: gather(&m.weights, NUM_JOINTS, idx),
    }
}
