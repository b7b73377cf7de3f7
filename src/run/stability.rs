//! The stability job: maps over (Ω, W) for the laws of an ABC run's last population or for one
//! law's parameters — the deterministic (MAP) and percentile boundaries of each law, the
//! mixture's, and each law's probability-of-instability grid, on the GPU where one is usable.
//! `bitrock stability` is its caller; the physics and the grids are `crate::stability::map`'s.

use crate::error::{Error, Result};
use crate::eval::Backend;
use crate::eval::surface::InferredString;
use crate::laws::Law;
use crate::run;
use crate::stability::fe::{DrillString, DrillStringSettings};
use crate::stability::lumped::Lumped;
use crate::stability::map::{self, Boundaries, Criterion, LawSamples};
use std::path::PathBuf;

/// A grid computed on the CPU for longer than this says how far it is...
const PROGRESS_AFTER: std::time::Duration = std::time::Duration::from_secs(2);
/// ...every this often.
const PROGRESS_EVERY: std::time::Duration = std::time::Duration::from_secs(10);

/// The paper's grid of top-drive speeds, rpm, as MIN:MAX:COUNT ([`map::parse_axis`]).
pub const DEFAULT_OMEGA_RPM: &str = "20:220:101";
/// The paper's grid of weights on bit, kN, as MIN:MAX:COUNT.
pub const DEFAULT_WOB_KN: &str = "20:700:69";
/// The paper's percentile of the stochastic boundary, %.
pub const DEFAULT_PERCENT: f64 = 2.0;
/// The paper's posterior samples per law for the stochastic maps.
pub const DEFAULT_SAMPLES: usize = 700;

/// The drill string a map is drawn for.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
pub enum Structure {
    /// The paper's 1-DOF model (closed-form 2x2 criterion).
    #[default]
    #[cfg_attr(feature = "cli", value(name = "1dof"))]
    #[serde(rename = "1dof")]
    Lumped,
    /// The finite-element string (critical bit damping by bisection).
    #[serde(rename = "fe")]
    Fe,
}

/// Whose maps: a run's last population, or one law at given parameters.
#[derive(Clone, Debug, PartialEq)]
pub enum MapSource {
    /// The run directory: every law with particles in its last population, with its posterior
    /// probability, MAP and `samples` posterior samples.
    Run(PathBuf),
    /// One law at `params_si` (SI, torques in N·m): a what-if map without a run.
    Law { law: Law, params_si: Vec<f64> },
    /// Weighted posterior particles of one or more laws held in memory (SI; weights over all
    /// of them, each law's share its probability): the model evidence's
    /// ([`crate::abc::evidence::Evidence::particles`]), or any sampler's.
    Posterior(Vec<crate::abc::Particle>),
}

impl MapSource {
    /// One law at `params` in its order, torques in `unit` (made SI here); a wrong count is
    /// refused naming `params`.
    pub fn law(law: Law, params: &[f64], unit: crate::units::TorqueUnit) -> Result<Self> {
        // The count first: scaling takes one value per parameter.
        if params.len() != law.n_params() {
            law.check_params(params, "params")?;
        }
        Ok(MapSource::Law {
            law,
            params_si: law.scale_torque(params, unit.newton_metres()),
        })
    }
}

/// Refuses, naming `source`, posterior particles that cannot be mapped: none, a weight that is
/// not a finite number ≥ 0 or all weights 0, or parameters a law cannot take.
fn check_posterior(particles: &[crate::abc::Particle]) -> Result<()> {
    if particles.is_empty() {
        return Err(Error::setting("source", "the posterior holds no particles"));
    }
    if let Some(p) = particles.iter().find(|p| !(p.weight.is_finite() && p.weight >= 0.0)) {
        return Err(Error::setting(
            "source",
            format!(
                "a particle of {} has the weight {}: weights must be finite numbers ≥ 0",
                p.law, p.weight
            ),
        ));
    }
    if particles.iter().all(|p| p.weight == 0.0) {
        return Err(Error::setting("source", "every particle of the posterior has weight 0"));
    }
    particles
        .iter()
        .try_for_each(|p| p.law.check_params(&p.params, "source"))
}

