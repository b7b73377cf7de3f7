//! An ABC run's populations, from configuration to run directory and back: the two entry
//! points, [`start`] (fits, prior, evaluator, sampler, in a fresh directory or in memory) and
//! [`resume`] (continues a killed or finished run from its store and gives exactly the
//! populations an uninterrupted run would), each scoring where its [`Scoring`] says.

use super::config::{Config, Continuation, SamplerConfig};
use super::store::{self, PendingPopulation, STORE_FILE, Setup, Store, Stored};
use crate::abc::floor;
use crate::abc::rejection;
use crate::abc::shard::Workers;
use crate::abc::smc;
use crate::abc::{Observer, Population, Progress, Run};
use crate::data::FieldData;
use crate::error::{Error, Result};
use crate::eval::Problem;
use crate::files;
use crate::fit;
use crate::prior::{Prior, PriorFile};
use crate::run::dir::{Claim, Dir, check_new};
use crate::run::scoring::{Placement, Scoring};
use std::path::Path;

/// How a user continues the run in `dir`, from the command line or from Python: what every
/// message that says "resume it" ends with.
pub fn resume_advice(dir: &Path) -> String {
    format!(
        "resume it: `bitrock abc --resume {0}`, or `bitrock.resume(\"{0}\")` in Python",
        dir.display()
    )
}

/// A run after an invocation: its set-up, every population, and why it stopped.
pub struct Outcome {
    pub config: Config,
    pub setup: Setup,
    pub run: Run,
    /// Backend that scored this invocation's candidates (`cpu`, `gpu`).
    pub backend: &'static str,
    /// The run directory's lock, held while the outcome lives (its summary files are written
    /// under it); `None` for a run in memory.
    pub lock: Option<files::DirLock>,
    /// Populations this invocation added (a resume whose stopping rules already end the run
    /// adds none, and then changes nothing: `config` is the stored one).
    pub added: usize,
}

/// How a run starts, besides its record and configuration. [`Default`]: in memory, fitted and
/// scored here, without a prior file.
#[derive(Default)]
pub struct Start<'a, 'w> {
    /// The run directory to create; `None` keeps the run in memory.
    pub dir: Option<&'a Dir>,
    /// The parsed `config.prior_file`.
    pub prior_file: Option<&'a PriorFile>,
    /// The record's least-squares fits, where the caller made them
    /// (`fit::fit_record(&config.laws, &data, &config.fit)`: the selection check fits all its
    /// replicates' records before sampling any); `None`: fitted here.
    pub fits: Option<Vec<fit::LawFit>>,
    pub scoring: Scoring<'a, 'w>,
}

/// Fits, builds the prior and the evaluator, then samples. With a `dir`, the run directory is
/// claimed (locked, one writer at a time) with its store first, and every population is
/// stored as it completes; without one the run lives in memory only. A run replacing another
/// ([`crate::run::DirState::Replace`]) is staged beside it and swapped in once its first population is
/// stored, so that the directory holds the old run or the new one at every moment. The
/// directory is created only once everything that can be refused has been.
pub fn start(data: FieldData, config: Config, how: Start, observer: &mut dyn Observer) -> Result<Outcome> {
    config.validate()?;
    if let Some(dir) = how.dir {
        check_new(dir, Some(&data.source))?;
    }
    let fits = match how.fits {
        Some(fits) => fits,
        None => fit::fit_record(&config.laws, &data, &config.fit)?,
    };
    let mut scoring = how.scoring;
    start_with_fits(how.dir, data, config, fits, how.prior_file, &mut scoring, observer)
}

