//! A record's time column as seconds. Loggers stamp rows in seconds or milliseconds from
//! their start, or with the wall clock: ISO 8601 stamps (`2026-11-29T14:30:00.125Z`, with a
//! zone offset or without one, `T` or a space between date and time) or seconds or
//! milliseconds since 1970 (epoch). A wall clock is read as seconds since midnight UTC of the
//! day of the record's first stamp: times stay readable as times of day and keep their digits
//! in f64, and a record read as ISO stamps and the same record exported in epoch seconds give
//! the same times. Which clock a column holds is decided at its first cell and holds for the
//! rest: a stamp in a numeric column, or a number among stamps, is refused.

use std::fmt;
use std::sync::OnceLock;

/// A numeric time at or above this is an absolute clock, s since 1970 (1973-03-03 onwards): no
/// record runs three years from its start.
const EPOCH_SECONDS_FROM: f64 = 1e8;
/// A numeric time at or above this is milliseconds since 1970 (seconds would put it past the
/// year 5000).
const EPOCH_MILLISECONDS_FROM: f64 = 1e11;
/// Seconds in a day.
const DAY_S: i64 = 86_400;
/// Nanoseconds in a day.
const NS_PER_DAY: i128 = 86_400 * 1_000_000_000;

/// How a record's time column reads.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum Clock {
    /// Seconds from the logger's start (or milliseconds, where the column's name says so).
    Elapsed,
    /// ISO 8601 stamps; `day_start` is the midnight UTC (s since 1970) the times count from,
    /// `zoned` whether the first stamp carried its zone (else it was read as UTC).
    Iso { day_start: i64, zoned: bool },
    /// Seconds since 1970; times count from `day_start`.
    EpochSeconds { day_start: i64 },
    /// Milliseconds since 1970; times count from `day_start`.
    EpochMilliseconds { day_start: i64 },
}

impl Clock {
    /// Whether the column holds the wall clock (times count from a midnight UTC).
    pub fn is_wall(self) -> bool {
        !matches!(self, Clock::Elapsed)
    }
}

impl fmt::Display for Clock {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let midnight = |day_start: i64| {
            jiff::Timestamp::from_second(day_start).map_or_else(
                |_| format!("{day_start} s since 1970"),
                |t| t.strftime("%Y-%m-%d 00:00 UTC").to_string(),
            )
        };
        match *self {
            Clock::Elapsed => write!(f, "s from the logger's start"),
            Clock::Iso { day_start, zoned } => write!(
                f,
                "ISO 8601 stamps{}, s since {}",
                if zoned { "" } else { " without a zone, read as UTC" },
                midnight(day_start)
            ),
            Clock::EpochSeconds { day_start } => {
                write!(f, "s since 1970, counted from {}", midnight(day_start))
            }
            Clock::EpochMilliseconds { day_start } => {
                write!(f, "ms since 1970, counted in s from {}", midnight(day_start))
            }
        }
    }
}

/// Reads one time column cell by cell, deciding its clock at the first cell.
#[derive(Debug, Default)]
pub struct TimeReader {
    /// The column's name says milliseconds (`time_ms`, `[ms]`).
    named_ms: bool,
    clock: OnceLock<Clock>,
}

impl TimeReader {
    /// A reader of a column whose name does (`named_ms`) or does not say milliseconds.
    pub fn new(named_ms: bool) -> Self {
        Self {
            named_ms,
            clock: OnceLock::new(),
        }
    }

    /// The clock decided by the first cell read, if any was.
    pub fn clock(&self) -> Option<Clock> {
        self.clock.get().copied()
    }

    /// A cell's text as seconds; `Err` says what is wrong with it, in the user's words.
    pub fn text(&self, text: &str) -> Result<f64, String> {
        let text = text.trim();
        if let Ok(v) = text.parse::<f64>() {
            return self.number(v);
        }
        let Some((at_ns, zoned)) = iso_instant(text) else {
            return Err(format!(
                "'{text}' is neither a number nor an ISO 8601 time stamp (2026-11-29T14:30:00.125Z)"
            ));
        };
        let clock = *self.clock.get_or_init(|| Clock::Iso {
            day_start: at_ns.div_euclid(NS_PER_DAY) as i64 * DAY_S,
            zoned,
        });
        match clock {
            // In integer nanoseconds from midnight, then one division: the stamp's decimal
            // rounded once, as the same time written as a number of seconds is.
            Clock::Iso { day_start, .. } => Ok((at_ns - i128::from(day_start) * 1_000_000_000) as f64 / 1e9),
            _ => Err(format!(
                "'{text}' is a time stamp where the column's first row holds a number ({clock})"
            )),
        }
    }

