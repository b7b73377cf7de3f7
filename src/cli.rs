//! Command-line interface: clap structures only. Each subcommand turns into validated library
//! configuration in `main.rs` before any work starts.

use bitrock::data::{DataOptions, SplitRule};
use bitrock::eval::Backend;
use bitrock::units::{ForceUnit, SpeedUnit, TorqueUnit};
use clap::{Args, Parser, Subcommand, ValueEnum};
use std::path::PathBuf;

/// Calibrate and select drill-string bit-rock interaction laws from downhole measurements of
/// bit speed and torque on bit, and simulate torsional stick-slip.
///
/// Laws (Castello & Ritto): m1 Tucker-Wang (tanh + hump), m2 Navarro-Lopez exponential decay,
/// m3 exponential bump + tanh (the paper's new law), m4 cubic polynomial. Bit speed w in rad/s;
/// every law is scaled by r = WOB / W_ref.
#[derive(Debug, Parser)]
#[command(name = "bitrock", version, about, long_about)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Least-squares fit of each law to a field record (the paper's deterministic calibration).
    Fit(FitCmd),
    /// ABC with model selection, rejection (the paper's Algorithm 1) or SMC: posterior law
    /// probabilities and parameter distributions, written to a run directory and its store;
    /// `--resume DIR` continues a killed or finished run.
    Abc(Box<AbcCmd>),
    /// Export a run directory's store: particles as CSV (one row per particle, parameters in
    /// columns, the record's torque unit), or the whole run as JSON.
    Export(ExportCmd),
    /// The paper's figures (SVG and PNG) and report.md from one or more run directories, e.g.
    /// the runs for δ = 0.4, 0.6 and 0.8 of one record; the first is the reference run of the
    /// single-run figures (correlations, envelopes, stability maps).
    Report(ReportCmd),
    /// Simulate the 1-DOF torsional drill string with a bit-rock law; writes a field-like CSV.
    Simulate(SimulateCmd),
    /// The whole paper on the embedded (synthetic) demo record: fits, ABC for δ = 0.4, 0.6, 0.8,
    /// stability maps (1-DOF and FE) and the report, ending with the headline numbers.
    Demo(DemoCmd),
    /// Score the same candidates on the CPU and the GPU and report their agreement: what to run
    /// on new hardware before trusting its GPU. Exit status 1 when a check fails.
    Parity(ParityCmd),
    /// Benchmark report: evaluator throughput per law and backend, the fixed cost of a call,
    /// a paper-scale ABC run end to end, and rejection versus SMC to the same ε.
    Bench(BenchCmd),
    /// Natural frequencies, modal damping and critical bit damping of the finite-element
    /// torsional drill string (the paper's appendix).
    Fe(FeCmd),
    /// Stability maps over top-drive speed and weight on bit: deterministic (MAP), stochastic
    /// (percentile over posterior samples) and the mixture of laws, from an ABC run or a law.
    Stability(StabilityCmd),
}

/// Which columns of the CSV to read, their units, and which rows to use.
#[derive(Debug, Args, Clone)]
pub struct DataArgs {
    /// Bit-speed column [default: the one column whose name contains "speed"].
    #[arg(long, value_name = "NAME")]
    pub speed_col: Option<String>,
    /// Torque-on-bit column [default: the one column whose name contains "torque"].
    #[arg(long, value_name = "NAME")]
    pub torque_col: Option<String>,
    /// Weight-on-bit column [default: the one column whose name contains "wob", if any].
    #[arg(long, value_name = "NAME")]
    pub wob_col: Option<String>,
    /// Time column, in seconds [default: the one column whose name contains "time", if any].
    #[arg(long, value_name = "NAME")]
    pub time_col: Option<String>,
    /// Unit of the speed column [default: from its suffix, _rpm or _rad_s].
    #[arg(long, value_enum)]
    pub speed_unit: Option<SpeedUnit>,
    /// Unit of the torque column [default: from its suffix, _nm or _knm].
    #[arg(long, value_enum)]
    pub torque_unit: Option<TorqueUnit>,
    /// Unit of the weight-on-bit column [default: from its suffix, _n or _kn].
    #[arg(long, value_enum)]
    pub wob_unit: Option<ForceUnit>,
    /// Drop rows whose bit speed is below this, rpm: the laws hold for a turning bit, and
    /// stick-phase samples say nothing about them.
    #[arg(long, default_value_t = 5.0, value_name = "RPM")]
    pub min_speed_rpm: f64,
    /// Use only rows at or after this time, s (needs a time column).
    #[arg(long, value_name = "SECONDS")]
    pub t_start_s: Option<f64>,
    /// Use only rows at or before this time, s (needs a time column).
    #[arg(long, value_name = "SECONDS")]
    pub t_end_s: Option<f64>,
    /// Keep every K-th row of the time window (applied before the speed filter).
    #[arg(long, default_value_t = 1, value_name = "K")]
    pub thin: usize,
    /// Fraction of the kept rows used for calibration; the rest validates the fit.
    #[arg(long, default_value_t = 0.5, value_name = "F")]
    pub calibration_fraction: f64,
    /// How calibration rows are chosen: block = the first part of the record, interleaved =
    /// spread evenly through it.
    #[arg(long, value_enum, default_value_t = SplitRule::Block)]
    pub split: SplitRule,
}