/// [`start`] after the fits: the floor, the prior, the evaluator, the sampler.
fn start_with_fits(
    dir: Option<&Dir>,
    data: FieldData,
    mut config: Config,
    fits: Vec<fit::LawFit>,
    prior_file: Option<&PriorFile>,
    scoring: &mut Scoring,
    observer: &mut dyn Observer,
) -> Result<Outcome> {
    let input = data.source.clone();
    let base = config.sampler.schedule_mut();
    let floor = floor::resolve(&fits, (!config.eps_min_from_record).then_some(base.eps_min))?;
    base.eps_min = floor.eps_min;
    floor::check_start_epsilon(&fits, base.start_epsilon)?;
    // A schedule ends the run itself: a floor out of reach says nothing then.
    if let Some(line) = &floor.note
        && base.epsilons.is_none()
    {
        observer.note(line.clone());
    }
    let prior = Prior::from_fits_by(
        &fits,
        config.prior_rule,
        config.delta,
        prior_file,
        data.torque_unit.newton_metres(),
    )?;
    let problem = Problem::new(prior.clone(), config.seed, &data.calibration, config.fit.w_ref_n).with_best_rho(&fits);
    let evaluator = scoring.workers(problem, &Placement::of(&config), &mut |line| observer.note(line))?;
    config.take_shape_of(evaluator.as_ref());
    let mut setup = Setup {
        config: serde_json::to_value(&config).expect("the configuration serialises"),
        data,
        fits,
        prior,
    };
    let (run, lock) = match dir {
        Some(dir) => {
            let mut claim = Claim::new(dir, Some(&input))?;
            let store = Store::create(claim.store_dir(), &setup)?;
            let run = sample(
                Some(store),
                Some(&mut claim),
                "start",
                &config,
                evaluator.as_ref(),
                Vec::new(),
                observer,
            )?;
            (run, Some(claim.finish()?))
        }
        None => (
            sample(None, None, "start", &config, evaluator.as_ref(), Vec::new(), observer)?,
            None,
        ),
    };
    let added = run.populations.len();
    // Workers elsewhere name their shape only once they have scored.
    config.take_shape_of(evaluator.as_ref());
    setup.config = serde_json::to_value(&config).expect("the configuration serialises");
    Ok(Outcome {
        config,
        setup,
        run,
        backend: evaluator.backend(),
        lock,
        added,
    })
}

/// Writes a run made in memory (`outcome`, whose populations all hold their particles) to the
/// run directory `dir` as [`start`] would have written it: the same store (set-up, every
/// population, the invocation that made them), so that export, report, stability and the
/// selection check read it and [`resume`] continues it exactly. Checked and claimed like a new
/// run; a run it replaces ([`crate::run::DirState::Replace`]) stays until the new store is complete.
/// Returns the directory's lock, under which the caller writes the summary files.
pub fn save(dir: &Dir, outcome: &Outcome) -> Result<files::DirLock> {
    let (setup, run) = (&outcome.setup, &outcome.run);
    let populations = &run.populations;
    if populations.is_empty() {
        return Err(Error::Incomplete(format!(
            "the run has no completed population ({}): nothing to write",
            run.stop.describe()
        )));
    }
    if let Some(p) = populations.iter().find(|p| p.particles.len() != p.record.accepted) {
        return Err(Error::Incomplete(format!(
            "population {} holds {} of its {} particles in memory: only a run kept whole in memory can be written",
            p.record.index,
            p.particles.len(),
            p.record.accepted
        )));
    }
    let input = setup.data.source.clone();
    check_new(dir, Some(&input))?;
    let mut claim = Claim::new(dir, Some(&input))?;
    let mut store = Store::create(claim.store_dir(), setup)?;
    let invocation = store.begin_invocation("start", outcome.backend, &setup.config)?;
    let mut previous = None;
    for population in populations {
        store.append_population(population, previous)?;
        previous = Some(population);
    }
    let stop = serde_json::to_value(run.stop).expect("a stop reason serialises");
    store.finish_invocation(
        invocation,
        stop.as_str().unwrap_or_default(),
        outcome.backend,
        &setup.config,
    )?;
    drop(store);
    claim.put_in_place()?;
    claim.finish()
}

/// The first store schema written by bitrock with the integer-exact candidate transform
/// ([`crate::rng::uniform_between`]); runs of older stores cannot be continued exactly.
const FIRST_EXACT_CANDIDATES_SCHEMA: i64 = 2;

