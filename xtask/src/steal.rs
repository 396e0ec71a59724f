//! Hypervisor steal time over an interval, from the aggregate `cpu` line of `/proc/stat` (Linux).
//! On a virtual machine the host can take a share of the guest's CPUs ("steal"); benchmark lines
//! carry it as `steal_pct` so that a slow figure can be told apart from slow code. `null` where
//! `/proc/stat` is unavailable or unreadable.

/// Cumulative CPU times of all CPUs, in clock ticks.
#[derive(Clone, Copy, Debug, PartialEq)]
struct CpuTicks {
    steal: u64,
    total: u64,
}

/// Parses the aggregate `cpu` line (`cpu user nice system idle iowait irq softirq steal ...`); the
/// total is the sum of those eight fields (guest time is already inside `user`).
fn parse(stat: &str) -> Option<CpuTicks> {
    let line = stat.lines().find(|l| l.starts_with("cpu "))?;
    let fields: Vec<u64> = line
        .split_whitespace()
        .skip(1)
        .take(8)
        .map(|f| f.parse().ok())
        .collect::<Option<_>>()?;
    if fields.len() < 8 {
        return None;
    }
    Some(CpuTicks {
        steal: fields[7],
        total: fields.iter().sum(),
    })
}

fn sample() -> Option<CpuTicks> {
    parse(&std::fs::read_to_string("/proc/stat").ok()?)
}

/// Measures the share of CPU time stolen by the hypervisor between [`Meter::start`] and
/// [`Meter::percent`].
pub struct Meter(Option<CpuTicks>);

impl Meter {
    /// Starts measuring now.
    pub fn start() -> Self {
        Self(sample())
    }

    /// Steal time since the start as a percentage of all CPU time (0–100, one decimal), or `None`
    /// if it cannot be read or no tick has passed.
    pub fn percent(&self) -> Option<f64> {
        let (a, b) = (self.0?, sample()?);
        let total = b.total.checked_sub(a.total)?;
        let steal = b.steal.checked_sub(a.steal)?;
        (total > 0).then(|| (1000.0 * steal as f64 / total as f64).round() / 10.0)
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn parses_the_aggregate_cpu_line() {
        let stat = "cpu  100 5 50 800 10 1 2 32 0 0\ncpu0 50 2 25 400 5 0 1 16 0 0\nintr 1\n";
        let t = super::parse(stat).expect("parsed");
        assert_eq!(t.steal, 32);
        assert_eq!(t.total, 100 + 5 + 50 + 800 + 10 + 1 + 2 + 32);
        assert_eq!(super::parse("cpu0 1 2 3\n"), None);
        assert_eq!(super::parse("cpu  1 2 x 4 5 6 7 8\n"), None);
        assert_eq!(super::parse("cpu  1 2 3\n"), None);
    }
}
