//! Stability maps from a run or a law.

use crate::errors::*;
use bitrock::error::Error;
use bitrock::run::stability::{StringGiven, Structure};
use bitrock::stability::{fe::DrillStringSettings, lumped::Lumped};
use bitrock::units::TorqueUnit;
use numpy::{PyArray1, PyArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;

/// The drill string the keyword arguments give (`structure`, `inertia_kg_m2`, `omega_n_rad_s`,
/// `damping_ratio`, `fe_file`, `dp_elements`, `bha_elements`, `alpha`, `beta`), each field
/// given or not.
pub(crate) fn string_given(py: Python<'_>, options: &Bound<'_, PyDict>) -> PyResult<StringGiven> {
    Ok(StringGiven {
        structure: named(py, "structure", kwarg(options, "structure")?)?,
        inertia_kg_m2: kwarg(options, "inertia_kg_m2")?,
        omega_n_rad_s: kwarg(options, "omega_n_rad_s")?,
        damping_ratio: kwarg(options, "damping_ratio")?,
        fe: DrillStringSettings {
            fe_file: kwarg(options, "fe_file")?,
            dp_elements: kwarg(options, "dp_elements")?,
            bha_elements: kwarg(options, "bha_elements")?,
            alpha: kwarg(options, "alpha")?,
            beta: kwarg(options, "beta")?,
            base: None,
        },
    })
}

/// The structure, 1-DOF string and finite-element settings the keyword arguments give, over
/// the paper's string.
pub(crate) fn structure_options(
    py: Python<'_>,
    options: &Bound<'_, PyDict>,
) -> PyResult<(Structure, Lumped, DrillStringSettings)> {
    Ok(string_given(py, options)?.over(None))
}

/// The axis `options[key]`: values, or "MIN:MAX:COUNT" as on the command line; `default`'s
/// where not given.
fn axis(py: Python<'_>, options: &Bound<'_, PyDict>, key: &str, default: &str) -> PyResult<Vec<f64>> {
    match options.get_item(key)?.filter(|v| !v.is_none()) {
        None => check(py, bitrock::stability::map::parse_axis(default, key)),
        Some(value) => match value.extract::<String>() {
            Ok(text) => check(py, bitrock::stability::map::parse_axis(&text, key)),
            Err(_) => value.extract(),
        },
    }
}

/// Stability maps over (Ω, W) for the run in `run`, or for `law` at `params` (torques in
/// `torque_unit`): a dict of NumPy arrays the Python layer makes a Dataset of.
#[pyfunction]
#[pyo3(signature = (run, law, params, options, note))]
pub(crate) fn stability<'py>(
    py: Python<'py>,
    run: Option<PathBuf>,
    law: Option<String>,
    params: Option<Vec<f64>>,
    options: &Bound<'py, PyDict>,
    note: Option<Py<PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    use bitrock::run::stability::{self as job, MapSource, StabilityJob};
    use bitrock::stability::map;
    let posterior: Option<String> = kwarg(options, "posterior")?;
    let in_memory: Option<Py<crate::run::Run>> = kwarg(options, "run_in_memory")?;
    // A run kept in memory keeps its record too: its bit and W_ref, for the record's advice.
    let (memory_bit, memory_w_ref_n) = in_memory
        .as_ref()
        .and_then(|run| run.get().record_in_memory())
        .unwrap_or((None, None));
    // A surface directory: its posterior, the W_ref its laws hold at and the bit its surface
    // implies, as `bitrock stability --run` reads them.
    let surface = match &run {
        Some(dir) if bitrock::run::surface::dir::is_surface_dir(dir) => {
            let finished = check(py, bitrock::run::surface::dir::Finished::read(dir))?;
            let (particles, w_ref_n, _) = check(py, finished.posterior())?;
            Some((particles, w_ref_n, check(py, finished.bit())?))
        }
        _ => None,
    };
    let surface_w_ref_n = surface.as_ref().map(|s| s.1);
    let surface_dir = run.clone().filter(|_| surface.is_some());
    // A surface run that inferred its string: every sample's own for the simulated strings.
    let sample_strings = match &surface_dir {
        Some(dir) => check(
            py,
            bitrock::run::stability::sample_strings(dir, &string_given(py, options)?),
        )?,
        None => None,
    };
    let surface_bit = surface.as_ref().map(|s| s.2);
    // A run's or an evidence's own string, under what the keywords give.
    let stored = match (&run, &in_memory) {
        (Some(dir), _) => check(py, bitrock::run::stability::stored_string(dir))?,
        (None, Some(run)) => run.get().string_in_memory(),
        (None, None) => None,
    };
    let source = match (run, law, params) {
        (None, None, None) if posterior.is_some() => {
            MapSource::Posterior(posterior_particles(py, posterior.as_deref().expect("given"))?)
        }
        (None, None, None) if in_memory.is_some() => {
            let run = in_memory.expect("given");
            let particles = run.get().last_particles_in_memory().ok_or_else(|| {
                to_py(
                    py,
                    Error::setting("source", "the run kept in memory has no completed population"),
                )
            })?;
            MapSource::Posterior(particles.to_vec())
        }
        (Some(_), None, None) if surface.is_some() => MapSource::Posterior(surface.expect("a surface directory").0),
        (Some(dir), None, None) => MapSource::Run(dir),
        (None, Some(law), Some(params)) => {
            let law = self::laws(py, Some(vec![law]))?.expect("one law")[0];
            let unit = unit(
                py,
                "torque_unit",
                kwarg(options, "torque_unit")?,
                TorqueUnit::from_suffix,
            )?;
            check(py, MapSource::law(law, &params, unit.unwrap_or(TorqueUnit::KNm)))?
        }
        _ => {
            return Err(to_py(
                py,
                Error::setting(
                    "source",
                    "give a run (a Result or its directory), an Evidence, or a law with its params",
                ),
            ));
        }
    };
    let axis = |key: &str, default: &str| axis(py, options, key, default);
    let (structure, lumped, fe) = string_given(py, options)?.over(stored.as_ref());
    let job = StabilityJob {
        source,
        omega_rpm: axis("omega_rpm", job::DEFAULT_OMEGA_RPM)?,
        wob_kn: axis("wob_kn", job::DEFAULT_WOB_KN)?,
        criterion: map::Criterion::Lumped(lumped),
        w_ref_n: kwarg::<f64>(options, "w_ref_kn")?
            .map(|kn| kn * 1000.0)
            .or(surface_w_ref_n)
            .unwrap_or(bitrock::laws::PAPER_W_REF_N),
        percentile: kwarg::<f64>(options, "percentile")?.unwrap_or(job::DEFAULT_PERCENT) / 100.0,
        samples: kwarg(options, "samples")?.unwrap_or(job::DEFAULT_SAMPLES),
        backend: named(py, "backend", kwarg(options, "backend")?)?.unwrap_or_default(),
    };
    let mut notes = Vec::new();
    let maps = py.detach(|| {
        let job = job.on(structure, lumped, &fe, &mut |line| notes.push(line))?;
        let maps = job.run(&mut |line| notes.push(line))?;
        Ok::<_, Error>((job, maps))
    });
    let (job, maps) = check(py, maps)?;
    if let Some(callback) = &note {
        for line in notes.into_iter().chain(maps.early_end.clone()) {
            callback.call1(py, (as_arguments(&line),))?;
        }
    }
    let nan = |v: &Option<f64>| v.unwrap_or(f64::NAN);
    let (n_omega, n_wob) = (job.omega_rpm.len(), job.wob_kn.len());
    let out = PyDict::new(py);
    out.set_item("laws", maps.inputs.iter().map(|i| i.law.name()).collect::<Vec<_>>())?;
    out.set_item(
        "probability",
        maps.inputs.iter().map(|i| i.probability).collect::<Vec<_>>(),
    )?;
    out.set_item(
        "samples",
        maps.inputs.iter().map(|i| i.samples_si.len()).collect::<Vec<_>>(),
    )?;
    out.set_item("omega_rpm", PyArray1::from_slice(py, &job.omega_rpm))?;
    out.set_item("wob_kn", PyArray1::from_slice(py, &job.wob_kn))?;
    let grids: Vec<f64> = maps.grids.concat();
    out.set_item(
        "probability_unstable",
        PyArray1::from_vec(py, grids).reshape([maps.inputs.len(), n_omega, n_wob])?,
    )?;
    let boundary = |pick: fn(&map::LawBoundaries) -> &Vec<Option<f64>>| -> PyResult<_> {
        let flat: Vec<f64> = maps
            .boundaries
            .laws
            .iter()
            .flat_map(|b| pick(b).iter().map(nan))
            .collect();
        PyArray1::from_vec(py, flat).reshape([maps.inputs.len(), n_omega])
    };
    out.set_item("map_wob_kn", boundary(|b| &b.map_wob_kn)?)?;
    out.set_item("p_wob_kn", boundary(|b| &b.p_wob_kn)?)?;
    if let Some(mixture) = &maps.boundaries.mixture_wob_kn {
        out.set_item(
            "mixture_p_wob_kn",
            PyArray1::from_vec(py, mixture.iter().map(nan).collect()),
        )?;
    }
    // A string the simulator cannot hold is refused where the simulated maps are asked for;
    // the record's advice then says only what the linear maps can.
    let chain = bitrock::run::strings::chain(structure, &lumped, &fe);
    let given_w_ref_n = kwarg::<f64>(options, "w_ref_kn")?.map(|kn| kn * 1000.0);
    let record_bit = maps.record_bit.or(memory_bit).or(surface_bit);
    let record_w_ref_n = record_bit.map(|seen| {
        let scaled = given_w_ref_n
            .or(surface_w_ref_n)
            .or(maps.run_w_ref_n)
            .or(memory_w_ref_n);
        bitrock::run::advice::params_w_ref_n(scaled, &seen, job.w_ref_n)
    });
    let sim_inputs = match (&sample_strings, &surface_dir) {
        (Some(_), Some(dir)) => check(
            py,
            bitrock::run::stability::with_sample_strings(dir, &maps.inputs, job.samples),
        )?,
        _ => maps.inputs.clone(),
    };
    if let (Some(seen), Some(w_ref_n)) = (&record_bit, record_w_ref_n) {
        use bitrock::run::advice::Adviser;
        let adviser = Adviser::for_record(job.criterion, chain.as_ref().ok().cloned(), job.backend)
            .with_sample_strings(sample_strings);
        let advice = py.detach(|| adviser.advise_record(&sim_inputs, w_ref_n, seen));
        out.set_item(
            "record_advice",
            serde_json::json!({"record": seen, "advice": advice}).to_string(),
        )?;
    }
    if kwarg::<bool>(options, "simulate")?.unwrap_or(false) {
        let record_at = record_bit
            .zip(record_w_ref_n)
            .map(|(seen, w_ref_n)| (bitrock::run::advice::record_point(&seen, w_ref_n), w_ref_n));
        simulated(
            py,
            options,
            &job,
            &sim_inputs,
            check(py, chain)?,
            sample_strings,
            record_at,
            &note,
            &out,
        )?;
    }
    out.set_item("critical_bit_damping_nms", job.criterion.critical_nms())?;
    out.set_item("percentile", job.percentile * 100.0)?;
    out.set_item(
        "structure",
        serde_json::to_value(structure)
            .ok()
            .and_then(|v| v.as_str().map(String::from)),
    )?;
    Ok(out)
}

