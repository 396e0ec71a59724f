//! The LPIPS network's contract: the shipped weights load, a distance is zero between equal images
//! and symmetric, the value with the gradient is the value without it, results are bit-identical for
//! one and two threads, and bad inputs (sizes, lengths, weight files) are refused naming what is
//! wrong. Agreement with the reference formulation on real images is checked end to end by
//! `xtask/tests/lpips_cli.rs`; the gradient by `tests/gradient-checks/tests/lpips.rs`.

use lpips::{Lpips, LpipsError, ALEXNET_CHANNELS, MIN_SIZE};
use rand::{Rng, SeedableRng};
use safetensors::tensor::{Dtype, TensorView};
use std::path::Path;

fn shipped() -> Lpips<f32> {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../data-fixtures/lpips/alexnet-lpips-v0.1.safetensors"
    );
    lpips::load_safetensors(Path::new(path)).expect("the shipped LPIPS weights")
}

/// A smooth colour pattern plus seeded noise of amplitude `noise`, planar (3, h, w) in [0, 1].
fn image(h: usize, w: usize, noise: f32, seed: u64) -> Vec<f32> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mut out = vec![0.0f32; 3 * h * w];
    for c in 0..3 {
        for y in 0..h {
            for x in 0..w {
                let v = 0.5
                    + 0.3 * ((x as f32 * 0.3 + c as f32).sin() * (y as f32 * 0.2).cos())
                    + noise * rng.gen_range(-1.0f32..1.0);
                out[(c * h + y) * w + x] = v.clamp(0.0, 1.0);
            }
        }
    }
    out
}

#[test]
fn distances_are_zero_for_equal_images_symmetric_and_grow_with_the_difference() {
    let net = shipped();
    assert_eq!(net.channels(), ALEXNET_CHANNELS);
    let (h, w) = (64, 48);
    let a = image(h, w, 0.0, 1);
    let b = image(h, w, 0.05, 2);
    let c = image(h, w, 0.2, 3);
    assert_eq!(net.distance(&a, &a, h, w).expect("size"), 0.0);
    let ab = net.distance(&a, &b, h, w).expect("size");
    let ba = net.distance(&b, &a, h, w).expect("size");
    assert!(ab > 0.0 && (ab - ba).abs() <= 1e-6 * ab, "{ab} {ba}");
    let ac = net.distance(&a, &c, h, w).expect("size");
    assert!(ac > ab, "more noise, larger distance: {ab} then {ac}");
    let reference = net.features(&b, h, w).expect("size");
    let (value, gradient) = net
        .distance_and_gradient(&a, h, w, &reference)
        .expect("size");
    assert_eq!(value, ab);
    assert_eq!(gradient.len(), a.len());
    assert!(gradient.iter().all(|g| g.is_finite()) && gradient.iter().any(|&g| g != 0.0));
    // At equal images the distance is at its minimum: the gradient vanishes.
    let own = net.features(&a, h, w).expect("size");
    let (zero, flat) = net.distance_and_gradient(&a, h, w, &own).expect("size");
    assert_eq!(zero, 0.0);
    assert!(flat.iter().all(|&g| g == 0.0));
}

#[test]
fn results_are_bit_identical_for_one_and_two_threads() {
    let net = shipped();
    let (h, w) = (64, 64);
    let a = image(h, w, 0.1, 4);
    let b = image(h, w, 0.1, 5);
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("pool");
        pool.install(|| {
            let reference = net.features(&b, h, w).expect("size");
            let (d, g) = net
                .distance_and_gradient(&a, h, w, &reference)
                .expect("size");
            (
                d.to_bits(),
                g.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            )
        })
    };
    assert_eq!(run(1), run(2));
}

