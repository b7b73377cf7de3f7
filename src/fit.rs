//! Least-squares calibration of each law: minimise the paper's misfit
//! ρ(φ) = ‖y − A(φ)‖² / ‖y‖² over the calibration samples (eq. LSeq).
//!
//! The problem is made scale-free before the optimiser sees it: torques are divided by the
//! RMS torque and speeds by the 95th-percentile speed, and every parameter is rescaled by its
//! dimension ([`crate::laws::ParamSpec`]). So laboratory data in N·m and field data in kN·m are
//! the same problem to the optimiser. Starting points come from the data: for each law the
//! parameters that enter linearly are solved exactly on a grid of the nonlinear ones
//! (variable projection), and Levenberg-Marquardt (the `levenberg-marquardt` crate) polishes
//! the best few. Physical bounds are kept by MINUIT's transforms (p = lb − 1 + √(u² + 1) above
//! a lower bound, its mirror below an upper one, lb + (ub − lb)(sin u + 1)/2 between both),
//! which leave the optimiser unconstrained.

pub mod axial_rests;
pub mod coupled;

use crate::data::{FieldData, SAME_SPEED_TOLERANCE, Samples};
use crate::error::{Error, Result};
use crate::laws::{Law, PAPER_W_REF_N};
use crate::memo::{Key, Memo};
use crate::numerics::{compensated_sum, geomspace, quantile};
use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt, TerminationReason};
use nalgebra::{DMatrix, DVector, Dyn, Owned};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::cell::Cell;
use std::collections::HashMap;

/// How to fit.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct FitOptions {
    /// Keep every parameter within its physical bound (`bounded: false` lifts them).
    pub bounded: bool,
    /// Number of grid starting points polished by Levenberg-Marquardt per law.
    pub starts: usize,
    /// When set, the predicted torque of each sample is scaled by r = WOB / W_ref (N); when
    /// `None`, r = 1 for every sample (the paper's assumption).
    pub w_ref_n: Option<f64>,
}

impl FitOptions {
    /// The options as a user sets them: `bounded`, `starts` (`None`: the default), and
    /// `scale_by_wob` with its reference weight `w_ref_kn` (kN; `None`: the paper's 244.2).
    /// `w_ref_kn` without `scale_by_wob` is refused: r = 1 then, and the user could believe
    /// W_ref was used.
    pub fn from_settings(
        bounded: bool,
        starts: Option<usize>,
        scale_by_wob: bool,
        w_ref_kn: Option<f64>,
    ) -> Result<Self> {
        if w_ref_kn.is_some() && !scale_by_wob {
            return Err(Error::setting(
                "w_ref_kn",
                "applies only with `scale_by_wob` (r = WOB / W_ref); without it r = 1 for every sample and W_ref is not used",
            ));
        }
        let w_ref_kn = w_ref_kn.unwrap_or(PAPER_W_REF_N / 1000.0);
        Ok(Self {
            bounded,
            starts: starts.unwrap_or(Self::default().starts),
            w_ref_n: scale_by_wob.then_some(w_ref_kn * 1000.0),
        })
    }
}

impl Default for FitOptions {
    fn default() -> Self {
        Self {
            bounded: true,
            starts: 6,
            w_ref_n: None,
        }
    }
}

impl FitOptions {
    /// The options into a memo's key ([`crate::memo`]), taken apart field by field so that a
    /// field added must be placed here or left out on purpose.
    pub(crate) fn hash_into(&self, key: &mut Key) {
        let FitOptions {
            bounded,
            starts,
            w_ref_n,
        } = *self;
        key.value((bounded, starts, w_ref_n.map(f64::to_bits)));
    }

    /// Refuses options that cannot fit, naming the flag: no starting point, a W_ref that is
    /// not a positive number.
    pub fn validate(&self) -> Result<()> {
        if self.starts == 0 {
            return Err(Error::setting("starts", "must be at least 1"));
        }
        if let Some(w_ref_n) = self.w_ref_n
            && !(w_ref_n.is_finite() && w_ref_n > 0.0)
        {
            return Err(Error::setting(
                "w_ref_kn",
                format!("must be a positive number of kN, got {}", w_ref_n / 1000.0),
            ));
        }
        Ok(())
    }

    /// [`Self::validate`], and refuses scaling by r = WOB / W_ref on samples without weight on
    /// bit.
    pub fn validate_for(&self, calibration: &Samples) -> Result<()> {
        self.validate()?;
        if self.w_ref_n.is_some() && calibration.wob_n.is_none() {
            return Err(Error::setting(
                "scale_by_wob",
                "the record has no weight-on-bit column (name one with `wob_column`)",
            ));
        }
        if let (Some(_), Some(wob)) = (self.w_ref_n, &calibration.wob_n) {
            let not_positive = wob.iter().filter(|&&w| w.is_nan() || w <= 0.0).count();
            if not_positive > 0 {
                return Err(Error::setting(
                    "scale_by_wob",
                    format!(
                        "{not_positive} of the {} calibration rows have weight on bit ≤ 0, where r = WOB / W_ref makes every law predict no torque; drop `scale_by_wob` or those rows",
                        wob.len()
                    ),
                ));
            }
        }
        Ok(())
    }
}

/// The least-squares estimate of one law. Parameters are SI (torques in N·m).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct LawFit {
    pub law: Law,
    /// Estimates, SI (torque-valued parameters in N·m).
    pub params_si: Vec<f64>,
    /// Standard errors from the Jacobian, SI; `None` for a parameter on its bound or one the
    /// data cannot determine.
    pub std_errors_si: Vec<Option<f64>>,
    /// ρ on the calibration samples.
    #[serde(with = "crate::numerics::json_f64")]
    pub rho: f64,
    /// ρ on the validation samples, when there are any.
    pub validation_rho: Option<f64>,
    /// Condition number of the column-normalised Jacobian at the estimate.
    #[serde(with = "crate::numerics::json_f64")]
    pub condition_number: f64,
    /// Pearson correlations of the estimates (row-major, n × n); `None` entries where a
    /// standard error is undefined.
    pub correlations: Vec<Vec<Option<f64>>>,
    /// Whatever the user must know before trusting the numbers.
    pub warnings: Vec<String>,
    /// Levenberg-Marquardt runs made (starting points polished).
    pub starts: usize,
    /// How the runs ended. Counted while fitting; the run store does not keep it.
    #[serde(skip)]
    pub endings: Endings,
    /// Scales of the calibration samples the law was fitted to; not serialised (a reader
    /// recomputes them from those samples, as [`crate::run::abc::Setup`] does).
    #[serde(skip, default = "RecordScales::unknown")]
    pub scales: RecordScales,
}

/// How a fit's Levenberg-Marquardt runs ended, where not converged.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Endings {
    /// Runs that spent their whole budget of evaluations (the optimiser's patience) still
    /// improving.
    pub out_of_patience: usize,
    /// Runs stopped early because they could not beat the misfit of a run already finished
    /// ([`fit_law_from`]).
    pub abandoned: usize,
    /// Whether the estimate itself comes from a run that spent its patience.
    pub estimate_out_of_patience: bool,
}

/// y − r·T(w) of `law` at `params` on `samples`, N·m: what a fit leaves (and what the
/// selection check and the evidence check resample as noise).
pub fn residuals(law: Law, params: &[f64], samples: &Samples, w_ref_n: Option<f64>) -> Vec<f64> {
    let r = samples.wob_ratio(w_ref_n);
    samples
        .speed_rad_s
        .iter()
        .zip(&samples.torque_nm)
        .zip(&r)
        .map(|((&w, &y), &r)| y - law.torque(params, w, r))
        .collect()
}

