//! `bitrock watch`: a growing record followed window by window through
//! [`bitrock::watch::follow`]; a table line per window, or JSON lines.

use super::args::{ColumnArgs, StructureArgs, finite_number, parse_laws, set_threads};
use super::print;
use bitrock::abc::evidence::EvidenceConfig;
use bitrock::eval::Backend;
use bitrock::run::abc::Sampler;
use bitrock::run::stability::Structure;
use bitrock::watch::serve::{DEFAULT_ADDRESS, Server};
use bitrock::watch::source::{Rows, Source};
use bitrock::watch::wits::WitsItems;
use bitrock::watch::{FollowOptions, Update, WatchSettings, abc_config};
use clap::Args;
use std::collections::HashSet;
use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};

#[derive(Debug, Args)]
pub struct WatchCmd {
    /// The record: a CSV file, - for standard input, or tcp://HOST:PORT for a feed
    /// (reconnected with back-off when it drops). CSV lines (columns and units read as `fit`
    /// reads them; a time column, s, by which the windows are cut) or WITS level-0 blocks
    /// (`--wits-items`), told apart by the first line.
    pub source: PathBuf,
    /// Follow the file as it grows (like `tail -f`) until stopped (Ctrl-C).
    #[arg(long, conflicts_with = "replay_speed")]
    pub follow: bool,
    /// Replay the file against its own time column at this many times real time (1 = as the
    /// rig sent it): what the watch would have said while drilling, at its pace.
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, value_name = "X")]
    pub replay_speed: Option<f64>,
    /// Laws compared (comma-separated).
    #[arg(long, default_value = bitrock::built_in_law_list!(), value_name = "LAWS")]
    pub laws: String,
    /// Use one row in K, as `fit --thin` does [default: a record faster than 100 Hz thinned
    /// to at most 50 Hz, the paper's rate; slower ones whole].
    #[arg(long, value_name = "K")]
    pub thin: Option<usize>,
    /// Window length, s [default: 10 s or 500 samples, whichever is longer].
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, value_name = "SECONDS")]
    pub window_s: Option<f64>,
    /// Time between window starts, s [default: a fifth of the window].
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, value_name = "SECONDS")]
    pub step_s: Option<f64>,
    /// Weight of the law probabilities carried from one window length before, in (0, 1]: 1
    /// adds up the evidence of every sample once, smaller forgets faster.
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, default_value_t = WatchSettings::default().forgetting, value_name = "LAMBDA")]
    pub forgetting: f64,
    /// No law's probability goes below this: none is ruled out for good.
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, default_value_t = WatchSettings::default().floor, value_name = "P")]
    pub floor: f64,
    /// Log-likelihood (nats) the fits of the latest window sharing no time with a window may
    /// lose on it, beyond their running level, before a change of formation is declared.
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, default_value_t = WatchSettings::default().change_nats, value_name = "NATS")]
    pub change_nats: f64,
    /// The probability of stick-slip the advice keeps below.
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, default_value_t = WatchSettings::default().risk, value_name = "P")]
    pub risk: f64,
    /// Particles of each island of each window's evidence [default: 300]; with --abc, of each
    /// window's ABC population [default: 4,000]; in a record of surface channels alone, of
    /// each population of each window's sampler of simulated strings [default: 300].
    #[arg(long, value_name = "N")]
    pub particles: Option<usize>,
    /// Islands of each window's evidence (their spread is ln Z's error) [default: 2].
    #[arg(long, value_name = "K", conflicts_with = "abc")]
    pub islands: Option<usize>,
    /// Each window's law probabilities by the paper's ABC instead of the evidence: the
    /// sampler of `bitrock abc` (--sampler) on δ boxes around the window's fits (--delta), down
    /// to the floor the window reaches (--eps-min), each window's ε in its update. Its
    /// probabilities are ratios of the laws' prior volumes below ε, not evidence.
    #[arg(long)]
    pub abc: bool,
    /// With --abc: rejection = the paper's Algorithm 1; smc = ABC-SMC with model selection.
    #[arg(long, value_enum, requires = "abc")]
    pub sampler: Option<Sampler>,
    /// With --abc: the prior half-width δ around each window's fits [default: 0.4].
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, value_name = "DELTA", requires = "abc")]
    pub delta: Option<f64>,
    /// With --abc: the smallest tolerance [default: 0.014, the paper's, where the window
    /// reaches it; else 1.1 × its best least-squares ρ].
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, value_name = "EPS", requires = "abc")]
    pub eps_min: Option<f64>,
    /// Seed of each window's samplers (window k uses seed + k).
    #[arg(long, default_value_t = EvidenceConfig::default().seed)]
    pub seed: u64,
    /// WITS item codes over the defaults of record 01 (speed=0120, torque=0118, wob=0116: the
    /// surface averages; date=0105 YYMMDD, time=0106 HHMMSS), as key=CODE,…: keys speed,
    /// torque, wob (or wob=none), top_drive, date, time, and seconds (an item in seconds
    /// instead of date and time). WITS names no units: give --torque-unit and --wob-unit.
    #[arg(long, value_name = "ITEMS")]
    pub wits_items: Option<String>,
    #[command(flatten)]
    pub columns: ColumnArgs,
    /// Where ρ is computed: auto = the GPU when an adapter exists (else the CPU, saying so).
    #[arg(long, value_enum, default_value_t = Backend::Auto)]
    pub backend: Backend,
    /// Worker threads [default: all cores].
    #[arg(long, value_name = "N")]
    pub threads: Option<usize>,
    /// The drill string the advice's stability is judged on.
    #[command(flatten)]
    pub string: StructureArgs,
    /// Each window's evidence from the laws' boxes, the whole procedure repeated as the paper
    /// would (by default each starts from the window before's posterior: the same evidence,
    /// fewer candidates); a record of surface channels: each window's sampler from the prior.
    #[arg(long)]
    pub cold_start: bool,
    /// One JSON line per window instead of the table.
    #[arg(long)]
    pub json: bool,
    /// Watch directory: every window stored as it finishes (watch.sqlite), to go on with after
    /// a stop (`--resume`) and to draw (`bitrock report DIR`).
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Go on with the watch in `--out DIR` after its last stored window, reading SOURCE again
    /// from its start: the same windows and numbers as a watch that never stopped. Its
    /// settings are the stored ones (a flag that differs is refused).
    #[arg(long, requires = "out")]
    pub resume: bool,
    /// Serve a live page of the watch at this address (HOST:PORT; 127.0.0.1:8080, this machine
    /// only, when none is given): the law probabilities along the record, the window's torque
    /// cloud, the stability map with the advice, the parameters. Read-only; it stops with the
    /// watch.
    #[arg(long, value_name = "ADDR", num_args = 0..=1, default_missing_value = DEFAULT_ADDRESS)]
    pub serve: Option<String>,
}

