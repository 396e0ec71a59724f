//! `cargo xtask events info|convert|voxelize|simulate|flow`: thin wrappers over the `events` crate
//! (argument parsing, progress bars, file orchestration). Algorithms live in `events`.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use events::io::prophesee::RawEncoding;
use events::io::{EventReader, ReadOptions};
use events::{EventStream, SensorSize};
use indicatif::ProgressBar;

/// Arguments of `events`.
#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(subcommand)]
    command: Sub,
}

#[derive(clap::Subcommand, Debug)]
enum Sub {
    /// Print one JSON line {"format","events","positive","t_first_us","t_last_us","width","height",
    /// "skipped_words"}.
    Info {
        /// Event file (.txt/.csv, .npz, .aedat4, .raw, .dat).
        file: PathBuf,
        #[command(flatten)]
        read: ReadArgs,
    },
    /// Convert between event formats (by extension); validates order and sensor bounds.
    Convert {
        /// Input event file.
        input: PathBuf,
        /// Output event file.
        output: PathBuf,
        #[command(flatten)]
        read: ReadArgs,
        /// Sort by timestamp instead of failing on non-monotonic input.
        #[arg(long)]
        sort: bool,
        /// Sensor size WxH to record in the output (formats that store it: AEDAT 4, EVT, DAT,
        /// text header), replacing the input's; every event must lie inside it. Default: the
        /// input's, else the bounding box of the events.
        #[arg(long)]
        sensor: Option<String>,
    },
    /// Write the E-RAFT voxel grid (bins, H, W) of a time window as f32 .npy.
    Voxelize {
        /// Input event file.
        input: PathBuf,
        /// Output .npy.
        output: PathBuf,
        #[command(flatten)]
        read: ReadArgs,
        /// Number of time bins.
        #[arg(long, default_value_t = 5)]
        bins: usize,
        /// Window start (microseconds; default: first event).
        #[arg(long)]
        t0_us: Option<i64>,
        /// Window end, exclusive (microseconds; default: last event + 1).
        #[arg(long)]
        t1_us: Option<i64>,
        /// Sensor size WxH when the file does not state it (default: bounding box of the events).
        #[arg(long)]
        sensor: Option<String>,
        /// Standardise non-zero voxels (E-RAFT).
        #[arg(long)]
        normalize: bool,
    },
    /// Simulate events (ESIM model) from a directory of PNG frames (sorted by name) at a frame rate.
    Simulate {
        /// Directory of frames (8/16-bit PNG, sRGB treated as linear grey).
        frames: PathBuf,
        /// Output event file.
        output: PathBuf,
        /// Frames per second.
        #[arg(long, default_value_t = 1000.0)]
        fps: f64,
        /// Mean contrast threshold C+ = C-.
        #[arg(long, default_value_t = 0.2)]
        threshold: f32,
        /// Threshold standard deviation.
        #[arg(long, default_value_t = 0.03)]
        sigma: f32,
        /// Refractory period (microseconds).
        #[arg(long, default_value_t = 0)]
        refractory_us: i64,
        /// Seed.
        #[arg(long, default_value_t = 0)]
        seed: u64,
    },
    /// Event-only flow (contrast maximisation) between two times; writes a flow file (+ colour PNG).
    Flow {
        /// Input event file.
        input: PathBuf,
        #[command(flatten)]
        read: ReadArgs,
        /// Frame k time (microseconds).
        #[arg(long)]
        t0_us: i64,
        /// Frame k+1 time (microseconds).
        #[arg(long)]
        t1_us: i64,
        /// Output flow file (.flo, .npy, .exr, .png).
        #[arg(long)]
        out: PathBuf,
        /// Optional Middlebury colour-coded PNG.
        #[arg(long)]
        viz: Option<PathBuf>,
        /// Sensor size WxH when the file does not state it.
        #[arg(long)]
        sensor: Option<String>,
    },
}

/// How to read the input event file (the `events` library's `ReadOptions`).
#[derive(clap::Args, Debug, Clone, Copy)]
struct ReadArgs {
    /// Encoding of a Prophesee .raw input whose header does not state it (no `% evt 2.0|3.0` or
    /// `% format EVT2|EVT3` line); such a file is refused without it. Refused when the header
    /// states the other encoding, and for inputs that are not .raw.
    #[arg(long, value_enum)]
    format: Option<RawFormatArg>,
    /// Skip the words of a Prophesee EVT 2.0 / 3.0 input that its specification does not allow
    /// (reserved word types, events outside the header's sensor, events without a row, vectors
    /// without a base, time going backwards) instead of failing at the first, and print how many
    /// were skipped. Without it the first such word is an error naming its byte offset.
    #[arg(long)]
    lenient: bool,
}

