//! `cargo xtask fuzz --target T --inputs N [--seed S]`: feed a parser of user files N mutated
//! inputs and fail on any panic, abort, hang or over-allocation.
//!
//! Inputs are made by structure-aware mutation of small seed files that the project's own writers
//! produce ([`targets`]): bit flips, interesting bytes and integers (0, −1, 2³¹, 2⁶⁴−1 …) written
//! over header fields, NaN / ±Inf / huge floats, digit runs of text formats replaced by huge or
//! negative numbers, truncations, deleted, duplicated and spliced chunks. Input `k` is a pure
//! function of `(seed, k)`, so a finding is reproduced by its index.
//!
//! The inputs run in a worker process (this executable, `fuzz --worker-from`), started under
//! `ulimit -v` (the memory limit) so that an allocation sized by an unchecked header fails instead
//! of taking the machine. The worker writes each input to a file (parsers read files, as users'
//! do), announces its index on stdout, then parses it, catching panics. The parent watches: a
//! worker that dies (an abort, a failed allocation) or goes quiet for longer than the time limit
//! (a hang) is killed, its input copied to `target/fuzz/T/crash-K.EXT`, and a new worker carries on
//! from the next input. A worker also reports an input whose parse took longer than the time limit
//! or grew the process's peak virtual memory by more than the allocation limit. Any finding fails
//! the command.

mod mutate;
mod targets;

use anyhow::{bail, Context, Result};
use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

pub use targets::TARGETS;

/// Arguments of `fuzz`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The parser to fuzz (`all` for every one): ply, camera, scene, npz, motion, safetensors,
    /// flo, flow-png, aedat4, aedat4-frames, zju-model, events-raw, dat, events-text, t7.
    #[arg(long)]
    pub target: String,
    /// Number of inputs per target.
    #[arg(long, default_value_t = 100_000)]
    pub inputs: u64,
    /// Seed of the mutations (input `k` of a seed is always the same bytes).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Time limit of one input (milliseconds); longer is reported as a hang.
    #[arg(long, default_value_t = 2_000)]
    pub time_limit_ms: u64,
    /// Virtual-memory limit of the worker process (MiB), enforced with `ulimit -v`.
    #[arg(long, default_value_t = 8_192)]
    pub memory_limit_mib: u64,
    /// Largest growth of the worker's peak virtual memory one input may cause (MiB).
    #[arg(long, default_value_t = 1_024)]
    pub allocation_limit_mib: u64,
    /// Internal: run as a worker from this input index.
    #[arg(long, hide = true)]
    pub worker_from: Option<u64>,
    /// Internal: the worker's scratch directory.
    #[arg(long, hide = true)]
    pub worker_dir: Option<PathBuf>,
}

/// What one target's run found.
#[derive(Debug, Default)]
pub struct Outcome {
    /// Inputs parsed.
    pub inputs: u64,
    /// Inputs the parser accepted (the rest were refused with an error, as they should mostly be).
    pub accepted: u64,
    /// One line per finding (panic, abort, hang, slow input, over-allocation) with its file.
    pub findings: Vec<String>,
    /// Wall time (s).
    pub seconds: f64,
}

/// Runs `fuzz`.
pub fn run(args: Args) -> Result<()> {
    if let Some(from) = args.worker_from {
        return worker(&args, from);
    }
    let names: Vec<&str> = if args.target == "all" {
        TARGETS.iter().map(|t| t.name).collect()
    } else {
        vec![targets::find(&args.target)?.name]
    };
    let mut failed = false;
    for name in names {
        let o = fuzz_target(name, args.inputs, args.seed, &args)?;
        println!(
            "{name}: {} inputs in {:.1} s ({:.0}/s), {} accepted, {} findings",
            o.inputs,
            o.seconds,
            o.inputs as f64 / o.seconds.max(1e-9),
            o.accepted,
            o.findings.len()
        );
        for f in &o.findings {
            println!("  {f}");
        }
        failed |= !o.findings.is_empty();
    }
    if failed {
        bail!("fuzzing found inputs that crash, hang or over-allocate (files under target/fuzz/)");
    }
    Ok(())
}

