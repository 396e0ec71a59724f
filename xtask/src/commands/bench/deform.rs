//! `cargo xtask bench deform`: time posing N human Gaussians (non-rigid net + skinning field + LBS),
//! forward and forward + backward, on the built-in body; one JSON line per repetition (with
//! `steal_pct`, the hypervisor's steal time during it; null off Linux).

use std::time::Instant;

use anyhow::{Context, Result};
use smpl_deform::deform_net::{
    deform_gaussians, deform_gaussians_backward, pose_code, CanonicalGaussians, NonRigidNet,
    SkinningField, NR_FEATURE_DIM,
};
use smpl_deform::{sample_surface, BodyModel, CanonicalBody, SmplParams};

/// Arguments of `cargo xtask bench deform`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Number of Gaussians.
    #[arg(long, default_value_t = 50_000)]
    pub n: usize,
    /// Hidden width of both MLPs (128 in 3DGS-Avatar, 64 the project's default).
    #[arg(long, default_value_t = smpl_deform::deform_net::DEFAULT_HIDDEN)]
    pub hidden: usize,
    /// Timed repetitions (after one warm-up).
    #[arg(long, default_value_t = 3)]
    pub reps: usize,
    /// Seed of the samples and network initialisation.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
}

/// Runs the benchmark.
pub fn run(args: Args) -> Result<()> {
    let body = BodyModel::builtin_makehuman().context("loading builtin:makehuman")?;
    let canon = CanonicalBody::new(&body, &[])?;
    let s = sample_surface(
        &canon.posed.vertices,
        &body.faces,
        &body.weights,
        args.n,
        args.seed,
    );
    let n = s.points.len();
    let log_scales = vec![[-5.0f32; 3]; n];
    let quats = vec![[1.0f32, 0.0, 0.0, 0.0]; n];
    let nonrigid = NonRigidNet::<f32>::new(&canon.posed.vertices, args.hidden, args.seed)?;
    let field = SkinningField::<f32>::new(&canon.posed.vertices, args.hidden, args.seed + 1)?;
    let mut p = SmplParams::zero();
    p.pose[3 * 18 + 1] = 1.2;
    p.pose[3 * 4] = 0.6;
    p.pose[3 * 16 + 2] = -0.4;
    let frame = body.pose(&p)?;
    let bones = canon.frame_from_canonical(&frame);
    let code = pose_code(&frame.local_rotations);
    let g = CanonicalGaussians {
        positions: &s.points,
        log_scales: &log_scales,
        quats: &quats,
    };
    let threads = std::env::var("RAYON_NUM_THREADS").unwrap_or_else(|_| "default".into());
    for rep in 0..=args.reps {
        let cpu0 = process_cpu_seconds();
        let steal = crate::steal::Meter::start();
        let t0 = Instant::now();
        let (out, cache) = deform_gaussians(&nonrigid, &field, &g, &code, &bones)?;
        let t_fwd = t0.elapsed();
        let d_pos = vec![[1.0f32; 3]; n];
        let d_s = vec![[1.0f32; 3]; n];
        let d_m = vec![[1.0f32; 9]; n];
        let d_f = vec![1.0f32; n * NR_FEATURE_DIM];
        let mut d_nr = vec![0.0f32; nonrigid.mlp.params.len()];
        let mut d_field = vec![0.0f32; field.mlp.params.len()];
        let t1 = Instant::now();
        let grad = deform_gaussians_backward(
            &nonrigid,
            &field,
            &bones,
            &cache,
            &d_pos,
            &d_s,
            &d_m,
            &d_f,
            &mut d_nr,
            &mut d_field,
        )?;
        let t_bwd = t1.elapsed();
        let cpu = match (cpu0, process_cpu_seconds()) {
            (Some(a), Some(b)) => Some((b - a) * 1e3),
            _ => None,
        };
        std::hint::black_box((&out, &grad));
        if rep > 0 {
            println!(
                "{}",
                serde_json::json!({
                    "bench": "deform",
                    "n": n,
                    "hidden": args.hidden,
                    "rayon_num_threads": threads,
                    "forward_ms": t_fwd.as_secs_f64() * 1e3,
                    "backward_ms": t_bwd.as_secs_f64() * 1e3,
                    "forward_backward_ms": (t_fwd + t_bwd).as_secs_f64() * 1e3,
                    "steal_pct": steal.percent(),
                    // User + system CPU time of the whole process over forward + backward (and the
                    // cotangent set-up), 10 ms resolution; robust to other load on a shared machine.
                    "cpu_ms": cpu,
                })
            );
        }
    }
    Ok(())
}

/// User + system CPU time of this process in seconds (all threads), from `/proc/self/stat`
/// (Linux, whose `USER_HZ` is 100; `None` elsewhere or if the file cannot be parsed). Resolution:
/// one clock tick (10 ms).
fn process_cpu_seconds() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the parenthesised command name: state is field 3, utime 14, stime 15.
    let rest = &stat[stat.rfind(')')? + 2..];
    let fields: Vec<&str> = rest.split_whitespace().collect();
    let utime: f64 = fields.get(11)?.parse().ok()?;
    let stime: f64 = fields.get(12)?.parse().ok()?;
    Some((utime + stime) / 100.0)
}
