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
/// time runs backwards are refused ([`Windows::push`] says so) and change nothing. A row whose
/// time jumps forward by more than a window is held until the next row says what it was: a
/// glitch of the time column where the record goes on from before it (dropped, and said), a
/// gap where it goes on after it. Windows that no row falls in (a gap) are not given: a gap of
/// any length costs nothing. Thinned
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
    /// A row whose time jumped forward by more than a window, until the next row decides.
    pending: Option<Row>,
    /// Rows taken in a row with the last row's time stamp.
    same_stamp: usize,
}

/// Rows with one time stamp beyond which the clock has stopped: they are skipped until it moves
/// (held, they would complete no window and grow without bound). Far above any record whose
/// stamps are rounded (20 rows per second at 20 Hz, 1,000 at 1 kHz).
pub const MAX_ROWS_AT_ONE_STAMP: usize = 65_536;

/// What [`Windows::push`] did with a row.
#[derive(Clone, Debug, PartialEq)]
pub enum Pushed {
    /// Kept; the windows it completed (often none).
    Kept(Vec<Window>),
    /// Its time was before the last row's (by `by_s`): skipped.
    Backwards { by_s: f64 },
    /// The row had no time stamp: windows need one.
    NoTime,
    /// Its time jumps forward by more than a window: held until the next row says whether it
    /// is a glitch or a gap.
    Held,
    /// More than [`MAX_ROWS_AT_ONE_STAMP`] rows carry the time stamp `at_s`: the clock has
    /// stopped, and this row is skipped.
    Stopped { at_s: f64 },
    /// The row held before this one was a glitch of the time column (stamped `at_s`, `ahead_s`
    /// after the row before it, and followed by rows from before it): dropped. `then`: what
    /// became of this row.
    Glitch { at_s: f64, ahead_s: f64, then: Box<Pushed> },
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
            pending: None,
            same_stamp: 0,
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
        if let Some(held) = self.pending.take() {
            let held_s = held.time_s.expect("a held row has a time");
            if t < held_s {
                return Pushed::Glitch {
                    at_s: held_s,
                    ahead_s: held_s - self.last_s,
                    then: Box::new(self.push(row)),
                };
            }
            // A gap: the held row, then this one.
            let mut done = self.accept(held, held_s);
            done.extend(self.accept(row, t));
            return Pushed::Kept(done);
        }
        if t < self.last_s {
            return Pushed::Backwards { by_s: self.last_s - t };
        }
        // (Not before the last row's: the same stamp.)
        if t <= self.last_s && self.same_stamp >= MAX_ROWS_AT_ONE_STAMP {
            return Pushed::Stopped { at_s: t };
        }
        if self.origin_s.is_some() && t - self.last_s > self.length_s {
            self.pending = Some(row);
            return Pushed::Held;
        }
        Pushed::Kept(self.accept(row, t))
    }

    /// Takes `row`, at time `t` (not before the last row's); gives the windows it completes.
    fn accept(&mut self, row: Row, t: f64) -> Vec<Window> {
        // `t` is never before the last row's: not after it is the same stamp.
        self.same_stamp = if t <= self.last_s { self.same_stamp + 1 } else { 1 };
        self.last_s = t;
        self.origin_s.get_or_insert(t);
        let done = self.complete_before(t);
        let held = self.seen.is_multiple_of(self.thin as u64);
        self.seen += 1;
        // A row before the next window (one skipped) is in none to come.
        if held && t >= self.start_of(self.next) {
            self.rows.push_back(row);
        }
        done
    }

    /// At the record's end: the windows its last row completes, one sample period (`period_s`)
    /// after it (the window ending with the record); none later is given. A last row held for
    /// its jump forward has no row after it to tell a gap from a glitch: it is dropped, and its
    /// time returned.
    pub fn finish(&mut self, period_s: f64) -> (Vec<Window>, Option<f64>) {
        let dropped = self.pending.take().and_then(|r| r.time_s);
        if self.origin_s.is_none() {
            return (Vec::new(), dropped);
        }
        let reach = self.last_s + period_s * (1.0 + 1e-9);
        (self.complete_before(reach), dropped)
    }

    /// Gives every window whose end is at or before `t`, dropping the rows no later window
    /// holds.
    fn complete_before(&mut self, t: f64) -> Vec<Window> {
        let mut out = Vec::new();
        loop {
            // Windows no row falls in are skipped: the next one given is the first that can
            // hold the earliest row held, or, with none held, a row at `t` or later.
            let first = self.rows.front().and_then(|r| r.time_s).unwrap_or(t);
            self.next = self.next.max(self.first_ending_after(first));
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

    /// The first window whose end lies after `t` (s): the first that can hold a row at `t`.
    fn first_ending_after(&self, t: f64) -> usize {
        let origin = self.origin_s.unwrap_or(0.0);
        let estimate = ((t - origin - self.length_s) / self.step_s).floor() + 1.0;
        // Below 0, or not a number (a time of ±∞ is refused where rows are read): the first.
        let mut k = if estimate >= 0.0 { estimate as usize } else { 0 };
        // The same arithmetic as the windows' own ends decides, past the estimate's rounding.
        while self.start_of(k) + self.length_s <= t {
            k += 1;
        }
        while k > 0 && self.start_of(k - 1) + self.length_s > t {
            k -= 1;
        }
        k
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
            bit: Some(crate::data::BitReading {
                speed_rad_s: t,
                torque_nm: 1.0,
            }),
            wob_n: None,
            top_drive_rad_s: None,
            surface_torque_nm: None,
            depth_m: None,
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
        given.extend(windows.finish(0.1).0);
        let starts: Vec<f64> = given.iter().map(|w| w.start_s).collect();
        assert_eq!(starts, [0.0, 2.0, 4.0, 6.0, 8.0, 10.0, 12.0, 14.0]);
        assert!(windows.finish(0.1).0.is_empty());
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
        // A gap gives the windows its rows fall in, none where no row fell.
        let mut gap = Windows::new(1.0, 1.0);
        gap.push(row(0.0));
        assert_eq!(gap.push(row(0.5)), Pushed::Kept(Vec::new()));
        // (A jump of more than a window is held until the next row shows it a gap.)
        assert_eq!(gap.push(row(3.5)), Pushed::Held);
        let Pushed::Kept(done) = gap.push(row(4.2)) else {
            panic!()
        };
        assert_eq!(
            done.iter().map(|w| (w.index, w.rows.len())).collect::<Vec<_>>(),
            [(0, 2), (3, 1)]
        );
    }

    #[test]
    fn a_time_stamp_far_ahead_is_a_glitch_where_the_record_goes_on_from_before_it() {
        // 10 Hz; windows of 2 s every 1 s. Row 30 is stamped 10⁶ s, the rows after it go on
        // at 3.1 s: a glitch, dropped, and no window between is computed.
        let mut windows = Windows::new(2.0, 1.0);
        let mut given = Vec::new();
        for k in 0..60 {
            let t = if k == 30 { 1e6 } else { k as f64 / 10.0 };
            match windows.push(row(t)) {
                Pushed::Kept(done) => given.extend(done),
                Pushed::Held => assert_eq!(k, 30),
                Pushed::Glitch { at_s, ahead_s, then } => {
                    assert_eq!((k, at_s), (31, 1e6));
                    assert!((ahead_s - (1e6 - 2.9)).abs() < 1e-6, "{ahead_s}");
                    let Pushed::Kept(done) = *then else { panic!() };
                    given.extend(done);
                }
                other => panic!("{other:?} at row {k}"),
            }
        }
        let (last, dropped) = windows.finish(0.1);
        given.extend(last);
        assert_eq!(dropped, None);
        let starts: Vec<f64> = given.iter().map(|w| w.start_s).collect();
        assert_eq!(starts, [0.0, 1.0, 2.0, 3.0, 4.0]);
        assert!(given.iter().all(|w| w.rows.iter().all(|r| r.time_s.unwrap() < 10.0)));
        assert_eq!(given[2].rows.len(), 19, "the glitch's row is in no window");

        // A gap: the rows go on after the jump. The held row and the next are both kept,
        // and the windows of the gap are skipped.
        let mut windows = Windows::new(2.0, 1.0);
        let mut given = Vec::new();
        for k in 0..40 {
            let t = if k < 20 {
                k as f64 / 10.0
            } else {
                500.0 + k as f64 / 10.0
            };
            match windows.push(row(t)) {
                Pushed::Kept(done) => given.extend(done),
                Pushed::Held => assert_eq!(k, 20),
                other => panic!("{other:?} at row {k}"),
            }
        }
        given.extend(windows.finish(0.1).0);
        let starts: Vec<f64> = given.iter().map(|w| w.start_s).collect();
        assert_eq!(starts, [0.0, 1.0, 501.0, 502.0], "{starts:?}");
        assert_eq!(given[3].rows.len(), 20);
        // A last row held for its jump has no row after it: dropped, and said.
        let mut windows = Windows::new(2.0, 1.0);
        for k in 0..30 {
            windows.push(row(k as f64 / 10.0));
        }
        assert_eq!(windows.push(row(1e9)), Pushed::Held);
        let (last, dropped) = windows.finish(0.1);
        assert_eq!(dropped, Some(1e9));
        assert_eq!(last.iter().map(|w| w.start_s).collect::<Vec<_>>(), [1.0]);
    }

    #[test]
    fn a_clock_that_stops_holds_a_bounded_number_of_rows() {
        let mut windows = Windows::new(2.0, 1.0);
        for k in 0..30 {
            windows.push(row(k as f64 / 10.0));
        }
        // The clock stops at 3 s: rows beyond the bound are skipped, not held.
        let mut stopped = 0;
        for _ in 0..MAX_ROWS_AT_ONE_STAMP + 1000 {
            match windows.push(row(3.0)) {
                Pushed::Kept(_) => {}
                Pushed::Stopped { at_s } => {
                    assert_eq!(at_s.to_bits(), 3.0f64.to_bits());
                    stopped += 1;
                }
                other => panic!("{other:?}"),
            }
        }
        assert_eq!(stopped, 1000, "every row past the bound");
        assert!(windows.held() <= MAX_ROWS_AT_ONE_STAMP + 20, "{}", windows.held());
        // It moves again: rows are taken, and the windows complete.
        assert_eq!(windows.push(row(3.1)), Pushed::Kept(Vec::new()));
        let Pushed::Kept(done) = windows.push(row(4.0)) else {
            panic!()
        };
        assert_eq!(done.iter().map(|w| w.start_s).collect::<Vec<_>>(), [2.0]);
        assert_eq!(done[0].rows.len(), 10 + MAX_ROWS_AT_ONE_STAMP + 1);
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
        from_thinned.extend(thinned.finish(0.01).0);
        from_plain.extend(plain.finish(0.1).0);
        assert_eq!(from_thinned.len(), 8);
        assert_eq!(from_thinned, from_plain);
    }
}
