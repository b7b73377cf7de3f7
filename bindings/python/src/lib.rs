//! `bitrock._bitrock`: the library's entry points for the Python package. Arguments arrive as
//! the Python layer's keyword arguments (named like the command line's flags without dashes);
//! results leave as JSON documents (the ones `run.json` and `fit --json` hold) and NumPy
//! arrays. Work runs with the interpreter released; Ctrl-C stops a run between batches.

mod coupled;
mod distributed;
mod errors;
mod evidence;
mod fit;
mod law;
mod record;
mod run;
mod selection;
mod stability;
mod strings;
mod surface;
mod watch;

use pyo3::prelude::*;

/// The extension module: the Rust library's entry points. Use the ``bitrock`` package, which
/// wraps these in pandas and xarray; signatures here may change between releases.
#[pymodule]
mod _bitrock {
    #[pymodule_export]
    use crate::coupled::{coupled, coupled_calibrate, coupled_select, coupled_select_surface, coupled_well};
    #[pymodule_export]
    use crate::distributed::{needs_payloads, serve};
    #[pymodule_export]
    use crate::errors::settings_fields;
    #[pymodule_export]
    use crate::evidence::{ComputedEvidence, evidence, is_evidence_dir, read_evidence, resume_evidence};
    #[pymodule_export]
    use crate::fit::fit;
    #[pymodule_export]
    use crate::law::{law_colours, load_law, parity, simulate, torque};
    #[pymodule_export]
    use crate::record::{Record, read_columns, read_csv};
    #[pymodule_export]
    use crate::run::{Run, abc, open_run, resume};
    #[pymodule_export]
    use crate::selection::check_selection;
    #[pymodule_export]
    use crate::stability::stability;
    #[pymodule_export]
    use crate::strings::simulate_strings;
    #[pymodule_export]
    use crate::surface::{check_surface, is_surface_dir, read_surface, resume_surface, surface};
    #[pymodule_export]
    use crate::watch::{read_watch, watch};
    use pyo3::prelude::*;

    /// True for a note that only informs (which GPU scores): logged, not warned.
    #[pyfunction]
    fn is_information(note: &str) -> bool {
        bitrock::eval::is_information(note)
    }

    /// The library's version.
    #[pyfunction]
    fn version() -> &'static str {
        env!("CARGO_PKG_VERSION")
    }
}