impl DataArgs {
    pub fn options(&self) -> DataOptions {
        DataOptions {
            speed_column: self.speed_col.clone(),
            torque_column: self.torque_col.clone(),
            wob_column: self.wob_col.clone(),
            time_column: self.time_col.clone(),
            speed_unit: self.speed_unit,
            torque_unit: self.torque_unit,
            wob_unit: self.wob_unit,
            min_speed_rpm: self.min_speed_rpm,
            t_start_s: self.t_start_s,
            t_end_s: self.t_end_s,
            thin: self.thin,
            calibration_fraction: self.calibration_fraction,
            split: self.split,
        }
    }
}

/// How the least-squares fit runs.
#[derive(Debug, Args, Clone)]
pub struct FitArgs {
    /// Laws to fit, comma-separated.
    #[arg(long, default_value = "m1,m2,m3,m4", value_parser = bitrock::laws::parse_law_list)]
    pub laws: std::vec::Vec<bitrock::Law>,
    /// Lift the physical bounds (positive static and dynamic torques, positive rates and widths).
    #[arg(long)]
    pub no_bounds: bool,
    /// Starting points polished by Levenberg-Marquardt per law (chosen from a data-driven grid).
    #[arg(long, default_value_t = 6, value_name = "N")]
    pub starts: usize,
    /// Scale each sample's predicted torque by r = WOB / W_ref (needs a WOB column). Off: r = 1,
    /// the paper's assumption that the record was taken at W = W_ref.
    #[arg(long)]
    pub scale_by_wob: bool,
    /// Reference weight on bit W_ref, kN.
    #[arg(long, default_value_t = 244.2, value_name = "KN")]
    pub w_ref_kn: f64,
}

#[derive(Debug, Args)]
pub struct FitCmd {
    /// Field record (CSV with a header) [default: the embedded demo record].
    pub data: Option<PathBuf>,
    #[command(flatten)]
    pub data_args: DataArgs,
    #[command(flatten)]
    pub fit: FitArgs,
    /// Print JSON instead of tables.
    #[arg(long)]
    pub json: bool,
}

/// Where the simulation starts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum InitialState {
    /// Steady rotation at the top-drive speed, with the bit speed kicked by --kick-rpm.
    Equilibrium,
    /// Everything at rest; the top drive starts at the set speed at t = 0.
    Rest,
}

