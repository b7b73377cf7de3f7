//! Windows of a growing record, cut by the record's own time stamps, never by when rows
//! arrive: the same record gives the same windows read whole, replayed at any speed or
//! followed as it is written.

use crate::data::Row;
use std::collections::VecDeque;

/// One window: its rows with `start_s ≤ t < end_s`, in record order.
#[derive(Clone, Debug, PartialEq)]
pub struct Window {
    /// 0, 1, … in record order.
    pub index: usize,
    pub start_s: f64,
    pub end_s: f64,
    pub rows: Vec<Row>,
}

/// Cuts rows into windows [t₀ + k·step, t₀ + k·step + length), t₀ the first row's time. A
/// window is complete once a row at or after its end has arrived: only complete windows are
/// given, so a window never changes once given; at the record's end, [`Windows::finish`]
/// gives the window that ends with it (a last, partial window is none). Rows whose
/// time runs backwards are refused ([`Windows::push`] says so) and change nothing. Thinned
/// ([`Windows::thinned`]), a window holds every k-th row of the record, counted from its
/// first, and still completes when the record's time passes its end. Memory: the rows of
/// one window.
#[derive(Clone, Debug)]
pub struct Windows {
    length_s: f64,
    step_s: f64,
    origin_s: Option<f64>,
    /// The next window to give.
    next: usize,
    /// The rows at or after the next window's start.
    rows: VecDeque<Row>,
    last_s: f64,
    /// Every `thin`-th row is held; `seen` rows have been taken.
    thin: usize,
    seen: u64,
}

/// What [`Windows::push`] did with a row.
#[derive(Clone, Debug, PartialEq)]
pub enum Pushed {
    /// Kept; the windows it completed (often none).
    Kept(Vec<Window>),
    /// Its time was before the last row's (by `by_s`): skipped.
    Backwards { by_s: f64 },
    /// The row had no time stamp: windows need one.
    NoTime,
}

impl Windows {
    /// Windows of `length_s` every `step_s` (both positive and finite; step ≤ length so that
    /// every row lies in a window).
    pub fn new(length_s: f64, step_s: f64) -> Self {
        assert!(length_s.is_finite() && length_s > 0.0 && step_s.is_finite() && step_s > 0.0 && step_s <= length_s);
        Self {
            length_s,
            step_s,
            origin_s: None,
            next: 0,
            rows: VecDeque::new(),
            last_s: f64::NEG_INFINITY,
            thin: 1,
            seen: 0,
        }
    }

    /// Holding every `thin`-th row (at least 1) of the record, as `fit --thin` does.
    pub fn thinned(mut self, thin: usize) -> Self {
        self.thin = thin.max(1);
        self
    }

    /// ⌈length / step⌉: window k + span() is the first that shares no time with window k.
    pub fn span(&self) -> usize {
        ((self.length_s / self.step_s - 1e-9).ceil() as usize).max(1)
    }

    /// Window length and step, s.
    pub fn shape(&self) -> (f64, f64) {
        (self.length_s, self.step_s)
    }

    /// Every how many rows one is held.
    pub fn thin(&self) -> usize {
        self.thin
    }

    fn start_of(&self, k: usize) -> f64 {
        self.origin_s.unwrap_or(0.0) + k as f64 * self.step_s
    }

    /// Windows up to `index` are not given: a watch that goes on after them.
    pub fn skip_through(&mut self, index: usize) {
        self.next = self.next.max(index + 1);
    }

    /// Takes the next row; gives the windows it completes.
    pub fn push(&mut self, row: Row) -> Pushed {
        let Some(t) = row.time_s else {
            return Pushed::NoTime;
        };
        if t < self.last_s {
            return Pushed::Backwards { by_s: self.last_s - t };
        }
        self.last_s = t;
        self.origin_s.get_or_insert(t);
        let done = self.complete_before(t);
        let held = self.seen.is_multiple_of(self.thin as u64);
        self.seen += 1;
        // A row before the next window (one skipped) is in none to come.
        if held && t >= self.start_of(self.next) {
            self.rows.push_back(row);
        }
        Pushed::Kept(done)
    }

    /// At the record's end: the windows its last row completes, one sample period (`period_s`)
    /// after it (the window ending with the record); none later is given.
    pub fn finish(&mut self, period_s: f64) -> Vec<Window> {
        if self.origin_s.is_none() {
            return Vec::new();
        }
        let reach = self.last_s + period_s * (1.0 + 1e-9);
        self.complete_before(reach)
    }