/// A stability job: what to map, on which grid, by which criterion.
#[derive(Clone, Debug)]
pub struct StabilityJob {
    pub source: MapSource,
    /// Top-drive speeds, rpm.
    pub omega_rpm: Vec<f64>,
    /// Weights on bit, kN.
    pub wob_kn: Vec<f64>,
    /// The 1-DOF closed form or a finite-element string's critical bit damping.
    pub criterion: Criterion,
    /// Reference weight on bit W_ref of the laws' parameters, N.
    pub w_ref_n: f64,
    /// Share of the posterior samples unstable above the percentile boundary, in (0, 1).
    pub percentile: f64,
    /// Posterior samples per law for the stochastic maps.
    pub samples: usize,
    /// Where the probability grids are computed.
    pub backend: Backend,
}

/// The maps of a [`StabilityJob`].
pub struct StabilityMaps {
    /// Each law's inputs: probability, MAP, samples (SI).
    pub inputs: Vec<LawSamples>,
    pub boundaries: Boundaries,
    /// Each law's share of unstable samples, row-major over (Ω, W), in `inputs` order.
    pub grids: Vec<Vec<f64>>,
    /// How the run ended when not by its own rules ([`run::abc::Store::early_end`]), for a run source.
    pub early_end: Option<String>,
    /// What the run's record showed of its bit (a run source whose store keeps it).
    pub record_bit: Option<crate::data::BitSeen>,
    /// The W_ref (N) a run's parameters are for where its fit scaled each torque by WOB / W_ref.
    pub run_w_ref_n: Option<f64>,
}

impl StabilityJob {
    /// Refuses, naming the setting, what cannot be mapped: a percentile outside (0, 1), a
    /// W_ref that is not a positive number, no samples, a law's parameters it cannot take, and
    /// a grid beyond memory or a day's work (one law's, before any run is read).
    pub fn validate(&self) -> Result<()> {
        if !(self.percentile > 0.0 && self.percentile < 1.0) {
            return Err(Error::setting(
                "percentile",
                format!("must lie in (0, 100) %, got {}", self.percentile * 100.0),
            ));
        }
        if !(self.w_ref_n.is_finite() && self.w_ref_n > 0.0) {
            return Err(Error::setting(
                "w_ref_kn",
                format!("must be a positive number of kN, got {}", self.w_ref_n / 1000.0),
            ));
        }
        if self.samples == 0 {
            return Err(Error::setting("samples", "must be at least 1"));
        }
        for (field, axis) in [("omega_rpm", &self.omega_rpm), ("wob_kn", &self.wob_kn)] {
            let positive = axis.iter().all(|v| v.is_finite() && *v > 0.0);
            if axis.is_empty() || !positive || axis.windows(2).any(|w| w[0] >= w[1]) {
                return Err(Error::setting(
                    field,
                    format!(
                        "must be positive numbers in increasing order, got {} values",
                        axis.len()
                    ),
                ));
            }
        }
        match &self.source {
            MapSource::Law { law, params_si } => law.check_params(params_si, "params")?,
            MapSource::Posterior(particles) => check_posterior(particles)?,
            MapSource::Run(_) => {}
        }
        map::check_grid_size(self.cells(), 1, self.samples)
    }

    /// The job on `structure`: the 1-DOF model `lumped`, or the finite-element string `fe`
    /// describes, whose critical bit damping is found (a bisection) once the job's cheap checks
    /// passed (a long search said through `note`). Refuses FE settings given for the 1-DOF
    /// string.
    pub fn on(
        mut self,
        structure: Structure,
        lumped: Lumped,
        fe: &DrillStringSettings,
        note: &mut dyn FnMut(String),
    ) -> Result<Self> {
        check_structure(structure, &lumped, fe)?;
        self.criterion = Criterion::Lumped(lumped);
        self.validate()?;
        self.criterion = criterion(structure, lumped, fe, note)?;
        Ok(self)
    }

    fn cells(&self) -> usize {
        self.omega_rpm.len() * self.wob_kn.len()
    }

