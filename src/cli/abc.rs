//! `bitrock abc`: a new run into `--out`, or `--resume DIR`, through the library's
//! [`bitrock::run::abc`]; then the population table and posterior, or run.json on stdout.

use super::args::finite_number;
use super::args::{FitArgs, InferenceArgs, load_data, set_threads};
use super::print;
use super::progress::RunProgress;
use bitrock::Error;
use bitrock::abc::rejection::Mode;
use bitrock::abc::schedule::Schedule;
use bitrock::abc::shard::Devices;
use bitrock::abc::smc::{LawProposal, Perturbation, Refill, WeightsOn};
use bitrock::eval::Backend;
use bitrock::run::abc::{self, Analysis};
use bitrock::run::{abc::Continuation, abc::PriorRuleName, abc::Sampler, abc::Settings};
use clap::Args;
use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

/// How the ABC sampler runs.
#[derive(Debug, Args, Clone)]
pub struct AbcArgs {
    /// Particles per population, N (the paper's 25,000).
    #[arg(long, default_value_t = Schedule::default().particles, value_name = "N")]
    pub particles: usize,
    /// Prior half-width: each parameter is uniform on [p(1 − δ), p(1 + δ)] around its
    /// least-squares estimate p, clipped to its physical bound.
    #[arg(long, value_parser = finite_number, default_value_t = bitrock::run::abc::Config::default().delta, value_name = "DELTA", allow_hyphen_values = true)]
    pub delta: f64,
    /// How the prior boxes are sized: delta = the paper's φ̂(1 ± δ); stderr = φ̂ ± k·σ̂ with σ̂
    /// the least-squares standard error (k = --prior-k), which does not grow with |φ̂| (the
    /// δ box where σ̂ is undefined). Both clipped to the physical bounds.
    #[arg(long, value_enum, default_value_t = PriorRuleName::Delta)]
    pub prior_rule: PriorRuleName,
    /// Standard errors on each side of the estimate with --prior-rule stderr [default: 3].
    #[arg(long, value_parser = finite_number, value_name = "K", allow_hyphen_values = true)]
    pub prior_k: Option<f64>,
    /// Prior file (TOML) with explicit bounds or law weights; overrides the δ rule where it
    /// speaks (format in docs/commands.md).
    #[arg(long, value_name = "FILE")]
    pub prior: Option<PathBuf>,
    /// Smallest tolerance on ρ: the population that reaches it is the last [default: 0.014,
    /// the paper's; with --resume: the run's].
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, value_name = "EPS")]
    pub eps_min: Option<f64>,
    /// Tolerance schedule ε_1 > ε_2 > ... instead of the median rule (ε_0 stays ∞), run as
    /// given: the run ends with its last tolerance (values below --eps-min are refused).
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, value_delimiter = ',', value_name = "E1,E2,...")]
    pub epsilons: Option<Vec<f64>>,
    /// Tolerance of population 0 [default: ∞, the first N prior draws].
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, value_name = "EPS")]
    pub start_epsilon: Option<f64>,
    /// Most populations, population 0 included [default: 30; with --resume: the run's].
    #[arg(long, value_name = "G")]
    pub max_populations: Option<usize>,
    /// Most candidates scored over the run [default: 2e9; with --resume: the run's].
    #[arg(long, value_name = "COUNT")]
    pub max_draws: Option<u64>,
    /// Stop when the projected acceptance rate of the next population falls below this
    /// [default: 1e-5; with --resume: the run's].
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, value_name = "RATE")]
    pub min_acceptance: Option<f64>,
    /// Wall-time budget of this invocation in seconds; the population in progress is dropped
    /// and the run can be continued with --resume (which has no budget unless given again).
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, value_name = "SECONDS")]
    pub max_seconds: Option<f64>,
    /// Rejection sampler only. nested: one candidate stream, each population keeps the previous
    /// particles below its tolerance (same distribution, 0.38× the evaluations on the demo
    /// record); paper: a fresh stream per population, as the paper's Algorithm 1 [default:
    /// nested].
    #[arg(long, value_enum)]
    pub mode: Option<Mode>,
    /// rejection: the paper's Algorithm 1 (see --mode); smc: ABC-SMC with model selection
    /// (population 0 from the prior, then perturbed, importance-weighted populations).
    #[arg(long, value_enum, default_value_t = Sampler::Rejection)]
    pub sampler: Sampler,
    /// SMC only, with --law-proposal kernel: probability that the model kernel keeps a
    /// particle's law (else it jumps uniformly to another law still alive) [default: 0.7].
    #[arg(long, value_parser = finite_number, value_name = "P", allow_hyphen_values = true)]
    pub p_stay: Option<f64>,
    /// SMC only, with --perturbation global: the Gaussian perturbation's covariance is this times
    /// the weighted covariance of the law's ancestors [default: 2, Beaumont et al. 2009].
    #[arg(long, value_parser = finite_number, value_name = "S", allow_hyphen_values = true)]
    pub kernel_scale: Option<f64>,
    /// SMC only: where the importance weights' O(N²) kernel sums run. host: f64 on the CPU, so
    /// that GPU and CPU runs give the same populations; evaluator: on the --backend (the
    /// GPU's f32 kernel: faster for large N, but its populations drift from the CPU run's)
    /// [default: host].
    #[arg(long, value_enum)]
    pub smc_weights: Option<WeightsOn>,
    /// SMC only: how a population after the first is filled. fresh: N new proposals from the
    /// whole previous population; survivors: the previous particles below the new ε stay and
    /// new proposals from them top the population up to N [default: survivors].
    #[arg(long, value_enum)]
    pub refill: Option<Refill>,
    /// SMC only: how a proposal's law is chosen. kernel: by the previous population's law
    /// probabilities, then kept with probability --p-stay; worth: in proportion to each law's
    /// probability below the new ε, with a 5 % floor shared by the laws, and none for a law
    /// whose best least-squares ρ cannot reach ε [default: worth].
    #[arg(long, value_enum)]
    pub law_proposal: Option<LawProposal>,
    /// SMC only: the Gaussian step from an ancestor. global: one covariance per law,
    /// --kernel-scale × its ancestors' covariance; local: one per ancestor, the covariance of the
    /// law's particles below the new ε plus the ancestor's offset from their mean (Filippi et
    /// al. 2013: narrow at the posterior's centre, wide at its edges) [default: local].
    #[arg(long, value_enum)]
    pub perturbation: Option<Perturbation>,
    /// Seed of the candidate streams: the same seed gives the same populations.
    #[arg(long, default_value_t = bitrock::run::abc::Config::default().seed)]
    pub seed: u64,
    /// Worker threads [default: all cores].
    #[arg(long, value_name = "N")]
    pub threads: Option<usize>,
    /// Where ρ is computed: auto = the GPU when an adapter exists (else the CPU, saying so),
    /// gpu = the GPU or an error, cpu = the f64 reference [default: auto; with --resume: the
    /// run's].
    #[arg(long, value_enum)]
    pub backend: Option<Backend>,
    /// GPUs to score on: one = the one BITROCK_ADAPTER or CUDA_VISIBLE_DEVICES names (else
    /// the best), all = every GPU of the machine, each a share of every round; the populations
    /// are the same [default: one; with --resume: the run's].
    #[arg(long, value_enum)]
    pub devices: Option<Devices>,
    /// Population to summarise (statistics, MAP, envelopes) [default: the last].
    #[arg(long, value_name = "G")]
    pub summary_population: Option<usize>,
}