/// The `--format` values.
#[derive(clap::ValueEnum, Debug, Clone, Copy)]
enum RawFormatArg {
    /// EVT 2.0 (32-bit words).
    Evt2,
    /// EVT 3.0 (16-bit words).
    Evt3,
}

impl ReadArgs {
    fn options(self) -> ReadOptions {
        ReadOptions {
            raw_format: self.format.map(|f| match f {
                RawFormatArg::Evt2 => RawEncoding::Evt2,
                RawFormatArg::Evt3 => RawEncoding::Evt3,
            }),
            lenient: self.lenient,
        }
    }
}

fn progress(r: &dyn EventReader) -> Result<ProgressBar> {
    crate::common::byte_progress_bar(r.total_bytes().unwrap_or(0), "read")
}

/// A file read by [`read_with_progress`].
struct ReadFile {
    events: EventStream,
    /// Short format name of the reader.
    format: &'static str,
    /// Bad words a lenient reader skipped.
    skipped: u64,
}

/// Reads a whole file with a progress bar on stderr (hidden for small files); a lenient read that
/// skipped words says how many on stderr.
fn read_with_progress(path: &Path, read: ReadArgs) -> Result<ReadFile> {
    if read.format.is_some()
        && events::io::EventFormat::from_path(path).ok()
            != Some(events::io::EventFormat::PropheseeRaw)
    {
        bail!(
            "--format evt2|evt3 applies to Prophesee .raw files only, and {} is not one",
            path.display()
        );
    }
    let mut r = events::io::open_events_with(path, &read.options())
        .with_context(|| format!("opening {}", path.display()))?;
    let pb = progress(r.as_ref())?;
    if r.total_bytes().unwrap_or(0) < (64 << 20) {
        pb.set_draw_target(indicatif::ProgressDrawTarget::hidden());
    }
    let mut s = EventStream::new();
    loop {
        let n = r
            .read_chunk(&mut s, events::io::DEFAULT_CHUNK)
            .with_context(|| format!("reading {}", path.display()))?;
        pb.set_position(r.bytes_read());
        pb.set_message(format!("{} events", s.len()));
        if n == 0 {
            break;
        }
    }
    pb.finish_and_clear();
    s.sensor = r.sensor();
    let skipped = r.skipped_words();
    if read.lenient {
        eprintln!(
            "{}: skipped {skipped} bad word{} (--lenient)",
            path.display(),
            if skipped == 1 { "" } else { "s" }
        );
    }
    Ok(ReadFile {
        events: s,
        format: r.format(),
        skipped,
    })
}

fn parse_sensor(s: &str) -> Result<SensorSize> {
    let (w, h) = s.split_once(['x', 'X']).context("sensor must be WxH")?;
    Ok(SensorSize::new(
        w.trim()
            .parse()
            .with_context(|| format!("sensor width {w:?}"))?,
        h.trim()
            .parse()
            .with_context(|| format!("sensor height {h:?}"))?,
    ))
}

fn sensor_of(s: &EventStream, arg: &Option<String>) -> Result<SensorSize> {
    if let Some(a) = arg {
        return parse_sensor(a);
    }
    s.sensor
        .or_else(|| s.bounding_sensor())
        .context("no sensor size: the file does not state it and has no events; pass --sensor WxH")
}

