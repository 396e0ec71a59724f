//! Test-time camera alignment (`train::camera_alignment`) on the tiny fixture: a frame rendered
//! from a known camera and then handed a camera off by a known twist is aligned back towards the
//! right one, from its mid-exposure render and from an exposure of renders whose cameras move, and
//! the alignment never raises its loss.
#![allow(clippy::unwrap_used)]

use train::camera_alignment::{align_camera, AlignmentSettings};
use train::pose::camera_correction::corrected_world_to_camera;
use train::trainer::Trainer;

mod common;
use common::*;

/// The rotation angle (degrees) and the centre distance (metres) between two cameras.
fn camera_error(a: &[[f64; 4]; 4], b: &[[f64; 4]; 4]) -> (f64, f64) {
    // trace(R_a R_bᵀ) = 1 + 2 cos θ.
    let trace: f64 = (0..3)
        .map(|i| (0..3).map(|k| a[i][k] * b[i][k]).sum::<f64>())
        .sum();
    let angle = ((trace - 1.0) / 2.0).clamp(-1.0, 1.0).acos().to_degrees();
    // Centres c = −Rᵀ t.
    let centre = |m: &[[f64; 4]; 4]| -> [f64; 3] {
        std::array::from_fn(|j| -(0..3).map(|i| m[i][j] * m[i][3]).sum::<f64>())
    };
    let (ca, cb) = (centre(a), centre(b));
    let distance = (0..3).map(|j| (ca[j] - cb[j]).powi(2)).sum::<f64>().sqrt();
    (angle, distance)
}

#[test]
fn a_camera_off_by_a_known_twist_is_aligned_back() {
    let ctx = context();
    let mut t = Trainer::new(&ctx, tiny_config(30)).unwrap();
    t.run(&ctx, 30, |_, _| Ok(())).unwrap();
    let model = &t.model;
    let given = ctx.camera.clone();
    let pose = ctx.body.prepare(&ctx.frames[1].pose.params).unwrap();
    let latent = model.latent(1).to_vec();
    // The observed frame: the model's own render from the given camera.
    let observed = model.render(&given, &pose, &latent).unwrap().rgb;
    // A start 0.4° and 8 mm off.
    let off = [0.004, -0.005, 0.002, 0.006, -0.004, 0.003];
    let start = rasterize_cpu::Camera {
        world_to_camera: corrected_world_to_camera(&given.world_to_camera, &off),
        ..given.clone()
    };
    let (angle0, centre0) = camera_error(&start.world_to_camera, &given.world_to_camera);
    let settings = AlignmentSettings::with_steps(60, None);
    let aligned = align_camera(
        model,
        (&start, &given),
        &[(start.clone(), &pose)],
        &latent,
        (&observed, false),
        &settings,
    )
    .unwrap();
    let (angle, centre) = camera_error(&aligned.camera.world_to_camera, &given.world_to_camera);
    assert!(
        aligned.loss_after < 0.2 * aligned.loss_before,
        "loss {} → {}",
        aligned.loss_before,
        aligned.loss_after
    );
    // The image error falls five-fold and the camera comes closer to the right one: a wrong
    // sign or a missing term in the gradient would move it away or not at all.
    assert!(angle < 0.5 * angle0, "rotation {angle0}° → {angle}°");
    assert!(centre < centre0, "centre {centre0} m → {centre} m");
    // No steps: the start camera, its loss on both sides.
    let none = align_camera(
        model,
        (&start, &given),
        &[(start.clone(), &pose)],
        &latent,
        (&observed, false),
        &AlignmentSettings::with_steps(0, None),
    )
    .unwrap();
    assert_eq!(none.camera.world_to_camera, start.world_to_camera);
    assert_eq!(none.loss_before, none.loss_after);
    assert_eq!(none.loss_before, aligned.loss_before);

    // An exposure of three renders whose cameras move inside it: the observed frame is their
    // mean from the right cameras; every render's camera starts off by the same twist, and the
    // mid camera comes back.
    let path = [
        [0.0, 0.003, 0.0, -0.004, 0.0, 0.0],
        [0.0; 6],
        [0.0, -0.003, 0.0, 0.004, 0.0, 0.0],
    ];
    let moved = |twist: &[f64; 6], from: &rasterize_cpu::Camera| rasterize_cpu::Camera {
        world_to_camera: corrected_world_to_camera(&from.world_to_camera, twist),
        ..from.clone()
    };
    let truth: Vec<_> = path.iter().map(|p| moved(p, &given)).collect();
    let renders: Vec<Vec<f32>> = truth
        .iter()
        .map(|c| model.render(c, &pose, &latent).unwrap().rgb)
        .collect();
    let observed: Vec<f32> = (0..renders[0].len())
        .map(|i| renders.iter().map(|r| r[i]).sum::<f32>() / 3.0)
        .collect();
    let exposure: Vec<_> = truth.iter().map(|c| (moved(&off, c), &pose)).collect();
    let aligned = align_camera(
        model,
        (&exposure[1].0, &given),
        &exposure,
        &latent,
        (&observed, false),
        &settings,
    )
    .unwrap();
    let (angle, centre) = camera_error(&aligned.camera.world_to_camera, &given.world_to_camera);
    assert!(aligned.loss_after < 0.2 * aligned.loss_before);
    assert!(
        angle < 0.5 * angle0,
        "exposure: rotation {angle0}° → {angle}°"
    );
    assert!(
        centre < centre0,
        "exposure: centre {centre0} m → {centre} m"
    );
}
