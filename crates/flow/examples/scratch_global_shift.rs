use flow::synthetic::{generate_pair, PairConfig};
use nn::{avg_pool2x2_forward, warp_forward};
fn pool(img: &[f32], mut s: usize, times: usize) -> (Vec<f32>, usize) {
    let mut v = img.to_vec();
    for _ in 0..times {
        let mut o = vec![0.0; 3 * (s / 2) * (s / 2)];
        avg_pool2x2_forward(3, s, s, &v, &mut o).unwrap();
        v = o;
        s /= 2;
    }
    (v, s)
}
fn main() {
    let cfg = PairConfig::default();
    let times: usize = std::env::args().nth(1).map_or(3, |s| s.parse().unwrap());
    let (mut net_sum, mut zero_sum) = (0.0f64, 0.0f64);
    for k in 0..40 {
        let p = generate_pair(1_000_003, k, &cfg);
        let (a, s) = pool(&p.img1, p.width, times);
        let (b, _) = pool(&p.img2, p.width, times);
        let truth = flow::train::flow_at_level(&p.flow, p.height, p.width, times + 1, 0);
        let hw = s * s;
        let mut best = (f64::MAX, 0.0f32, 0.0f32);
        let r = 24i32;
        let step = 0.125f32 * (8.0 / s as f32).max(1.0);
        let _ = step;
        for iu in -r..=r {
            for iv in -r..=r {
                let (u, v) = (iu as f32 * 0.125, iv as f32 * 0.125);
                let mut fl = vec![u; 2 * hw];
                fl[hw..].iter_mut().for_each(|x| *x = v);
                let mut out = vec![0.0; 3 * hw];
                warp_forward(1, 3, s, s, &b, &fl, &mut out).unwrap();
                let e: f64 = out
                    .iter()
                    .zip(&a)
                    .map(|(x, y)| f64::from((x - y).abs()))
                    .sum();
                if e < best.0 {
                    best = (e, u, v);
                }
            }
        }
        let scale = f64::from(1u32 << times);
        for i in 0..hw {
            let (gx, gy) = (f64::from(truth[i]), f64::from(truth[hw + i]));
            net_sum += scale * (f64::from(best.1) - gx).hypot(f64::from(best.2) - gy);
            zero_sum += scale * gx.hypot(gy);
        }
    }
    println!(
        "global shift at level size (pooled {times}x): ratio {:.3}",
        net_sum / zero_sum
    );
}
