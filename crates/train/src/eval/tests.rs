//! Unit tests of the evaluation figures.

use super::*;

#[test]
fn psnr_and_iou_basics() {
    assert!((psnr(&[0.5; 4], &[0.6; 4]) - 20.0).abs() < 1e-5);
    assert_eq!(
        mask_iou(&[1.0, 1.0, 0.0, 0.0], &[1.0, 0.0, 1.0, 0.0]),
        1.0 / 3.0
    );
    assert_eq!(mask_iou(&[0.0; 3], &[0.0; 3]), 1.0);
}

/// `box_psnr` scores the box's pixels of every plane and nothing outside it: an error outside
/// the box does not count, one inside counts over the box's 3 × 2 × 2 values.
#[test]
fn box_psnr_reads_only_the_box() {
    let (w, h) = (5, 4);
    let a = vec![0.5f32; 3 * w * h];
    let mut b = a.clone();
    b[w * h] = 0.9; // plane 1, pixel (0, 0): outside the box (1, 1)–(3, 3)
    b[2 * w * h + 2 * w + 2] = 0.6; // plane 2, pixel (2, 2): inside
    let expected = -10.0 * (0.1f64.powi(2) / 12.0).log10();
    assert!((box_psnr(&a, &b, w, h, (1, 1, 3, 3)) - expected).abs() < 1e-4);
}

#[test]
fn bbox_psnr_and_iou_on_a_toy_frame() {
    let (w, h) = (16, 12);
    let reference: Vec<f32> = (0..3 * w * h).map(|i| (i % 7) as f32 / 7.0).collect();
    let mut render = reference.clone();
    let mut mask = vec![false; w * h];
    for y in 3..6 {
        for x in 4..9 {
            mask[y * w + x] = true;
            render[y * w + x] += 0.1; // error only inside the box, channel 0
        }
    }
    let prob: Vec<f32> = mask.iter().map(|&m| if m { 0.9 } else { 0.1 }).collect();
    let f = EvalFrame {
        width: w,
        height: h,
        render: &render,
        reference: &reference,
        blurred: &reference,
        mask: Some(&mask),
        human_probability: &prob,
    };
    assert_eq!(mask_bbox(&mask, w, h), Some((4, 3, 9, 6)));
    let m = evaluate_frame(&f, None).expect("no LPIPS, no error");
    assert_eq!(m.mask_iou, 1.0);
    // Box: 15 of 45 values off by 0.1 → MSE 1/300 → 24.77 dB; full frame: 15 of 576.
    assert!(
        (m.psnr_human_box - 10.0 * 300f64.log10()).abs() < 1e-3,
        "{m:?}"
    );
    assert!((m.psnr_full - 10.0 * (576.0f64 / 15.0 / 0.01).log10()).abs() < 1e-3);
    assert!(m.blurred_psnr_full.is_infinite());
    // The blurred input is the reference here: SSIM 1 over the frame and the box.
    assert!((m.blurred_ssim_full - 1.0).abs() < 1e-6, "{m:?}");
    assert!((m.blurred_ssim_human_box - 1.0).abs() < 1e-6, "{m:?}");
    assert!(m.ssim_human_box < 1.0);
    assert!(m.lpips_full.is_nan() && m.blurred_lpips_human_box.is_nan());
    // Outside the box nothing is wrong; one value off by 0.2 there: MSE 0.04 / 531 values.
    assert!(m.psnr_outside_box.is_infinite(), "{m:?}");
    let mut off_outside = render.clone();
    off_outside[0] += 0.2;
    let m2 = evaluate_frame(
        &EvalFrame {
            render: &off_outside,
            ..f
        },
        None,
    )
    .expect("no LPIPS, no error");
    assert!(
        (m2.psnr_outside_box - 10.0 * (531.0f64 / 0.04).log10()).abs() < 1e-3,
        "{m2:?}"
    );
    assert_eq!(m2.psnr_human_box, m.psnr_human_box);
    let (sw, sh, strip) = comparison_strip(&f);
    assert_eq!((sw, sh, strip.len()), (4 * 16 + 6, 12, 3 * 12 * 70));
}

#[test]
fn empty_masks_give_nan_box_figures_that_the_mean_skips() {
    let a = FrameMetrics {
        psnr_full: 20.0,
        ssim_full: 0.5,
        psnr_human_box: f64::NAN,
        ssim_human_box: f64::NAN,
        mask_iou: 1.0,
        blurred_psnr_full: 18.0,
        blurred_psnr_human_box: f64::NAN,
        blurred_ssim_full: 0.4,
        blurred_ssim_human_box: f64::NAN,
        lpips_full: 0.1,
        lpips_human_box: f64::NAN,
        blurred_lpips_full: 0.2,
        blurred_lpips_human_box: f64::NAN,
        psnr_outside_box: f64::NAN,
        blurred_psnr_outside_box: f64::NAN,
    };
    let b = FrameMetrics {
        psnr_human_box: 10.0,
        ..a
    };
    let m = mean_metrics(&[a, b]);
    assert_eq!(m.psnr_human_box, 10.0);
    assert_eq!(m.lpips_full, 0.1);
    assert!(m.lpips_human_box.is_nan());
    assert_eq!(m.psnr_full, 20.0);
}

#[test]
fn small_boxes_grow_to_the_network_minimum_inside_the_frame() {
    assert_eq!(
        grown_box((10, 5, 50, 60), 64, 64, 31),
        Some((10, 5, 50, 60))
    );
    // 10 px wide at x 20..30: 21 px more, 10 on the left.
    assert_eq!(
        grown_box((20, 0, 30, 40), 64, 64, 31),
        Some((10, 0, 41, 40))
    );
    // Against the left and right edges.
    assert_eq!(grown_box((2, 0, 6, 40), 64, 64, 31), Some((0, 0, 31, 40)));
    assert_eq!(
        grown_box((60, 0, 64, 40), 64, 64, 31),
        Some((33, 0, 64, 40))
    );
    assert_eq!(grown_box((0, 0, 5, 5), 30, 64, 31), None);
}

#[test]
fn lpips_figures_are_zero_for_a_perfect_render_and_cover_a_small_box() {
    let (w, h) = (48, 40);
    let reference: Vec<f32> = (0..3 * w * h)
        .map(|i| 0.5 + 0.4 * ((i % 13) as f32 / 13.0 - 0.5))
        .collect();
    let blurred: Vec<f32> = reference.iter().map(|v| v * 0.9).collect();
    let mut mask = vec![false; w * h];
    mask[10 * w + 20] = true; // a one-pixel human
    let prob = vec![0.0; w * h];
    let net = Lpips::<f32>::random([4, 4, 4, 4, 4], 1);
    let f = EvalFrame {
        width: w,
        height: h,
        render: &reference,
        reference: &reference,
        blurred: &blurred,
        mask: Some(&mask),
        human_probability: &prob,
    };
    let m = evaluate_frame(&f, Some(&net)).expect("sizes");
    assert_eq!((m.lpips_full, m.lpips_human_box), (0.0, 0.0));
    assert!(
        m.blurred_lpips_full > 0.0 && m.blurred_lpips_human_box > 0.0,
        "{m:?}"
    );
}