    /// Reads the source, checks the grid for its laws, and computes every boundary and grid.
    /// A GPU that cannot be used under `auto` is told to `note`, and the CPU computes.
    pub fn run(&self, note: &mut dyn FnMut(String)) -> Result<StabilityMaps> {
        self.validate()?;
        if let MapSource::Law { law, params_si } = &self.source
            && let Some(warning) = law.implausible_torque(params_si, "torque_unit")
        {
            note(format!("warning: {warning}"));
        }
        let (inputs, early_end, record_bit, run_w_ref_n) = match &self.source {
            MapSource::Run(dir) => from_run(dir, self.samples)?,
            MapSource::Posterior(particles) => (
                crate::abc::posterior::map_inputs_of(particles, self.samples),
                None,
                None,
                None,
            ),
            MapSource::Law { law, params_si } => (
                vec![LawSamples {
                    law: *law,
                    probability: 1.0,
                    map_si: params_si.clone(),
                    samples_si: vec![params_si.clone()],
                    strings: Vec::new(),
                }],
                None,
                None,
                None,
            ),
        };
        map::check_grid_size(self.cells(), inputs.len(), self.samples)?;
        // Per law, the speeds where a sample's torque has no value: said once, and masked in
        // a GPU grid (the CPU twin masks its own).
        let unknown: Vec<Vec<bool>> = inputs
            .iter()
            .map(|input| map::unknown_speeds(input.law, &input.samples_si, &self.omega_rpm))
            .collect();
        for (input, unknown) in inputs.iter().zip(&unknown) {
            let count = unknown.iter().filter(|&&u| u).count();
            if count > 0 {
                note(format!(
                    "warning: law {}: its torque has no value at {count} of the {} speeds for some of its samples (first at {} rpm): its boundaries and map cells there are unknown, not stable",
                    input.law,
                    unknown.len(),
                    self.omega_rpm[unknown.iter().position(|&u| u).expect("one is")]
                ));
            }
        }
        let c = self.criterion.critical_nms();
        let boundaries = map::boundaries(&inputs, &self.omega_rpm, c, self.w_ref_n, self.percentile);
        for warning in boundaries.off_the_map(&self.omega_rpm, &self.wob_kn, &self.criterion, self.percentile) {
            note(format!("warning: {warning}"));
        }
        let mut backend = self.backend;
        let note = std::cell::RefCell::new(note);
        let total = (self.cells() * self.samples * inputs.len()) as u64;
        let (start, mut last) = (std::time::Instant::now(), std::time::Instant::now());
        let mut report = |done: u64, total: u64| {
            if start.elapsed() >= PROGRESS_AFTER && last.elapsed() >= PROGRESS_EVERY {
                last = std::time::Instant::now();
                (note.borrow_mut())(format!(
                    "stability grid: {:.1} % of the cell-samples after {}",
                    100.0 * done as f64 / total.max(1) as f64,
                    crate::limits::human_seconds(start.elapsed().as_secs_f64())
                ));
            }
        };
        let mut pace = crate::limits::Pace::new(
            "samples",
            format!(
                "{} cells × {} samples × {} laws on the CPU",
                self.cells(),
                self.samples,
                inputs.len()
            ),
            total,
            &mut report,
        );
        let grids = inputs
            .iter()
            .zip(&unknown)
            .map(|(input, unknown)| self.grid(input, unknown, &mut backend, &note, &mut pace))
            .collect::<Result<_>>()?;
        Ok(StabilityMaps {
            inputs,
            boundaries,
            grids,
            early_end,
            record_bit,
            run_w_ref_n,
        })
    }

    /// One law's probability grid: the GPU's `stability_grid` unless the backend is the CPU;
    /// under `auto` a GPU that cannot be used is said once and the CPU computes this grid and
    /// the next ones.
    fn grid(
        &self,
        input: &LawSamples,
        unknown: &[bool],
        backend: &mut Backend,
        note: &std::cell::RefCell<&mut dyn FnMut(String)>,
        pace: &mut crate::limits::Pace,
    ) -> Result<Vec<f64>> {
        let grid = map::Grid {
            law: input.law,
            samples: &input.samples_si,
            omega_rpm: &self.omega_rpm,
            wob_kn: &self.wob_kn,
            criterion: self.criterion,
            w_ref_n: self.w_ref_n,
        };
        if *backend != Backend::Cpu {
            match crate::eval::gpu::stability::stability_grid(&grid) {
                Ok((counts, _)) => {
                    let n = input.samples_si.len() as f64;
                    let row = self.wob_kn.len();
                    return Ok(counts
                        .iter()
                        .enumerate()
                        .map(|(k, &c)| if unknown[k / row] { f64::NAN } else { f64::from(c) / n })
                        .collect());
                }
                Err(e) if *backend == Backend::Gpu => return Err(e.into()),
                Err(e) => {
                    crate::eval::fall_back_to_cpu(e, *note.borrow_mut())?;
                    *backend = Backend::Cpu;
                }
            }
        }
        map::probability_grid_with(&grid, pace)
    }
}