impl LawFit {
    /// A fit with the given estimates and ρ, no standard errors and unit scales: for tests of
    /// what is built on fits (priors, floors).
    #[cfg(test)]
    pub(crate) fn for_tests(law: Law, params_si: Vec<f64>, rho: f64) -> Self {
        Self {
            law,
            std_errors_si: vec![None; params_si.len()],
            params_si,
            rho,
            validation_rho: None,
            condition_number: 1.0,
            correlations: vec![],
            warnings: vec![],
            starts: 1,
            endings: Endings::default(),
            scales: RecordScales {
                torque: 1.0,
                speed: 1.0,
            },
        }
    }
}

/// The paper's misfit ρ = Σ(y − r·T(w))² / Σy², summed with compensation. `sum_y2` is Σy²
/// (pass [`Samples::sum_sq_torque`]); `params` must be in the unit of `y`.
pub fn misfit(law: Law, params: &[f64], w: &[f64], y: &[f64], r: &[f64], sum_y2: f64) -> f64 {
    let ssr = compensated_sum(w.iter().zip(y).zip(r).map(|((&w, &y), &r)| {
        let e = y - law.torque(params, w, r);
        e * e
    }));
    ssr / sum_y2
}

/// Fits every law in `laws` to a record's calibration samples ([`fit_laws`]); a fit the
/// samples defeat is refused as bad input naming the record ([`Error::Fit`]). Worked out once
/// per process for the same laws, samples and options: asked again (every run on one record,
/// the report of each), the same fits come back.
pub fn fit_record(laws: &[Law], data: &FieldData, opts: &FitOptions) -> Result<Vec<LawFit>> {
    static MEMO: Memo<Vec<LawFit>> = Memo::new();
    let mut key = Key::new();
    // A law's name is its definition within a process: a second law file of the same name
    // and another law is refused.
    key.value(laws.iter().map(|l| l.name()).collect::<Vec<_>>());
    key.samples(&data.calibration)
        .samples(&data.validation)
        .value(&data.source);
    opts.hash_into(&mut key);
    MEMO.get_or_try(key.finish(), || fit_record_from(laws, data, opts, &[]))
}

/// [`fit_record`] with known starting points, SI, by law ([`fit_law_from`]).
pub fn fit_record_from(
    laws: &[Law],
    data: &FieldData,
    opts: &FitOptions,
    known: &[(Law, Vec<f64>)],
) -> Result<Vec<LawFit>> {
    fit_record_within(laws, data, opts, known, 0.0)
}

/// [`fit_record_from`] for fits whose sums of squared residuals matter only to within
/// `resolution_nm2` (N·m²; [`fit_law_within`]), the validation samples not used where it is
/// positive; at 0, [`fit_record_from`] itself.
pub fn fit_record_within(
    laws: &[Law],
    data: &FieldData,
    opts: &FitOptions,
    known: &[(Law, Vec<f64>)],
    resolution_nm2: f64,
) -> Result<Vec<LawFit>> {
    let resolution_nm2 = resolution_nm2.max(0.0);
    let empty = Samples::default();
    let validation = if resolution_nm2 > 0.0 { &empty } else { &data.validation };
    fit_laws_to(laws, &data.calibration, validation, opts, known, resolution_nm2).map_err(|e| match e {
        Error::Fit { law, message, .. } => Error::Fit {
            record: Some(data.source.clone()),
            law,
            message,
        },
        other => other,
    })
}

/// Fits every law in `laws` (in parallel) to the calibration part of `samples`.
/// Refuses options that cannot fit these samples first ([`FitOptions::validate_for`]); of
/// several laws that fail, the first in `laws` is reported, whatever the threads' order.
pub fn fit_laws(laws: &[Law], calibration: &Samples, validation: &Samples, opts: &FitOptions) -> Result<Vec<LawFit>> {
    fit_laws_from(laws, calibration, validation, opts, &[])
}

/// [`fit_laws`] with known starting points, SI, by law: each law is given those of `known`
/// that name it ([`fit_law_from`]).
pub fn fit_laws_from(
    laws: &[Law],
    calibration: &Samples,
    validation: &Samples,
    opts: &FitOptions,
    known: &[(Law, Vec<f64>)],
) -> Result<Vec<LawFit>> {
    fit_laws_to(laws, calibration, validation, opts, known, 0.0)
}

/// [`fit_laws_from`], each run stopped once its gain falls below `resolution_nm2` where > 0.
fn fit_laws_to(
    laws: &[Law],
    calibration: &Samples,
    validation: &Samples,
    opts: &FitOptions,
    known: &[(Law, Vec<f64>)],
    resolution_nm2: f64,
) -> Result<Vec<LawFit>> {
    opts.validate_for(calibration)?;
    let fits: Vec<Result<LawFit>> = laws
        .par_iter()
        .map(|&law| {
            let starts: Vec<Vec<f64>> = known
                .iter()
                .filter(|(l, _)| *l == law)
                .map(|(_, p)| p.clone())
                .collect();
            fit_law_to(law, calibration, validation, opts, &starts, resolution_nm2)
        })
        .collect();
    fits.into_iter().collect()
}

/// Characteristic scales of a record, which make the least-squares problem dimensionless and
/// give every parameter a natural size (a torque parameter the RMS torque, a rate the inverse
/// of a typical speed) where its estimate gives none (see [`crate::prior`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct RecordScales {
    /// RMS torque, N·m.
    pub torque: f64,
    /// 95th-percentile bit speed, rad/s.
    pub speed: f64,
}

impl RecordScales {
    /// Scales not yet known (NaN): what a fit read without its samples holds until they are
    /// recomputed from them.
    fn unknown() -> Self {
        Self {
            torque: f64::NAN,
            speed: f64::NAN,
        }
    }

    /// The scales of the samples a law is fitted to.
    pub fn of(samples: &Samples) -> Self {
        let m = samples.speed_rad_s.len().max(1);
        Self {
            torque: (samples.sum_sq_torque() / m as f64).sqrt(),
            speed: quantile(&samples.speed_rad_s, 0.95).max(f64::MIN_POSITIVE),
        }
    }

    /// Factor that takes an SI parameter to the scaled problem.
    fn factor(&self, law: Law, j: usize) -> f64 {
        let s = law.params()[j];
        self.speed.powi(s.inverse_speed_power) / self.torque.powi(s.torque_power)
    }

    /// The record's natural size of parameter `j` of `law`, SI: torque^t · speed^(−s) for a
    /// parameter of dimension torque^t · (rad/s)^(−s).
    pub fn param_scale(&self, law: Law, j: usize) -> f64 {
        1.0 / self.factor(law, j)
    }
}

/// One parameter's map from the optimiser's unconstrained u to the scaled parameter p.
#[derive(Clone, Copy, Debug)]
enum Transform {
    Free,
    /// MINUIT's one-sided transform: p = lb − 1 + √(u² + 1) ≥ lb.
    Lower(f64),
    /// Its mirror: p = ub + 1 − √(u² + 1) ≤ ub.
    Upper(f64),
    /// MINUIT's two-sided transform: p = lb + (ub − lb)·(sin u + 1)/2 in [lb, ub].
    Both(f64, f64),
}

