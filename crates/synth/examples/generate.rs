//! Minimal driver for timing the generator without the xtask (which pulls in every crate):
//! `cargo run --release -p synth --example generate -- OUT [tiny|default|paper] [slow|medium|fast] [cm|nocm] [FRAMES]`.

use std::time::Instant;

use synth::{Preset, Speed, SynthConfig};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let out = args.get(1).ok_or("usage: generate OUT [preset] [speed]")?;
    let preset = match args.get(2).map(String::as_str) {
        Some("tiny") => Preset::Tiny,
        Some("paper") => Preset::Paper,
        _ => Preset::Default,
    };
    let mut cfg = SynthConfig::preset(preset);
    match args.get(3).map(String::as_str) {
        Some("slow") => cfg.speed = Speed::Slow,
        Some("medium") => cfg.speed = Speed::Medium,
        Some("fast") | None => cfg.speed = Speed::Fast,
        Some(other) => return Err(format!("unknown speed {other}").into()),
    }
    if args.get(4).map(String::as_str) == Some("nocm") {
        cfg.event_flow = false;
    }
    if let Some(f) = args.get(5) {
        cfg.frames = f.parse()?;
    }
    std::fs::create_dir_all(out)?;
    let start = Instant::now();
    let stats = synth::generate(&cfg, std::path::Path::new(out), &mut |_, _| {})?;
    println!("{:.1} s", start.elapsed().as_secs_f64());
    println!("{}", serde_json::to_string_pretty(&stats)?);
    Ok(())
}
