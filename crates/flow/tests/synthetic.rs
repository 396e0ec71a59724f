//! The procedural pair generator: deterministic, and its ground-truth flow is consistent with its images.

use flow::synthetic::{average_epe, generate_pair, PairConfig};

#[test]
fn pairs_are_deterministic_and_distinct() {
    let cfg = PairConfig::default();
    let a = generate_pair(7, 3, &cfg);
    let b = generate_pair(7, 3, &cfg);
    let c = generate_pair(7, 4, &cfg);
    assert_eq!(a.img1, b.img1);
    assert_eq!(a.flow, b.flow);
    assert_ne!(a.img1, c.img1);
    assert!(
        average_epe(&vec![0.0; a.flow.len()], &a.flow) > 0.5,
        "pairs should move"
    );
}

#[test]
fn warping_frame_two_by_the_true_flow_reproduces_frame_one() {
    // Photometric check of the ground truth: img2 sampled at x + F(x) ≈ img1(x) except at occlusions
    // and where the brightness jitter applies; the median error must be far below that of zero flow.
    let cfg = PairConfig::default();
    let mut ratios = Vec::new();
    for k in 0..4 {
        let p = generate_pair(11, k, &cfg);
        let (h, w) = (p.height, p.width);
        let mut warped = vec![0.0f32; p.img2.len()];
        nn::warp_forward(1, 3, h, w, &p.img2, &p.flow, &mut warped).expect("warp");
        let med = |img: &[f32]| {
            let mut e: Vec<f32> = (0..h * w)
                .map(|i| {
                    (0..3)
                        .map(|c| (img[c * h * w + i] - p.img1[c * h * w + i]).abs())
                        .sum()
                })
                .collect();
            e.sort_by(f32::total_cmp);
            e[e.len() / 2]
        };
        ratios.push(med(&warped) / med(&p.img2).max(1e-6));
    }
    let mean = ratios.iter().sum::<f32>() / ratios.len() as f32;
    assert!(
        mean < 0.6,
        "warped/unwarped median photometric error ratios {ratios:?}"
    );
}