/// The weighted posterior particles (SI) of an Evidence's document (`torque_unit`, and per
/// law its probability and posterior sets in that unit).
fn posterior_particles(py: Python<'_>, document: &str) -> PyResult<Vec<bitrock::abc::Particle>> {
    #[derive(serde::Deserialize)]
    struct Sets {
        params: Vec<Vec<f64>>,
        weights: Vec<f64>,
    }
    #[derive(serde::Deserialize)]
    struct LawEntry {
        law: String,
        probability: f64,
        posterior: Sets,
    }
    #[derive(serde::Deserialize)]
    struct Document {
        torque_unit: TorqueUnit,
        laws: Vec<LawEntry>,
    }
    let document: Document = serde_json::from_str(document).map_err(|e| {
        to_py(
            py,
            Error::setting("source", format!("the posterior cannot be read: {e}")),
        )
    })?;
    let mut particles = Vec::new();
    for entry in &document.laws {
        let law = laws(py, Some(vec![entry.law.clone()]))?.expect("one law")[0];
        for (i, (params, w)) in entry.posterior.params.iter().zip(&entry.posterior.weights).enumerate() {
            particles.push(bitrock::abc::Particle {
                law,
                index: i as u64,
                params: law.scale_torque(params, document.torque_unit.newton_metres()),
                rho: f64::NAN,
                weight: entry.probability * w,
            });
        }
    }
    Ok(particles)
}

