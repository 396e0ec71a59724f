//! The realised pose-error figures of the benchmark's motion without rendering anything (the
//! numbers `synth` writes to `stats.json`, key `pose_error`), per seed and their mean: how the
//! `realistic` preset's figures were set against published fitter errors (`synth::PoseError`).
//!
//! `cargo run -p synth --example pose_error -- [JOINT_DEG ROOT_DEG ROOT_CM [FRAMES [SEEDS]]]`
//! (defaults: the `realistic` preset's figures, the default benchmark's 100 frames, seeds 0..10).

use synth::body::DressedBody;
use synth::generate::benchmark_motion;
use synth::{FramePose, PoseError, PoseErrorStats, Preset, SynthConfig};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut cfg = SynthConfig::preset(Preset::Realistic);
    if args.len() >= 3 {
        cfg.pose_error = PoseError {
            joint_rms_deg: args[0].parse()?,
            root_orient_rms_deg: args[1].parse()?,
            root_transl_rms_cm: args[2].parse()?,
        };
    }
    if let Some(f) = args.get(3) {
        cfg.frames = f.parse()?;
    }
    let seeds: u64 = args.get(4).map_or(Ok(10), |s| s.parse())?;
    cfg.validate()?;
    let model = smpl_deform::BodyRef::parse(&cfg.body)?.load()?;
    let body = DressedBody::new(model, vec![0.0; 10])?;
    let joints_rest = body
        .model
        .rest_joints(&body.model.shaped_vertices(&body.betas)?);
    println!(
        "{:>4} {:>9} {:>9} {:>9} {:>9} {:>8} {:>9} {:>9}",
        "seed", "joint°", "root°", "root cm", "MPJPE", "PA-MPJPE", "MPJAE°", "accel0"
    );
    let mut all: Vec<PoseErrorStats> = Vec::new();
    for seed in 0..seeds {
        cfg.seed = seed;
        let motion = benchmark_motion(&cfg, &body)?;
        let truth: Vec<FramePose> = (0..cfg.frames)
            .map(|k| {
                let t = f64::from(k) / cfg.fps;
                let (pose, transl) = motion.at(t);
                FramePose {
                    index: k,
                    time_s: t,
                    pose: pose.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
                    transl,
                }
            })
            .collect();
        // A camera about where the benchmark's stands; it only orients the translation error,
        // which none of the figures below but its length depends on.
        let centre = [
            0.2 * f64::from(cfg.camera_distance),
            f64::from(cfg.camera_height),
            f64::from(cfg.camera_distance),
        ];
        let est = synth::pose_error::perturb(&truth, &cfg.pose_error, seed, centre, joints_rest[0]);
        let s = synth::pose_metrics::measure(&truth, &est, &joints_rest, &body.model.parents);
        print_row(&seed.to_string(), &s);
        all.push(s);
    }
    let n = all.len().max(1) as f64;
    let mean = |f: fn(&PoseErrorStats) -> f64| all.iter().map(f).sum::<f64>() / n;
    let avg = PoseErrorStats {
        joint_mean_deg: mean(|s| s.joint_mean_deg),
        root_orient_mean_deg: mean(|s| s.root_orient_mean_deg),
        root_transl_mean_cm: mean(|s| s.root_transl_mean_cm),
        mpjpe_mm: mean(|s| s.mpjpe_mm),
        pa_mpjpe_mm: mean(|s| s.pa_mpjpe_mm),
        mpjae_deg: mean(|s| s.mpjae_deg),
        accel_error_still_mm: mean(|s| s.accel_error_still_mm),
        ..PoseErrorStats::default()
    };
    print_row("mean", &avg);
    println!("(angles and lengths: means over joints and frames; accel0: acceleration error on a still body, mm/frame²)");
    Ok(())
}

fn print_row(label: &str, s: &PoseErrorStats) {
    println!(
        "{label:>4} {:>9.2} {:>9.2} {:>9.2} {:>9.1} {:>8.1} {:>9.1} {:>9.1}",
        s.joint_mean_deg,
        s.root_orient_mean_deg,
        s.root_transl_mean_cm,
        s.mpjpe_mm,
        s.pa_mpjpe_mm,
        s.mpjae_deg,
        s.accel_error_still_mm
    );
}
