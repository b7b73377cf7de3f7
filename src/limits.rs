//! Bounds the machine sets on what a flag may ask for: worker threads and memory. A request
//! beyond them is refused before any work, naming the flag and the estimate, rather than
//! spawning without end or aborting on a failed allocation.

use crate::error::{Error, Result};

/// Most worker threads per hardware thread: more only adds switching.
pub const THREADS_PER_CORE: usize = 4;

/// The most worker threads `--threads` may ask for: [`THREADS_PER_CORE`] × the hardware
/// threads available to this process.
pub fn max_threads() -> usize {
    std::thread::available_parallelism().map_or(1, usize::from) * THREADS_PER_CORE
}

/// Refuses a `--threads` of 0 or above [`max_threads`].
pub fn check_threads(threads: usize) -> Result<()> {
    let max = max_threads();
    if threads == 0 || threads > max {
        return Err(Error::setting(
            "threads",
            format!(
                "must lie in 1..={max} ({THREADS_PER_CORE} × the {} hardware threads here), got {threads}",
                max / THREADS_PER_CORE
            ),
        ));
    }
    Ok(())
}

/// Memory this process can use, bytes: `MemAvailable` of /proc/meminfo; `None` where the
/// machine does not say.
pub fn available_memory_bytes() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

/// Refuses, naming `flag`, work whose memory estimate (`bytes`, for `what`) exceeds the memory
/// available. Where the machine does not say, the estimate is checked against the address
/// space only.
pub fn check_memory(field: &str, bytes: f64, what: &str) -> Result<()> {
    let available = available_memory_bytes().map_or(u64::MAX as f64, |b| b as f64);
    if bytes.is_nan() || bytes > available {
        return Err(Error::setting(
            field,
            format!(
                "{what} needs about {} of memory; {} is available",
                human_bytes(bytes),
                human_bytes(available)
            ),
        ));
    }
    Ok(())
}

/// Candidate × sample evaluations per second above any machine's (the fastest GPU measured
/// scores under 10¹²): a work estimate at this rate is a lower bound.
pub const FASTEST_EVALUATIONS_PER_S: f64 = 1e12;

/// The most a settings file (a prior file, a drill-string file) may hold, bytes: a hand-written
/// TOML of a few kB, with room to spare; a larger one is not what the flag means.
pub const MAX_SETTINGS_FILE_BYTES: u64 = 1_000_000;

/// The longest work a flag may ask for, s: past a day the request is a typo or a unit error,
/// not a computation anyone waits for.
pub const MAX_WORK_SECONDS: f64 = 86_400.0;

/// Refuses, naming `flag`, work of `operations` units that would take longer than
/// [`MAX_WORK_SECONDS`] even at `fastest_per_s` units per second (a rate above what the
/// fastest machine bitrock runs on reaches: the estimate is a lower bound on the time, so only
/// requests that cannot finish in a day are refused).
pub fn check_work(field: &str, operations: f64, fastest_per_s: f64, what: &str) -> Result<()> {
    let seconds = operations / fastest_per_s;
    if seconds.is_nan() || seconds > MAX_WORK_SECONDS {
        return Err(Error::setting(
            field,
            format!(
                "{what} would take more than {:.0} hours even at {fastest_per_s:.0e} per second; the most accepted is a day's work",
                (seconds / 3600.0).min(1e12)
            ),
        ));
    }
    Ok(())
}

/// How long a serial computation runs before its pace is measured ([`Pace`]).
const CALIBRATION: std::time::Duration = std::time::Duration::from_millis(20);

/// How often a [`Pace`] reports progress.
const REPORT_EVERY: std::time::Duration = std::time::Duration::from_millis(250);

/// Refuses, naming `flag`, work estimated at `seconds` on this machine (from a pace measured
/// here) beyond [`MAX_WORK_SECONDS`].
pub fn check_estimate(field: &str, seconds: f64, what: &str) -> Result<()> {
    if seconds.is_nan() || seconds > MAX_WORK_SECONDS {
        return Err(Error::setting(
            field,
            format!(
                "{what} would take about {} on this machine (its pace measured at the start); the most accepted is a day's work",
                human_seconds(seconds)
            ),
        ));
    }
    Ok(())
}

/// The pace of a long serial computation, measured as it runs: after 20 ms of work
/// it refuses (naming the flag, through [`check_estimate`]) work whose rest could not finish in
/// a day on this machine, and it reports `(done, total)` to `report` every quarter second.
pub struct Pace<'a> {
    field: &'a str,
    what: String,
    total: u64,
    done: u64,
    next_look: u64,
    start: std::time::Instant,
    last_report: std::time::Instant,
    calibrated: bool,
    report: Option<&'a mut dyn FnMut(u64, u64)>,
}