impl Transform {
    fn to_param(self, u: f64) -> f64 {
        match self {
            Transform::Free => u,
            Transform::Lower(lb) => lb - 1.0 + (u * u + 1.0).sqrt(),
            Transform::Upper(ub) => ub + 1.0 - (u * u + 1.0).sqrt(),
            Transform::Both(lb, ub) => lb + 0.5 * (ub - lb) * (u.sin() + 1.0),
        }
    }
    fn to_internal(self, p: f64) -> f64 {
        match self {
            Transform::Free => p,
            Transform::Lower(lb) => {
                let a = (p - lb + 1.0).max(1.0);
                (a * a - 1.0).sqrt()
            }
            Transform::Upper(ub) => {
                let a = (ub - p + 1.0).max(1.0);
                (a * a - 1.0).sqrt()
            }
            Transform::Both(lb, ub) => (2.0 * (p - lb) / (ub - lb) - 1.0).clamp(-1.0, 1.0).asin(),
        }
    }
    fn derivative(self, u: f64) -> f64 {
        match self {
            Transform::Free => 1.0,
            Transform::Lower(_) => u / (u * u + 1.0).sqrt(),
            Transform::Upper(_) => -u / (u * u + 1.0).sqrt(),
            Transform::Both(lb, ub) => 0.5 * (ub - lb) * u.cos(),
        }
    }
}

/// The scaled least-squares problem handed to Levenberg-Marquardt.
struct Problem<'a> {
    law: Law,
    w: &'a [f64],
    y: &'a [f64],
    r: &'a [f64],
    transforms: Vec<Transform>,
    u: DVector<f64>,
    /// Where set, the run is stopped once it cannot reach the race's target, or once what is
    /// left of it no longer matters.
    race: Option<Race>,
}

/// A run of Levenberg-Marquardt against a misfit already reached (`target`). Every `window`
/// evaluations, at the accepted point, the run's progress is extrapolated: its gain per window
/// over the last window, shrinking no faster than 1/k in the window index k counted from the
/// run's start (a crawl's gains shrink faster, a run descending into a valley does not
/// shrink), over all its remaining evaluations. The run is stopped once that would not take it
/// below the target by more than what counts as an equal fit ([`EQUAL_FIT`]): runs crawling
/// along a ridge of the law toward a limit at infinity, behind another, stop within a few
/// windows. A fit that needs its misfit only to a `resolution` also stops a run whose
/// extrapolated gain falls below it, and one that cannot beat the target by more than it. The
/// rule only observes: a run it does not stop takes exactly the steps it takes without it.
struct Race {
    /// Sum of squared residuals (scaled) to beat, where a finished run has set one.
    target: Option<f64>,
    /// Gain in the sum of squares (scaled) below which the rest of a run does not matter
    /// (0: every gain matters).
    resolution: f64,
    window: usize,
    max_evaluations: usize,
    /// Residual evaluations so far, and the sum of squares of the last.
    evaluations: Cell<usize>,
    last_ssr: Cell<f64>,
    /// Evaluations and sum of squares at the start of the current window.
    checkpoint: Cell<Option<(usize, f64)>>,
    stopped: Cell<bool>,
}

impl Race {
    fn new(stop: Stop, patience: usize, n: usize) -> Self {
        Self {
            target: stop.target,
            resolution: stop.resolution,
            window: (patience / RACE_WINDOWS).max(1) * (n + 1),
            max_evaluations: patience * (n + 1),
            evaluations: Cell::new(0),
            last_ssr: Cell::new(f64::INFINITY),
            checkpoint: Cell::new(None),
            stopped: Cell::new(false),
        }
    }

    fn evaluated(&self, residuals: &DVector<f64>) {
        self.evaluations.set(self.evaluations.get() + 1);
        self.last_ssr.set(residuals.norm_squared());
    }

    /// At an accepted point (Levenberg-Marquardt asks for the Jacobian there, right after
    /// evaluating its residuals): whether to go on.
    fn goes_on(&self) -> bool {
        let (evaluations, ssr) = (self.evaluations.get(), self.last_ssr.get());
        let Some((since, ssr_then)) = self.checkpoint.get() else {
            self.checkpoint.set(Some((evaluations, ssr)));
            return true;
        };
        if evaluations < since + self.window {
            return true;
        }
        let gain_per_window = (ssr_then - ssr).max(0.0) * self.window as f64 / (evaluations - since) as f64;
        // Window k of the run gains g·k/(k + j) in its j-th window from now.
        let k = evaluations as f64 / self.window as f64;
        let remaining_windows = self.max_evaluations.saturating_sub(evaluations) as f64 / self.window as f64;
        // A sum of squares cannot fall below zero: no run gains more than it has left.
        let reachable_gain = (gain_per_window * k * (1.0 + remaining_windows / k).ln()).min(ssr);
        let cannot_win = self
            .target
            .is_some_and(|target| ssr - reachable_gain > target * (1.0 - EQUAL_FIT) - self.resolution);
        if cannot_win || reachable_gain < self.resolution {
            self.stopped.set(true);
            return false;
        }
        self.checkpoint.set(Some((evaluations, ssr)));
        true
    }
}

impl Problem<'_> {
    fn scaled_params(&self) -> Vec<f64> {
        self.transforms
            .iter()
            .zip(self.u.iter())
            .map(|(t, &u)| t.to_param(u))
            .collect()
    }
}

impl LeastSquaresProblem<f64, Dyn, Dyn> for Problem<'_> {
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, Dyn>;
    type ParameterStorage = Owned<f64, Dyn>;

    fn set_params(&mut self, u: &DVector<f64>) {
        self.u.copy_from(u);
    }

    fn params(&self) -> DVector<f64> {
        self.u.clone()
    }

    fn residuals(&self) -> Option<DVector<f64>> {
        let p = self.scaled_params();
        let res = DVector::from_iterator(
            self.w.len(),
            self.w
                .iter()
                .zip(self.y)
                .zip(self.r)
                .map(|((&w, &y), &r)| self.law.torque(&p, w, r) - y),
        );
        if let Some(race) = &self.race {
            race.evaluated(&res);
        }
        res.iter().all(|v| v.is_finite()).then_some(res)
    }

    fn jacobian(&self) -> Option<DMatrix<f64>> {
        if let Some(race) = &self.race
            && !race.goes_on()
        {
            return None;
        }
        let p = self.scaled_params();
        let n = p.len();
        let chain: Vec<f64> = self
            .transforms
            .iter()
            .zip(self.u.iter())
            .map(|(t, &u)| t.derivative(u))
            .collect();
        let mut jac = DMatrix::zeros(self.w.len(), n);
        let mut grad = [0.0; crate::laws::MAX_PARAMS];
        for (i, (&w, &r)) in self.w.iter().zip(self.r).enumerate() {
            self.law.torque_and_gradient(&p, w, &mut grad[..n]);
            for j in 0..n {
                jac[(i, j)] = r * grad[j] * chain[j];
            }
        }
        jac.iter().all(|v| v.is_finite()).then_some(jac)
    }
}