/// Runs the subcommand.
pub fn run(args: Args) -> Result<()> {
    match args.command {
        Sub::Info { file, read } => {
            let ReadFile {
                events: s,
                format,
                skipped,
            } = read_with_progress(&file, read)?;
            let line = serde_json::json!({
                "format": format,
                "events": s.len(),
                "positive": s.positive_count(),
                "t_first_us": s.t.first(),
                "t_last_us": s.t.last(),
                "width": s.sensor.map(|z| z.width),
                "height": s.sensor.map(|z| z.height),
                "skipped_words": skipped,
            });
            println!("{line}");
        }
        Sub::Convert {
            input,
            output,
            read,
            sort,
            sensor,
        } => {
            let mut s = read_with_progress(&input, read)?.events;
            if let Some(arg) = &sensor {
                s.sensor = Some(parse_sensor(arg).context("--sensor")?);
            }
            if let Err(e) = s.validate(None) {
                if sort && matches!(e, events::EventsError::NonMonotonic { .. }) {
                    s.sort_by_time();
                    s.validate(None)
                        .with_context(|| format!("{} after sorting", input.display()))?;
                } else {
                    return Err(e).with_context(|| format!("validating {}", input.display()));
                }
            }
            events::write_events(&output, &s)
                .with_context(|| format!("writing {}", output.display()))?;
        }
        Sub::Voxelize {
            input,
            output,
            read,
            bins,
            t0_us,
            t1_us,
            sensor,
            normalize,
        } => {
            let s = read_with_progress(&input, read)?.events;
            let sz = sensor_of(&s, &sensor)?;
            let t0 = t0_us
                .or(s.t.first().copied())
                .context("no events and no --t0-us")?;
            let t1 = t1_us
                .or(s.t.last().map(|t| t + 1))
                .context("no events and no --t1-us")?;
            let win = s.window(t0, t1);
            let grid = events::voxel_grid(&win, sz, bins, t0, t1, normalize)?;
            write_npy_f32(
                &output,
                &[bins as u64, sz.height as u64, sz.width as u64],
                &grid,
            )?;
        }
        Sub::Simulate {
            frames,
            output,
            fps,
            threshold,
            sigma,
            refractory_us,
            seed,
        } => {
            if !(fps.is_finite() && fps > 0.0) {
                bail!("--fps {fps} must be > 0");
            }
            let mut paths: Vec<PathBuf> = std::fs::read_dir(&frames)
                .with_context(|| format!("listing {}", frames.display()))?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.extension().is_some_and(|x| x.eq_ignore_ascii_case("png")))
                .collect();
            paths.sort();
            if paths.len() < 2 {
                bail!(
                    "{} holds {} PNG frames, need at least 2",
                    frames.display(),
                    paths.len()
                );
            }
            let cfg = events::EsimConfig {
                c_pos: threshold,
                c_neg: threshold,
                sigma,
                refractory_us,
                seed,
                ..events::EsimConfig::default()
            };
            let mut sim: Option<events::EventSimulator> = None;
            let mut all = EventStream::new();
            let pb = crate::common::progress_bar(paths.len() as u64, "simulate frames")?;
            for (k, p) in paths.iter().enumerate() {
                let img = image::open(p)
                    .with_context(|| format!("reading {}", p.display()))?
                    .into_luma16();
                let (w, h) = (img.width() as usize, img.height() as usize);
                let grey: Vec<f32> = img.pixels().map(|px| px.0[0] as f32 / 65535.0).collect();
                let sim = match &mut sim {
                    Some(s) => s,
                    None => sim.insert(events::EventSimulator::new(cfg, w, h)?),
                };
                let t = (k as f64 * 1e6 / fps).round() as i64;
                let ev = sim
                    .add_frame(t, &grey)
                    .with_context(|| format!("frame {}", p.display()))?;
                all.extend_from(&ev.as_slice());
                all.sensor = ev.sensor;
                pb.inc(1);
            }
            pb.finish_and_clear();
            events::write_events(&output, &all)
                .with_context(|| format!("writing {}", output.display()))?;
            eprintln!("{} events from {} frames", all.len(), paths.len());
        }
        Sub::Flow {
            input,
            read,
            t0_us,
            t1_us,
            out,
            viz,
            sensor,
        } => {
            let s = read_with_progress(&input, read)?.events;
            s.validate(None)
                .with_context(|| format!("validating {}", input.display()))?;
            let sz = sensor_of(&s, &sensor)?;
            let win = s.window(t0_us, t1_us);
            let f =
                events::flow_from_events(&win, sz, t0_us, t1_us, &events::CmaxConfig::default())?;
            events::write_flow(&out, &f).with_context(|| format!("writing {}", out.display()))?;
            if let Some(v) = viz {
                events::write_flow_colour_png(&v, &f, None)
                    .with_context(|| format!("writing {}", v.display()))?;
            }
        }
    }
    Ok(())
}

/// Writes a little-endian f32 C-order `.npy` (format 1.0 header written here, data in one pass).
fn write_npy_f32(path: &Path, shape: &[u64], data: &[f32]) -> Result<()> {
    use std::io::Write;
    let dims: Vec<String> = shape.iter().map(u64::to_string).collect();
    let dict = format!(
        "{{'descr': '<f4', 'fortran_order': False, 'shape': ({},), }}",
        dims.join(", ")
    );
    let pad = (64 - (10 + dict.len() + 1) % 64) % 64;
    let f = std::fs::File::create(path).with_context(|| format!("creating {}", path.display()))?;
    let mut w = std::io::BufWriter::new(f);
    let mut head = b"\x93NUMPY\x01\x00".to_vec();
    head.extend_from_slice(&((dict.len() + pad + 1) as u16).to_le_bytes());
    head.extend_from_slice(dict.as_bytes());
    head.extend(std::iter::repeat_n(b' ', pad));
    head.push(b'\n');
    w.write_all(&head)
        .with_context(|| format!("writing {}", path.display()))?;
    for v in data {
        w.write_all(&v.to_le_bytes())
            .with_context(|| format!("writing {}", path.display()))?;
    }
    w.flush()
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}