    /// A number (in the column's unit) as seconds; `Err` says what is wrong with it.
    pub fn number(&self, v: f64) -> Result<f64, String> {
        if !v.is_finite() {
            return Err(format!("'{v}' is not a finite number"));
        }
        let scale = if self.named_ms { 1e-3 } else { 1.0 };
        let clock = *self.clock.get_or_init(|| {
            if v >= EPOCH_MILLISECONDS_FROM {
                Clock::EpochMilliseconds {
                    day_start: day_start(v * 1e-3),
                }
            } else if v * scale >= EPOCH_SECONDS_FROM {
                Clock::EpochSeconds {
                    day_start: day_start(v * scale),
                }
            } else {
                Clock::Elapsed
            }
        });
        match clock {
            Clock::Elapsed => Ok(v * scale),
            Clock::EpochSeconds { day_start } => Ok(v * scale - day_start as f64),
            Clock::EpochMilliseconds { day_start } => Ok(v * 1e-3 - day_start as f64),
            Clock::Iso { .. } => Err(format!(
                "'{v}' is a number where the column's first row holds an ISO 8601 time stamp"
            )),
        }
    }
}

/// The midnight UTC (s since 1970) that begins the day of `at_s` (s since 1970).
fn day_start(at_s: f64) -> i64 {
    (at_s.floor() as i64).div_euclid(DAY_S) * DAY_S
}

/// An ISO 8601 stamp as ns since 1970 and whether it carried its zone (without one it is read
/// as UTC).
fn iso_instant(text: &str) -> Option<(i128, bool)> {
    if let Ok(t) = text.parse::<jiff::Timestamp>() {
        return Some((t.as_nanosecond(), true));
    }
    let civil = text.parse::<jiff::civil::DateTime>().ok()?;
    let t = jiff::tz::TimeZone::UTC.to_timestamp(civil).ok()?;
    Some((t.as_nanosecond(), false))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 2026-11-29 00:00 UTC, s since 1970.
    const DAY: f64 = 1_795_910_400.0;

    #[test]
    fn iso_stamps_count_from_midnight_utc_of_the_first_day() {
        let r = TimeReader::new(false);
        assert_eq!(r.text("2026-11-29T14:30:00.125Z"), Ok(52_200.125));
        // Another zone, the same instant's clock; a space for the `T`; seven decimals.
        assert_eq!(r.text("2026-11-29 15:30:01+01:00"), Ok(52_201.0));
        assert_eq!(r.text("2026-11-29T14:30:02.5000000+00:00"), Ok(52_202.5));
        // Past midnight the count goes on.
        assert_eq!(r.text("2026-11-30T00:00:01Z"), Ok(86_401.0));
        // A stamp's decimals rounded once, as the same time written in seconds.
        let epoch = TimeReader::new(false);
        assert_eq!(
            epoch.text("1970-01-01T00:00:12.34Z"),
            Ok("12.34".parse::<f64>().unwrap())
        );
        assert_eq!(epoch.text("1970-01-01T00:00:00.07Z"), Ok(0.07));
        assert_eq!(
            r.clock(),
            Some(Clock::Iso {
                day_start: DAY as i64,
                zoned: true
            })
        );
        assert_eq!(
            r.clock().unwrap().to_string(),
            "ISO 8601 stamps, s since 2026-11-29 00:00 UTC"
        );
        assert!(r.text("12.5").unwrap_err().contains("a number where"));
    }

    #[test]
    fn stamps_without_a_zone_are_utc_and_said_so() {
        let r = TimeReader::new(false);
        assert_eq!(r.text("2026-11-29T23:59:59.75"), Ok(86_399.75));
        assert!(r.clock().unwrap().to_string().contains("without a zone, read as UTC"));
    }

    #[test]
    fn epoch_seconds_and_milliseconds_read_as_the_same_clock() {
        let s = TimeReader::new(false);
        let ms = TimeReader::new(false);
        let named = TimeReader::new(true);
        let at = DAY + 52_200.125;
        assert_eq!(s.number(at), Ok(52_200.125));
        assert_eq!(ms.number(at * 1e3), Ok(52_200.125));
        assert_eq!(named.number(at * 1e3), Ok(52_200.125));
        assert_eq!(s.clock(), Some(Clock::EpochSeconds { day_start: DAY as i64 }));
        assert_eq!(ms.clock(), Some(Clock::EpochMilliseconds { day_start: DAY as i64 }));
        assert!(
            s.text("2026-11-29T14:30:00Z")
                .unwrap_err()
                .contains("a time stamp where")
        );
    }

    #[test]
    fn elapsed_time_is_left_as_it_is() {
        let s = TimeReader::new(false);
        assert_eq!(s.text("0"), Ok(0.0));
        // Past the epoch threshold later in the record: still elapsed, decided at the first cell.
        assert_eq!(s.number(2e8), Ok(2e8));
        let ms = TimeReader::new(true);
        assert_eq!(ms.text("1500"), Ok(1.5));
        assert_eq!(ms.clock(), Some(Clock::Elapsed));
        assert!(
            TimeReader::new(false)
                .text("12:30")
                .unwrap_err()
                .contains("neither a number")
        );
    }
}
