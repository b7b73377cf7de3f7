//! Every kind of run, in one home: what defines it, where it is scored, its directory and how
//! it resumes.
//!
//! On the ground floor, what every kind shares: [`scoring`] (here, on workers, or on an
//! evaluator of the caller's) and [`dir`] (a directory checked before any work, claimed under
//! its lock, checked again there, staged beside what it replaces; the names of what each kind
//! holds), [`sqlite`] (a store made whole, opened behind its schema gate) and [`settings`] (the gate each kind's settings pass, once, whichever surface filled them). A folder or file per kind:
//!
//! - [`answer`]: one answer to "which law, and how sure" from either kind of selection;
//! - [`abc`]: the paper's ABC run (rejection or SMC): [`abc::Job`], its populations in
//!   `run.sqlite`, resumed by [`abc::resume`];
//! - [`evidence`]: the model evidence per law and the Bayes factors, [`evidence::Job`], with its
//!   check by re-simulation and its directory;
//! - [`stability`]: stability maps from a run's or an evidence's posterior, or from the
//!   paper's estimates;
//! - [`strings`]: simulated strings: onset and escape maps from a posterior, and
//!   [`advice`], the operating advice read from them.
//! - [`surface`]: laws from a surface record through simulated strings;
//! - [`coupled`]: the coupled axial-torsional bit: one string, a regime map, a drilling
//!   record's calibration and the regimes' probabilities over its posterior;
//! - [`choice`]: which structure a bit record shows, a torsional law or the coupled bit, by
//!   simulation.

pub mod abc;
pub mod advice;
pub mod answer;
pub mod choice;
pub mod coupled;
pub mod dir;
pub mod evidence;
pub mod scoring;
pub mod selection;
pub mod settings;
pub mod sqlite;
pub mod stability;
pub mod strings;
pub mod surface;

pub use dir::{Dir, DirState};
pub use scoring::{MakeEvaluator, MakeWorkers, Placement, Scoring};