#[derive(Debug, Args)]
pub struct SimulateCmd {
    /// Bit-rock law (m1, m2, m3, m4).
    #[arg(long)]
    pub law: bitrock::Law,
    /// The law's parameters in its order (m2: tsb,tcb,g), torques in --param-torque-unit
    /// [default: the paper's least-squares estimate].
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true, value_name = "P1,P2,...")]
    pub params: Option<Vec<f64>>,
    /// Torque unit of the torque-valued parameters in --params.
    #[arg(long, value_enum, default_value_t = TorqueUnit::KNm)]
    pub param_torque_unit: TorqueUnit,
    /// Top-drive (rotary table) speed Omega, rpm.
    #[arg(long, value_name = "RPM")]
    pub omega_rpm: f64,
    /// Weight on bit W, kN.
    #[arg(long, default_value_t = 244.2, value_name = "KN")]
    pub wob_kn: f64,
    /// Reference weight on bit W_ref at which the law's parameters hold, kN.
    #[arg(long, default_value_t = 244.2, value_name = "KN")]
    pub w_ref_kn: f64,
    #[command(flatten)]
    pub lumped: LumpedArgs,
    /// Recorded duration, s.
    #[arg(long, default_value_t = 60.0, value_name = "SECONDS")]
    pub duration_s: f64,
    /// Simulated time discarded before recording starts (lets a limit cycle settle), s.
    #[arg(long, default_value_t = 0.0, value_name = "SECONDS")]
    pub settle_s: f64,
    /// Output sample rate, Hz (the paper's downhole tool records at 50 Hz).
    #[arg(long, default_value_t = 50.0, value_name = "HZ")]
    pub sample_hz: f64,
    /// Integration step of the RK4 scheme, s.
    #[arg(long, default_value_t = 1e-3, value_name = "SECONDS")]
    pub dt_s: f64,
    /// Initial state.
    #[arg(long, value_enum, default_value_t = InitialState::Equilibrium)]
    pub initial: InitialState,
    /// Bit-speed kick added to steady rotation at t = 0 (with --initial equilibrium), rpm.
    #[arg(long, default_value_t = 5.0, value_name = "RPM", allow_hyphen_values = true)]
    pub kick_rpm: f64,
    /// Standard deviation of Gaussian noise added to the recorded torque, kN·m.
    #[arg(long, default_value_t = 0.0, value_name = "KNM")]
    pub noise_torque_knm: f64,
    /// Standard deviation of Gaussian noise added to the recorded bit speed, rpm.
    #[arg(long, default_value_t = 0.0, value_name = "RPM")]
    pub noise_speed_rpm: f64,
    /// Standard deviation of a slow random fluctuation of the weight on bit, kN.
    #[arg(long, default_value_t = 0.0, value_name = "KN")]
    pub wob_fluctuation_kn: f64,
    /// Correlation time of the weight-on-bit fluctuation, s.
    #[arg(long, default_value_t = 20.0, value_name = "SECONDS")]
    pub wob_correlation_s: f64,
    /// Seed of the noise and fluctuation generator.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Output CSV (time_s, bit_speed_rpm, torque_knm, wob_kn) [default: standard output].
    #[arg(long, short, value_name = "FILE")]
    pub out: Option<PathBuf>,
}

/// Which ABC sampler runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Sampler {
    Rejection,
    Smc,
}