/// The normal equations of a grid's linear parameters. Grid points share columns (m3's 378
/// points use 54 Gaussian columns, one constant and 7 tanh columns), so each column, and each
/// product of two columns or of a column and y, is computed once and reused: the same sums,
/// bit for bit, as computing them at every point.
struct GridColumns<'a> {
    y: &'a [f64],
    columns: Vec<Vec<f64>>,
    /// Σ column_a · column_b (compensated), by (a, b) with a ≤ b.
    products: HashMap<(usize, usize), f64>,
    /// Σ column_a · y (compensated), by a.
    with_y: HashMap<usize, f64>,
}

impl<'a> GridColumns<'a> {
    fn new(y: &'a [f64]) -> Self {
        Self {
            y,
            columns: Vec::new(),
            products: HashMap::new(),
            with_y: HashMap::new(),
        }
    }

    /// Adds a column (one value per sample); returns its id.
    fn add(&mut self, column: Vec<f64>) -> usize {
        self.columns.push(column);
        self.columns.len() - 1
    }

    /// Least squares for the coefficients of columns `ids`, by normal equations on a handful
    /// of columns. `None` when singular.
    fn coefficients(&mut self, ids: &[usize]) -> Option<Vec<f64>> {
        let k = ids.len();
        let mut ata = DMatrix::<f64>::zeros(k, k);
        let mut aty = DVector::<f64>::zeros(k);
        for a in 0..k {
            for b in a..k {
                let key = (ids[a].min(ids[b]), ids[a].max(ids[b]));
                let columns = &self.columns;
                let v = *self
                    .products
                    .entry(key)
                    .or_insert_with(|| compensated_sum(columns[key.0].iter().zip(&columns[key.1]).map(|(x, z)| x * z)));
                ata[(a, b)] = v;
                ata[(b, a)] = v;
            }
            let (columns, y) = (&self.columns, self.y);
            aty[a] = *self
                .with_y
                .entry(ids[a])
                .or_insert_with(|| compensated_sum(columns[ids[a]].iter().zip(y).map(|(x, z)| x * z)));
        }
        let solution = ata.cholesky()?.solve(&aty);
        solution
            .iter()
            .all(|v| v.is_finite())
            .then(|| solution.iter().copied().collect())
    }
}

/// Points of a law file's law have no grid of their own: its reference values (where the file
/// gives them all) and a Halton design of [`DESIGN_POINTS`] points, each parameter log-uniform
/// over [10^−1.5, 10^1.5] of its natural size in the record's scales, negative as often as
/// positive where the parameter has no lower bound (scaled parameters).
fn design_starts(law: Law, bounds: &[Bound], scales: &RecordScales) -> Vec<Vec<f64>> {
    const BASES: [u32; 12] = [2, 3, 5, 7, 11, 13, 17, 19, 23, 29, 31, 37];
    let radical_inverse = |mut i: u32, base: u32| {
        let (mut f, mut x) = (1.0, 0.0);
        while i > 0 {
            f /= f64::from(base);
            x += f * f64::from(i % base);
            i /= base;
        }
        x
    };
    let n = law.n_params();
    let mut out: Vec<Vec<f64>> = law
        .paper_estimate()
        .map(|p| {
            let si = law.scale_torque(p, 1000.0);
            (0..n).map(|j| si[j] * scales.factor(law, j)).collect()
        })
        .into_iter()
        .collect();
    for i in 1..=DESIGN_POINTS {
        out.push(
            (0..n)
                .map(|j| {
                    let magnitude = 10f64.powf(3.0 * radical_inverse(i, BASES[2 * j]) - 1.5);
                    let negative = bounds[j].lower == f64::NEG_INFINITY && radical_inverse(i, BASES[2 * j + 1]) < 0.5;
                    if negative { -magnitude } else { magnitude }
                })
                .collect(),
        );
    }
    out
}

/// How many design points a law without a grid is started from ([`design_starts`]).
const DESIGN_POINTS: u32 = 256;

/// Candidate starting points (scaled parameters) from a grid over the nonlinear parameters,
/// the linear ones solved exactly at each grid point: the paper's four laws have one, other
/// laws (`None`) start from their design ([`design_starts`]).
fn grid_starts(law: Law, w: &[f64], y: &[f64], r: &[f64]) -> Option<Vec<Vec<f64>>> {
    let col = |f: &dyn Fn(f64) -> f64| -> Vec<f64> { w.iter().zip(r).map(|(&w, &r)| r * f(w)).collect() };
    let mut grid = GridColumns::new(y);
    let mut out = Vec::new();
    match law {
        Law::M1 => {
            let b1s = geomspace(0.3, 100.0, 8);
            let b3s = geomspace(0.3, 3e4, 10);
            let tanh_ids: Vec<usize> = b1s.iter().map(|&b1| grid.add(col(&|w| (b1 * w).tanh()))).collect();
            let rational_ids: Vec<usize> = b3s
                .iter()
                .map(|&b3| grid.add(col(&|w| w / (1.0 + b3 * w * w))))
                .collect();
            for (&b1, &tanh_id) in b1s.iter().zip(&tanh_ids) {
                for (&b3, &rational_id) in b3s.iter().zip(&rational_ids) {
                    if let Some(c) = grid.coefficients(&[tanh_id, rational_id])
                        && c[0].abs() > 1e-12
                    {
                        out.push(vec![c[0], b1, c[1] / c[0], b3]);
                    }
                }
            }
        }
        Law::M2 => {
            for &g in &geomspace(0.05, 100.0, 24) {
                let ids = [
                    grid.add(col(&|w| (-g * w).exp())),
                    grid.add(col(&|w| 1.0 - (-g * w).exp())),
                ];
                if let Some(c) = grid.coefficients(&ids) {
                    out.push(vec![c[0], c[1], g]);
                }
            }
        }
        Law::M3 => {
            let a2s = [-0.05, 0.0, 0.02, 0.08, 0.2, 0.5];
            let a5s = geomspace(0.1, 30.0, 7);
            let constant_id = grid.add(col(&|_| 1.0));
            let tanh_ids: Vec<usize> = a5s.iter().map(|&a5| grid.add(col(&|w| -(a5 * w).tanh()))).collect();
            for &a1 in &geomspace(0.3, 3e4, 9) {
                for &a2 in &a2s {
                    let gauss_id = grid.add(col(&|w| (-a1 * (w - a2) * (w - a2)).exp()));
                    for (&a5, &tanh_id) in a5s.iter().zip(&tanh_ids) {
                        if let Some(c) = grid.coefficients(&[gauss_id, constant_id, tanh_id]) {
                            out.push(vec![c[0], a1, a2, c[1], c[2], a5]);
                        }
                    }
                }
            }
        }
        Law::M4 => {
            let ids = [
                grid.add(col(&|_| 1.0)),
                grid.add(col(&|w| w)),
                grid.add(col(&|w| w * w)),
                grid.add(col(&|w| w * w * w)),
            ];
            if let Some(c) = grid.coefficients(&ids) {
                out.push(c);
            }
        }
        _ => return None,
    }
    Some(out)
}

/// Bit speeds among `speeds` that differ by more than [`SAME_SPEED_TOLERANCE`] of the largest:
/// the points a law, a curve torque(speed), is fitted through.
fn distinct_speeds(speeds: &[f64]) -> usize {
    let mut sorted = speeds.to_vec();
    sorted.sort_by(f64::total_cmp);
    let largest = sorted.iter().fold(0.0f64, |m, w| m.max(w.abs()));
    1 + sorted
        .windows(2)
        .filter(|p| p[1] - p[0] > SAME_SPEED_TOLERANCE * largest)
        .count()
}