/// Continues the run in `dir` after its last stored population with the stopping rules of
/// `more`, scored where `scoring` says; the populations are those an uninterrupted run with
/// the same settings gives.
pub fn resume(dir: &Path, more: &Continuation, mut scoring: Scoring, observer: &mut dyn Observer) -> Result<Outcome> {
    let store = Store::open(dir)?;
    if store.schema_version() < FIRST_EXACT_CANDIDATES_SCHEMA {
        return Err(Error::Data {
            path: store.path().to_path_buf(),
            message: format!(
                "written by an older bitrock (store schema {}), whose candidate parameters were rounded differently (by an ulp in some candidates): continuing it would not reproduce an uninterrupted run; start a new run (export and report still read this one)",
                store.schema_version()
            ),
        });
    }
    let lock = files::DirLock::acquire(dir)?;
    files::remove_stale(dir);
    let Stored { setup, populations } = store.load_with_last_particles()?;

    let mut config: Config = serde_json::from_value(setup.config.clone()).map_err(|e| Error::Store {
        path: dir.join(STORE_FILE),
        message: format!("the stored configuration is not one this bitrock reads: {e}"),
    })?;
    check_stored_run(dir, &config, &setup.prior, &populations)?;
    let stored_config = config.clone();
    config.sampler.apply(more);
    config.backend = more.backend.unwrap_or(config.backend);
    config.devices = more.devices.unwrap_or(config.devices);
    config.validate()?;
    config.check_summary_population(more.summary_population)?;
    let problem = Problem::new(
        setup.prior.clone(),
        config.seed,
        &setup.data.calibration,
        config.fit.w_ref_n,
    )
    .with_best_rho(&setup.fits);
    let evaluator = scoring.workers(problem, &Placement::of(&config), &mut |line| observer.note(line))?;
    config.take_shape_of(evaluator.as_ref());
    let stored = populations.len();
    observer.note(format!(
        "continuing {} after population {} ({} stored)",
        dir.display(),
        stored.saturating_sub(1),
        stored
    ));
    let run = sample(
        Some(store),
        None,
        "resume",
        &config,
        evaluator.as_ref(),
        populations,
        observer,
    )?;
    let added = run.populations.len() - stored;
    config.take_shape_of(evaluator.as_ref());
    if added == 0 {
        // Nothing was run: the stored facts stand, and so does every file made from them.
        config = stored_config;
    }
    let setup = Setup {
        config: serde_json::to_value(&config).expect("the configuration serialises"),
        ..setup
    };
    Ok(Outcome {
        config,
        setup,
        run,
        backend: evaluator.backend(),
        lock: Some(lock),
        added,
    })
}

/// Refuses a store whose populations no longer match its settings (rows deleted or edited by
/// hand): the sampler continues from the last population and would otherwise silently give a
/// run that no settings produce. Earlier populations are loaded without particles
/// (`load_with_last_particles`), so their records are checked, and the last one's particles:
/// the count, each particle's law, parameters inside the stored prior, ρ below its ε, and
/// weights that sum to 1.
fn check_stored_run(dir: &Path, config: &Config, prior: &Prior, populations: &[Population]) -> Result<()> {
    let refuse = |g: usize, what: String| Error::Data {
        path: dir.join(STORE_FILE),
        message: format!(
            "population {g} {what}; the store was altered and this run cannot be continued (start a new run)"
        ),
    };
    let n = config.sampler.schedule().particles;
    let mut previous_epsilon = f64::INFINITY;
    for (g, p) in populations.iter().enumerate() {
        let r = &p.record;
        if r.index != g {
            return Err(refuse(g, format!("is stored as population {}", r.index)));
        }
        if r.accepted != n {
            return Err(refuse(
                g,
                format!("holds {} particles where the run draws {n}", r.accepted),
            ));
        }
        let epsilon = r.epsilon.unwrap_or(f64::INFINITY);
        if g > 0 && epsilon.partial_cmp(&previous_epsilon) != Some(std::cmp::Ordering::Less) {
            return Err(refuse(
                g,
                format!("has ε = {epsilon}, not below the previous population's {previous_epsilon}"),
            ));
        }
        previous_epsilon = epsilon;
    }
    let Some(last) = populations.last() else {
        return Ok(());
    };
    let g = last.record.index;
    if last.particles.len() != last.record.accepted {
        return Err(refuse(
            g,
            format!("has {} of its {} particles", last.particles.len(), last.record.accepted),
        ));
    }
    let epsilon = last.record.epsilon.unwrap_or(f64::INFINITY);
    for particle in &last.particles {
        let Some(law_box) = prior.boxes.iter().find(|b| b.law == particle.law) else {
            return Err(refuse(
                g,
                format!("holds a particle of {}, a law the run does not compete", particle.law),
            ));
        };
        if particle.params.len() != particle.law.n_params() || !law_box.contains(&particle.params) {
            return Err(refuse(
                g,
                format!(
                    "holds a {} particle (index {}) outside the run's prior",
                    particle.law, particle.index
                ),
            ));
        }
        if particle.rho.partial_cmp(&epsilon) != Some(std::cmp::Ordering::Less) {
            return Err(refuse(
                g,
                format!(
                    "holds a particle (index {}) with ρ = {} not below its ε = {epsilon}",
                    particle.index, particle.rho
                ),
            ));
        }
    }
    let total: f64 = last.particles.iter().map(|p| p.weight).sum();
    if !last.particles.iter().all(|p| p.weight.is_finite() && p.weight >= 0.0) || (total - 1.0).abs() > 1e-6 {
        return Err(refuse(g, format!("has particle weights summing to {total}, not 1")));
    }
    Ok(())
}

