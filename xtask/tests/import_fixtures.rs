//! Regenerates the committed importer fixtures in `data-fixtures/import/` from the tiny benchmark
//! fixture: `cargo test -p xtask --test import_fixtures -- --ignored`. The import tests read the
//! committed files; this test only writes them.
#![allow(clippy::unwrap_used)]

mod common;

#[test]
#[ignore = "writes data-fixtures/import/; run by hand to regenerate the fixtures"]
fn write_the_import_fixtures() {
    let root = common::import_fixtures();
    // import frames: the tiny fixture's frames (data-fixtures/tiny/sharp), its poses and camera.
    let frames = root.join("frames");
    std::fs::create_dir_all(&frames).unwrap();
    common::write_poses(&frames.join("poses.json"), 15);
    let tiny = common::tiny();
    let camera = serde_json::json!({
        "width": tiny.camera.width, "height": tiny.camera.height,
        "fx": tiny.camera.fx, "fy": tiny.camera.fy, "cx": tiny.camera.cx, "cy": tiny.camera.cy,
        "world_to_camera": tiny.camera.world_to_camera,
    });
    std::fs::write(
        frames.join("camera.json"),
        serde_json::to_string_pretty(&camera).unwrap() + "\n",
    )
    .unwrap();
    // import aedat4: a DAVIS-like recording (grey frames with their own exposures, the events).
    let davis = root.join("davis");
    std::fs::create_dir_all(&davis).unwrap();
    common::write_recording(&davis, 15);
    // import zju: one view of a ZJU-MoCap-layout subject with a distorting lens.
    let zju = root.join("zju/CoreView_tiny");
    let _ = std::fs::remove_dir_all(&zju);
    common::write_subject(&zju, [-0.3, 0.1, 0.0, 0.0, 0.0]);
}