/// How the ABC sampler runs.
#[derive(Debug, Args, Clone)]
pub struct AbcArgs {
    /// Particles per population, N (the paper's 25,000).
    #[arg(long, default_value_t = 25_000, value_name = "N")]
    pub particles: usize,
    /// Prior half-width: each parameter is uniform on [p(1 − δ), p(1 + δ)] around its
    /// least-squares estimate p, clipped to its physical bound.
    #[arg(long, default_value_t = 0.4, value_name = "DELTA", allow_hyphen_values = true)]
    pub delta: f64,
    /// Prior file (TOML) with explicit bounds or law weights; overrides the δ rule where it
    /// speaks (format in the README).
    #[arg(long, value_name = "FILE")]
    pub prior: Option<PathBuf>,
    /// Smallest tolerance on ρ: the population that reaches it is the last [default: 0.014,
    /// the paper's; with --resume: the run's].
    #[arg(long, value_name = "EPS")]
    pub eps_min: Option<f64>,
    /// Tolerance schedule ε_1 > ε_2 > ... instead of the median rule (ε_0 stays ∞).
    #[arg(long, value_delimiter = ',', value_name = "E1,E2,...")]
    pub epsilons: Option<Vec<f64>>,
    /// Tolerance of population 0 [default: ∞, the first N prior draws].
    #[arg(long, value_name = "EPS")]
    pub start_epsilon: Option<f64>,
    /// Most populations, population 0 included [default: 30; with --resume: the run's].
    #[arg(long, value_name = "G")]
    pub max_populations: Option<usize>,
    /// Most candidates scored over the run [default: 2e9; with --resume: the run's].
    #[arg(long, value_name = "COUNT")]
    pub max_draws: Option<u64>,
    /// Stop when the projected acceptance rate of the next population falls below this
    /// [default: 1e-5; with --resume: the run's].
    #[arg(long, value_name = "RATE")]
    pub min_acceptance: Option<f64>,
    /// Wall-time budget of this invocation in seconds; the population in progress is dropped
    /// and the run can be continued with --resume (which has no budget unless given again).
    #[arg(long, value_name = "SECONDS")]
    pub max_seconds: Option<f64>,
    /// nested: one candidate stream, each population keeps the previous particles below its
    /// tolerance (same distribution, 0.38× the evaluations on the demo record); paper: a fresh stream per
    /// population, as the paper's Algorithm 1.
    #[arg(long, value_enum, default_value_t = bitrock::abc::rejection::Mode::Nested)]
    pub mode: bitrock::abc::rejection::Mode,
    /// rejection: the paper's Algorithm 1 (see --mode); smc: ABC-SMC with model selection
    /// (population 0 from the prior, then perturbed, importance-weighted populations).
    #[arg(long, value_enum, default_value_t = Sampler::Rejection)]
    pub sampler: Sampler,
    /// SMC: probability that the model kernel keeps a particle's law (else it jumps uniformly
    /// to another law still alive).
    #[arg(long, default_value_t = 0.7, value_name = "P", allow_hyphen_values = true)]
    pub p_stay: f64,
    /// SMC: the Gaussian perturbation's covariance is this times the weighted covariance of
    /// the law's previous particles (2: Beaumont et al. 2009).
    #[arg(long, default_value_t = 2.0, value_name = "S", allow_hyphen_values = true)]
    pub kernel_scale: f64,
    /// SMC: where the importance weights' O(N²) kernel sums run. host: f64 on the CPU, so
    /// that GPU and CPU runs give the same populations; evaluator: on the --backend (the
    /// GPU's f32 kernel: faster for large N, but its populations drift from the CPU run's).
    #[arg(long, value_enum, default_value_t = bitrock::abc::smc::WeightsOn::Host)]
    pub smc_weights: bitrock::abc::smc::WeightsOn,
    /// Seed of the candidate streams: the same seed gives the same populations.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Worker threads [default: all cores].
    #[arg(long, value_name = "N")]
    pub threads: Option<usize>,
    /// Where ρ is computed: auto = the GPU when an adapter exists (else the CPU, saying so),
    /// gpu = the GPU or an error, cpu = the f64 reference [default: auto; with --resume: the
    /// run's].
    #[arg(long, value_enum)]
    pub backend: Option<Backend>,
    /// Population to summarise (statistics, MAP, envelopes) [default: the last].
    #[arg(long, value_name = "G")]
    pub summary_population: Option<usize>,
}

#[derive(Debug, Args)]
pub struct AbcCmd {
    /// Field record (CSV with a header) [default: the embedded demo record].
    pub data: Option<PathBuf>,
    /// Run directory to write: run.sqlite (the run store: every population and particle,
    /// written as each population completes), run.json (summary) and envelopes.csv.
    #[arg(long, value_name = "DIR", required_unless_present = "resume")]
    pub out: Option<PathBuf>,
    /// Replace a non-empty run directory.
    #[arg(long)]
    pub force: bool,
    /// Continue the run in DIR (killed or finished) after its last stored population: more
    /// populations, a lower --eps-min, a new --max-draws/--max-seconds or --backend. The
    /// populations are exactly those an uninterrupted run gives.
    #[arg(long, value_name = "DIR", conflicts_with_all = [
        "data", "out", "force", "speed_col", "torque_col", "wob_col", "time_col", "speed_unit", "torque_unit",
        "wob_unit", "t_start_s", "t_end_s", "thin", "min_speed_rpm", "calibration_fraction", "split", "laws",
        "no_bounds", "starts", "scale_by_wob", "w_ref_kn", "particles", "delta", "prior", "epsilons",
        "start_epsilon", "mode", "seed", "summary_population", "sampler", "p_stay", "kernel_scale", "smc_weights",
    ])]
    pub resume: Option<PathBuf>,
    /// No progress bar or population lines on stderr.
    #[arg(long, short)]
    pub quiet: bool,
    #[command(flatten)]
    pub data_args: DataArgs,
    #[command(flatten)]
    pub fit: FitArgs,
    #[command(flatten)]
    pub abc: AbcArgs,
    /// Print JSON instead of tables.
    #[arg(long)]
    pub json: bool,
}

/// Format of `bitrock export`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum ExportFormat {
    /// Particles: population, law, candidate, rho, weight, then every law's parameters.
    Csv,
    /// Configuration, data summary, fits, prior, and every population with its particles.
    Json,
}