/// Runs the sampler after `previous`, writing each new population to `store` when there is
/// one, and putting a staged run in place once its first population is stored.
fn sample(
    store: Option<Store>,
    claim: Option<&mut Claim>,
    kind: &'static str,
    config: &Config,
    evaluator: &dyn Workers,
    previous: Vec<Population>,
    observer: &mut dyn Observer,
) -> Result<Run> {
    let Some(store) = store else {
        return run_sampler(config, evaluator, previous, observer);
    };
    let invocation = Invocation {
        kind,
        backend: evaluator.backend(),
        config: serde_json::to_value(config).expect("the configuration serialises"),
        id: None,
    };
    let mut storing = Storing {
        store: Writer::Here(store),
        claim,
        inner: observer,
        invocation,
    };
    // A new run's invocation is stored at once; a resumed run's with its first new population,
    // so that a resume which adds none leaves the store as it was.
    if kind == "start" {
        storing.begin_invocation()?;
    }
    let run = run_sampler(config, evaluator, previous, &mut storing);
    let invocation = storing.invocation.id;
    // Every population handed over is written before the run is reported (or its error).
    let store = storing.store.finish();
    let run = run?;
    let mut store = store?;
    if let Some(invocation) = invocation {
        let stop = serde_json::to_value(run.stop).expect("a stop reason serialises");
        // The backends that scored, as the workers reported them (a pool may mix them), and
        // the GPU scoring shape, which workers elsewhere name only once they have scored.
        let mut finished = config.clone();
        finished.take_shape_of(evaluator);
        store.finish_invocation(
            invocation,
            stop.as_str().unwrap_or_default(),
            evaluator.backend(),
            &serde_json::to_value(&finished).expect("the configuration serialises"),
        )?;
    }
    Ok(run)
}

/// One invocation of a run (`start` or `resume`) as the store records it.
struct Invocation {
    kind: &'static str,
    backend: &'static str,
    config: serde_json::Value,
    /// Its row in the store, once begun.
    id: Option<i64>,
}

/// The configured sampler from `previous` on.
fn run_sampler(
    config: &Config,
    workers: &dyn Workers,
    previous: Vec<Population>,
    observer: &mut dyn Observer,
) -> Result<Run> {
    match &config.sampler {
        SamplerConfig::Rejection(c) => rejection::run_on(workers, c, previous, observer),
        SamplerConfig::Smc(c) => smc::run_on(workers, c, previous, observer),
    }
}

