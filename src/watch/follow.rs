//! Following a source to its end (or to a stop): rows in, windows out, each stored as it is
//! finished, a stored watch resumed.

use super::*;

/// Rows read before the watch starts, to measure the record's rate (its median time step).
pub(super) const RATE_ROWS: usize = 64;
/// Distinct time stamps the rate is measured over where stamps repeat (a logger that rounds
/// its clock to a coarser tick than its rate: whole seconds at 20 Hz).
const RATE_STAMPS: usize = 5;
/// Rows at most before the rate is measured, however the stamps repeat.
const RATE_ROWS_MOST: usize = 160 * RATE_ROWS;

/// How a watch ended.
#[derive(Clone, Debug, Serialize)]
pub struct Ended {
    /// Windows given by this watch (a resumed one: since it resumed).
    pub windows: usize,
    /// Lines of the source skipped (not rows of the record).
    pub skipped_lines: u64,
    /// Window length and step, s.
    pub window_s: f64,
    pub step_s: f64,
    /// Whether it was stopped (`stop` set) before the source ended.
    pub stopped: bool,
}

impl Ended {
    /// How the watch ended as its page says it (and its store keeps it): these fields and
    /// `said`, the page's status in words.
    pub fn page_json(&self) -> serde_json::Value {
        let mut json = serde_json::to_value(self).expect("an end serialises");
        json["said"] = serde_json::Value::from(if self.stopped {
            "the watch was stopped"
        } else {
            "the watch has ended"
        });
        json
    }
}

/// Where a watch keeps its windows and how it is stopped.
#[derive(Clone, Copy, Default)]
pub struct FollowOptions<'a> {
    /// A watch directory ([`store`]): each window is stored before it is given.
    pub dir: Option<&'a Path>,
    /// Go on with the watch stored in `dir`, after its last window: the same settings, the
    /// same source read again from its start (its rows up to that window are read, not
    /// computed).
    pub resume: bool,
    /// Asked between rows (and while a followed file is silent); true (after Ctrl-C) ends the
    /// watch: the window in progress is finished and stored, the rest of the source not read.
    pub stop: Option<&'a dyn Fn() -> bool>,
    /// The live page's server: told the watch's meta when its windows are known, and each
    /// window as it is given.
    pub serve: Option<&'a serve::Server>,
}

/// Follows `rows` to their end: measures the record's rate on its first rows (for the
/// default window), then gives each window's update to `on_update` as soon as the window is
/// complete (and stored, with `options.dir`). Skipped lines and what the user should know go
/// to `observer`, each once.
pub fn follow(
    rows: &mut source::Rows,
    mut settings: WatchSettings,
    options: FollowOptions<'_>,
    observer: &mut dyn Observer,
    on_update: &mut dyn FnMut(&Update) -> Result<()>,
) -> Result<Ended> {
    let source = rows.name().to_path_buf();
    refuse_untimed(rows)?;
    let stopped = || options.stop.is_some_and(|stop| stop());
    // A resumed watch: its store, checked against these settings, and where it stopped.
    let mut resumed = if options.resume {
        Some(resume_stored(rows, &mut settings, options.dir, observer)?)
    } else {
        None
    };
    let mut kept: Option<store::WatchStore> = None;
    let mut first: Vec<(Row, std::time::Instant)> = Vec::new();
    let mut watch: Option<Watch> = None;
    let mut given = 0;
    let mut interrupted = false;
    let started = std::time::Instant::now();
    // The record's first and latest time stamps read, for the estimate of its windows.
    let mut span_s: Option<(f64, f64)> = None;
    loop {
        if stopped() {
            interrupted = true;
            break;
        }
        let next = rows.next_row()?;
        let ended = matches!(next, source::Next::End);
        take(next, &mut first, &mut span_s, &source, observer);
        if watch.is_none() && (enough_to_measure(&first) || (ended && !first.is_empty())) {
            let (made, store) = start_watch(&settings, rows, &first, resumed.take(), &options, observer)?;
            kept = store;
            watch = Some(made);
        }
        if let Some(watch) = watch.as_mut() {
            let share = rows.share_read();
            let mut give = |update: Update, watch: &Watch, observer: &mut dyn Observer| -> Result<()> {
                if let Some(store) = kept.as_mut() {
                    store.append(&update, watch.carried(), watch.view())?;
                }
                given += 1;
                if given == 1 && !options.resume {
                    say_estimate(share, span_s, watch.windows(), started.elapsed(), observer);
                }
                on_update(&update)?;
                if let Some(server) = options.serve {
                    server.publish(&update, watch.view());
                }
                Ok(())
            };
            for (row, arrived) in first.drain(..) {
                for update in watch.push(row, arrived, observer)? {
                    give(update, watch, observer)?;
                }
                if stopped() {
                    break;
                }
            }
            if ended && !stopped() {
                for update in watch.finish(observer)? {
                    give(update, watch, observer)?;
                }
            }
        }
        if ended {
            break;
        }
    }
    let (window_s, step_s) = watch.as_ref().map_or((0.0, 0.0), Watch::windows);
    // A resumed watch may rightly give none: its windows were stored before.
    if given == 0 && !options.resume && !interrupted && !stopped() {
        say_no_window(watch.is_some(), window_s, &source, observer);
    }
    let ended = Ended {
        windows: given,
        skipped_lines: rows.skipped,
        window_s,
        step_s,
        stopped: interrupted || stopped(),
    };
    if let Some(store) = kept.as_mut() {
        store.record_end(&ended.page_json())?;
    }
    Ok(ended)
}

