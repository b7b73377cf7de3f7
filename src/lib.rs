//! bitrock: calibration and selection of drill-string bit-rock interaction laws from downhole
//! data (least squares, then Approximate Bayesian Computation), and torsional stick-slip
//! stability maps. The method is Castello & Ritto, "ABC for model selection and parameter
//! estimation of drill-string bit-rock interaction models and stochastic stability".
//!
//! Inside the library every quantity is SI (rad/s, N·m, N, kg·m², s); the user's units appear
//! only at the edges (CSV columns, flags, printed tables), always named.
//!
//! # The whole job in one call
//!
//! [`run::abc::Job`] is what `bitrock abc` runs: a record → least-squares fits → prior →
//! ABC populations → posterior summary and predictive envelopes, optionally written to a run
//! directory. Its [`Default`] is the command line's defaults:
//!
//! ```
//! use bitrock::abc::Silent;
//! use bitrock::abc::schedule::Schedule;
//! use bitrock::data::{DataOptions, demo_field_data};
//! use bitrock::eval::Backend;
//! use bitrock::run::{self, abc::SamplerConfig};
//!
//! # fn main() -> bitrock::Result<()> {
//! let data = demo_field_data(&DataOptions::default())?;
//! let job = run::abc::Job {
//!     config: run::abc::Config {
//!         backend: Backend::Cpu,
//!         sampler: SamplerConfig::Rejection(
//!             Schedule {
//!                 particles: 200,
//!                 eps_min: 0.05,
//!                 ..Schedule::default()
//!             }
//!             .into(),
//!         ),
//!         ..run::abc::Config::default()
//!     },
//!     ..run::abc::Job::default() // in memory; `out: Some(run::Dir { .. })` writes the run directory
//! };
//! // Scored here (`run::Scoring::Workers` hands the populations to a pool of processes or
//! // machines); `Silent` watches nothing, an `Observer` of your own hears progress,
//! // populations and notes.
//! let analysis = job.run(data, run::Scoring::Here, &mut Silent)?;
//! let probabilities = &analysis.posterior.model_probabilities;
//! let total: f64 = probabilities.iter().map(|(_, p)| p).sum();
//! assert!((total - 1.0).abs() < 1e-12);
//! assert_eq!(analysis.envelopes.len(), analysis.posterior.laws.len());
//! # Ok(())
//! # }
//! ```
//!
//! # Where to start
//!
//! | for | read |
//! |---|---|
//! | a record | [`data::read_field_data`] (CSV, units named) or [`data::demo_field_data`] → [`data::FieldData`] |
//! | the laws and their least-squares fits | [`Law`], [`fit::fit_record`] → [`fit::LawFit`] |
//! | the prior | [`prior::Prior`] (boxes around the fits, or a [`prior::PriorFile`]) |
//! | scoring candidates | the [`eval::Evaluator`] trait, made by [`eval::evaluator`] for a [`eval::Backend`] |
//! | the samplers | [`abc::rejection`], [`abc::smc`], the schedule they share ([`abc::schedule`]); a run's [`abc::Population`]s, watched by an [`abc::Observer`] |
//! | a whole run | [`run::abc::Job`] → [`run::abc::Analysis`] ([`abc::posterior::PosteriorSummary`], envelopes); [`run::abc::resume`] |
//! | every kind of run | [`run`]: the ABC run ([`run::abc`]: [`run::abc::start`] and [`run::abc::populations::resume`], its [`run::abc::Config`], [`run::abc::Store`] (SQLite)), the evidence ([`run::evidence::Job`]), maps and simulated strings; [`run::Dir`] (claim, lock, staging; what a directory holds), [`run::Scoring`] |
//! | the selection check | [`run::selection::check`] → [`run::selection::SelectionCheck`] |
//! | stability maps | [`run::stability::StabilityJob`] → [`run::stability::StabilityMaps`]; the physics in [`stability`] |
//! | a report | [`report::write_report`] |
//! | errors | [`Error`]: bad input ([`Error::is_bad_input`]) names the file, line, column or setting |
#![deny(clippy::float_cmp)]
// The library speaks through its results and callbacks, never to a terminal.
#![cfg_attr(not(test), deny(clippy::print_stdout, clippy::print_stderr))]

pub mod abc;
pub mod bench;
pub mod data;
pub mod documents;
pub mod error;
pub mod eval;
pub mod files;
pub mod fit;
pub mod laws;
pub mod limits;
mod memo;
pub mod numerics;
pub mod prior;
pub mod report;
pub mod rng;
pub mod run;
pub mod separation;
pub mod simulate;
pub mod stability;
pub mod units;
pub mod watch;

pub use error::{Error, Result};
pub use laws::Law;