/// The maps by simulated strings (`simulate=True`) on `chain`: the onset grid and, from
/// `at_rpm` and `at_kn` (or `record_at`, the run's record's operating point with the W_ref its
/// parameters are for there), the escape grid
/// and the advice, added to `out`.
#[allow(clippy::too_many_arguments)]
fn simulated<'py>(
    py: Python<'py>,
    options: &Bound<'py, PyDict>,
    job: &bitrock::run::stability::StabilityJob,
    inputs: &[bitrock::stability::map::LawSamples],
    chain: bitrock::simulate::strings::Chain,
    sample_strings: Option<bitrock::eval::surface::InferredString>,
    record_at: Option<(bitrock::run::strings::OperatingPoint, f64)>,
    note: &Option<Py<PyAny>>,
    out: &Bound<'py, PyDict>,
) -> PyResult<()> {
    use bitrock::run::strings::{self, OperatingPoint, SimulatedJob, SimulatedSettings};
    let axis = |key: &str, default: &str| axis(py, options, key, default);
    let (at, w_ref_n) = match (kwarg::<f64>(options, "at_rpm")?, kwarg::<f64>(options, "at_kn")?) {
        (Some(omega_rpm), Some(wob_kn)) => (Some(OperatingPoint { omega_rpm, wob_kn }), job.w_ref_n),
        (None, None) => record_at.map_or((None, job.w_ref_n), |(at, w)| (Some(at), w)),
        (given, _) => {
            let (field, other) = if given.is_some() {
                ("at_rpm", "at_kn")
            } else {
                ("at_kn", "at_rpm")
            };
            return Err(to_py(
                py,
                Error::setting(field, format!("needs {other} too: where the bit is now")),
            ));
        }
    };
    let sim = SimulatedJob {
        settings: SimulatedSettings {
            dt_s: kwarg(options, "dt_s")?.unwrap_or(strings::DEFAULT_DT_S),
            string: sample_strings,
            ..SimulatedSettings::new(chain, w_ref_n, job.backend)
        },
        omega_rpm: axis("sim_omega_rpm", strings::DEFAULT_OMEGA_RPM)?,
        wob_kn: axis("sim_wob_kn", strings::DEFAULT_WOB_KN)?,
        samples: kwarg(options, "sim_samples")?.unwrap_or(strings::DEFAULT_SAMPLES),
        at,
    };
    let mut notes = Vec::new();
    let maps = py.detach(|| sim.run(inputs, &mut |line| notes.push(line)));
    if let Some(callback) = note {
        for line in notes {
            callback.call1(py, (as_arguments(&line),))?;
        }
    }
    let maps = check(py, maps)?;
    let shape = [sim.omega_rpm.len(), sim.wob_kn.len()];
    out.set_item("sim_omega_rpm", PyArray1::from_slice(py, &sim.omega_rpm))?;
    out.set_item("sim_wob_kn", PyArray1::from_slice(py, &sim.wob_kn))?;
    out.set_item(
        "onset_probability",
        PyArray1::from_slice(py, &maps.onset.probability).reshape(shape)?,
    )?;
    if let Some((grid, advice)) = &maps.escape {
        out.set_item(
            "escape_probability",
            PyArray1::from_slice(py, &grid.probability).reshape(shape)?,
        )?;
        let a = PyDict::new(py);
        a.set_item("at_rpm", advice.point.omega_rpm)?;
        a.set_item("at_kn", advice.point.wob_kn)?;
        a.set_item("stick_slip_probability", advice.stick_slip_probability)?;
        a.set_item("speed_rpm", advice.speed_rpm.map(|w| w.to))?;
        a.set_item("speed_end_probability", advice.speed_rpm.map(|w| w.ends_probability))?;
        a.set_item("speed_diverged_share", advice.speed_rpm.map(|w| w.diverged_share))?;
        a.set_item("wob_kn", advice.wob_kn.map(|w| w.to))?;
        a.set_item("wob_end_probability", advice.wob_kn.map(|w| w.ends_probability))?;
        a.set_item("wob_diverged_share", advice.wob_kn.map(|w| w.diverged_share))?;
        a.set_item("text", advice.text())?;
        out.set_item("advice", a)?;
    }
    out.set_item("simulated_strings", maps.strings)?;
    Ok(())
}