#[test]
fn bad_images_are_refused_with_what_is_wrong() {
    let net = Lpips::<f32>::random([4, 4, 4, 4, 4], 0);
    let a = image(40, 40, 0.0, 0);
    let reference = net.features(&image(40, 41, 0.0, 0), 40, 41).expect("size");
    let err = net
        .distance_to(&a, 40, 40, &reference)
        .expect_err("sizes differ");
    assert!(
        matches!(
            err,
            LpipsError::SizeMismatch {
                a_width: 40,
                a_height: 40,
                b_width: 41,
                b_height: 40
            }
        ),
        "{err}"
    );
    assert_eq!(err.to_string(), "image sizes differ: 40x40 and 41x40");
    let small = image(MIN_SIZE - 1, 64, 0.0, 0);
    let err = net
        .distance(&small, &small, MIN_SIZE - 1, 64)
        .expect_err("too small");
    assert_eq!(
        err.to_string(),
        "image 64x30 is too small for LPIPS (AlexNet needs at least 31x31 pixels)"
    );
    let ok = image(MIN_SIZE, MIN_SIZE, 0.0, 0);
    assert!(net.distance(&ok, &ok, MIN_SIZE, MIN_SIZE).is_ok());
    let err = net.distance(&a[1..], &a, 40, 40).expect_err("length");
    assert!(
        matches!(
            err,
            LpipsError::ImageLength {
                expected: 4800,
                actual: 4799,
                ..
            }
        ),
        "{err}"
    );
}

/// Safetensors bytes of the AlexNet tensors (zeros) with `edit` applied to the (name, shape, dtype)
/// list first.
fn weights_file(edit: impl FnOnce(&mut Vec<(String, Vec<usize>, Dtype)>)) -> Vec<u8> {
    let mut specs = Vec::new();
    for i in 0..5 {
        let c_out = ALEXNET_CHANNELS[i];
        let c_in = if i == 0 { 3 } else { ALEXNET_CHANNELS[i - 1] };
        let k = lpips::KERNELS[i];
        specs.push((
            format!("conv{i}.weight"),
            vec![c_out, c_in, k, k],
            Dtype::F32,
        ));
        specs.push((format!("conv{i}.bias"), vec![c_out], Dtype::F32));
        specs.push((format!("lin{i}.weight"), vec![1, c_out, 1, 1], Dtype::F32));
    }
    edit(&mut specs);
    let buffers: Vec<(String, Vec<usize>, Dtype, Vec<u8>)> = specs
        .into_iter()
        .map(|(name, shape, dtype)| {
            let bytes = vec![0u8; shape.iter().product::<usize>() * dtype.bitsize() / 8];
            (name, shape, dtype, bytes)
        })
        .collect();
    let views: Vec<(String, TensorView<'_>)> = buffers
        .iter()
        .map(|(n, s, d, b)| (n.clone(), TensorView::new(*d, s.clone(), b).expect("view")))
        .collect();
    safetensors::serialize(views, None).expect("serialise")
}

#[test]
fn weight_files_with_wrong_tensors_are_refused_naming_the_tensor() {
    assert!(lpips::read_safetensors(&weights_file(|_| ())).is_ok());
    let err = lpips::read_safetensors(&weights_file(|s| s[3].1 = vec![192, 64, 3, 3]))
        .expect_err("wrong shape");
    assert_eq!(
        err.to_string(),
        "tensor conv1.weight: expected shape [192, 64, 5, 5], found [192, 64, 3, 3]"
    );
    let err = lpips::read_safetensors(&weights_file(|s| {
        s.retain(|t| t.0 != "lin4.weight");
    }))
    .expect_err("missing");
    assert_eq!(err.to_string(), "missing tensor lin4.weight");
    let err = lpips::read_safetensors(&weights_file(|s| s[1].2 = Dtype::F16)).expect_err("dtype");
    assert_eq!(
        err.to_string(),
        "tensor conv0.bias: unsupported dtype F16 (expected F32)"
    );
    let err = lpips::read_safetensors(b"not a safetensors file").expect_err("garbage");
    assert!(matches!(err, LpipsError::Safetensors(_)), "{err}");
    let err =
        lpips::load_safetensors(Path::new("/nonexistent/lpips.safetensors")).expect_err("no file");
    assert!(
        err.to_string()
            .starts_with("/nonexistent/lpips.safetensors: "),
        "{err}"
    );
}
