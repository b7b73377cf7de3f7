//! `bitrock._bitrock`: the library's entry points for the Python package. Arguments arrive as
//! the Python layer's keyword arguments (named like the command line's flags without dashes);
//! results leave as JSON documents (the ones `run.json` and `fit --json` hold) and NumPy
//! arrays. Work runs with the interpreter released; Ctrl-C stops a run between batches.

mod distributed;
mod errors;
mod fit;
mod law;
mod record;
mod run;
mod selection;
mod stability;

use pyo3::prelude::*;

/// The library's version.
#[pyfunction]
fn version() -> &'static str {
    env!("CARGO_PKG_VERSION")
}

#[pymodule]
fn _bitrock(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<record::Record>()?;
    m.add_class::<run::Run>()?;
    m.add_function(wrap_pyfunction!(record::read_csv, m)?)?;
    m.add_function(wrap_pyfunction!(record::read_columns, m)?)?;
    m.add_function(wrap_pyfunction!(fit::fit, m)?)?;
    m.add_function(wrap_pyfunction!(run::abc, m)?)?;
    m.add_function(wrap_pyfunction!(run::resume, m)?)?;
    m.add_function(wrap_pyfunction!(run::open_run, m)?)?;
    m.add_function(wrap_pyfunction!(stability::stability, m)?)?;
    m.add_function(wrap_pyfunction!(selection::check_selection, m)?)?;
    m.add_function(wrap_pyfunction!(law::simulate, m)?)?;
    m.add_function(wrap_pyfunction!(law::parity, m)?)?;
    m.add_function(wrap_pyfunction!(version, m)?)?;
    m.add_function(wrap_pyfunction!(law::load_law, m)?)?;
    m.add_function(wrap_pyfunction!(distributed::serve, m)?)?;
    m.add_function(wrap_pyfunction!(distributed::needs_payloads, m)?)?;
    Ok(())
}
