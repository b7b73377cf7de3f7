//! The `bitrock` command line: one module per command, each with its clap arguments, its call
//! into the library and its printing; argument groups shared by several commands in [`args`],
//! printing shared by several in [`print`]. `main.rs` parses, dispatches and maps errors to
//! exit statuses.

pub mod abc;
pub mod args;
pub mod bench;
pub mod check;
pub mod coupled;
pub mod demo;
pub mod devices;
pub mod evidence;
pub mod export;
pub mod fe;
pub mod fields;
pub mod fit;
pub mod law;
pub mod parity;
pub mod print;
pub mod progress;
pub mod report;
pub mod serve;
pub mod simulate;
pub mod stability;
pub mod surface;
pub mod watch;

use clap::{Parser, Subcommand};

/// Exit statuses, for scripts (as `grep` tells "no match" from "error"); listed in `--help`.
pub mod exit {
    /// `bitrock parity` ran and found a difference between the CPU and the GPU.
    pub const DIFFERENCE: u8 = 1;
    /// Bad input (a file, a cell, a flag, named in the message); nothing was written.
    pub const BAD_INPUT: u8 = 2;
    /// A failure that stopped the work: no GPU adapter, a lost device, a full disk...
    pub const FAILURE: u8 = 3;
    /// The reader of the output pipe went away (`| head`): what a shell reports for a tool
    /// killed by SIGPIPE (128 + 13).
    pub const CLOSED_PIPE: u8 = 141;
}

/// Calibrate and select drill-string bit-rock interaction laws from downhole measurements of
/// bit speed and torque on bit, and simulate torsional stick-slip.
///
/// Laws (Castello & Ritto): m1 Tucker-Wang (tanh + hump), m2 Navarro-Lopez exponential decay,
/// m3 exponential bump + tanh (the paper's new law), m4 cubic polynomial. Bit speed w in rad/s;
/// every law is scaled by r = WOB / W_ref.
#[derive(Debug, Parser)]
#[command(name = "bitrock", version, about, long_about, after_long_help = EXIT_STATUS_HELP)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
    /// A law of your own, for every command that takes laws: a TOML law file (its name,
    /// parameters with units and bounds, the torque as an expression of w, r and the
    /// parameters; docs/law-files.md), named by its law's name in --laws and --law. Repeatable.
    #[arg(long = "law-file", value_name = "FILE", global = true)]
    pub law_files: Vec<std::path::PathBuf>,
}

impl Cli {
    /// Reads and registers every --law-file, so that the commands' --laws and --law name
    /// their laws.
    pub fn register_law_files(&self) -> anyhow::Result<()> {
        for path in &self.law_files {
            bitrock::laws::file::load_and_register(path)?;
        }
        Ok(())
    }
}

/// The exit statuses of [`exit`], as `--help` lists them.
const EXIT_STATUS_HELP: &str = "Exit status: 0 done; 1 `bitrock parity` ran and found a difference; 2 bad input (a file, \
cell or flag, named in the message; nothing written); 3 a failure that stopped the work (no GPU adapter, a lost \
device, a full disk...); 141 the output pipe was closed (`| head`).";

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Least-squares fit of each law to a field record (the paper's deterministic calibration).
    Fit(fit::FitCmd),
    /// ABC with model selection, rejection (the paper's Algorithm 1) or SMC: posterior law
    /// probabilities and parameter distributions, written to a run directory and its store;
    /// `--resume DIR` continues a killed or finished run.
    Abc(Box<abc::AbcCmd>),
    /// The model evidence of each law (its marginal likelihood, by tempered SMC with the
    /// residuals' noise integrated out) and the posterior law probabilities it gives, with
    /// Monte-Carlo errors and Bayes factors: what the data say about the laws, where the
    /// paper's ABC probabilities are ratios of prior volumes under a tolerance.
    Evidence(evidence::EvidenceCmd),
    /// Export a run directory's store: particles as CSV (one row per particle, parameters in
    /// columns, the record's torque unit), or the whole run as JSON.
    Export(export::ExportCmd),
    /// The paper's figures (SVG and PNG) and report.md from one or more run directories, e.g.
    /// the runs for δ = 0.4, 0.6 and 0.8 of one record; the first is the reference run of the
    /// single-run figures (correlations, envelopes, stability maps).
    Report(report::ReportCmd),
    /// Simulate the 1-DOF torsional drill string with a bit-rock law; writes a field-like CSV.
    Simulate(simulate::SimulateCmd),
    /// The coupled axial-torsional bit (Richard, Germay & Detournay): cutting and friction
    /// carried by a depth of cut that the bit's own rotation sets, simulated on the 1-DOF
    /// string; one string's record and regime, or `--map` the regimes (steady, stick-slip, bit
    /// bounce) over top-drive speed and weight on bit or feed.
    Coupled(Box<coupled::CoupledCmd>),
    /// The law at the bit from what the rig streams (top-drive speed and surface torque),
    /// through strings simulated per candidate (ABC-SMC on the cycle's summaries); the model
    /// choice checked by re-simulation, and what the surface implies at the bit.
    Surface(Box<surface::SurfaceCmd>),
    /// The whole paper on the embedded (synthetic) demo record: fits, ABC for δ = 0.4, 0.6, 0.8,
    /// stability maps (1-DOF and FE) and the report, ending with the headline numbers.
    Demo(demo::DemoCmd),
    /// Score the same candidates and simulate the same strings on the CPU and the GPU, and report
    /// their agreement: what to run on new hardware before trusting its GPU. Exit status 1 when
    /// a check fails.
    Parity(parity::ParityCmd),
    /// Benchmark report: evaluator throughput per law and backend, the fixed cost of a call,
    /// a paper-scale ABC run end to end, and rejection versus SMC to the same ε.
    Bench(bench::BenchCmd),
    /// How far the run's model selection can be trusted: K synthetic records per law made at the
    /// record's speeds (posterior parameters, bootstrapped residuals), each through the run's own
    /// fits, prior and sampler; the confusion matrix, written to RUN_DIR/selection/.
    CheckSelection(check::CheckCmd),
    /// Natural frequencies, modal damping and critical bit damping of the finite-element
    /// torsional drill string (the paper's appendix).
    Fe(fe::FeCmd),
    /// Read and compile a law file, and show it as bitrock understood it: parameters, units,
    /// bounds, the torque and its derivatives (dT/dw, ∂T/∂parameter), and with --wgsl the
    /// kernels' code.
    Law(law::LawCmd),
    /// The GPU adapters this machine offers (index, type, PCI bus id), marking the one
    /// BITROCK_ADAPTER, WGPU_ADAPTER_NAME or CUDA_VISIBLE_DEVICES picks.
    Devices(devices::DevicesCmd),
    /// Stability maps over top-drive speed and weight on bit: deterministic (MAP), stochastic
    /// (percentile over posterior samples) and the mixture of laws, from an ABC run or a law.
    Stability(stability::StabilityCmd),
    /// Follow a growing record window by window (a file, followed or replayed against its time
    /// column, or standard input): each window's law probabilities from the evidence, carried
    /// with forgetting, a change of formation noticed, and the top-drive speed and weight on
    /// bit that avoid stick-slip now.
    Watch(watch::WatchCmd),
    /// Serve the live page of a watch directory (`bitrock watch --out DIR`), finished or still
    /// being written, read-only: the page follows the windows as the watch stores them.
    Serve(serve::ServeCmd),
}
