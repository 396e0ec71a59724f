//! The scene format (versions 1, 2 and 3): the on-disk dataset layout (`scene.json` + images, masks,
//! flows, events) written by `synth` and read, with validation, by `train`.
//!
//! A scene is a directory holding `scene.json` and the files it names by relative path
//! (forward slashes, no `..`): blurred input images, optional sharp references, optional human
//! masks, optional flow fields to the next frame (`.flo`, with an optional validity mask), optional
//! raw events (`.npz`); version 2 adds a camera pose per frame (a moving camera), version 3 several
//! people (a stable id, a shape and a pose per frame each, and an image of which person each pixel
//! shows). The full specification is `docs/FORMATS.md`, section "Scene format (versions 1, 2 and
//! 3)".
//!
//! [`load`] validates everything (JSON structure, value ranges, time order, every referenced file's
//! existence, size and pixel format) and reports *every* problem with its JSON path or file path,
//! never stopping at the first one; [`Scene::write`] writes `scene.json` after the same checks.
//! [`image_io`] owns the on-disk pixel encoding so writer and reader can never disagree.
//! [`camera_files`] reads a lone camera (the project's camera JSON, a `scene.json`'s camera, INRIA
//! 3DGS `cameras.json`) into the same [`Camera`].
//!
//! This crate is generic: it knows nothing of the method, of training or of how a scene was made.

pub mod camera_files;
pub mod colmap;
pub mod error;
pub mod image_io;
pub mod types;
pub mod validate;

pub use error::{Problem, Result, SceneError};
pub use image_io::{
    read_mask, read_person_ids, read_rgb, write_mask, write_person_ids, write_rgb, Rgb,
};
pub use types::{
    camera_json, BodySpec, Camera, Distortion, FlowKind, FlowRef, Frame, ImageEncoding, PersonPose,
    PersonSpec, RawEventsFormat, Scene, Split, Transfer, FORMAT_VERSION,
    FORMAT_VERSION_MOVING_CAMERA, FORMAT_VERSION_PEOPLE, NUM_JOINTS, SCENE_FILE,
};
pub use validate::{load, validate_dir};