#[derive(Debug, Args)]
pub struct AbcCmd {
    /// Run directory to write: run.sqlite (the run store: every population and particle,
    /// written as each population completes), run.json (summary) and envelopes.csv.
    #[arg(long, value_name = "DIR", required_unless_present = "resume")]
    pub out: Option<PathBuf>,
    /// Replace a non-empty run directory.
    #[arg(long)]
    pub force: bool,
    /// Continue the run in DIR (killed or finished) after its last stored population: more
    /// populations, a lower --eps-min, a new --max-draws/--max-seconds or --backend, another
    /// --summary-population. The populations are exactly those an uninterrupted run gives.
    #[arg(long, value_name = "DIR", conflicts_with_all = super::args::resume_conflicts!(
        "particles", "delta", "prior_rule", "prior_k", "prior", "epsilons", "start_epsilon", "mode", "seed",
        "sampler", "p_stay", "kernel_scale", "smc_weights", "refill", "law_proposal", "perturbation",
    ))]
    pub resume: Option<PathBuf>,
    /// No progress bar or population lines on stderr.
    #[arg(long, short)]
    pub quiet: bool,
    #[command(flatten)]
    pub input: InferenceArgs,
    #[command(flatten)]
    pub abc: AbcArgs,
    /// Print JSON instead of tables.
    #[arg(long)]
    pub json: bool,
}

