//! Weights I/O (safetensors and Torch7 import, both on synthetic data built here) and bad-input errors.

use flow::t7::{file_name, import_dir, parse_float_tensor, write_float_tensor};
use flow::{
    load_safetensors, read_safetensors, save_safetensors, write_safetensors, FlowError, SpyNet,
};

#[test]
fn safetensors_round_trip_is_exact() {
    let net = SpyNet::<f32>::random(3, 42);
    let bytes = write_safetensors(&net).expect("serialise");
    let back = read_safetensors(&bytes).expect("parse");
    assert_eq!(back.num_levels(), 3);
    assert_eq!(back, net);
}

#[test]
fn saving_replaces_the_file_whole_and_leaves_no_temporary_file() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("w.safetensors");
    let (first, second) = (SpyNet::<f32>::random(2, 1), SpyNet::<f32>::random(3, 2));
    save_safetensors(&first, &path).expect("save");
    save_safetensors(&second, &path).expect("save over");
    assert_eq!(load_safetensors(&path).expect("load"), second);
    let names: Vec<_> = std::fs::read_dir(dir.path())
        .expect("list")
        .map(|e| e.expect("entry").file_name())
        .collect();
    assert_eq!(names, [std::ffi::OsString::from("w.safetensors")]);
    // A directory that does not exist: an error naming the file, nothing written.
    let missing = dir.path().join("no-such-dir").join("w.safetensors");
    let err = save_safetensors(&first, &missing).expect_err("no directory");
    assert!(
        matches!(&err, FlowError::Io { path, .. } if path.contains("no-such-dir")),
        "{err}"
    );
}

#[test]
fn safetensors_bytes_are_reproducible() {
    // The metadata map's iteration order is random per map; every write must still give the same
    // bytes (seven more writes: the chance that a random order repeats them all is 1/128).
    let net = SpyNet::<f32>::random(2, 5);
    let first = write_safetensors(&net).expect("serialise");
    for _ in 0..7 {
        assert_eq!(write_safetensors(&net).expect("serialise"), first);
    }
    let st = safetensors::SafeTensors::deserialize(&first).expect("parse");
    let (_, meta) = safetensors::SafeTensors::read_metadata(&first).expect("header");
    let meta = meta.metadata().clone().expect("metadata");
    assert_eq!(meta.get("format").map(String::as_str), Some("spynet"));
    assert_eq!(meta.get("levels").map(String::as_str), Some("2"));
    assert_eq!(st.names().len(), 2 * 5 * 2);
}

#[test]
fn safetensors_missing_tensor_and_wrong_shape_are_named() {
    use safetensors::tensor::{Dtype, TensorView};
    let net = SpyNet::<f32>::random(2, 1);
    let full = read_safetensors(&write_safetensors(&net).expect("ser")).expect("parse");
    assert_eq!(full.num_levels(), 2);
    // Rebuild the file without level1.conv3.bias, and with a wrongly shaped level0.conv2.weight.
    let st_bytes = write_safetensors(&net).expect("ser");
    let st = safetensors::SafeTensors::deserialize(&st_bytes).expect("parse");
    let build = |skip: &str, reshape: Option<(&str, Vec<usize>)>| {
        let mut owned: Vec<(String, Vec<usize>, Vec<u8>)> = Vec::new();
        for name in st.names() {
            if name == skip {
                continue;
            }
            let t = st.tensor(name).expect("tensor");
            let mut shape = t.shape().to_vec();
            let mut data = t.data().to_vec();
            if let Some((n, s)) = &reshape {
                if name == *n {
                    shape = s.clone();
                    data.truncate(s.iter().product::<usize>() * 4);
                }
            }
            owned.push((name.to_string(), shape, data));
        }
        let views: Vec<(String, TensorView<'_>)> = owned
            .iter()
            .map(|(n, s, d)| {
                (
                    n.clone(),
                    TensorView::new(Dtype::F32, s.clone(), d).expect("view"),
                )
            })
            .collect();
        safetensors::serialize(views, None).expect("ser")
    };
    match read_safetensors(&build("level1.conv3.bias", None)) {
        Err(FlowError::MissingTensor { name }) => assert_eq!(name, "level1.conv3.bias"),
        other => panic!("expected a missing-tensor error, got {other:?}"),
    }
    match read_safetensors(&build(
        "",
        Some(("level0.conv2.weight", vec![32, 64, 5, 5])),
    )) {
        Err(e @ FlowError::WrongShape { .. }) => {
            let msg = e.to_string();
            assert!(
                msg.contains("level0.conv2.weight") && msg.contains("[32, 64, 7, 7]"),
                "{msg}"
            );
        }
        other => panic!("expected a wrong-shape error, got {other:?}"),
    }
}

#[test]
fn mismatched_image_sizes_are_rejected() {
    let net = SpyNet::<f32>::random(2, 3);
    let a = vec![0.5f32; 3 * 8 * 8];
    let b = vec![0.5f32; 3 * 8 * 9];
    match net.forward(&a, &b, 8, 8) {
        Err(FlowError::Size(msg)) => assert!(msg.contains("8x8"), "{msg}"),
        other => panic!("expected a size error, got {other:?}"),
    }
}

fn write_t7_dir(dir: &std::path::Path, net: &SpyNet<f32>, variant: &str) {
    for (l, level) in net.levels.iter().enumerate() {
        for (i, c) in level.iter().enumerate() {
            let (ci, co) = flow::LAYER_CHANNELS[i];
            std::fs::write(
                dir.join(file_name(l, variant, i, "weight")),
                write_float_tensor(&[co, ci, 7, 7], &c.weight),
            )
            .expect("write");
            std::fs::write(
                dir.join(file_name(l, variant, i, "bias")),
                write_float_tensor(&[co], &c.bias),
            )
            .expect("write");
        }
    }
}

#[test]
fn torch7_directory_import_round_trips_and_reports_bad_files() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mut net = SpyNet::<f32>::random(2, 9);
    for (k, b) in net.levels[1][4].bias.iter_mut().enumerate() {
        *b = 0.25 + k as f32;
    }
    write_t7_dir(dir.path(), &net, "K");
    let imported = import_dir(dir.path(), "K").expect("import");
    // The original weights run with the reference pyramid rule, recorded in the converted file.
    let net = net.with_depth(flow::PyramidDepth::REFERENCE);
    assert_eq!(imported, net);
    let reread = read_safetensors(&write_safetensors(&imported).expect("write")).expect("read");
    assert_eq!(reread, net);
    // A truncated file names the file.
    let victim = dir.path().join(file_name(1, "K", 2, "weight"));
    let bytes = std::fs::read(&victim).expect("read");
    std::fs::write(&victim, &bytes[..bytes.len() - 10]).expect("write");
    let err = import_dir(dir.path(), "K").expect_err("truncated");
    let msg = err.to_string();
    assert!(
        msg.contains("modelL2_K-3-weight.t7") && msg.contains("truncated"),
        "{msg}"
    );
    // A wrong shape names the file.
    std::fs::write(
        &victim,
        write_float_tensor(&[32, 64, 3, 3], &vec![0.0; 32 * 64 * 9]),
    )
    .expect("write");
    match import_dir(dir.path(), "K") {
        Err(FlowError::WrongShape { name, .. }) => assert_eq!(name, "modelL2_K-3-weight.t7"),
        other => panic!("expected a wrong-shape error, got {other:?}"),
    }
    // A missing file names the file.
    std::fs::remove_file(dir.path().join(file_name(0, "K", 4, "bias"))).expect("rm");
    match import_dir(dir.path(), "K") {
        Err(FlowError::MissingTensor { name }) => assert_eq!(name, "modelL1_K-5-bias.t7"),
        other => panic!("expected a missing-tensor error, got {other:?}"),
    }
}