/// Refuses, before any store is made, a record without time stamps: a watch cuts its windows
/// by them.
fn refuse_untimed(rows: &source::Rows) -> Result<()> {
    if rows.declared().columns.time.is_none() {
        return Err(crate::Error::setting(
            "time_column",
            format!(
                "a watch cuts its windows by the record's time stamps, and {} has no time column (no column's name contains 'time'; `time_column` names one)",
                rows.name().display()
            ),
        ));
    }
    Ok(())
}

/// What the source gave next: a row kept in `first` (the record's first and latest stamps in
/// `span_s`), or what it said, said through `observer`.
fn take(
    next: source::Next,
    first: &mut Vec<(Row, std::time::Instant)>,
    span_s: &mut Option<(f64, f64)>,
    source: &Path,
    observer: &mut dyn Observer,
) {
    match next {
        source::Next::Row(row, arrived) => {
            if let Some(t) = row.time_s {
                *span_s = Some(span_s.map_or((t, t), |(a, _)| (a, t)));
            }
            first.push((row, arrived));
        }
        source::Next::Skipped(why) => observer.note(format!("warning: {why}: line skipped")),
        source::Next::Said(what) => observer.note(format!("warning: {what}")),
        source::Next::Stalled(silent) => observer.note(format!(
            "warning: {}: no row for {:.0} s: the feed has stalled (still following)",
            source.display(),
            silent.as_secs_f64()
        )),
        source::Next::Waiting | source::Next::End => {}
    }
}

/// A record too short for one window of `window_s` (a watch was made), or with no row at all,
/// said as such.
fn say_no_window(made: bool, window_s: f64, source: &Path, observer: &mut dyn Observer) {
    observer.note(if made {
        format!(
            "warning: {} ended before a window of {window_s} s was complete: no window to give (`window_s` sets a shorter one)",
            source.display()
        )
    } else {
        format!("warning: {}: no data row: nothing to watch", source.display())
    });
}

/// Seconds of work past which the watch of a file says how many windows it holds and how
/// long they take.
const SAY_ESTIMATE_AFTER_S: f64 = 60.0;

/// After a file's first window: its windows and their time at the first one's pace, from the
/// share of the file read (`share`) over the record's time stamps so far (`span_s`), said
/// where they take more than a minute. Sources whose end is not known say nothing.
fn say_estimate(
    share: Option<f64>,
    span_s: Option<(f64, f64)>,
    (length, step): (f64, f64),
    first_took: std::time::Duration,
    observer: &mut dyn Observer,
) {
    let (Some(share), Some((t0, t1))) = (share, span_s) else {
        return;
    };
    if share <= 0.0 || share >= 1.0 || t1 <= t0 {
        return;
    }
    let record_s = (t1 - t0) / share;
    let windows = ((record_s - length) / step).floor().max(0.0) + 1.0;
    let seconds = windows * first_took.as_secs_f64();
    if seconds > SAY_ESTIMATE_AFTER_S {
        observer.note(format!(
            "about {windows:.0} windows in this record (about {} of record, from the file's size), about {} at the first window's pace",
            crate::limits::human_seconds(record_s),
            crate::limits::human_seconds(seconds)
        ));
    }
}