/// Writes every completed population to the store; the first one stored puts a staged run in
/// place. Once the run is in place, populations are written by a thread of their own while
/// the sampler draws the next one (at N = 10⁶ the writes are seconds: on a GPU, longer than
/// the scoring), one at a time and in order; a failed write ends the run with its error at
/// the next population or at the end.
struct Storing<'a> {
    store: Writer,
    claim: Option<&'a mut Claim>,
    inner: &'a mut dyn Observer,
    invocation: Invocation,
}

impl Storing<'_> {
    /// Records the invocation in the store (once; the store is still on this thread then).
    fn begin_invocation(&mut self) -> Result<()> {
        if self.invocation.id.is_some() {
            return Ok(());
        }
        let Writer::Here(store) = &mut self.store else {
            return Err(Error::Incomplete(
                "the invocation is recorded before any population is written".into(),
            ));
        };
        let inv = &self.invocation;
        self.invocation.id = Some(store.begin_invocation(inv.kind, inv.backend, &inv.config)?);
        Ok(())
    }
}

/// The run store, written on this thread or by a thread of its own.
enum Writer {
    Here(Store),
    Thread {
        layout: store::Layout,
        /// A rendezvous channel: a population is handed over when the thread has written the
        /// one before, so at most one population's copy waits (memory stays O(N)).
        queue: std::sync::mpsc::SyncSender<PendingPopulation>,
        thread: std::thread::JoinHandle<Result<Store>>,
    },
    /// The thread failed, and its error was returned.
    Failed,
}

impl Writer {
    /// Hands `population` to the writing thread, starting it the first time.
    fn hand_over(&mut self, population: &Population, previous: Option<&Population>) -> Result<()> {
        if let Writer::Here(store) = self {
            let layout = store.layout();
            let Writer::Here(mut store) = std::mem::replace(self, Writer::Failed) else {
                unreachable!("matched above")
            };
            let (queue, receive) = std::sync::mpsc::sync_channel::<PendingPopulation>(0);
            let thread = std::thread::Builder::new()
                .name("bitrock-store".into())
                .spawn(move || {
                    for pending in receive {
                        store.write_pending(pending)?;
                    }
                    Ok(store)
                })
                .map_err(|e| Error::Incomplete(format!("cannot start the store's writing thread: {e}")))?;
            *self = Writer::Thread { layout, queue, thread };
        }
        let Writer::Thread { layout, queue, .. } = self else {
            return Err(Error::Incomplete("the run store's writer failed before".into()));
        };
        if queue.send(layout.prepare(population, previous)).is_err() {
            // The thread stopped at a failed write: its error ends the run.
            return std::mem::replace(self, Writer::Failed).finish().map(|_| ());
        }
        Ok(())
    }

    /// The store once every population handed over is written, or the first write's error.
    fn finish(self) -> Result<Store> {
        match self {
            Writer::Here(store) => Ok(store),
            Writer::Thread { queue, thread, .. } => {
                drop(queue);
                match thread.join() {
                    Ok(result) => result,
                    Err(panic) => std::panic::resume_unwind(panic),
                }
            }
            Writer::Failed => Err(Error::Incomplete("the run store's writer failed before".into())),
        }
    }
}

impl Observer for Storing<'_> {
    fn progress(&mut self, progress: &Progress) {
        self.inner.progress(progress);
    }

    fn population_done(&mut self, population: &Population, previous: Option<&Population>) -> Result<()> {
        self.begin_invocation()?;
        match (&mut self.store, self.claim.as_deref_mut()) {
            // A staged run is put in place once its first population is stored: written here.
            (Writer::Here(store), Some(claim)) if claim.is_staged() => {
                store.append_population(population, previous)?;
                claim.put_in_place()?;
                // SQLite names its journal after the path it opened: reopen at the new place.
                self.store = Writer::Here(Store::open(&claim.dir)?);
            }
            (store, _) => store.hand_over(population, previous)?,
        }
        self.inner.population_done(population, previous)
    }

    /// The store holds every population's particles.
    fn keeps_particles(&self) -> bool {
        true
    }

    fn note(&mut self, line: String) {
        self.inner.note(line);
    }

    fn interrupted(&mut self) -> bool {
        self.inner.interrupted()
    }
}
