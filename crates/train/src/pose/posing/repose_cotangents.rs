//! [`ReposeCotangents`]: what a frame's re-posings ([`crate::pose::reposing`]) hand back to the frame's
//! one backward ([`super::pose_frame_backward_with`]). It lives here, beside its reader, so that
//! `posing` does not import `reposing` (which builds on `posing`).

use crate::TrainError;
use nn::Real;
use rayon::prelude::*;
use smpl_deform::deform_net::MovedCotangents;

/// Cotangents of a frame pass's internal quantities coming from its re-posings (summed over them);
/// [`pose_frame_backward_with`](crate::pose::posing::pose_frame_backward_with) adds them to its own.
#[derive(Clone, Debug, PartialEq)]
pub struct ReposeCotangents<T> {
    /// ∂L/∂ stored means through the static path, N.
    pub means: Vec<[T; 3]>,
    /// ∂L/∂ static covariances, N.
    pub covariances: Vec<[[T; 3]; 3]>,
    /// ∂L/∂ scene colours, N × 3.
    pub scene_colours: Vec<T>,
    /// ∂L/∂ human probability, N.
    pub human_probability: Vec<T>,
    /// ∂L/∂ each person's probability, N × P with several people (else empty).
    pub person_probability: Vec<T>,
    /// ∂L/∂ human colours of the active Gaussians, active × 3.
    pub human_colours: Vec<T>,
    /// ∂L/∂ deformed log-scales of the active Gaussians.
    pub log_scales: Vec<[T; 3]>,
    /// ∂L/∂ moved Gaussians (the inputs of LBS) of the active Gaussians.
    pub moved: MovedCotangents<T>,
}

impl<T: Real> ReposeCotangents<T> {
    /// Zero cotangents of `n` Gaussians of which `active` have a human branch.
    pub fn zeros(n: usize, active: usize) -> Self {
        Self {
            means: vec![[T::zero(); 3]; n],
            covariances: vec![[[T::zero(); 3]; 3]; n],
            scene_colours: vec![T::zero(); n * 3],
            human_probability: vec![T::zero(); n],
            person_probability: Vec::new(),
            human_colours: vec![T::zero(); active * 3],
            log_scales: vec![[T::zero(); 3]; active],
            moved: MovedCotangents::zeros(active),
        }
    }

    /// Adds `other` element by element.
    pub fn add(&mut self, other: &Self) {
        // Element by element, so the chunks may run in parallel with the bits of a serial loop.
        fn add<T: Real>(a: &mut [T], b: &[T]) {
            const CHUNK: usize = 1 << 14;
            a.par_chunks_mut(CHUNK)
                .zip(b.par_chunks(CHUNK))
                .for_each(|(a, b)| a.iter_mut().zip(b).for_each(|(x, &y)| *x = *x + y));
        }
        add(self.means.as_flattened_mut(), other.means.as_flattened());
        add(
            self.covariances.as_flattened_mut().as_flattened_mut(),
            other.covariances.as_flattened().as_flattened(),
        );
        add(&mut self.scene_colours, &other.scene_colours);
        add(&mut self.human_probability, &other.human_probability);
        if self.person_probability.is_empty() {
            self.person_probability = other.person_probability.clone();
        } else {
            add(&mut self.person_probability, &other.person_probability);
        }
        add(&mut self.human_colours, &other.human_colours);
        add(
            self.log_scales.as_flattened_mut(),
            other.log_scales.as_flattened(),
        );
        self.moved.add(&other.moved);
    }

    /// Checks the lengths against a frame of `n` Gaussians with `active` human branches.
    pub(crate) fn check(&self, n: usize, active: usize) -> Result<(), TrainError> {
        let lengths = [
            ("re-posing cotangent means", n, self.means.len()),
            ("re-posing cotangent covariances", n, self.covariances.len()),
            (
                "re-posing cotangent scene colours",
                n * 3,
                self.scene_colours.len(),
            ),
            (
                "re-posing cotangent probability",
                n,
                self.human_probability.len(),
            ),
            (
                "re-posing cotangent human colours",
                active * 3,
                self.human_colours.len(),
            ),
            (
                "re-posing cotangent log-scales",
                active,
                self.log_scales.len(),
            ),
            (
                "re-posing cotangent moved positions",
                active,
                self.moved.positions.len(),
            ),
        ];
        for (what, expected, found) in lengths {
            if expected != found {
                return Err(TrainError::Shape {
                    what: what.into(),
                    expected,
                    found,
                });
            }
        }
        Ok(())
    }
}