#[derive(Debug, Args)]
pub struct ExportCmd {
    /// Run directory (written by `bitrock abc --out`).
    pub dir: PathBuf,
    #[arg(long, value_enum, default_value_t = ExportFormat::Csv)]
    pub format: ExportFormat,
    /// Only this population [default: all].
    #[arg(long, value_name = "G")]
    pub population: Option<usize>,
    /// Write to FILE instead of stdout.
    #[arg(long, short, value_name = "FILE")]
    pub out: Option<PathBuf>,
}

#[derive(Debug, Args)]
pub struct ReportCmd {
    /// Run directories (written by `bitrock abc --out`), all calibrated on the same record.
    #[arg(required = true, value_name = "DIR")]
    pub runs: Vec<PathBuf>,
    /// Report directory: report.md and figures/ (files of the same names are replaced).
    #[arg(long, value_name = "DIR", default_value = "bitrock-report")]
    pub out: PathBuf,
}

#[derive(Debug, Args)]
pub struct DemoCmd {
    /// Directory of the demo: the runs (delta-0.4/, delta-0.6/, delta-0.8/) and report/.
    #[arg(long, value_name = "DIR", default_value = "bitrock-demo")]
    pub out: PathBuf,
    /// Particles per population (the paper's N is 25,000).
    #[arg(long, default_value_t = 25_000, value_name = "N")]
    pub particles: usize,
    /// Seed of the candidate streams.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Worker threads [default: all cores].
    #[arg(long, value_name = "N")]
    pub threads: Option<usize>,
    /// Where ρ is computed (auto, gpu, cpu).
    #[arg(long, value_enum, default_value_t = Backend::Auto)]
    pub backend: Backend,
}

#[derive(Debug, Args)]
pub struct ParityCmd {
    /// Field record (CSV with a header) [default: the embedded demo record].
    pub data: Option<PathBuf>,
    #[command(flatten)]
    pub data_args: DataArgs,
    /// Laws to compare, comma-separated (priors from their least-squares fits, δ = 0.4).
    #[arg(long, default_value = "m1,m2,m3,m4", value_parser = bitrock::laws::parse_law_list)]
    pub laws: std::vec::Vec<bitrock::Law>,
    /// Candidates scored per law on each backend.
    #[arg(long, default_value_t = 100_000, value_name = "N")]
    pub candidates: usize,
    /// Tolerance at which accept/reject decisions are compared [default: each law's median ρ].
    #[arg(long, value_name = "EPS")]
    pub epsilon: Option<f64>,
    /// Seed of the candidate stream.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Print JSON instead of a table.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, Args)]
pub struct BenchCmd {
    /// Repetitions per measurement (median, min and max are reported).
    #[arg(long, default_value_t = 5, value_name = "R")]
    pub reps: usize,
    /// Laws to measure, comma-separated.
    #[arg(long, default_value = "m1,m2,m3,m4", value_parser = bitrock::laws::parse_law_list)]
    pub laws: std::vec::Vec<bitrock::Law>,
    /// Only this backend [default: both].
    #[arg(long, value_enum)]
    pub backend: Option<Backend>,
    /// Small sizes only (65,536 × 5,000; end-to-end with N = 5,000): a smoke test in seconds.
    #[arg(long)]
    pub quick: bool,
    /// Print JSON instead of lines.
    #[arg(long)]
    pub json: bool,
}

/// The finite-element drill string: a TOML file (the paper's table built in) and overrides.
#[derive(Debug, Args, Clone)]
pub struct FeArgs {
    /// TOML file with any of: shear_modulus_pa, density_kg_m3, dp_length_m, bha_length_m,
    /// dp_outer_m, dp_inner_m, bha_outer_m, bha_inner_m, dp_elements, bha_elements, alpha, beta.
    #[arg(long, value_name = "FILE")]
    pub fe_file: Option<PathBuf>,
    /// Elements in the drill pipe.
    #[arg(long, value_name = "N")]
    pub dp_elements: Option<usize>,
    /// Elements in the BHA.
    #[arg(long, value_name = "N")]
    pub bha_elements: Option<usize>,
    /// Mass-proportional Rayleigh damping α, 1/s.
    #[arg(long, value_name = "ALPHA")]
    pub alpha: Option<f64>,
    /// Stiffness-proportional Rayleigh damping β, s.
    #[arg(long, value_name = "BETA")]
    pub beta: Option<f64>,
}

/// The equivalent 1-DOF string.
#[derive(Debug, Args, Clone)]
pub struct LumpedArgs {
    /// Equivalent moment of inertia I_eq, kg·m².
    #[arg(long, default_value_t = 383.33, value_name = "KG_M2")]
    pub inertia_kg_m2: f64,
    /// Natural frequency omega_n, rad/s.
    #[arg(long, default_value_t = 0.85, value_name = "RAD_S")]
    pub omega_n_rad_s: f64,
    /// Damping ratio xi.
    #[arg(long, default_value_t = 0.25, value_name = "XI")]
    pub damping_ratio: f64,
}

impl LumpedArgs {
    /// The 1-DOF model these flags describe (validate before use).
    pub fn lumped(&self) -> bitrock::stability::lumped::Lumped {
        bitrock::stability::lumped::Lumped {
            inertia_kg_m2: self.inertia_kg_m2,
            omega_n_rad_s: self.omega_n_rad_s,
            damping_ratio: self.damping_ratio,
        }
    }
}

#[derive(Debug, Args)]
pub struct FeCmd {
    #[command(flatten)]
    pub fe: FeArgs,
    #[command(flatten)]
    pub lumped: LumpedArgs,
    /// Find β (keeping α) so that the string's critical bit damping equals the 1-DOF model's:
    /// the appendix's damping adjustment.
    #[arg(long)]
    pub match_1dof: bool,
    /// Print JSON instead of a table.
    #[arg(long)]
    pub json: bool,
}

/// Which structure decides stability.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Structure {
    /// The paper's 1-DOF model (closed-form 2x2 criterion).
    #[value(name = "1dof")]
    Lumped,
    /// The finite-element string (critical bit damping by bisection).
    Fe,
}

