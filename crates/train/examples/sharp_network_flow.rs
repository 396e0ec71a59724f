//! Experiment: flow-loss targets made by the frozen flow network itself on the sharp reference
//! frames — the paper's ZJU-MoCap-Blur protocol ("the target optical flow is inferred from the
//! sharp ground-truth images using the pretrained RAFT model"), with the project's network in
//! RAFT's place. With such targets the sharp frames are an exact minimum of the flow loss (zero
//! loss), which the generator's exact flow is not for a network that errs; comparing the two
//! separates the harm of the network's errors from the harm of the loss itself.
//!
//! `sharp_network_flow DIR [WEIGHTS]` (default: the shipped weights) **modifies the scene in DIR**
//! (work on a copy): for every frame with a sharp reference and a next frame, it resizes both sharp
//! frames to 1/4 exactly as the flow loss resizes renders, runs the network, scales the flow back
//! up to the camera size (bilinear, `align_corners=True`, vectors × 4 — the loss's own resize back
//! to 1/4 then returns the prediction exactly, up to rounding), writes it to
//! `DIR/flow_network/NNNNNN.flo` and names it in `scene.json` as the frame's `external` flow
//! (replacing any). Then `cargo xtask reconstruct --data DIR --flow-loss on --flow-source file`
//! trains with it. Figures: docs/BENCHMARKS.md, flow loss; details in docs/notes/benchmarks-history.md, "Flow targets from the network on the sharp frames".

use nn::resize_bilinear_forward;
use std::path::{Path, PathBuf};

/// The flow loss's resolution scale (paper §4.4, r = 0.25).
const SCALE: usize = 4;
/// Sub-directory of the scene the flow files go to.
const SUBDIR: &str = "flow_network";

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let dir = PathBuf::from(
        args.first()
            .ok_or("usage: sharp_network_flow DIR [WEIGHTS]  (modifies DIR)")?,
    );
    let weights = args.get(1).map_or_else(
        || {
            Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("../../data-fixtures/flow/spynet-synthetic.safetensors")
        },
        PathBuf::from,
    );
    let net = flow::load_safetensors(&weights)?;
    let data = train::data::load_dataset(&dir)?;
    let mut scene = data.scene.clone();
    let (w, h) = (data.camera.width as usize, data.camera.height as usize);
    let (wo, ho) = (w / SCALE, h / SCALE);
    std::fs::create_dir_all(dir.join(SUBDIR))?;
    let mut written = 0;
    for (k, pair) in data.frames.windows(2).enumerate() {
        let (Some(sharp_a), Some(sharp_b)) = (&pair[0].sharp, &pair[1].sharp) else {
            continue;
        };
        let mut small = [vec![0.0f32; 3 * ho * wo], vec![0.0f32; 3 * ho * wo]];
        resize_bilinear_forward(3, h, w, sharp_a, ho, wo, true, &mut small[0])?;
        resize_bilinear_forward(3, h, w, sharp_b, ho, wo, true, &mut small[1])?;
        let predicted = net.forward(&small[0], &small[1], ho, wo)?.flow;
        let mut full = vec![0.0f32; 2 * h * w];
        resize_bilinear_forward(2, ho, wo, &predicted, h, w, true, &mut full)?;
        let (sx, sy) = (w as f32 / wo as f32, h as f32 / ho as f32);
        let (u, v) = full.split_at_mut(h * w);
        u.iter_mut().for_each(|x| *x *= sx);
        v.iter_mut().for_each(|x| *x *= sy);
        let rel = format!("{SUBDIR}/{:06}.flo", pair[0].index);
        events::write_flo(dir.join(&rel), &events::Flow::from_planar(w, h, full)?)?;
        let refs = &mut scene.frames[k].flow_to_next;
        refs.retain(|r| r.kind != scene::FlowKind::External);
        refs.push(scene::FlowRef {
            kind: scene::FlowKind::External,
            path: rel,
            valid_mask: None,
        });
        written += 1;
    }
    scene.write(&dir)?;
    println!(
        "{written} flow files in {}, named in scene.json as `external` flow",
        dir.join(SUBDIR).display()
    );
    Ok(())
}