/// Opens the watch stored in `dir` to go on with it: checked against `settings`, which take
/// its windows, and `rows` moved past its last window.
fn resume_stored(
    rows: &mut source::Rows,
    settings: &mut WatchSettings,
    dir: Option<&Path>,
    observer: &mut dyn Observer,
) -> Result<(store::WatchStore, store::StoredWatch)> {
    let dir = dir.ok_or_else(|| crate::Error::setting("resume", "needs the watch directory (`out`) to go on with"))?;
    let (kept, stored) = store::WatchStore::resume(dir)?;
    let kind = |surface: bool| {
        if surface {
            "surface channels alone"
        } else {
            "the bit's channels"
        }
    };
    let (was, now) = (stored.meta.surface.is_some(), rows.declared().surface.is_some());
    if was != now {
        return Err(crate::Error::setting(
            "resume",
            format!(
                "the watch in {} read {}; this record holds {} (a watch goes on with its own kind of record)",
                dir.display(),
                kind(was),
                kind(now)
            ),
        ));
    }
    check_same_watch(&stored.meta, settings, dir)?;
    settings.window_s = Some(stored.meta.window_s);
    settings.step_s = Some(stored.meta.step_s);
    if let Some(last) = stored.updates.last() {
        rows.replay_from(last.start_s + stored.meta.step_s);
        observer.note(format!(
            "going on with the watch in {} after window {} (t = {} s)",
            dir.display(),
            last.window,
            last.end_s
        ));
    }
    Ok((kept, stored))
}

/// Whether the first rows are enough to measure the record's rate: [`RATE_ROWS`] of them, over
/// [`RATE_STAMPS`] distinct time stamps where stamps repeat (at most [`RATE_ROWS_MOST`]).
fn enough_to_measure(first: &[(Row, std::time::Instant)]) -> bool {
    // Judged every RATE_ROWS rows: the count runs over all of them.
    if first.len() < RATE_ROWS || !first.len().is_multiple_of(RATE_ROWS) {
        return false;
    }
    let distinct = 1 + first
        .windows(2)
        .filter(|w| w[0].0.time_s != w[1].0.time_s || w[1].0.time_s.is_none())
        .count();
    distinct >= RATE_STAMPS || first.len() >= RATE_ROWS_MOST
}

/// The record's rate from its first rows' time stamps, Hz: one over the median step; where
/// most stamps repeat (a clock rounded to a coarser tick than the rate), the rows per second
/// of the stamps strictly between the first and the last, each a whole tick, with words that
/// say so. 1 Hz without two distinct stamps.
fn measured_rate_hz(first: &[(Row, std::time::Instant)]) -> Measured {
    let times: Vec<f64> = first.iter().filter_map(|(r, _)| r.time_s).collect();
    let all_steps: Vec<f64> = times.windows(2).map(|w| w[1] - w[0]).collect();
    let steps: Vec<f64> = all_steps.iter().copied().filter(|d| *d > 0.0).collect();
    let Some(tick_s) = crate::numerics::median(&steps) else {
        return Measured {
            rate_hz: 1.0,
            tick_s: 1.0,
            repeated: None,
        };
    };
    let repeated = all_steps.iter().filter(|d| **d == 0.0).count();
    let (t0, t1) = (times[0], times[times.len() - 1]);
    let inner = times.iter().filter(|&&t| t > t0 && t < t1).count();
    let inner_s = t1 - t0 - tick_s;
    if 2 * repeated <= all_steps.len() || inner == 0 || inner_s <= 0.0 {
        return Measured {
            rate_hz: 1.0 / tick_s,
            tick_s,
            repeated: None,
        };
    }
    let rate_hz = inner as f64 / inner_s;
    let words = format!(
        "time stamps repeat: about {:.0} rows share each stamp, {tick_s} s apart (a clock rounded to whole ticks?); the record's rate is taken as its rows per second, {rate_hz:.1} Hz, and its windows are cut by the stamps as they are",
        rate_hz * tick_s
    );
    Measured {
        rate_hz,
        tick_s,
        repeated: Some(words),
    }
}

/// What a record's first time stamps say of its clock.
struct Measured {
    /// Rows per second.
    rate_hz: f64,
    /// The stamps' step, s (the median of the positive ones).
    tick_s: f64,
    /// Words that say the stamps repeat (a clock rounded to whole ticks), where they do.
    repeated: Option<String>,
}