/// Lines a worker writes to stdout.
enum Report {
    /// About to parse input `k`.
    Start(u64),
    /// Input `k` parsed (accepted or refused).
    Done(u64, bool),
    /// A finding about input `k`.
    Finding(u64, String),
}

fn parse_report(line: &str) -> Option<Report> {
    let mut it = line.splitn(3, ' ');
    let kind = it.next()?;
    let k: u64 = it.next()?.parse().ok()?;
    Some(match kind {
        "start" => Report::Start(k),
        "ok" => Report::Done(k, true),
        "err" => Report::Done(k, false),
        "finding" => Report::Finding(k, it.next().unwrap_or("").to_string()),
        _ => return None,
    })
}

/// Fuzzes one target with inputs `0..inputs` in worker processes; see the module docs.
pub fn fuzz_target(name: &str, inputs: u64, seed: u64, args: &Args) -> Result<Outcome> {
    let target = targets::find(name)?;
    let out_dir = crate::common::target_dir().join("fuzz").join(name);
    std::fs::create_dir_all(&out_dir).with_context(|| format!("creating {}", out_dir.display()))?;
    let scratch = tempfile::Builder::new()
        .prefix("xtask-fuzz-")
        .tempdir_in(scratch_root())
        .context("creating the fuzz scratch directory")?;
    let exe = std::env::current_exe().context("locating the xtask executable")?;
    let started = Instant::now();
    let bar = crate::common::progress_bar(inputs, &format!("fuzz {name}"))?;
    let mut outcome = Outcome::default();
    let mut next = 0u64;
    while next < inputs {
        let mut child = Command::new("sh")
            .arg("-c")
            .arg("ulimit -v \"$1\" && shift && exec \"$@\"")
            .arg("sh")
            .arg((args.memory_limit_mib * 1024).to_string())
            .arg(&exe)
            .args(["fuzz", "--target", name, "--inputs"])
            .arg(inputs.to_string())
            .arg("--seed")
            .arg(seed.to_string())
            .arg("--time-limit-ms")
            .arg(args.time_limit_ms.to_string())
            .arg("--allocation-limit-mib")
            .arg(args.allocation_limit_mib.to_string())
            .arg("--worker-from")
            .arg(next.to_string())
            .arg("--worker-dir")
            .arg(scratch.path())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .context("starting a fuzz worker")?;
        let stdout = child.stdout.take().context("the worker's stdout")?;
        let (tx, rx) = mpsc::channel();
        let reader = std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines().map_while(Result::ok) {
                if tx.send(line).is_err() {
                    break;
                }
            }
        });
        let mut current: Option<u64> = None;
        let limit = Duration::from_millis(args.time_limit_ms.saturating_mul(5).max(1_000));
        let ended_cleanly = loop {
            match rx.recv_timeout(limit) {
                Ok(line) => match parse_report(&line) {
                    Some(Report::Start(k)) => current = Some(k),
                    Some(Report::Done(k, accepted)) => {
                        outcome.inputs += 1;
                        outcome.accepted += u64::from(accepted);
                        next = k + 1;
                        current = None;
                        if k % 256 == 0 {
                            bar.set_position(next);
                        }
                    }
                    Some(Report::Finding(k, what)) => {
                        let file = save_input(target, seed, k, &out_dir, "crash")?;
                        outcome
                            .findings
                            .push(format!("input {k}: {what} ({})", file.display()));
                    }
                    None => {}
                },
                Err(mpsc::RecvTimeoutError::Disconnected) => break true,
                Err(mpsc::RecvTimeoutError::Timeout) => {
                    let _ = child.kill();
                    break false;
                }
            }
        };
        let status = child.wait().context("waiting for a fuzz worker")?;
        let _ = reader.join();
        if let Some(k) = current {
            // The worker died or hung inside input k.
            let what = if ended_cleanly {
                format!("the worker died ({status}): an abort or a failed allocation")
            } else {
                format!("no answer within {} ms: a hang", limit.as_millis())
            };
            let file = save_input(target, seed, k, &out_dir, "crash")?;
            outcome
                .findings
                .push(format!("input {k}: {what} ({})", file.display()));
            outcome.inputs += 1;
            next = k + 1;
        } else if !status.success() && next < inputs {
            bail!("a fuzz worker failed outside any input ({status})");
        }
    }
    bar.finish_and_clear();
    outcome.seconds = started.elapsed().as_secs_f64();
    Ok(outcome)
}

