//! Live view of a sampler run on stderr: an indicatif bar per population on a terminal, one
//! line per population (and one every few seconds inside a long one) otherwise, nothing with
//! `--quiet`; the run's notes between them.

use bitrock::abc::{Observer, Population, Progress};
use indicatif::{ProgressBar, ProgressStyle};
use std::io::IsTerminal;
use std::time::{Duration, Instant};

/// How often a non-terminal log line reports a population in progress.
const LOG_EVERY: Duration = Duration::from_secs(10);

enum Display {
    Bar(Option<ProgressBar>),
    Lines { last: Instant },
    Quiet,
}

/// The progress display of one run.
pub struct RunProgress {
    display: Display,
}

impl RunProgress {
    /// A bar when stderr is a terminal, log lines when it is not, nothing when `quiet`.
    pub fn new(quiet: bool) -> Self {
        let display = if quiet {
            Display::Quiet
        } else if std::io::stderr().is_terminal() {
            Display::Bar(None)
        } else {
            Display::Lines { last: Instant::now() }
        };
        Self { display }
    }
}

fn epsilon_text(epsilon: Option<f64>) -> String {
    epsilon.map_or_else(|| "∞".to_string(), |e| format!("{e:.5}"))
}

fn rate(p: &Progress) -> f64 {
    if p.seconds > 0.0 {
        (p.scored as f64 * p.data_len as f64) / p.seconds
    } else {
        0.0
    }
}

impl Observer for RunProgress {
    fn progress(&mut self, p: &Progress) {
        match &mut self.display {
            Display::Bar(bar) => {
                let bar = bar.get_or_insert_with(|| {
                    let bar = ProgressBar::new(p.target as u64);
                    bar.set_style(
                        ProgressStyle::with_template("{prefix} [{bar:20}] {pos}/{len} · {msg} · ETA {eta}")
                            .expect("a valid template")
                            .progress_chars("=> "),
                    );
                    bar.set_prefix(format!("pop. {}", p.population));
                    bar
                });
                bar.set_message(format!(
                    "ε {} · {} drawn · {:.1e} eval/s",
                    epsilon_text(p.epsilon),
                    p.draws,
                    rate(p)
                ));
                bar.set_position(p.accepted as u64);
            }
            Display::Lines { last } => {
                if last.elapsed() >= LOG_EVERY {
                    *last = Instant::now();
                    super::print::note(format_args!(
                        "population {:>2}: ε = {}, {}/{} accepted, {} drawn, {:.2e} eval/s, {:.1} s",
                        p.population,
                        epsilon_text(p.epsilon),
                        p.accepted,
                        p.target,
                        p.draws,
                        rate(p),
                        p.seconds
                    ));
                }
            }
            Display::Quiet => {}
        }
    }

    fn population_done(&mut self, population: &Population, _previous: Option<&Population>) -> bitrock::Result<()> {
        let r = &population.record;
        let line = format!(
            "population {:>2}: ε = {}, {} accepted of {} drawn, ESS {:.0}, {:.2} s",
            r.index,
            epsilon_text(r.epsilon),
            r.accepted,
            r.draws,
            r.ess,
            r.seconds
        );
        match &mut self.display {
            Display::Bar(bar) => {
                if let Some(bar) = bar.take() {
                    bar.finish_and_clear();
                }
                super::print::note(line);
            }
            Display::Lines { last } => {
                *last = Instant::now();
                super::print::note(line);
            }
            Display::Quiet => {}
        }
        Ok(())
    }

    /// Notes go to stderr above a bar in progress; `--quiet` silences them too.
    fn note(&mut self, line: String) {
        match &self.display {
            Display::Bar(Some(bar)) => bar.suspend(|| super::print::note(&line)),
            Display::Bar(None) | Display::Lines { .. } => super::print::note(line),
            Display::Quiet => {}
        }
    }
}

/// Progress of one long computation that is not a sampler run (a simulation, an FE string's
/// eigenvalue solves): shown only once it has run [`WorkProgress::AFTER`], as a bar on a
/// terminal and a line every [`LOG_EVERY`] otherwise.
pub struct WorkProgress {
    what: &'static str,
    start: Instant,
    last_line: Instant,
    bar: Option<ProgressBar>,
    terminal: bool,
}

impl WorkProgress {
    /// Short work shows nothing.
    const AFTER: Duration = Duration::from_secs(2);

    pub fn new(what: &'static str) -> Self {
        Self {
            what,
            start: Instant::now(),
            last_line: Instant::now(),
            bar: None,
            terminal: std::io::stderr().is_terminal(),
        }
    }

    /// `done` of `total` units.
    pub fn update(&mut self, done: u64, total: u64) {
        if self.start.elapsed() < Self::AFTER {
            return;
        }
        if self.terminal {
            let what = self.what;
            let bar = self.bar.get_or_insert_with(|| {
                let bar = ProgressBar::new(total);
                bar.set_style(
                    ProgressStyle::with_template("{prefix} [{bar:20}] {percent} % · ETA {eta}")
                        .expect("a valid template")
                        .progress_chars("=> "),
                );
                bar.set_prefix(what);
                bar
            });
            bar.set_length(total);
            bar.set_position(done);
        } else if self.last_line.elapsed() >= LOG_EVERY {
            self.last_line = Instant::now();
            let share = done as f64 / total.max(1) as f64;
            let elapsed = self.start.elapsed().as_secs_f64();
            let left = if share > 0.0 {
                elapsed * (1.0 - share) / share
            } else {
                f64::NAN
            };
            super::print::note(format_args!(
                "{}: {:.1} % after {}, about {} left",
                self.what,
                100.0 * share,
                bitrock::limits::human_seconds(elapsed),
                bitrock::limits::human_seconds(left)
            ));
        }
    }
}

impl Drop for WorkProgress {
    fn drop(&mut self) {
        if let Some(bar) = self.bar.take() {
            bar.finish_and_clear();
        }
    }
}
