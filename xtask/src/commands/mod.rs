//! One module per `cargo xtask` command, named after the command (`render-pose` is
//! `render_pose`); a command with sub-commands is a folder (`bench`, `fuzz`, `import`).

pub mod ablate;
pub mod bench;
pub mod body;
pub mod body_convert;
pub mod deblur_edi;
pub mod eval;
pub mod events;
pub mod flow;
pub mod flow_import_t7;
pub mod fuzz;
pub mod import;
pub mod lpips;
pub mod ply_info;
pub mod reconstruct;
pub mod render;
pub mod render_pose;
pub mod synth;
pub mod train_flow;