/// Sum of squared residuals of scaled parameters on scaled data.
fn ssr(law: Law, p: &[f64], w: &[f64], y: &[f64], r: &[f64]) -> f64 {
    compensated_sum(w.iter().zip(y).zip(r).map(|((&w, &y), &r)| {
        let e = y - law.torque(p, w, r);
        e * e
    }))
}

/// One polished start.
struct Polished {
    params: Vec<f64>,
    ssr: f64,
    termination: TerminationReason,
    /// Stopped early: it could not beat a finished run's misfit ([`Race`]).
    abandoned: bool,
}

impl Polished {
    /// Whether the run ran out of patience (not one the race ended on purpose).
    fn lost_patience(&self) -> bool {
        matches!(self.termination, TerminationReason::LostPatience) && !self.abandoned
    }
}

/// Fits one law. See the module documentation for the method: samples that cannot determine
/// the law are refused first; the grid's best distinct starts are polished, and the best
/// polished start is the estimate, with its standard errors and what the user must know
/// before trusting it.
pub fn fit_law(law: Law, calibration: &Samples, validation: &Samples, opts: &FitOptions) -> Result<LawFit> {
    fit_law_from(law, calibration, validation, opts, &[])
}

/// [`fit_law`] with starting points where the answer is believed to be, SI (a run's own
/// estimates when its data are re-simulated, say), polished together with the grid's starts
/// that [`fit_law`] polishes: every run that is not stopped takes exactly the
/// steps it takes in [`fit_law`], and a run is stopped only once, extrapolating its progress,
/// it could not end below the best misfit already reached by more than an equal fit (10⁻⁶
/// of it). So the estimate is that of [`fit_law`] or a better one (up to that equal
/// fit), and the runs that crawl along a ridge of the law behind another (m3's Gaussian
/// sliding to infinite amplitude, its tanh flattening to a line) end early. Known starts of
/// the wrong length are ignored.
pub fn fit_law_from(
    law: Law,
    calibration: &Samples,
    validation: &Samples,
    opts: &FitOptions,
    known_si: &[Vec<f64>],
) -> Result<LawFit> {
    fit_law_to(law, calibration, validation, opts, known_si, 0.0)
}

/// [`fit_law_from`] for a fit whose sum of squared residuals matters only to within
/// `resolution_nm2` (N·m², > 0): every run also stops once, extrapolating its progress, the
/// rest of it would lower its sum of squares by less than that, and the runs that outlast
/// their first window go on from where it ended, side by side. Ridges the law can follow toward a limit at
/// infinity (m3 fitted to m2's or m4's curve) cost a few windows instead of a whole patience.
/// Validation samples are not used.
pub fn fit_law_within(
    law: Law,
    calibration: &Samples,
    opts: &FitOptions,
    known_si: &[Vec<f64>],
    resolution_nm2: f64,
) -> Result<LawFit> {
    fit_law_to(
        law,
        calibration,
        &Samples::default(),
        opts,
        known_si,
        resolution_nm2.max(0.0),
    )
}

/// [`fit_law_from`], each run stopped once its gain falls below `resolution_nm2` where > 0.
fn fit_law_to(
    law: Law,
    calibration: &Samples,
    validation: &Samples,
    opts: &FitOptions,
    known_si: &[Vec<f64>],
    resolution_nm2: f64,
) -> Result<LawFit> {
    check_determinable(law, calibration)?;
    let n = law.n_params();
    let sum_y2 = calibration.sum_sq_torque();
    let scales = RecordScales::of(calibration);
    let w: Vec<f64> = calibration.speed_rad_s.iter().map(|w| w / scales.speed).collect();
    let y: Vec<f64> = calibration.torque_nm.iter().map(|y| y / scales.torque).collect();
    let r = calibration.wob_ratio(opts.w_ref_n);
    let scaled = ScaledData { w: &w, y: &y, r: &r };

    let bounds = bounds(law, &scales, opts.bounded);
    let starts = select_starts(law, scaled, &bounds, &scales, opts.starts);
    let known = known_starts(law, scaled, &bounds, &scales, known_si);
    // The grid decides whether the law can describe these samples at all: a known start (an
    // earlier record's estimate) only speeds the fit, and is not let find a boundary optimum
    // where no starting point of the law's own would.
    if starts.is_empty() {
        return Err(refusal(
            law,
            "no starting point of the grid gives a finite misfit on the calibration samples (their torques against speed leave every start's linear parameters undetermined or overflowing)"
                .into(),
        ));
    }
    let resolution = resolution_nm2 / (scales.torque * scales.torque);
    let polished = if known.is_empty() {
        polish_starts(law, scaled, &bounds, &starts, resolution)
    } else {
        race_starts(law, scaled, &bounds, &[known.as_slice(), &starts].concat(), resolution)
    };
    if polished.is_empty() {
        return Err(refusal(
            law,
            format!(
                "Levenberg-Marquardt diverges to non-finite torques from every one of its {} starting points on the calibration samples",
                starts.len() + known.len()
            ),
        ));
    }
    let best = &polished[0];
    let p = &best.params;

    let on_bound: Vec<bool> = (0..n).map(|j| bounds[j].holds(p[j])).collect();
    let covariance = Covariance::at(law, best, scaled, &on_bound, &scales);
    let params_si: Vec<f64> = (0..n).map(|j| p[j] / scales.factor(law, j)).collect();
    let warnings = fit_warnings(law, &polished, &on_bound, &covariance, &params_si);
    let rho = best.ssr * scales.torque * scales.torque / sum_y2;
    let validation_rho = (!validation.is_empty()).then(|| {
        misfit(
            law,
            &params_si,
            &validation.speed_rad_s,
            &validation.torque_nm,
            &validation.wob_ratio(opts.w_ref_n),
            validation.sum_sq_torque(),
        )
    });
    Ok(LawFit {
        law,
        params_si,
        std_errors_si: covariance.std_errors_si,
        rho,
        validation_rho,
        condition_number: covariance.condition_number,
        correlations: covariance.correlations,
        warnings,
        starts: starts.len() + known.len(),
        endings: Endings {
            out_of_patience: polished.iter().filter(|p| p.lost_patience()).count(),
            abandoned: polished.iter().filter(|p| p.abandoned).count(),
            estimate_out_of_patience: best.lost_patience(),
        },
        scales,
    })
}

/// A fit of `law` refused for what the calibration samples are ([`Error::Fit`]; the record is
/// named by [`fit_record`]).
fn refusal(law: Law, message: String) -> Error {
    Error::Fit {
        record: None,
        law: law.to_string(),
        message,
    }
}

/// Refuses calibration samples that cannot determine `law`'s parameters before any fitting:
/// no more samples than parameters, or fewer distinct bit speeds than parameters (a law is a
/// curve torque(speed), fitted through the speeds).
fn check_determinable(law: Law, calibration: &Samples) -> Result<()> {
    let m = calibration.len();
    let n = law.n_params();
    if m <= n {
        return Err(refusal(
            law,
            format!("{m} calibration samples cannot determine its {n} parameters"),
        ));
    }
    let speeds = distinct_speeds(&calibration.speed_rad_s);
    if speeds < n {
        return Err(refusal(
            law,
            format!(
                "the {m} calibration samples have {speeds} distinct bit speeds, and a law of {n} parameters, a curve torque(speed), needs at least {n}; leave {law} out (`laws`) or record more speeds"
            ),
        ));
    }
    Ok(())
}

