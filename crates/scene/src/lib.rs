//! Scene format v1: the on-disk dataset layout (`scene.json` + images, masks, flows, events) written by `synth` and read, with validation, by `train`.
