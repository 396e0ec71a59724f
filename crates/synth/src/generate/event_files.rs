//! The simulated events of the generator's renders, bucketed by frame interval — the events of
//! `[t_k, t_{k+1})` go to frame k's events file (the last frame keeps everything after `t_{N−1}`;
//! events before `t_0` are dropped and counted) — and, with `SynthConfig::event_flow`, each
//! interval's event-only (contrast-maximisation) flow, computed on a helper thread while the next
//! frames render and scored against the ground-truth flow in frame order.

use std::collections::{BTreeMap, VecDeque};
use std::path::Path;

use super::scene_file::event_path;
use super::stats::{CmAcc, EventStats};
use crate::config::SynthConfig;
use crate::error::Result;

/// The events written so far and the event-only flows in flight.
pub(super) struct EventFiles<'a> {
    out: &'a Path,
    cfg: &'a SynthConfig,
    sensor: events::SensorSize,
    frames: usize,
    /// The events of frame interval `bucket_k` so far.
    bucket: events::EventStream,
    bucket_k: usize,
    /// Each written interval's two-channel count frame, in frame order.
    counts: Vec<Vec<f32>>,
    /// Event-only flow jobs in flight, oldest first.
    cm_jobs: VecDeque<CmJob>,
    /// Ground-truth and event-only flows meet here (either may be ready first).
    gt_wait: BTreeMap<usize, (Vec<f32>, Vec<bool>)>,
    cm_wait: BTreeMap<usize, Vec<f32>>,
    cm: CmAcc,
}

/// Frame k's time (µs, rounded), as the renders are stamped.
fn frame_us(cfg: &SynthConfig, k: usize) -> i64 {
    (k as f64 / cfg.fps * 1e6).round() as i64
}

impl<'a> EventFiles<'a> {
    /// Nothing written yet, for a sensor `sensor` and the scene directory `out`.
    pub(super) fn new(out: &'a Path, cfg: &'a SynthConfig, sensor: events::SensorSize) -> Self {
        let mut bucket = events::EventStream::new();
        bucket.sensor = Some(sensor);
        Self {
            out,
            cfg,
            sensor,
            frames: cfg.frames as usize,
            bucket,
            bucket_k: 0,
            counts: Vec::new(),
            cm_jobs: VecDeque::new(),
            gt_wait: BTreeMap::new(),
            cm_wait: BTreeMap::new(),
            cm: CmAcc::default(),
        }
    }

    /// Adds a render's events (in time order), writing every interval they have left behind.
    pub(super) fn add(&mut self, evs: &events::EventStream, stats: &mut EventStats) -> Result<()> {
        let first = frame_us(self.cfg, 0);
        for e in evs.iter() {
            if e.t < first {
                stats.dropped_before_first_frame += 1;
                continue;
            }
            while self.bucket_k + 1 < self.frames && e.t >= frame_us(self.cfg, self.bucket_k + 1) {
                self.flush(stats)?;
            }
            self.bucket.push(e);
        }
        Ok(())
    }

    /// Writes interval `bucket_k`, keeps its count frame and, when enabled and it has a next
    /// frame, starts its event-only flow on a helper thread (contrast maximisation is sequential;
    /// it overlaps the rendering of the next frames, and its result does not depend on when it
    /// runs).
    fn flush(&mut self, stats: &mut EventStats) -> Result<()> {
        let (k, s, sensor) = (self.bucket_k, &mut self.bucket, self.sensor);
        events::write_events(self.out.join(event_path(k)), s)?;
        stats.count += s.len();
        stats.positive += s.positive_count();
        let frame = events::count_frame(&s.as_slice(), sensor, events::CountMode::TwoChannel);
        self.counts.push(frame);
        if self.cfg.event_flow && k + 1 < self.frames {
            let (evs, t_a, t_b) = (s.clone(), frame_us(self.cfg, k), frame_us(self.cfg, k + 1));
            let path = self.out.join(format!("flow/{k:06}_cm.flo"));
            let handle = std::thread::spawn(move || -> Result<Vec<f32>> {
                let config = events::CmaxConfig::default();
                let f = events::flow_from_events(&evs.as_slice(), sensor, t_a, t_b, &config)?;
                events::write_flo(path, &f)?;
                Ok(f.data)
            });
            self.cm_jobs.push_back(CmJob { k, handle });
        }
        s.clear();
        self.bucket_k += 1;
        Ok(())
    }

    /// The ground-truth flow of pair (k, k+1) and its valid pixels, to score the event-only flow
    /// against (kept only when that flow is computed).
    pub(super) fn ground_truth(&mut self, k: usize, flow: &[f32], valid: &[bool]) {
        if self.cfg.event_flow {
            self.gt_wait.insert(k, (flow.to_vec(), valid.to_vec()));
            self.meet(k);
        }
    }

    /// Collects the finished event-only flows in order, keeping at most two in flight.
    pub(super) fn collect_finished(&mut self) -> Result<()> {
        while self
            .cm_jobs
            .front()
            .is_some_and(|j| j.handle.is_finished() || self.cm_jobs.len() > 2)
        {
            if let Some(job) = self.cm_jobs.pop_front() {
                let (k, cm) = job.join()?;
                self.cm_wait.insert(k, cm);
                self.meet(k);
            }
        }
        Ok(())
    }

    /// Writes the remaining intervals (the last one, and empty ones if nothing happened), waits
    /// for every event-only flow, and returns the count frames and the flows' error sums.
    pub(super) fn finish(mut self, stats: &mut EventStats) -> Result<(Vec<Vec<f32>>, CmAcc)> {
        while self.bucket_k < self.frames {
            self.flush(stats)?;
        }
        while let Some(job) = self.cm_jobs.pop_front() {
            let (k, cm) = job.join()?;
            self.cm_wait.insert(k, cm);
            self.meet(k);
        }
        Ok((self.counts, self.cm))
    }

    /// Scores pair k once both of its flows are here.
    fn meet(&mut self, k: usize) {
        if let (Some((g, v)), Some(c)) = (self.gt_wait.get(&k), self.cm_wait.get(&k)) {
            self.cm.add(c, g, v);
            self.gt_wait.remove(&k);
            self.cm_wait.remove(&k);
        }
    }
}

/// An event-only flow being computed on a helper thread for frame pair (k, k+1).
struct CmJob {
    k: usize,
    handle: std::thread::JoinHandle<Result<Vec<f32>>>,
}

impl CmJob {
    /// Waits for the flow (planar u then v, pixels).
    fn join(self) -> Result<(usize, Vec<f32>)> {
        match self.handle.join() {
            Ok(r) => Ok((self.k, r?)),
            Err(panic) => std::panic::resume_unwind(panic),
        }
    }
}