pub fn run(cmd: &AbcCmd) -> anyhow::Result<ExitCode> {
    let done = start_or_resume(cmd)?;
    for warning in done.run_warnings() {
        super::print::note(format_args!("warning: {warning}"));
    }
    let mut out = super::print::stdout();
    if cmd.json {
        super::print::json(&mut out, done.json())?;
    } else {
        let dir = cmd.resume.as_ref().or(cmd.out.as_ref()).expect("clap requires one");
        print::population_table(&mut out, &done.outcome.run)?;
        print::posterior(&mut out, &done.posterior, done.outcome.setup.data.torque_unit)?;
        print::answer(&mut out, done.answer.as_ref())?;
        writeln!(out, "\nrun written to {}", dir.display())?;
    }
    Ok(ExitCode::SUCCESS)
}

/// `bitrock abc`: a new run into `--out`, or `--resume DIR`; the library writes the run
/// directory and its summary files.
fn start_or_resume(cmd: &AbcCmd) -> anyhow::Result<Analysis> {
    set_threads(cmd.abc.threads)?;
    let mut progress = RunProgress::new(cmd.quiet);
    match (&cmd.resume, &cmd.out) {
        (Some(dir), _) => {
            let more = Continuation {
                eps_min: cmd.abc.eps_min,
                max_populations: cmd.abc.max_populations,
                max_draws: cmd.abc.max_draws,
                min_acceptance: cmd.abc.min_acceptance,
                max_seconds: cmd.abc.max_seconds,
                backend: cmd.abc.backend,
                devices: cmd.abc.devices,
                summary_population: cmd.abc.summary_population,
            };
            Ok(abc::resume(dir, &more, Default::default(), &mut progress)?)
        }
        (None, Some(dir)) => {
            let job = abc::Job {
                config: bitrock::run::abc::Config {
                    string: cmd.input.string.given().spec()?,
                    ..run_config(&cmd.input.fit, &cmd.abc)?
                },
                summary_population: cmd.abc.summary_population,
                out: Some(bitrock::run::Dir {
                    path: dir.clone(),
                    replace: cmd.force,
                }),
            };
            let data = load_data(&cmd.input.record)?;
            Ok(job.run(data, Default::default(), &mut progress)?)
        }
        (None, None) => Err(Error::setting("out", "give the run directory to write").into()),
    }
}

/// The run configuration the flags describe (the library applies the defaults and refuses
/// settings the run would ignore).
fn run_config(fit_args: &FitArgs, args: &AbcArgs) -> anyhow::Result<bitrock::run::abc::Config> {
    let settings = Settings {
        sampler: args.sampler,
        particles: Some(args.particles),
        delta: Some(args.delta),
        prior_rule: args.prior_rule,
        prior_k: args.prior_k,
        prior_file: args.prior.clone(),
        eps_min: args.eps_min,
        epsilons: args.epsilons.clone(),
        start_epsilon: args.start_epsilon,
        max_populations: args.max_populations,
        max_draws: args.max_draws,
        min_acceptance: args.min_acceptance,
        max_seconds: args.max_seconds,
        mode: args.mode,
        p_stay: args.p_stay,
        kernel_scale: args.kernel_scale,
        smc_weights: args.smc_weights,
        refill: args.refill,
        law_proposal: args.law_proposal,
        perturbation: args.perturbation,
        seed: Some(args.seed),
        backend: args.backend,
        devices: args.devices,
    };
    Ok(settings.config(Some(fit_args.laws()?), fit_args.options()?)?)
}
