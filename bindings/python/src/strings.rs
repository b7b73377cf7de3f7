//! Simulated drill strings: a batch of strings integrated to their summaries, on the backend
//! asked for (the kernel or its CPU twin).

use crate::errors::*;
use bitrock::error::Error;
use bitrock::simulate::strings::{MAX_NODES, Schedule, StringJob, StringState, padded, steady_start};
use bitrock::units::RAD_S_PER_RPM;
use numpy::PyArray1;
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// Strings of `law`, one per row of `params` (torques in `param_torque_unit`; `None`: the
/// law's reference values for every string), `omega_rpm` and `wob_kn` (equal lengths), started
/// from steady rotation kicked by `kick` × Ω or from rest, integrated for `settle_s` then
/// summarised over `record_s` at 50 Hz: a dict of NumPy arrays.
#[pyfunction]
#[pyo3(signature = (law, params, omega_rpm, wob_kn, options, note))]
pub(crate) fn simulate_strings<'py>(
    py: Python<'py>,
    law: String,
    params: Option<Vec<Vec<f64>>>,
    omega_rpm: Vec<f64>,
    wob_kn: Vec<f64>,
    options: &Bound<'py, PyDict>,
    note: Option<Py<PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    let law = laws(py, Some(vec![law]))?.expect("one law")[0];
    let unit = crate::law::param_torque_unit(py, options)?;
    let n = omega_rpm.len();
    let params: Vec<Option<Vec<f64>>> = match params {
        Some(rows) => rows.into_iter().map(Some).collect(),
        None => vec![None; n],
    };
    if wob_kn.len() != n || params.len() != n {
        let message = format!(
            "params, omega_rpm and wob_kn give one value per string: {} rows, {n} speeds, {} weights",
            params.len(),
            wob_kn.len()
        );
        return Err(to_py(py, Error::setting("params", message)));
    }
    let (structure, lumped, fe) = crate::stability::structure_options(py, options)?;
    let chain = check(py, bitrock::run::strings::chain(structure, &lumped, &fe))?;
    let dt_s = kwarg(options, "dt_s")?.unwrap_or(bitrock::run::strings::DEFAULT_DT_S);
    check(py, chain.check_step(dt_s))?;
    let schedule = check(
        py,
        Schedule::new(
            dt_s,
            50.0,
            kwarg(options, "settle_s")?.unwrap_or(60.0),
            kwarg(options, "record_s")?.unwrap_or(60.0),
        ),
    )?;
    let w_ref_n = kwarg::<f64>(options, "w_ref_kn")?.map_or(bitrock::laws::PAPER_W_REF_N, |kn| kn * 1000.0);
    let kick = kwarg(options, "kick")?.unwrap_or(bitrock::run::strings::DEFAULT_KICK);
    let from_rest = match kwarg::<String>(options, "start")?.as_deref() {
        None | Some("steady") => false,
        Some("rest") => true,
        Some(other) => {
            let message = format!("must be \"steady\" or \"rest\", got {other:?}");
            return Err(to_py(py, Error::setting("start", message)));
        }
    };
    let mut jobs = Vec::with_capacity(n);
    for i in 0..n {
        let p = padded(&crate::law::params_nm(py, law, params[i].clone(), unit)?);
        check(py, law.check_params(&p[..law.n_params()], "params"))?;
        let omega = omega_rpm[i] * RAD_S_PER_RPM;
        let ratio = wob_kn[i] * 1000.0 / w_ref_n;
        let start = if from_rest {
            StringState {
                lag_rad: [0.0; MAX_NODES],
                speed_rad_s: [0.0; MAX_NODES],
                stuck: true,
            }
        } else {
            steady_start(&chain, law, &p, omega, ratio, kick * omega)
        };
        jobs.push(StringJob {
            law,
            params_nm: p,
            omega_rad_s: omega,
            ratio,
            start,
        });
    }
    let backend = named(py, "backend", kwarg(options, "backend")?)?.unwrap_or_default();
    let mut notes = Vec::new();
    let results = py
        .detach(|| bitrock::eval::strings::integrate(&chain, &schedule, &jobs, backend, &mut |line| notes.push(line)));
    let (results, _) = check(py, results)?;
    if let Some(callback) = &note {
        for line in notes {
            callback.call1(py, (as_arguments(&line),))?;
        }
    }
    let per_unit = unit.newton_metres();
    let column = |f: &dyn Fn(&bitrock::simulate::strings::Summary) -> f64| -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_vec(py, results.iter().map(|(s, _)| f(s)).collect())
    };
    let out = PyDict::new(py);
    out.set_item("stuck_share", column(&|s| s.stuck_share()))?;
    out.set_item("period_s", column(&|s| s.period_s(50.0).unwrap_or(f64::NAN)))?;
    out.set_item("stick_onsets", column(&|s| f64::from(s.stick_onsets)))?;
    out.set_item("speed_min_rpm", column(&|s| s.speed_min_rad_s / RAD_S_PER_RPM))?;
    out.set_item("speed_max_rpm", column(&|s| s.speed_max_rad_s / RAD_S_PER_RPM))?;
    out.set_item("speed_mean_rpm", column(&|s| s.speed_mean_rad_s() / RAD_S_PER_RPM))?;
    out.set_item("severity", column(&|s| s.severity()))?;
    out.set_item("bit_torque_min", column(&|s| s.bit_torque_min_nm / per_unit))?;
    out.set_item("bit_torque_max", column(&|s| s.bit_torque_max_nm / per_unit))?;
    out.set_item("surface_torque_min", column(&|s| s.surface_torque_min_nm / per_unit))?;
    out.set_item("surface_torque_max", column(&|s| s.surface_torque_max_nm / per_unit))?;
    out.set_item(
        "stick_slips",
        results.iter().map(|(s, _)| s.stick_slips()).collect::<Vec<_>>(),
    )?;
    out.set_item("diverged", results.iter().map(|(s, _)| s.diverged).collect::<Vec<_>>())?;
    out.set_item("torque_unit", unit.label())?;
    Ok(out)
}