#[derive(Debug, Args)]
pub struct StabilityCmd {
    /// ABC run directory (from `bitrock abc`): MAP, posterior samples and law probabilities.
    #[arg(long, value_name = "DIR", conflicts_with_all = ["law", "params"])]
    pub run: Option<PathBuf>,
    /// A law for a what-if map without a run.
    #[arg(long, requires = "params")]
    pub law: Option<bitrock::Law>,
    /// The law's parameters in its order, torques in --torque-unit.
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true, value_name = "P1,P2,...")]
    pub params: Option<Vec<f64>>,
    /// Unit of the torque-valued parameters in --params.
    #[arg(long, value_enum, default_value_t = TorqueUnit::KNm)]
    pub torque_unit: TorqueUnit,
    /// Structure: 1dof (the paper's) or fe (the finite-element string).
    #[arg(long, value_enum, default_value_t = Structure::Lumped)]
    pub structure: Structure,
    #[command(flatten)]
    pub fe: FeArgs,
    #[command(flatten)]
    pub lumped: LumpedArgs,
    /// Reference weight on bit W_ref of the law's parameters, kN.
    #[arg(long, default_value_t = 244.2, value_name = "KN")]
    pub w_ref_kn: f64,
    /// Top-drive speeds, rpm, as MIN:MAX:COUNT.
    #[arg(long, default_value = "20:220:101", value_name = "MIN:MAX:COUNT")]
    pub omega_rpm: String,
    /// Weights on bit, kN, as MIN:MAX:COUNT.
    #[arg(long, default_value = "20:700:69", value_name = "MIN:MAX:COUNT")]
    pub wob_kn: String,
    /// Percentile of the stochastic boundary, %: the weight on bit above which at least this
    /// share of the posterior samples is unstable (the paper's 2 %).
    #[arg(long, default_value_t = 2.0, value_name = "PERCENT")]
    pub percentile: f64,
    /// Posterior samples per law for the stochastic maps (the paper's 700).
    #[arg(long, default_value_t = 700, value_name = "S")]
    pub samples: usize,
    /// Where the probability grids are computed (auto, gpu, cpu).
    #[arg(long, value_enum, default_value_t = Backend::Auto)]
    pub backend: Backend,
    /// Write the boundaries as CSV to FILE.
    #[arg(long, value_name = "FILE")]
    pub out: Option<PathBuf>,
    /// Print JSON (boundaries and probability grids) instead of a table.
    #[arg(long)]
    pub json: bool,
}