/// A drill string resolved, as a run or an evidence keeps it: the structure its maps and advice
/// are judged on, the 1-DOF string, and for the finite-element structure the string as read
/// and overridden when the run was made (a file changed later does not change the run).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DrillStringSpec {
    pub structure: Structure,
    pub lumped: Lumped,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fe: Option<DrillString>,
}

impl DrillStringSpec {
    /// The string `structure`, `lumped` and `fe` describe, checked as [`criterion`] checks it.
    pub fn of(structure: Structure, lumped: Lumped, fe: &DrillStringSettings) -> Result<Self> {
        check_structure(structure, &lumped, fe)?;
        let fe = match structure {
            Structure::Lumped => None,
            Structure::Fe => Some(fe.drill_string()?),
        };
        Ok(Self { structure, lumped, fe })
    }

    /// In one line, for a run's summary and a report.
    pub fn describe(&self) -> String {
        let l = &self.lumped;
        let one_dof = format!(
            "1-DOF string I_eq = {} kg·m², ω_n = {} rad/s, ξ = {}",
            l.inertia_kg_m2, l.omega_n_rad_s, l.damping_ratio
        );
        match &self.fe {
            Some(s) => format!(
                "finite-element string of {} + {} elements (α = {} 1/s, β = {} s); {one_dof}",
                s.dp_elements, s.bha_elements, s.alpha, s.beta
            ),
            None => one_dof,
        }
    }
}

/// A drill string as a user gives it, a field at a time: what is not given comes from the
/// string it is laid over (a run's or an evidence's own, else the paper's).
#[derive(Clone, Debug, Default)]
pub struct StringGiven {
    pub structure: Option<Structure>,
    pub inertia_kg_m2: Option<f64>,
    pub omega_n_rad_s: Option<f64>,
    pub damping_ratio: Option<f64>,
    /// The finite-element string's file and overrides (its `base` is set by [`Self::over`]).
    pub fe: DrillStringSettings,
}

impl StringGiven {
    /// True where any field is given.
    pub fn is_given(&self) -> bool {
        self.structure.is_some()
            || self.inertia_kg_m2.is_some()
            || self.omega_n_rad_s.is_some()
            || self.damping_ratio.is_some()
            || self.fe.first_given().is_some()
    }

    /// The string laid over `base` (`None`: the paper's 1-DOF string): the structure, the 1-DOF
    /// string and the finite-element settings every map and simulation takes.
    pub fn over(&self, base: Option<&DrillStringSpec>) -> (Structure, Lumped, DrillStringSettings) {
        let paper = Lumped::default();
        let lumped = base.map_or(paper, |b| b.lumped);
        let structure = self.structure.or(base.map(|b| b.structure)).unwrap_or_default();
        let lumped = Lumped {
            inertia_kg_m2: self.inertia_kg_m2.unwrap_or(lumped.inertia_kg_m2),
            omega_n_rad_s: self.omega_n_rad_s.unwrap_or(lumped.omega_n_rad_s),
            damping_ratio: self.damping_ratio.unwrap_or(lumped.damping_ratio),
        };
        let fe = DrillStringSettings {
            base: base.and_then(|b| b.fe.clone()),
            ..self.fe.clone()
        };
        (structure, lumped, fe)
    }

    /// The string a run made with these settings keeps: `None` where none is given (its maps
    /// take the paper's), refused as [`criterion`] refuses it.
    pub fn spec(&self) -> Result<Option<DrillStringSpec>> {
        if !self.is_given() {
            return Ok(None);
        }
        let (structure, lumped, fe) = self.over(None);
        DrillStringSpec::of(structure, lumped, &fe).map(Some)
    }
}

/// The drill string kept with the run or the evidence in `dir`, where it was made with one; a
/// surface run's, as it simulated its candidates on it.
pub fn stored_string(dir: &std::path::Path) -> Result<Option<DrillStringSpec>> {
    if run::surface::dir::is_surface_dir(dir) {
        return Ok(Some(DrillStringSpec {
            structure: Structure::Lumped,
            lumped: run::surface::dir::Finished::read(dir)?.string()?,
            fe: None,
        }));
    }
    if run::dir::is_evidence_dir(dir) {
        return Ok(run::evidence::dir::job(dir)?.and_then(|job| job.string));
    }
    if !run::dir::is_run_dir(dir) {
        return Ok(None);
    }
    let config = run::abc::Store::open(dir)?.config()?;
    Ok(serde_json::from_value::<run::abc::Config>(config)
        .ok()
        .and_then(|c| c.string))
}