/// The calibration samples on the optimiser's scale: speed w / speed scale, torque
/// y / torque scale, and the weight-on-bit ratio r per sample.
#[derive(Clone, Copy)]
struct ScaledData<'a> {
    w: &'a [f64],
    y: &'a [f64],
    r: &'a [f64],
}

impl ScaledData<'_> {
    /// Sum of squared residuals of scaled parameters `p` ([`ssr`]).
    fn ssr(&self, law: Law, p: &[f64]) -> f64 {
        ssr(law, p, self.w, self.y, self.r)
    }
}

/// A parameter's physical bounds on the scaled problem (±∞ where it has none).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Bound {
    lower: f64,
    upper: f64,
}

impl Bound {
    /// True when scaled value `p` sits on one of the bounds (within 1e-6), where the data push
    /// it further.
    fn holds(self, p: f64) -> bool {
        (self.lower.is_finite() && p - self.lower < 1e-6) || (self.upper.is_finite() && self.upper - p < 1e-6)
    }

    /// MINUIT's transform that keeps a parameter within these bounds.
    fn transform(self) -> Transform {
        match (self.lower.is_finite(), self.upper.is_finite()) {
            (false, false) => Transform::Free,
            (true, false) => Transform::Lower(self.lower),
            (false, true) => Transform::Upper(self.upper),
            (true, true) => Transform::Both(self.lower, self.upper),
        }
    }
}

/// Each parameter's bounds on the scaled problem: its physical bounds when `bounded`, else
/// none.
fn bounds(law: Law, scales: &RecordScales, bounded: bool) -> Vec<Bound> {
    (0..law.n_params())
        .map(|j| {
            let spec = law.params()[j];
            if bounded {
                let factor = scales.factor(law, j);
                Bound {
                    lower: spec.lower * factor,
                    upper: spec.upper * factor,
                }
            } else {
                Bound {
                    lower: f64::NEG_INFINITY,
                    upper: f64::INFINITY,
                }
            }
        })
        .collect()
}

/// The grid's starting points ([`grid_starts`]) to polish: each pulled just inside the
/// bounds, ranked by misfit, and the best `max_starts` (at least one) kept that are not
/// near-copies of a better one. Empty when no grid point gives a finite misfit.
fn select_starts(
    law: Law,
    data: ScaledData,
    bounds: &[Bound],
    scales: &RecordScales,
    max_starts: usize,
) -> Vec<Vec<f64>> {
    let grid = grid_starts(law, data.w, data.y, data.r).unwrap_or_else(|| design_starts(law, bounds, scales));
    let mut candidates: Vec<(f64, Vec<f64>)> = grid
        .into_iter()
        .map(|mut p| {
            pull_inside(&mut p, bounds);
            (data.ssr(law, &p), p)
        })
        .filter(|(s, _)| s.is_finite())
        .collect();
    candidates.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut starts: Vec<Vec<f64>> = Vec::new();
    for (_, p) in candidates {
        if starts.iter().all(|q| distinct(q, &p)) {
            starts.push(p);
        }
        if starts.len() >= max_starts.max(1) {
            break;
        }
    }
    starts
}

/// Relative difference of sums of squares within which two fits fit equally well.
const EQUAL_FIT: f64 = 1e-6;

/// Levenberg-Marquardt's patience: a run ends after patience × (parameters + 1) evaluations.
const PATIENCE: usize = 400;

/// Windows of a raced run's patience ([`Race`]): how often it is asked whether it can still win.
const RACE_WINDOWS: usize = 16;

/// How far inside its bounds a start is pulled (scaled units): a bound itself is where
/// MINUIT's transforms have no gradient.
const START_MARGIN: f64 = 1e-3;

/// Pulls a start (scaled) at or beyond a bound to [`START_MARGIN`] inside it (to the middle
/// of bounds closer than twice that).
fn pull_inside(p: &mut [f64], bounds: &[Bound]) {
    for (v, b) in p.iter_mut().zip(bounds) {
        if b.upper - b.lower < 2.0 * START_MARGIN {
            *v = 0.5 * (b.lower + b.upper);
        } else if *v < b.lower + START_MARGIN {
            *v = b.lower + START_MARGIN;
        } else if *v > b.upper - START_MARGIN {
            *v = b.upper - START_MARGIN;
        }
    }
}

/// Whether two starts (scaled) differ by more than 0.1 % in some parameter.
fn distinct(a: &[f64], b: &[f64]) -> bool {
    a.iter()
        .zip(b)
        .any(|(x, y)| (x - y).abs() > 1e-3 * (x.abs() + y.abs()).max(1e-6))
}

/// Polishes every start by Levenberg-Marquardt, bounds kept by MINUIT's transform, each
/// stopped once its gain falls below `resolution` where > 0; the runs that end on a finite
/// misfit, best first. Empty when every run diverges.
fn polish_starts(law: Law, data: ScaledData, bounds: &[Bound], starts: &[Vec<f64>], resolution: f64) -> Vec<Polished> {
    // The starts are polished in parallel (collected in order: the same result): a start that
    // loses patience costs seconds, and a lone slow fit would otherwise hold one thread while
    // others idle (the selection check fits many records side by side).
    let mut polished: Vec<Polished> = starts
        .par_iter()
        .filter_map(|p0| {
            polish(
                law,
                data,
                bounds,
                p0,
                PATIENCE,
                Stop {
                    target: None,
                    resolution,
                },
            )
        })
        .collect();
    polished.sort_by(|a, b| a.ssr.total_cmp(&b.ssr));
    polished
}

/// [`polish_starts`] for starts among which some are known to lie near the answer: every
/// start first gets one window of the patience ([`RACE_WINDOWS`]), in parallel. A run that
/// ends within it is final, and the same as with the whole patience (the patience only caps
/// the evaluations). The others are run again from their starts, best first, one after the
/// other, each racing the best misfit of the runs already final ([`Race`]): one run crawling
/// along a ridge goes the whole way, those behind it stop. A run that is not stopped takes
/// exactly the steps of [`polish_starts`].
///
/// With a `resolution` (> 0), the runs that outlast their first window go on from where it
/// ended, side by side, each stopped once its gain falls below the resolution or once it
/// cannot beat the best misfit of the first window's finished runs by more: no run waits for
/// another, and the result is the same on any number of threads.
fn race_starts(law: Law, data: ScaledData, bounds: &[Bound], starts: &[Vec<f64>], resolution: f64) -> Vec<Polished> {
    let first: Vec<(usize, Polished)> = starts
        .par_iter()
        .enumerate()
        .filter_map(|(i, p0)| polish(law, data, bounds, p0, PATIENCE / RACE_WINDOWS, Stop::default()).map(|p| (i, p)))
        .collect();
    let (mut unfinished, finished): (Vec<_>, Vec<_>) = first.into_iter().partition(|(_, p)| p.lost_patience());
    let mut polished: Vec<Polished> = finished.into_iter().map(|(_, p)| p).collect();
    unfinished.sort_by(|a, b| a.1.ssr.total_cmp(&b.1.ssr));
    let best = |polished: &[Polished]| polished.iter().map(|p| p.ssr).min_by(f64::total_cmp);
    if resolution > 0.0 {
        let stop = Stop {
            target: best(&polished),
            resolution,
        };
        if stop.beyond_reach() {
            // A finished run already fits within the resolution of zero: the others end here.
            polished.extend(unfinished.into_iter().map(|(_, first)| Polished {
                abandoned: true,
                ..first
            }));
            polished.sort_by(|a, b| a.ssr.total_cmp(&b.ssr));
            return polished;
        }
        let again: Vec<Polished> = unfinished
            .par_iter()
            .filter_map(|(_, first)| polish(law, data, bounds, &first.params, PATIENCE, stop))
            .collect();
        polished.extend(again);
    } else {
        for (i, _) in unfinished {
            let stop = Stop {
                target: best(&polished),
                resolution,
            };
            polished.extend(polish(law, data, bounds, &starts[i], PATIENCE, stop));
        }
    }
    polished.sort_by(|a, b| a.ssr.total_cmp(&b.ssr));
    polished
}