/// Set by the first Ctrl-C: the watch ends after storing the window in progress. The second
/// ends the process at once.
pub(super) static STOP: AtomicBool = AtomicBool::new(false);

/// The first Ctrl-C sets [`STOP`] and says `stopping`; the second exits at once.
pub(super) fn stop_on_ctrl_c(stopping: &'static str) {
    let installed = ctrlc::set_handler(move || {
        if STOP.swap(true, Ordering::SeqCst) {
            std::process::exit(130);
        }
        print::note(format_args!("note: {stopping} (Ctrl-C again stops at once)"));
    });
    if let Err(e) = installed {
        print::note(format_args!(
            "warning: Ctrl-C cannot be caught ({e}): it stops the watch at once"
        ));
    }
}

/// Says each distinct note once on standard error.
struct Notes(HashSet<String>);

impl bitrock::abc::Observer for Notes {
    fn note(&mut self, line: String) {
        if self.0.insert(line.clone()) {
            print::note(format_args!(
                "{}",
                if line.starts_with("warning:") {
                    line
                } else {
                    format!("note: {line}")
                }
            ));
        }
    }
}

pub fn run(cmd: &WatchCmd) -> anyhow::Result<ExitCode> {
    set_threads(cmd.threads)?;
    let settings = settings(cmd)?;
    let source = Source::named(&cmd.source, cmd.follow, cmd.replay_speed)?;
    stop_on_ctrl_c("stopping after the window in progress");
    let stop = || STOP.load(Ordering::SeqCst);
    let mut rows = match Rows::open(&source, &settings.data, &settings.wits, &stop) {
        Err(bitrock::Error::Interrupted) => {
            print::note(format_args!(
                "note: stopped before {} sent its first line",
                cmd.source.display()
            ));
            return Ok(ExitCode::from(130));
        }
        opened => opened?,
    };
    let unit = rows.declared().units.torque;
    let laws = settings.laws.clone();
    let mut out = print::stdout();
    if !cmd.json {
        header(&mut out, &laws)?;
    }
    let mut notes = Notes(HashSet::new());
    let json = cmd.json;
    // A standard output that cannot be written (a closed pipe) ends the watch with its own
    // error, which `main` says as for any command.
    let mut failed: Option<std::io::Error> = None;
    let server = cmd
        .serve
        .as_deref()
        .map(|address| start_server(address, "serve", &cmd.source))
        .transpose()?;
    let options = FollowOptions {
        dir: cmd.out.as_deref(),
        resume: cmd.resume,
        stop: Some(&stop),
        serve: server.as_ref(),
    };
    let followed = bitrock::watch::follow(&mut rows, settings, options, &mut notes, &mut |update| {
        let written = if json {
            serde_json::to_writer(&mut out, update)
                .map_err(std::io::Error::from)
                .and_then(|()| writeln!(out))
        } else {
            line(&mut out, update, &laws)
        };
        match written.and_then(|()| out.flush()) {
            Ok(()) => Ok(()),
            Err(e) => {
                failed = Some(e);
                Err(bitrock::Error::Incomplete("standard output cannot be written".into()))
            }
        }
    });
    if let Some(e) = failed {
        return Err(e.into());
    }
    let ended = followed?;
    say_ended(&mut out, cmd, &ended, unit, server)?;
    // Stopped by Ctrl-C: the shell's status for an interrupted command.
    Ok(if ended.stopped {
        ExitCode::from(130)
    } else {
        ExitCode::SUCCESS
    })
}