#[test]
fn torch7_strided_view_and_offset_are_honoured() {
    // A 2x3 tensor stored transposed (strides [1, 2]) at storage offset 3 (1-based) of a 9-value
    // storage: element (i, j) = storage[2 + i + 2j].
    let mut b = write_float_tensor(&[2, 3], &[0.0; 6]);
    // Patch strides and offset in the header: after type(4) idx(4) "V 1"(4+3) class(4+17) ndim(4)
    // sizes(16) come strides(16) and offset(8).
    let strides_at = 4 + 4 + 7 + 21 + 4 + 16;
    b[strides_at..strides_at + 8].copy_from_slice(&1i64.to_le_bytes());
    b[strides_at + 8..strides_at + 16].copy_from_slice(&2i64.to_le_bytes());
    b[strides_at + 16..strides_at + 24].copy_from_slice(&3i64.to_le_bytes());
    // Replace the storage by 9 values 0..9.
    let storage_at = strides_at + 24 + 4 + 4 + 7 + 22;
    b.truncate(storage_at);
    b.extend_from_slice(&9i64.to_le_bytes());
    for v in 0..9 {
        b.extend_from_slice(&(v as f32).to_le_bytes());
    }
    let t = parse_float_tensor(&b, "strided").expect("parse");
    assert_eq!(t.shape, vec![2, 3]);
    assert_eq!(t.data, vec![2.0, 4.0, 6.0, 3.0, 5.0, 7.0]);
    // A view that runs past the storage is an error, not a read out of bounds.
    b[strides_at + 16..strides_at + 24].copy_from_slice(&5i64.to_le_bytes());
    let msg = parse_float_tensor(&b, "strided")
        .expect_err("oob")
        .to_string();
    assert!(
        msg.contains("strided") && msg.contains("exceeds storage"),
        "{msg}"
    );
}

#[test]
fn forward_is_identical_for_one_and_two_threads_and_handles_odd_sizes() {
    let net = SpyNet::<f32>::random(3, 5);
    let (h, w) = (13, 18);
    let img1: Vec<f32> = (0..3 * h * w)
        .map(|i| ((i * 7919) % 101) as f32 / 100.0)
        .collect();
    let img2: Vec<f32> = (0..3 * h * w)
        .map(|i| ((i * 104729) % 97) as f32 / 96.0)
        .collect();
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("pool");
        pool.install(|| {
            let tape = net.forward(&img1, &img2, h, w).expect("forward");
            let g: Vec<f32> = tape.flow.iter().map(|v| 0.5 - v).collect();
            let (d1, d2) = net.backward(&tape, &g, None).expect("backward");
            (tape.flow.clone(), d1, d2)
        })
    };
    let a = run(1);
    assert_eq!(a.0.len(), 2 * h * w);
    assert_eq!(a.1.len(), 3 * h * w);
    assert!(a.0.iter().chain(&a.1).chain(&a.2).all(|v| v.is_finite()));
    assert_eq!(a, run(2));
}