/// The watch of `rows` at the rate its `first` rows show (a resumed watch: its stored rate),
/// what the user should know of its windows said, and its store: the `resumed` one (its
/// windows published again, its carried state taken), or a new one in `options.dir`.
fn start_watch(
    settings: &WatchSettings,
    rows: &source::Rows,
    first: &[(Row, std::time::Instant)],
    resumed: Option<(store::WatchStore, store::StoredWatch)>,
    options: &FollowOptions<'_>,
    observer: &mut dyn Observer,
) -> Result<(Watch, Option<store::WatchStore>)> {
    let measured = measured_rate_hz(first);
    let rate_hz = match &resumed {
        Some((_, stored)) => stored.meta.rate_hz,
        None => {
            if let Some(words) = &measured.repeated {
                observer.note(format!("warning: {words}"));
            }
            measured.rate_hz
        }
    };
    let declared = rows.declared();
    let surface_columns = declared.surface.clone();
    if let Some(columns) = &surface_columns {
        let downhole: Vec<&str> = [&columns.downhole_min, &columns.downhole_max]
            .into_iter()
            .flatten()
            .map(String::as_str)
            .collect();
        observer.note(format!(
            "a record of surface channels alone (top-drive speed {}, surface torque {}{}): each window's laws through strings simulated per candidate, its model choice checked by re-simulation{}",
            columns.top_drive,
            columns.surface_torque,
            columns.wob.as_ref().map_or(String::new(), |w| format!(", weight on bit {w}")),
            if downhole.is_empty() {
                String::new()
            } else {
                format!(
                    "; its MWD downhole channels ({}) are not read by the watch (a surface run reads them)",
                    downhole.join(", ")
                )
            }
        ));
    }
    let unit = declared.units.torque;
    let source = rows.name().to_path_buf();
    let mut made = Watch::new(settings.clone(), source.clone(), rate_hz, declared)?;
    // A clock rounded to whole ticks: the last stamp's rows reach a tick past it.
    if measured.repeated.is_some() {
        made.reach_past_last_stamp(measured.tick_s);
    }
    let (length, step) = made.windows();
    let thin = made.thin();
    if settings.thin.is_none() && thin > 1 {
        observer.note(format!(
            "one row in {thin} used ({rate_hz:.1} Hz thinned to {:.1} Hz); `thin` sets it",
            rate_hz / thin as f64
        ));
    }
    if let Some(items) = rows.wits_items() {
        let surface: Vec<String> = items
            .surface_averages()
            .iter()
            .map(|(code, what)| format!("item {code} is WITS record 01's {what}"))
            .collect();
        if !surface.is_empty() {
            let (average, it_was, it) = if surface.len() > 1 {
                ("surface averages", "they were", "them")
            } else {
                ("a surface average", "it was", "it")
            };
            observer.note(format!(
                "warning: {}, {average}, read as the bit's: where {it_was} measured at the surface, the laws fitted to {it} describe the string's top, not the bit (a stuck bit's surface torque still swings); the MWD's downhole items are named with `wits_items`; read as surface channels (`wits_items` surface_torque=0118), each window's law is inferred through simulated strings",
                surface.join(" and ")
            ));
        }
    }
    if let Some(config) = &settings.abc {
        observer.note(format!(
            "each window's law probabilities by the paper's ABC ({} sampler, {} particles, δ = {}): ratios of the laws' prior volumes below each window's ε, not evidence",
            match config.sampler {
                crate::run::abc::SamplerConfig::Rejection(_) => "rejection",
                crate::run::abc::SamplerConfig::Smc(_) => "SMC",
            },
            config.sampler.schedule().particles,
            config.delta
        ));
    }
    if settings.window_s.is_none() || settings.step_s.is_none() {
        observer.note(format!(
            "windows of {length} s every {step} s (the record's rate: {rate_hz:.1} Hz); `window_s` and `step_s` set them"
        ));
    }
    let mut kept = None;
    match resumed {
        Some((store, stored)) => {
            if let Some(server) = options.serve {
                server.set_meta(&serve::page_meta(&stored.meta));
                let last = stored.updates.last().map(|u| u.window);
                let view = stored.view.as_ref().filter(|v| Some(v.window) == last);
                for update in &stored.updates {
                    server.publish(update, view.filter(|_| Some(update.window) == last));
                }
            }
            if unit != stored.meta.torque_unit {
                return Err(crate::Error::setting(
                    "resume",
                    format!(
                        "the record's torques are in {}, the watch's were in {}",
                        unit.label(),
                        stored.meta.torque_unit.label()
                    ),
                ));
            }
            if let Some(carried) = stored.carried {
                made.resume(carried);
            }
            let mut store = store;
            store.clear_end()?;
            kept = Some(store);
        }
        None => {
            let meta = store::WatchMeta {
                source: source.display().to_string(),
                settings: store::settings_json(settings, surface_columns.is_some()),
                window_s: length,
                step_s: step,
                rate_hz,
                torque_unit: unit,
                bitrock_version: env!("CARGO_PKG_VERSION").to_string(),
                surface: surface_columns,
            };
            if let Some(dir) = options.dir {
                kept = Some(store::WatchStore::create(dir, &meta)?);
            }
            if let Some(server) = options.serve {
                server.set_meta(&serve::page_meta(&meta));
            }
        }
    }
    Ok((made, kept))
}