/// The watch's settings from the flags.
fn settings(cmd: &WatchCmd) -> anyhow::Result<WatchSettings> {
    let (structure, lumped, fe) = cmd.string.over(None);
    let defaults = WatchSettings::default();
    Ok(WatchSettings {
        laws: parse_laws(&cmd.laws)?,
        data: cmd.columns.options(),
        thin: cmd.thin,
        window_s: cmd.window_s,
        step_s: cmd.step_s,
        evidence: bitrock::run::evidence::Settings {
            particles: match cmd.abc {
                true => defaults.evidence.particles,
                false => cmd.particles.unwrap_or(defaults.evidence.particles),
            },
            islands: cmd.islands.unwrap_or(defaults.evidence.islands),
            seed: cmd.seed,
            ..defaults.evidence.clone()
        },
        surface: bitrock::run::surface::Settings {
            particles: match cmd.abc {
                true => defaults.surface.particles,
                false => cmd.particles.unwrap_or(defaults.surface.particles),
            },
            ..defaults.surface.clone()
        },
        abc: cmd
            .abc
            .then(|| abc_config(cmd.sampler.unwrap_or_default(), cmd.particles, cmd.delta, cmd.eps_min))
            .transpose()?,
        forgetting: cmd.forgetting,
        floor: cmd.floor,
        change_nats: cmd.change_nats,
        risk: cmd.risk,
        backend: cmd.backend,
        warm_start: !cmd.cold_start,
        criterion: {
            if structure == Structure::Fe {
                print::note(format_args!(
                    "note: finding the finite-element string's critical bit damping (its eigenvalues, by bisection)"
                ));
            }
            bitrock::run::stability::criterion(structure, lumped, &fe, &mut |line| print::note(line))?
        },
        fe_chain: match structure {
            Structure::Fe => bitrock::run::strings::chain(Structure::Fe, &lumped, &fe).ok(),
            Structure::Lumped => None,
        },
        wits: cmd
            .wits_items
            .as_deref()
            .map(WitsItems::parse)
            .transpose()?
            .unwrap_or_default(),
        ..defaults
    })
}

