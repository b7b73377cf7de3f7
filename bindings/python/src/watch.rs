//! A growing record followed window by window: each window's update handed to Python as it
//! completes.

use crate::errors::*;
use crate::record::data_options;
use crate::run::PyObserver;
use bitrock::error::Error;
use bitrock::run::stability::Structure;
use bitrock::watch::source::{Rows, Source};
use bitrock::watch::{FollowOptions, WatchSettings};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;

/// Follows `source` (a CSV path, or `-` for standard input; `follow`, `replay_speed` as the
/// command's flags) with the settings in `options` (`bitrock.watch`'s keyword arguments),
/// calling `on_update(json)` with each window's JSON line; an exception raised by it (or
/// Ctrl-C) stops the watch and is raised again. `stopped()`, asked between rows, ends the
/// watch after the window in progress when true. Returns how the watch ended, as JSON.
#[pyfunction]
#[pyo3(signature = (source, options, on_update, note, stopped=None))]
pub(crate) fn watch(
    py: Python<'_>,
    source: PathBuf,
    options: &Bound<'_, PyDict>,
    on_update: Py<PyAny>,
    note: Option<Py<PyAny>>,
    stopped: Option<Py<PyAny>>,
) -> PyResult<String> {
    let defaults = WatchSettings::default();
    let follow: bool = kwarg(options, "follow")?.unwrap_or(false);
    let replay_speed: Option<f64> = kwarg(options, "replay_speed")?;
    let (structure, lumped, fe) = crate::stability::structure_options(py, options)?;
    // The finite-element string's critical bit damping is a bisection: off Python's lock.
    let mut said = Vec::new();
    let criterion = check(
        py,
        py.detach(|| bitrock::run::stability::criterion(structure, lumped, &fe, &mut |line| said.push(line))),
    )?;
    // A stick-slipping window's way out on the finite-element string, where it can be simulated.
    let fe_chain = match structure {
        Structure::Fe => bitrock::run::strings::chain(structure, &lumped, &fe).ok(),
        Structure::Lumped => None,
    };
    let abc: bool = kwarg(options, "abc")?.unwrap_or(false);
    let sampler: Option<bitrock::run::abc::Sampler> = named(py, "sampler", kwarg(options, "sampler")?)?;
    let delta: Option<f64> = kwarg(options, "delta")?;
    let eps_min: Option<f64> = kwarg(options, "eps_min")?;
    let particles: Option<usize> = kwarg(options, "particles")?;
    let islands: Option<usize> = kwarg(options, "islands")?;
    // As the command refuses them: settings of the procedure not used.
    let unused = match abc {
        true => islands
            .is_some()
            .then_some(("islands", "applies only to the evidence; drop it or `abc`")),
        false => [
            ("sampler", sampler.is_some()),
            ("delta", delta.is_some()),
            ("eps_min", eps_min.is_some()),
        ]
        .into_iter()
        .find(|(_, given)| *given)
        .map(|(field, _)| (field, "applies only to `abc=True` (the paper's ABC on each window)")),
    };
    if let Some((field, why)) = unused {
        return Err(to_py(py, Error::setting(field, why)));
    }
    let settings = WatchSettings {
        criterion,
        fe_chain,
        abc: match abc {
            true => Some(check(
                py,
                bitrock::watch::abc_config(sampler.unwrap_or_default(), particles, delta, eps_min),
            )?),
            false => None,
        },
        laws: laws(py, kwarg(options, "laws")?)?.unwrap_or_else(|| defaults.laws.clone()),
        data: data_options(py, options)?,
        thin: kwarg(options, "thin")?,
        window_s: kwarg(options, "window_s")?,
        step_s: kwarg(options, "step_s")?,
        evidence: bitrock::run::evidence::Settings {
            particles: particles.filter(|_| !abc).unwrap_or(defaults.evidence.particles),
            islands: islands.unwrap_or(defaults.evidence.islands),
            seed: kwarg(options, "seed")?.unwrap_or(defaults.evidence.seed),
            ..defaults.evidence.clone()
        },
        surface: bitrock::run::surface::Settings {
            particles: particles.filter(|_| !abc).unwrap_or(defaults.surface.particles),
            ..defaults.surface.clone()
        },
        forgetting: kwarg(options, "forgetting")?.unwrap_or(defaults.forgetting),
        floor: kwarg(options, "floor")?.unwrap_or(defaults.floor),
        change_nats: kwarg(options, "change_nats")?.unwrap_or(defaults.change_nats),
        risk: kwarg(options, "risk")?.unwrap_or(defaults.risk),
        backend: named(py, "backend", kwarg(options, "backend")?)?.unwrap_or(defaults.backend),
        warm_start: !kwarg::<bool>(options, "cold_start")?.unwrap_or(false),
        wits: match kwarg::<String>(options, "wits_items")? {
            Some(spec) => check(py, bitrock::watch::wits::WitsItems::parse(&spec))?,
            None => defaults.wits.clone(),
        },
        ..defaults
    };
    let source = check(py, Source::named(&source, follow, replay_speed))?;
    let out: Option<PathBuf> = kwarg(options, "out")?;
    let resume: bool = kwarg(options, "resume")?.unwrap_or(false);
    let serve: Option<String> = kwarg(options, "serve")?;
    let mut observer = PyObserver::new(None, note);
    for line in said {
        bitrock::abc::Observer::note(&mut observer, line);
    }
    // What Python raised (Ctrl-C between rows, or in `on_update`): the watch stops after
    // storing the window in progress, then it is raised again.
    let raised: std::sync::Mutex<Option<PyErr>> = std::sync::Mutex::new(None);
    let ended = py.detach(|| {
        let stop = || {
            raised.lock().unwrap_or_else(|e| e.into_inner()).is_some()
                || Python::attach(|py| {
                    let asked = py.check_signals().and_then(|()| match &stopped {
                        Some(stopped) => stopped.call0(py)?.is_truthy(py),
                        None => Ok(false),
                    });
                    asked.unwrap_or_else(|e| {
                        *raised.lock().unwrap_or_else(|e| e.into_inner()) = Some(e);
                        true
                    })
                })
        };
        let mut rows = Rows::open(&source, &settings.data, &settings.wits, &stop)?;
        let server = serve
            .as_deref()
            .map(|address| {
                let meta = serde_json::json!({ "source": rows.name().display().to_string() });
                bitrock::watch::serve::Server::start(address, "serve", &meta)
            })
            .transpose()?;
        if let Some(server) = &server {
            bitrock::abc::Observer::note(
                &mut observer,
                format!("the live page is at http://{}/", server.address()),
            );
        }
        let options = FollowOptions {
            dir: out.as_deref(),
            resume,
            stop: Some(&stop),
            serve: server.as_ref(),
        };
        let ended = bitrock::watch::follow(&mut rows, settings, options, &mut observer, &mut |update| {
            let line = serde_json::to_string(update).map_err(|e| Error::Numerical(e.to_string()))?;
            Python::attach(|py| {
                let called = py
                    .check_signals()
                    .and_then(|()| on_update.call1(py, (line,)).map(|_| ()));
                called.map_err(|e| {
                    *raised.lock().unwrap_or_else(|e| e.into_inner()) = Some(e);
                    Error::Interrupted
                })
            })
        });
        if let (Some(server), Ok(ended)) = (server, &ended) {
            server.end(&ended.page_json());
        }
        ended
    });
    let raised = raised.into_inner().unwrap_or_else(|e| e.into_inner());
    if let Some(e) = raised.or_else(|| observer.take_raised()) {
        return Err(e);
    }
    let ended = check(py, ended)?;
    serde_json::to_string(&ended).map_err(|e| to_py(py, Error::Numerical(e.to_string())))
}

/// The watch stored in `dir` (written by `bitrock watch --out` or `bitrock.watch(out=...)`):
/// its description and every window's update, as JSON.
#[pyfunction]
pub(crate) fn read_watch(py: Python<'_>, dir: PathBuf) -> PyResult<(String, Vec<String>)> {
    let stored = check(py, py.detach(|| bitrock::watch::store::read(&dir)))?;
    let json = |e: serde_json::Error| to_py(py, Error::Numerical(e.to_string()));
    let meta = serde_json::to_string(&stored.meta).map_err(json)?;
    let updates = stored
        .updates
        .iter()
        .map(|u| serde_json::to_string(u).map_err(json))
        .collect::<PyResult<Vec<_>>>()?;
    Ok((meta, updates))
}