/// Where the surface run in `dir` inferred its string and `given` sets none of it: the
/// string every posterior sample carries after its law's parameters, on which the simulated
/// strings take it ([`crate::run::strings::SimulatedSettings::string`]); the linear maps
/// take the posterior medians.
pub fn sample_strings(dir: &std::path::Path, given: &StringGiven) -> Result<Option<InferredString>> {
    if given.is_given() || !run::surface::dir::is_surface_dir(dir) {
        return Ok(None);
    }
    run::surface::dir::Finished::read(dir)?.sample_strings()
}

/// The maps' `inputs` of the surface run in `dir` (`count` samples per law) with each
/// sample's string, where the run inferred it: the same particles, drawn as the maps drew
/// them ([`crate::abc::posterior::law_samples`]), with their strings' coordinates.
pub fn with_sample_strings(dir: &std::path::Path, inputs: &[LawSamples], count: usize) -> Result<Vec<LawSamples>> {
    let particles = run::surface::dir::Finished::read(dir)?.particles()?;
    Ok(inputs
        .iter()
        .map(|input| {
            crate::abc::posterior::law_samples_of(
                input.law,
                input.probability,
                input.map_si.clone(),
                &crate::abc::posterior::law_samples(&particles, input.law, count),
            )
        })
        .collect())
}

/// Refuses finite-element settings given for the 1-DOF string, and a 1-DOF model that is not
/// one.
fn check_structure(structure: Structure, lumped: &Lumped, fe: &DrillStringSettings) -> Result<()> {
    if structure == Structure::Lumped
        && let Some(field) = fe.first_given()
    {
        return Err(Error::setting(
            field,
            "applies to `structure` fe only (the 1-DOF string has no elements)",
        ));
    }
    lumped.validate()
}

/// Seconds of eigenvalue solves above which the search for a string's critical bit damping
/// is said before it starts.
const SAY_CRITICAL_AFTER_S: f64 = 5.0;

/// What decides stability on `structure`: the 1-DOF model `lumped`, or the critical bit
/// damping of the finite-element string `fe` describes (a bisection over its eigenvalues:
/// seconds to minutes, see [`crate::stability::fe`]; said through `note`, with its time
/// estimated, before a search of more than a few seconds).
pub fn criterion(
    structure: Structure,
    lumped: Lumped,
    fe: &DrillStringSettings,
    note: &mut dyn FnMut(String),
) -> Result<Criterion> {
    check_structure(structure, &lumped, fe)?;
    Ok(match structure {
        Structure::Lumped => Criterion::Lumped(lumped),
        Structure::Fe => {
            let string = fe.drill_string()?;
            let solves = crate::stability::fe::SOLVES_PER_CRITICAL;
            let seconds = string.estimate_seconds(solves);
            if seconds > SAY_CRITICAL_AFTER_S {
                note(format!(
                    "note: the critical bit damping of the {}-element string: about {solves:.0} eigenvalue solves of a {}-DOF Jacobian, about {} on this machine",
                    string.dp_elements + string.bha_elements,
                    string.dofs(),
                    crate::limits::human_seconds(seconds)
                ));
            }
            Criterion::Critical(string.critical_bit_damping()?.critical_bit_damping_nms)
        }
    })
}

/// What a map's source gives besides its grid: the inputs (samples per law), why a run ended
/// early, what its record's bit did, and the W_ref its torques were scaled by.
type SourceParts = (
    Vec<LawSamples>,
    Option<String>,
    Option<crate::data::BitSeen>,
    Option<f64>,
);

/// The map inputs of the ABC run in `dir` (its last population, `samples` per law), why it
/// ended early if it did, what its record's bit did, and the W_ref its torques were scaled by.
fn from_run(dir: &std::path::Path, samples: usize) -> Result<SourceParts> {
    run::dir::refuse_unfinished_evidence(dir)?;
    let store = run::abc::Store::open(dir)?;
    let early_end = store.early_end()?;
    let stored = store.load_with_last_particles()?;
    let last = stored.populations.last().ok_or_else(|| Error::Data {
        path: dir.to_path_buf(),
        message: format!(
            "the run has no completed population yet; {}",
            run::abc::resume_advice(dir)
        ),
    })?;
    let run_w_ref_n = serde_json::from_value::<run::abc::Config>(stored.setup.config.clone())
        .ok()
        .and_then(|c| c.fit.w_ref_n);
    Ok((
        crate::abc::posterior::map_inputs(last, samples),
        early_end,
        stored.setup.data.bit,
        run_w_ref_n,
    ))
}