/// When a run may end before its patience ([`Race`]): once it cannot beat `target`, or once
/// the rest of it would gain less than `resolution` (scaled sum of squares; 0: never).
#[derive(Clone, Copy, Default)]
struct Stop {
    target: Option<f64>,
    resolution: f64,
}

impl Stop {
    /// Whether no run can beat the target by more than the resolution, however far it went:
    /// that would take a sum of squares below zero.
    fn beyond_reach(&self) -> bool {
        self.resolution > 0.0
            && self
                .target
                .is_some_and(|target| target * (1.0 - EQUAL_FIT) - self.resolution <= 0.0)
    }
}

/// One Levenberg-Marquardt run from `p0` (scaled) with `patience`, stopped early as `stop`
/// says; `None` when it ends on a non-finite misfit.
fn polish(law: Law, data: ScaledData, bounds: &[Bound], p0: &[f64], patience: usize, stop: Stop) -> Option<Polished> {
    let n = law.n_params();
    let transforms: Vec<Transform> = bounds.iter().map(|b| b.transform()).collect();
    let problem = Problem {
        law,
        w: data.w,
        y: data.y,
        r: data.r,
        u: DVector::from_iterator(n, transforms.iter().zip(p0).map(|(t, &p)| t.to_internal(p))),
        transforms,
        race: (stop.target.is_some() || stop.resolution > 0.0).then(|| Race::new(stop, patience, n)),
    };
    let (problem, report) = LevenbergMarquardt::new().with_patience(patience).minimize(problem);
    let params = problem.scaled_params();
    let ssr = data.ssr(law, &params);
    ssr.is_finite().then(|| Polished {
        ssr,
        params,
        termination: report.termination,
        abandoned: problem.race.is_some_and(|race| race.stopped.get()),
    })
}

/// Known starting points (SI) on the scaled problem: pulled just inside the bounds like the
/// grid's, those of the wrong length, of a non-finite misfit or near-copies of another left out.
fn known_starts(
    law: Law,
    data: ScaledData,
    bounds: &[Bound],
    scales: &RecordScales,
    known_si: &[Vec<f64>],
) -> Vec<Vec<f64>> {
    let n = law.n_params();
    let mut starts: Vec<Vec<f64>> = Vec::new();
    for p_si in known_si.iter().filter(|p| p.len() == n) {
        let mut p: Vec<f64> = (0..n).map(|j| p_si[j] * scales.factor(law, j)).collect();
        pull_inside(&mut p, bounds);
        if data.ssr(law, &p).is_finite() && starts.iter().all(|q| distinct(q, &p)) {
            starts.push(p);
        }
    }
    starts
}

/// The Jacobian of r·T(w) with respect to the parameters `columns` of `p`, at the speeds `w`
/// and weight-on-bit ratios `r` (in the units of `p` and `w`), each column scaled to unit norm
/// where it has one; and the columns' norms.
pub(crate) fn normalised_jacobian(
    law: Law,
    p: &[f64],
    w: &[f64],
    r: &[f64],
    columns: &[usize],
) -> (DMatrix<f64>, Vec<f64>) {
    let n = law.n_params();
    let mut jacobian = DMatrix::<f64>::zeros(w.len(), columns.len());
    let mut gradient = [0.0; crate::laws::MAX_PARAMS];
    for (i, (&w, &r)) in w.iter().zip(r).enumerate() {
        law.torque_and_gradient(p, w, &mut gradient[..n]);
        for (c, &j) in columns.iter().enumerate() {
            jacobian[(i, c)] = r * gradient[j];
        }
    }
    let norms: Vec<f64> = jacobian.column_iter().map(|column| column.norm()).collect();
    for (mut column, &norm) in jacobian.column_iter_mut().zip(&norms) {
        if norm > 0.0 {
            column.scale_mut(1.0 / norm);
        }
    }
    (jacobian, norms)
}

/// The uncertainty of an estimate, from the Jacobian at it.
struct Covariance {
    /// Standard errors, SI; `None` for a parameter on its bound or one the data cannot
    /// determine.
    std_errors_si: Vec<Option<f64>>,
    /// Pearson correlations (n × n); `None` where a standard error is undefined.
    correlations: Vec<Vec<Option<f64>>>,
    /// Condition number of the column-normalised Jacobian (∞ when a column vanishes).
    condition_number: f64,
}

impl Covariance {
    /// σ² (JᵀJ)⁻¹ over the parameters not on a bound, at the estimate `best` (scaled), with
    /// σ² its sum of squared residuals over the degrees of freedom. The Jacobian's columns are
    /// normalised first, and the inverse is taken only below condition number 10¹².
    fn at(law: Law, best: &Polished, data: ScaledData, on_bound: &[bool], scales: &RecordScales) -> Self {
        let (m, n) = (data.w.len(), law.n_params());
        let p = &best.params;
        let free: Vec<usize> = (0..n).filter(|&j| !on_bound[j]).collect();
        let (normalised, norms) = normalised_jacobian(law, p, data.w, data.r, &free);
        let mut std_errors_si = vec![None; n];
        let mut correlations = vec![vec![None; n]; n];
        let mut condition_number = f64::INFINITY;
        if norms.iter().all(|&v| v > 0.0) && !free.is_empty() {
            let sv = normalised.singular_values();
            let (smax, smin) = (sv.max(), sv.min());
            condition_number = if smin > 0.0 { smax / smin } else { f64::INFINITY };
            if condition_number < 1e12 {
                let sigma2 = best.ssr / (m - free.len()).max(1) as f64;
                let jtj = normalised.transpose() * &normalised;
                if let Some(inv) = jtj.try_inverse() {
                    for (a, &ja) in free.iter().enumerate() {
                        let var = sigma2 * inv[(a, a)] / (norms[a] * norms[a]);
                        std_errors_si[ja] = Some(var.sqrt() / scales.factor(law, ja));
                        for (b, &jb) in free.iter().enumerate() {
                            correlations[ja][jb] = Some(inv[(a, b)] / (inv[(a, a)] * inv[(b, b)]).sqrt());
                        }
                    }
                }
            }
        }
        Self {
            std_errors_si,
            correlations,
            condition_number,
        }
    }
}

/// Why Levenberg-Marquardt stopped short, in the user's words.
fn why_not_converged(reason: &TerminationReason) -> String {
    match reason {
        TerminationReason::LostPatience => {
            "it ran out of evaluations while still improving (a ridge, or a limit at infinity)".to_string()
        }
        TerminationReason::Numerical(what) => format!("the {what} became infinite or not a number"),
        TerminationReason::NoImprovementPossible(what) => {
            format!("no step improves the fit within the machine's precision ({what})")
        }
        TerminationReason::User(what) => format!("the law could not be evaluated ({what})"),
        TerminationReason::WrongDimensions(what) => format!("the problem's shape is wrong ({what})"),
        TerminationReason::NoParameters => "the law has no parameter".to_string(),
        TerminationReason::NoResiduals => "no sample to fit".to_string(),
        TerminationReason::ResidualsZero | TerminationReason::Orthogonal | TerminationReason::Converged { .. } => {
            "it converged".to_string()
        }
    }
}

