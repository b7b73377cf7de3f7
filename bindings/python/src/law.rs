//! Laws: law files loaded, a law simulated on the drill string, and the GPU's parity with
//! the CPU per law.

use crate::errors::*;
use crate::record::*;
use bitrock::Law;
use bitrock::data::DataOptions;
use bitrock::error::Error;
use bitrock::units::TorqueUnit;
use numpy::{PyArray1, PyReadonlyArray1};
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// The unit of the torque-valued parameters: `param_torque_unit`, kN·m by default.
pub(crate) fn param_torque_unit(py: Python<'_>, options: &Bound<'_, PyDict>) -> PyResult<TorqueUnit> {
    Ok(unit(
        py,
        "param_torque_unit",
        kwarg(options, "param_torque_unit")?,
        TorqueUnit::from_suffix,
    )?
    .unwrap_or(TorqueUnit::KNm))
}

/// `law`'s parameters in N·m: `params` in `unit` (their count checked), or the law's reference
/// values where none are given.
pub(crate) fn params_nm(
    py: Python<'_>,
    law: bitrock::Law,
    params: Option<Vec<f64>>,
    unit: TorqueUnit,
) -> PyResult<Vec<f64>> {
    match params {
        Some(params) => {
            // The count first: scaling takes one value per parameter.
            if params.len() != law.n_params() {
                check(py, law.check_params(&params, "params"))?;
            }
            Ok(law.scale_torque(&params, unit.newton_metres()))
        }
        None => match law.paper_estimate() {
            Some(p) => Ok(law.scale_torque(p, TorqueUnit::KNm.newton_metres())),
            None => {
                let message = format!("law {law} has no reference values to default to; give its parameters");
                Err(to_py(py, bitrock::Error::setting("params", message)))
            }
        },
    }
}

/// Simulates the 1-DOF string with `law` at top-drive speed `omega_rpm`: the record as
/// `bitrock simulate` writes it (CSV text, torques in kN·m, the `channels` asked for). Parameters that look like the
/// wrong torque unit are said through `note`.
#[pyfunction]
#[pyo3(signature = (law, params, omega_rpm, options, note))]
pub(crate) fn simulate(
    py: Python<'_>,
    law: String,
    params: Option<Vec<f64>>,
    omega_rpm: f64,
    options: &Bound<'_, PyDict>,
    note: Option<Py<PyAny>>,
) -> PyResult<String> {
    use bitrock::simulate::{self as sim, Initial, SimConfig};
    use bitrock::units::RAD_S_PER_RPM;
    let law = self::laws(py, Some(vec![law]))?.expect("one law")[0];
    let params_nm = params_nm(py, law, params, param_torque_unit(py, options)?)?;
    if let (Some(callback), Some(warning)) = (&note, law.implausible_torque(&params_nm, "param_torque_unit")) {
        callback.call1(py, (as_arguments(&format!("warning: {warning}")),))?;
    }
    let mut c = SimConfig::new(law, params_nm, omega_rpm * RAD_S_PER_RPM, bitrock::laws::PAPER_W_REF_N);
    let kn = |key: &str| -> PyResult<Option<f64>> { Ok(kwarg::<f64>(options, key)?.map(|v| v * 1000.0)) };
    c.wob_n = kn("wob_kn")?.unwrap_or(c.wob_n);
    c.w_ref_n = kn("w_ref_kn")?.unwrap_or(c.w_ref_n);
    c.structure.inertia_kg_m2 = kwarg(options, "inertia_kg_m2")?.unwrap_or(c.structure.inertia_kg_m2);
    c.structure.omega_n_rad_s = kwarg(options, "omega_n_rad_s")?.unwrap_or(c.structure.omega_n_rad_s);
    c.structure.damping_ratio = kwarg(options, "damping_ratio")?.unwrap_or(c.structure.damping_ratio);
    c.duration_s = kwarg(options, "duration_s")?.unwrap_or(c.duration_s);
    c.recording.settle_s = kwarg(options, "settle_s")?.unwrap_or(c.recording.settle_s);
    c.recording.sample_hz = kwarg(options, "sample_hz")?.unwrap_or(c.recording.sample_hz);
    c.recording.dt_s = kwarg(options, "dt_s")?.unwrap_or(c.recording.dt_s);
    let kick_rpm = kwarg(options, "kick_rpm")?.unwrap_or(sim::DEFAULT_KICK_RPM);
    c.recording.initial = match kwarg::<String>(options, "initial")?
        .as_deref()
        .map(str::to_lowercase)
        .as_deref()
    {
        None | Some("equilibrium") => Initial::Equilibrium {
            speed_perturbation_rad_s: kick_rpm * RAD_S_PER_RPM,
        },
        Some("rest") => Initial::Rest,
        Some(other) => {
            return Err(to_py(
                py,
                Error::setting("initial", format!("`{other}` is not one of equilibrium, rest")),
            ));
        }
    };
    c.recording.noise_torque_nm = kn("noise_torque_knm")?.unwrap_or(c.recording.noise_torque_nm);
    c.recording.noise_speed_rad_s =
        kwarg::<f64>(options, "noise_speed_rpm")?.map_or(c.recording.noise_speed_rad_s, |v| v * RAD_S_PER_RPM);
    c.recording.wob_fluctuation_n = kn("wob_fluctuation_kn")?.unwrap_or(c.recording.wob_fluctuation_n);
    c.recording.wob_correlation_s = kwarg(options, "wob_correlation_s")?.unwrap_or(c.recording.wob_correlation_s);
    c.recording.seed = kwarg(options, "seed")?.unwrap_or(sim::DEFAULT_SEED);
    let channels = match kwarg::<String>(options, "channels")?
        .as_deref()
        .map(str::to_lowercase)
        .as_deref()
    {
        None | Some("bit") => sim::Channels::Bit,
        Some("surface") => sim::Channels::Surface,
        Some("all") => sim::Channels::All,
        Some("mwd") => sim::Channels::Mwd,
        Some(other) => {
            return Err(to_py(
                py,
                Error::setting("channels", format!("`{other}` is not one of bit, surface, all, mwd")),
            ));
        }
    };
    let text = py.detach(|| {
        c.validate()?;
        let record = sim::simulate_record_with(&c, &mut |_, _| {})?;
        let mut text = Vec::new();
        sim::write_record_csv(&record, None, channels, TorqueUnit::KNm, &mut text)
            .map_err(|e| Error::Numerical(e.to_string()))?;
        Ok::<_, Error>(String::from_utf8(text).expect("the CSV is ASCII"))
    });
    check(py, text)
}