    /// Gives every window whose end is at or before `t`, dropping the rows no later window
    /// holds.
    fn complete_before(&mut self, t: f64) -> Vec<Window> {
        let mut out = Vec::new();
        loop {
            let start = self.start_of(self.next);
            let end = start + self.length_s;
            if t < end {
                break;
            }
            let rows: Vec<Row> = self
                .rows
                .iter()
                .filter(|r| r.time_s.is_some_and(|s| s >= start && s < end))
                .copied()
                .collect();
            out.push(Window {
                index: self.next,
                start_s: start,
                end_s: end,
                rows,
            });
            self.next += 1;
            let next_start = self.start_of(self.next);
            while self
                .rows
                .front()
                .is_some_and(|r| r.time_s.is_some_and(|s| s < next_start))
            {
                self.rows.pop_front();
            }
        }
        out
    }

    /// The rows held now (at most about a window's).
    pub fn held(&self) -> usize {
        self.rows.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(t: f64) -> Row {
        Row {
            time_s: Some(t),
            speed_rad_s: t,
            torque_nm: 1.0,
            wob_n: None,
            top_drive_rad_s: None,
        }
    }

    #[test]
    fn windows_follow_the_time_stamps_not_the_arrivals() {
        // 20 s at 10 Hz, windows of 5 s every 2 s: starts 0, 2, …, 14 (the one at 14 ends with
        // the record, given at its end; the one at 16 would end at 21, after it).
        let mut windows = Windows::new(5.0, 2.0);
        let mut given = Vec::new();
        for k in 0..200 {
            if let Pushed::Kept(done) = windows.push(row(k as f64 / 10.0)) {
                given.extend(done);
            }
            assert!(windows.held() <= 51, "{}", windows.held());
        }
        given.extend(windows.finish(0.1));
        let starts: Vec<f64> = given.iter().map(|w| w.start_s).collect();
        assert_eq!(starts, [0.0, 2.0, 4.0, 6.0, 8.0, 10.0, 12.0, 14.0]);
        assert!(windows.finish(0.1).is_empty());
        // Windows 0 and 3 share [6, 5)… none: 3·2 ≥ 5; windows 0 and 2 share [4, 5).
        assert_eq!(windows.span(), 3);
        assert_eq!(Windows::new(20.0, 10.0).span(), 2);
        assert_eq!(Windows::new(5.0, 5.0).span(), 1);
        for w in &given {
            assert_eq!(w.rows.len(), 50, "window {}", w.index);
            assert!(
                w.rows
                    .iter()
                    .all(|r| r.time_s.unwrap() >= w.start_s && r.time_s.unwrap() < w.end_s)
            );
        }
        assert_eq!(windows.push(row(3.0)), Pushed::Backwards { by_s: 19.9 - 3.0 });
        // A gap gives its windows, empty where no row fell.
        let mut gap = Windows::new(1.0, 1.0);
        gap.push(row(0.0));
        let Pushed::Kept(done) = gap.push(row(3.5)) else {
            panic!()
        };
        assert_eq!(done.iter().map(|w| w.rows.len()).collect::<Vec<_>>(), [1, 0, 0]);
    }

    #[test]
    fn a_thinned_record_holds_every_kth_row_and_gives_the_same_windows() {
        // 20 s at 100 Hz thinned by 10 against the same 20 s at 10 Hz: the same windows, the
        // same rows, each window given on the same row's arrival.
        let (mut thinned, mut plain) = (Windows::new(5.0, 2.0).thinned(10), Windows::new(5.0, 2.0));
        let (mut from_thinned, mut from_plain) = (Vec::new(), Vec::new());
        for k in 0..2000 {
            let t = k as f64 / 100.0;
            let Pushed::Kept(done) = thinned.push(row(t)) else {
                panic!()
            };
            if k % 10 == 0 {
                let Pushed::Kept(expected) = plain.push(row(t)) else {
                    panic!()
                };
                from_plain.extend(expected);
            }
            from_thinned.extend(done);
            assert_eq!(from_thinned.len(), from_plain.len(), "at t = {t}");
        }
        from_thinned.extend(thinned.finish(0.01));
        from_plain.extend(plain.finish(0.1));
        assert_eq!(from_thinned.len(), 8);
        assert_eq!(from_thinned, from_plain);
    }
}