impl<'a> Pace<'a> {
    /// `total` units of `what` (named by `field` when refused), reported to `report`.
    pub fn new(field: &'a str, what: String, total: u64, report: &'a mut dyn FnMut(u64, u64)) -> Self {
        let now = std::time::Instant::now();
        Self {
            field,
            what,
            total,
            done: 0,
            next_look: 1,
            start: now,
            last_report: now,
            calibrated: false,
            report: Some(report),
        }
    }

    /// A pace that only counts: it neither refuses nor reports (for callers that bounded the
    /// work themselves).
    pub fn unchecked() -> Self {
        let now = std::time::Instant::now();
        Self {
            field: "",
            what: String::new(),
            total: 0,
            done: 0,
            next_look: u64::MAX,
            start: now,
            last_report: now,
            calibrated: true,
            report: None,
        }
    }

    /// Counts `units` more done; an error once the measured pace says the rest cannot finish.
    /// Cheap: the clock is read once every few thousand units.
    pub fn advance(&mut self, units: u64) -> Result<()> {
        self.done += units;
        if self.done < self.next_look {
            return Ok(());
        }
        self.next_look = self.done + 4096;
        let elapsed = self.start.elapsed();
        if !self.calibrated && elapsed >= CALIBRATION {
            self.calibrated = true;
            let per_s = self.done as f64 / elapsed.as_secs_f64();
            let rest = self.total.saturating_sub(self.done) as f64;
            check_estimate(self.field, rest / per_s + elapsed.as_secs_f64(), &self.what)?;
        }
        if self.last_report.elapsed() >= REPORT_EVERY {
            self.last_report = std::time::Instant::now();
            if let Some(report) = self.report.as_mut() {
                report(self.done.min(self.total), self.total);
            }
        }
        Ok(())
    }
}

/// A duration for people: seconds, minutes, hours or days, two significant figures or so.
pub fn human_seconds(seconds: f64) -> String {
    if seconds < 90.0 {
        format!("{seconds:.1} s")
    } else if seconds < 5400.0 {
        format!("{:.0} min", seconds / 60.0)
    } else if seconds < 2.0 * 86_400.0 {
        format!("{:.1} hours", seconds / 3600.0)
    } else {
        let days = seconds / 86_400.0;
        if days < 1e6 {
            format!("{days:.0} days")
        } else {
            format!("{days:.1e} days")
        }
    }
}

/// A number as a user typed it: plain where that reads (0.02, 150), in scientific notation
/// where plain would run to dozens of digits (1e-300).
pub fn readable(value: f64) -> String {
    if value != 0.0 && !(1e-4..1e9).contains(&value.abs()) {
        format!("{value:e}")
    } else {
        format!("{value}")
    }
}

/// Bytes in decimal units (B, kB, MB, GB, TB...) with one decimal.
pub fn human_bytes(bytes: f64) -> String {
    const UNITS: [&str; 7] = ["B", "kB", "MB", "GB", "TB", "PB", "EB"];
    let mut value = bytes;
    let mut unit = 0;
    while value >= 1000.0 && unit + 1 < UNITS.len() {
        value /= 1000.0;
        unit += 1;
    }
    format!("{value:.1} {}", UNITS[unit])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn work_beyond_a_day_is_refused_naming_the_flag() {
        assert!(check_work("samples", 1e14, 1e10, "the grid").is_ok());
        let e = check_work("samples", 1e16, 1e10, "the grid").unwrap_err().to_string();
        assert!(e.contains("samples") && e.contains("278 hours"), "{e}");
        assert!(check_work("samples", f64::NAN, 1e10, "the grid").is_err());
    }

    #[test]
    fn bytes_read_in_decimal_units() {
        assert_eq!(human_bytes(512.0), "512.0 B");
        assert_eq!(human_bytes(56e9), "56.0 GB");
        assert_eq!(human_bytes(4e14), "400.0 TB");
    }

    #[test]
    fn threads_are_bounded_by_the_machine() {
        assert!(check_threads(1).is_ok());
        assert!(check_threads(max_threads()).is_ok());
        for bad in [0, max_threads() + 1, 99_999_999_999] {
            let e = check_threads(bad).unwrap_err().to_string();
            assert!(e.starts_with("`threads`: must lie in 1..="), "{e}");
        }
    }

    #[test]
    fn memory_beyond_the_machine_is_refused_with_the_estimate() {
        assert!(check_memory("particles", 1e6, "a population").is_ok());
        let e = check_memory("particles", 1e30, "two populations")
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("`particles`: two populations needs about 1000000000000.0 EB"),
            "{e}"
        );
    }
}