/// What a window's fits, evidence or ABC give, or why its samples cannot give it (a fit, a
/// finite likelihood, boxes a sampler reaches, a law's curve limit that keeps too little of
/// its box on the window's torques): that ends the window, not the watch, since the next
/// window may be fine. Any other error ends the watch.
pub(super) fn of_window<T>(result: Result<T>) -> Result<std::result::Result<T, String>> {
    match result {
        Ok(value) => Ok(Ok(value)),
        Err(e @ (crate::Error::Data { .. } | crate::Error::Fit { .. } | crate::Error::Numerical(_))) => {
            Ok(Err(e.to_string()))
        }
        Err(crate::Error::InvalidSetting { field, message })
            if field == "prior" || field == "max_stages" || field == "prior_curve_within" =>
        {
            Ok(Err(message))
        }
        Err(e) => Err(e),
    }
}

/// Refuses to go on with a stored watch whose law files' texts (`was`, by law name) differ
/// from those given now (`now`), naming the law.
fn check_same_law_files(was: &serde_json::Value, now: &serde_json::Value, dir: &Path) -> Result<()> {
    let (Some(was), Some(now)) = (was.as_object(), now.as_object()) else {
        return Ok(());
    };
    for (law, text) in now {
        if was.get(law).is_some_and(|before| before != text) {
            return Err(crate::Error::setting(
                "law_file",
                format!(
                    "the law file of {law} is not the one the watch in {} started with: its windows would compare another law under the same name; restore that file, or start a new watch",
                    dir.display()
                ),
            ));
        }
    }
    Ok(())
}

/// Refuses to go on with a stored watch under other settings: its windows would not be the
/// ones it would have given.
pub(super) fn check_same_watch(meta: &store::WatchMeta, settings: &WatchSettings, dir: &Path) -> Result<()> {
    let surface = meta.surface.is_some();
    let now = store::settings_json(settings, surface);
    let defaults = store::settings_json(&WatchSettings::default(), surface);
    let (Some(stored), Some(now)) = (meta.settings.as_object(), now.as_object()) else {
        return Ok(());
    };
    for (field, value) in now {
        let was = match field.as_str() {
            // Window and step: those the watch used (given or its defaults); left out here,
            // the watch's own.
            "window_s" if !value.is_null() => &serde_json::json!(meta.window_s),
            "step_s" if !value.is_null() => &serde_json::json!(meta.step_s),
            "window_s" | "step_s" => continue,
            // A watch stored without its law files' texts cannot tell; one with them names
            // the law whose file changed.
            "law_files" => {
                if let Some(was) = stored.get(field) {
                    check_same_law_files(was, value, dir)?;
                }
                continue;
            }
            // A setting a watch stored without had the value it has by default then.
            _ => match stored.get(field) {
                Some(was) => was,
                None => &defaults[field],
            },
        };
        if was != value {
            // In the user's words: the setting as the user gives it (`cold_start`, not the
            // stored `warm_start`), and a setting made of parts said to differ, not dumped.
            let (field, value, was) = match field.as_str() {
                "warm_start" => (
                    "cold_start",
                    serde_json::json!(value == false),
                    serde_json::json!(was == false),
                ),
                _ => (field.as_str(), value.clone(), was.clone()),
            };
            let message = if value.is_object() || was.is_object() {
                format!(
                    "differs from the one the watch in {} started with (a watch goes on with its own settings)",
                    dir.display()
                )
            } else {
                format!(
                    "is {value} here, {was} in the watch in {} (a watch goes on with its own settings)",
                    dir.display()
                )
            };
            return Err(crate::Error::setting(field, message));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    /// What a window's own samples make impossible ends the window; any other setting the
    /// watch.
    #[test]
    fn a_window_s_own_refusals_end_the_window_and_others_the_watch() {
        for field in ["prior", "max_stages"] {
            let ended = super::of_window::<()>(Err(crate::Error::setting(field, "too little of the box")));
            assert_eq!(ended.unwrap(), Err("too little of the box".to_string()), "{field}");
        }
        // A law's curve limit that keeps almost none of its box on the window's torques.
        let (lower, upper) = ([0.0f32, -10.0, -10.0, -10.0], [2.0f32, 10.0, 10.0, 10.0]);
        let refused = crate::prior::CurveLimit::new(crate::laws::Law::M4, 1e-3, 1.0, 1.0, (&lower, &upper));
        assert!(super::of_window(refused).unwrap().is_err());
        assert!(super::of_window::<()>(Err(crate::Error::setting("particles", "no"))).is_err());
    }
}
