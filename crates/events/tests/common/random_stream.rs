//! Seeded random event streams for the reader/writer tests (`tests/eventio.rs`,
//! `tests/camera_formats.rs`).

use events::{Event, EventStream, SensorSize};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// `n` events at uniformly random pixels of `sensor` and random polarities, from time `t0` (µs) on
/// with steps uniform in `0..max_step` (so repeated timestamps occur), drawn by ChaCha8 from `seed`.
pub fn random_stream(
    n: usize,
    sensor: SensorSize,
    t0: i64,
    max_step: i64,
    seed: u64,
) -> EventStream {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut s = EventStream::with_capacity(n);
    s.sensor = Some(sensor);
    let mut t = t0;
    for _ in 0..n {
        t += rng.gen_range(0..max_step);
        s.push(Event {
            t,
            x: rng.gen_range(0..sensor.width) as u16,
            y: rng.gen_range(0..sensor.height) as u16,
            p: if rng.gen::<bool>() { 1 } else { -1 },
        });
    }
    s
}