/// What the user must know before trusting the estimate `polished[0]` (the polished starts,
/// best first): an optimiser that did not converge, other starts that fit as well elsewhere,
/// parameters on their bounds, an ill-conditioned Jacobian, standard errors above half the
/// value. In that order.
fn fit_warnings(
    law: Law,
    polished: &[Polished],
    on_bound: &[bool],
    covariance: &Covariance,
    params_si: &[f64],
) -> Vec<String> {
    let n = law.n_params();
    let best = &polished[0];
    let p = &best.params;
    let mut warnings = Vec::new();
    if !best.termination.was_successful() {
        warnings.push(format!(
            "the optimiser stopped without converging: {}",
            why_not_converged(&best.termination)
        ));
    }
    // Other starts that fit as well but land elsewhere mean the data do not pin the law down.
    for other in &polished[1..] {
        if other.ssr <= best.ssr * (1.0 + EQUAL_FIT) + 1e-300 {
            let differing: Vec<&str> = (0..n)
                .filter(|&j| (other.params[j] - p[j]).abs() > 1e-2 * p[j].abs().max(1e-3))
                .map(|j| law.params()[j].name)
                .collect();
            if !differing.is_empty() {
                warnings.push(format!(
                    "several parameter sets fit equally well; the data do not identify {}",
                    differing.join(", ")
                ));
                break;
            }
        }
    }
    for j in (0..n).filter(|&j| on_bound[j]) {
        let spec = law.params()[j];
        let (relation, bound) = if (params_si[j] - spec.lower).abs() <= (params_si[j] - spec.upper).abs() {
            ("≥", spec.lower)
        } else {
            ("≤", spec.upper)
        };
        warnings.push(format!(
            "{} sits on its physical bound ({} {relation} {bound}): the data push it further; try `no_bounds` to see where",
            spec.name, spec.name
        ));
    }
    warnings.extend(conditioning_warning(law, covariance));
    for (spec, (&se, value)) in law.params().iter().zip(covariance.std_errors_si.iter().zip(params_si)) {
        if let Some(se) = se
            && se > 0.5 * value.abs()
        {
            warnings.push(format!(
                "{} is not identified by the data: its standard error exceeds half its value",
                spec.name
            ));
        }
    }
    warnings
}

/// The warning for a condition number of 10⁶ or more, naming the most strongly correlated
/// pair of parameters where correlations are known; `None` below it.
fn conditioning_warning(law: Law, covariance: &Covariance) -> Option<String> {
    let condition_number = covariance.condition_number;
    if condition_number >= 1e6 {
        Some(ill_conditioned(law, condition_number, &covariance.correlations))
    } else {
        None
    }
}

/// The ill-conditioning warning: the condition number, and the parameter pair of largest
/// |correlation| where one is known.
fn ill_conditioned(law: Law, condition_number: f64, correlations: &[Vec<Option<f64>>]) -> String {
    let mut worst = (0.0, "", "");
    for (a, row) in correlations.iter().enumerate() {
        for (b, &c) in row.iter().enumerate().skip(a + 1) {
            if let Some(c) = c
                && c.abs() > worst.0
            {
                worst = (c.abs(), law.params()[a].name, law.params()[b].name);
            }
        }
    }
    let pair = if worst.0 > 0.0 {
        format!(
            "; {} and {} trade off (|correlation| = {:.6})",
            worst.1, worst.2, worst.0
        )
    } else {
        String::new()
    };
    format!("ill-conditioned (condition number {condition_number:.2e}){pair}")
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Runs the stopping rule on a made-up run of one parameter (patience 160: windows of 20
    /// evaluations, 320 in all), every evaluation an accepted point: the evaluation it stops
    /// at, if any.
    fn stops_at(stop: Stop, ssr_at: impl Fn(usize) -> f64) -> Option<usize> {
        let race = Race::new(stop, 160, 1);
        (0..320).find(|&e| {
            race.evaluated(&DVector::from_element(1, ssr_at(e).sqrt()));
            !race.goes_on()
        })
    }

    #[test]
    fn an_optimiser_that_stops_short_is_said_in_words_not_in_rust_names() {
        for reason in [
            TerminationReason::LostPatience,
            TerminationReason::Numerical("jacobian"),
            TerminationReason::NoImprovementPossible("gtol"),
            TerminationReason::NoResiduals,
        ] {
            let words = why_not_converged(&reason);
            let debug = format!("{reason:?}");
            let name = debug.split(['(', ' ']).next().unwrap();
            assert!(!words.contains(name), "{words}");
        }
        assert!(why_not_converged(&TerminationReason::LostPatience).contains("ran out of evaluations"));
    }

    /// A run that gains more than the resolution per window goes on; a crawl whose gains
    /// shrink (geometrically, faster than the 1/k the rule extrapolates) stops, with less than
    /// the resolution left to gain; without a resolution or a target nothing stops; against a
    /// target, a run stops once it cannot beat it by more than the resolution, no sum of
    /// squares falling below zero.
    #[test]
    fn a_run_stops_once_what_is_left_of_it_does_not_matter() {
        let resolution = 0.01;
        let only = Stop {
            target: None,
            resolution,
        };
        let descent = |e: usize| 10.0 - 0.001 * e as f64; // 0.02 per window
        assert_eq!(stops_at(only, descent), None);
        let crawl = |e: usize| 1.0 + 0.5 * 0.97f64.powi(e as i32);
        let at = stops_at(only, crawl).expect("a crawl stops");
        let left = crawl(at) - 1.0;
        assert!(left < resolution, "stopped at {at} with {left} left");
        assert!(at < 319, "{at}");
        assert_eq!(stops_at(Stop::default(), crawl), None);
        // The descent cannot reach a target of 5 within its patience and stops at its first
        // window; it can beat 9.95 by more than the resolution, and goes on.
        let raced = |target: f64| Stop {
            target: Some(target),
            resolution,
        };
        assert_eq!(stops_at(raced(5.0), descent), Some(20));
        assert_eq!(stops_at(raced(9.95), descent), None);
        // Extrapolated from its first window (9.98 − 0.02·ln 16 ≈ 9.925), it beats 9.93 but not
        // by the resolution: stopped there.
        assert_eq!(stops_at(raced(9.93), descent), Some(20));
        assert_eq!(
            stops_at(
                Stop {
                    target: Some(9.93),
                    resolution: 0.0
                },
                descent
            ),
            None
        );
        // A run on its way to zero cannot gain more than its sum of squares: against a
        // finished run within the resolution of zero it stops at its first window, however
        // fast it descends; against one further from zero it goes on.
        let to_zero = |e: usize| 0.3 * 0.9f64.powi(e as i32);
        assert!(raced(0.005).beyond_reach() && !raced(0.05).beyond_reach());
        assert_eq!(stops_at(raced(0.005), to_zero), Some(20));
        assert_eq!(stops_at(raced(0.05), to_zero), Some(40));
    }
}
