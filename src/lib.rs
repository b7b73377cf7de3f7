//! bitrock: calibration and selection of drill-string bit-rock interaction laws from downhole
//! data (least squares, then Approximate Bayesian Computation), and torsional stick-slip
//! stability maps. The method is Castello & Ritto, "ABC for model selection and parameter
//! estimation of drill-string bit-rock interaction models and stochastic stability".
//!
//! Inside the library every quantity is SI (rad/s, N·m, N, kg·m², s); the user's units appear
//! only at the edges (CSV columns, flags, printed tables), always named.
#![deny(clippy::float_cmp)]

pub mod abc;
pub mod bench;
pub mod data;
pub mod error;
pub mod eval;
pub mod fit;
pub mod laws;
pub mod numerics;
pub mod prior;
pub mod report;
pub mod rng;
pub mod run;
pub mod simulate;
pub mod stability;
pub mod store;
pub mod units;

pub use error::{Error, Result};
pub use laws::Law;