/// Where inputs are written: memory-backed `/dev/shm` when there is one.
fn scratch_root() -> PathBuf {
    let shm = Path::new("/dev/shm");
    if shm.is_dir() {
        shm.to_path_buf()
    } else {
        std::env::temp_dir()
    }
}

/// Writes input `k` to `out_dir/<prefix>-k.<ext>` and returns the path.
fn save_input(
    target: &targets::Target,
    seed: u64,
    k: u64,
    out_dir: &Path,
    prefix: &str,
) -> Result<PathBuf> {
    let seeds = (target.seeds)()?;
    let bytes = mutate::input(&seeds, seed, k);
    let path = out_dir.join(format!("{prefix}-{k}.{}", target.extension));
    std::fs::write(&path, bytes).with_context(|| format!("writing {}", path.display()))?;
    Ok(crate::common::shown(&path))
}

/// The process's peak virtual memory (bytes), from `/proc/self/status` (`VmPeak`); 0 elsewhere.
fn peak_virtual_bytes() -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmPeak:"))
                .and_then(|l| l.split_whitespace().nth(1))
                .and_then(|kb| kb.parse::<u64>().ok())
        })
        .map_or(0, |kb| kb * 1024)
}

/// The worker: parses inputs `from..inputs` and reports each on stdout (see [`Report`]).
fn worker(args: &Args, from: u64) -> Result<()> {
    let target = targets::find(&args.target)?;
    let dir = args
        .worker_dir
        .clone()
        .context("--worker-from needs --worker-dir")?;
    let workspace = tempfile::Builder::new()
        .prefix("w-")
        .tempdir_in(&dir)
        .context("creating the worker's directory")?;
    let prepared = (target.prepare)(workspace.path())?;
    let seeds = (target.seeds)()?;
    std::panic::set_hook(Box::new(|_| {}));
    let stdout = std::io::stdout();
    let mut out = stdout.lock();
    let time_limit = Duration::from_millis(args.time_limit_ms);
    let allocation_limit = args.allocation_limit_mib * 1024 * 1024;
    let mut peak = peak_virtual_bytes();
    for k in from..args.inputs {
        let bytes = mutate::input(&seeds, args.seed, k);
        std::fs::write(&prepared.input, &bytes)
            .with_context(|| format!("writing {}", prepared.input.display()))?;
        writeln!(out, "start {k}")?;
        out.flush()?;
        let t0 = Instant::now();
        let result = std::panic::catch_unwind(|| (target.parse)(&prepared));
        let took = t0.elapsed();
        match result {
            Ok(accepted) => {
                let now = peak_virtual_bytes();
                if now > peak + allocation_limit {
                    writeln!(
                        out,
                        "finding {k} grew peak virtual memory by {} MiB",
                        (now - peak) >> 20
                    )?;
                }
                peak = peak.max(now);
                if took > time_limit {
                    writeln!(out, "finding {k} took {} ms", took.as_millis())?;
                }
                writeln!(out, "{} {k}", if accepted { "ok" } else { "err" })?;
            }
            Err(panic) => {
                let message = panic
                    .downcast_ref::<String>()
                    .cloned()
                    .or_else(|| panic.downcast_ref::<&str>().map(|s| (*s).to_string()))
                    .unwrap_or_default()
                    .replace('\n', " ");
                writeln!(out, "finding {k} panicked: {message}")?;
                writeln!(out, "err {k}")?;
            }
        }
    }
    out.flush()?;
    Ok(())
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn reports_round_trip() {
        assert!(matches!(parse_report("start 12"), Some(Report::Start(12))));
        assert!(matches!(parse_report("ok 3"), Some(Report::Done(3, true))));
        assert!(matches!(
            parse_report("err 4"),
            Some(Report::Done(4, false))
        ));
        match parse_report("finding 7 panicked: index out of bounds") {
            Some(Report::Finding(7, what)) => assert_eq!(what, "panicked: index out of bounds"),
            _ => panic!("not a finding"),
        }
        assert!(parse_report("noise").is_none());
    }
}