/// The end of a watch said: to the live page's viewers, in the table's last line, and where
/// its windows are stored.
fn say_ended(
    out: &mut impl Write,
    cmd: &WatchCmd,
    ended: &bitrock::watch::Ended,
    unit: bitrock::units::TorqueUnit,
    server: Option<Server>,
) -> anyhow::Result<()> {
    if let Some(server) = server {
        server.end(&ended.page_json());
    }
    if !cmd.json && ended.window_s == 0.0 {
        writeln!(out, "no window: no data row; {} lines skipped", ended.skipped_lines)?;
    } else if !cmd.json {
        writeln!(
            out,
            "{} windows of {} s every {} s; torques in {}; {} lines skipped",
            ended.windows,
            ended.window_s,
            ended.step_s,
            unit.label(),
            ended.skipped_lines
        )?;
    }
    if let Some(dir) = &cmd.out {
        print::note(format_args!(
            "note: the windows are stored in {} (`bitrock report {}` draws them{})",
            dir.display(),
            dir.display(),
            if ended.stopped { "; `--resume` goes on" } else { "" }
        ));
    }
    Ok(())
}

/// Starts the live page's server at `address` (the setting `field`) and says where it is.
pub(super) fn start_server(address: &str, field: &'static str, source: &std::path::Path) -> anyhow::Result<Server> {
    let server = Server::start(
        address,
        field,
        &serde_json::json!({ "source": source.display().to_string() }),
    )?;
    let at = server.address();
    let flag = super::fields::flag_of(field).unwrap_or("--serve");
    print::note(format_args!(
        "note: the live page is at http://{at}/{}",
        if at.ip().is_loopback() {
            format!(" (this machine only: {flag} 0.0.0.0:PORT serves the network)")
        } else {
            String::new()
        }
    ));
    Ok(server)
}

fn header(out: &mut impl Write, laws: &[bitrock::Law]) -> std::io::Result<()> {
    write!(out, "{:>6} {:>9} {:>7}", "window", "t (s)", "samples")?;
    for law in laws {
        write!(out, " {:>6}", format!("P({law})"))?;
    }
    writeln!(out, "  change  {:<34}  advice", "this window's answer")
}

fn line(out: &mut impl Write, u: &Update, laws: &[bitrock::Law]) -> std::io::Result<()> {
    write!(out, "{:>6} {:>9.1} {:>7}", u.window, u.end_s, u.samples_used)?;
    for law in laws {
        match u.laws.iter().find(|l| l.law == *law) {
            Some(l) => write!(out, " {:>6.3}", l.probability)?,
            None => write!(out, " {:>6}", "-")?,
        }
    }
    let change = match (u.change, u.change_nats) {
        (true, Some(nats)) => format!("yes ({nats:.0} nats)"),
        _ => "-".into(),
    };
    let advice = match (&u.uninformative, &u.advice) {
        (Some(why), _) => format!("window uninformative: {why}"),
        (None, Some(a)) => a.words.clone(),
        (None, None) => String::new(),
    };
    let answer = match (&u.answer, &u.check) {
        (Some(a), _) => a.headline(),
        (None, Some(check)) => check.headline(),
        (None, None) => "-".into(),
    };
    writeln!(out, "  {change:<6}  {answer:<34}  {advice}")
}