/// CPU-vs-GPU parity on `record` (`None`: the embedded demo record): `bitrock parity`'s
/// report as JSON text.
#[pyfunction]
#[pyo3(signature = (record, laws, options))]
pub(crate) fn parity(
    py: Python<'_>,
    record: Option<&Record>,
    laws: Option<Vec<String>>,
    options: &Bound<'_, PyDict>,
) -> PyResult<String> {
    use bitrock::bench;
    let laws = self::laws(py, laws)?.unwrap_or_else(|| Law::ALL.to_vec());
    let candidates = kwarg(options, "candidates")?.unwrap_or(bench::PARITY_CANDIDATES);
    let epsilon = kwarg(options, "epsilon")?;
    let seed = kwarg(options, "seed")?.unwrap_or(bench::PARITY_SEED);
    let report = py.detach(|| {
        let demo;
        let data = match record {
            Some(r) => &r.data,
            None => {
                demo = bitrock::data::demo_field_data(&DataOptions::default())?;
                &demo
            }
        };
        bench::parity_on(data, &laws, candidates, epsilon, seed)
    });
    let report = check(py, report)?;
    serde_json::to_string(&report).map_err(|e| to_py(py, Error::Numerical(e.to_string())))
}

/// Each law's colour (`#rrggbb`) by its name, the same in every figure of the report, on the
/// watch's page and in `bitrock.plot`.
#[pyfunction]
pub(crate) fn law_colours(py: Python<'_>, laws: Vec<String>) -> PyResult<Vec<String>> {
    Ok(self::laws(py, Some(laws))?
        .unwrap_or_default()
        .into_iter()
        .map(|law| law.colour_hex())
        .collect())
}

/// Reads, compiles and registers the law file at `path`; its law's name, for `laws=` and
/// `law=` everywhere in this process.
#[pyfunction]
pub(crate) fn load_law(py: Python<'_>, path: std::path::PathBuf) -> PyResult<String> {
    let law = check(py, bitrock::laws::file::load_and_register(&path))?;
    Ok(law.name().to_string())
}

/// The law's torque r·T(w) at the bit speeds `speed_rad_s` (rad/s, a contiguous float64
/// array, read without a copy), its parameters `params` in its order with torques in
/// `torque_unit` (kN·m by default); the torques in that unit, as a new array. A speed where the
/// torque has no value gives NaN.
#[pyfunction]
#[pyo3(signature = (law, speed_rad_s, params, r, torque_unit))]
pub(crate) fn torque<'py>(
    py: Python<'py>,
    law: String,
    speed_rad_s: PyReadonlyArray1<'py, f64>,
    params: Vec<f64>,
    r: f64,
    torque_unit: Option<String>,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let law = self::laws(py, Some(vec![law]))?.expect("one law")[0];
    let unit = unit(py, "torque_unit", torque_unit, TorqueUnit::from_suffix)?.unwrap_or(TorqueUnit::KNm);
    if params.len() != law.n_params() || params.iter().any(|v| !v.is_finite()) {
        check(py, law.check_params(&params, "params"))?;
    }
    if !r.is_finite() {
        return Err(to_py(
            py,
            bitrock::Error::setting("r", format!("must be a finite number, got {r}")),
        ));
    }
    let speeds = speed_rad_s.as_slice()?;
    if let Some(w) = speeds.iter().find(|w| !w.is_finite()) {
        return Err(to_py(
            py,
            bitrock::Error::setting("speed_rad_s", format!("must be finite numbers, got {w}")),
        ));
    }
    let si = law.scale_torque(&params, unit.newton_metres());
    Ok(PyArray1::from_iter(
        py,
        speeds.iter().map(|&w| law.torque(&si, w, r) / unit.newton_metres()),
    ))
}
