//! Stability maps over operating points (top-drive speed Ω, weight on bit W).
//!
//! Linearised about steady rotation at Ω, the law enters only through the bit damping
//! c_b = r·dT/dw(Ω), r = W / W_ref, and steady rotation is unstable when c_b ≤ c_b*, the
//! structure's critical bit damping (−c_eq for the 1-DOF model, found once by bisection for the
//! finite-element string). So every map reduces to a critical weight on bit per sample and speed,
//! W*(Ω) = W_ref · c_b* / dT/dw(Ω) where dT/dw(Ω) < 0 (never unstable otherwise): unstable for
//! W ≥ W*. The stochastic boundary at percentile p is the p-quantile of W* over posterior
//! samples (P(unstable | Ω, W) = share of samples with W* ≤ W); a mixture of laws weights each
//! law's samples by its posterior probability. The grids computed cell by cell (CPU here, GPU in
//! `shaders/stability.wgsl`) check the reduction.

use crate::error::{Error, Result};
use crate::laws::Law;
use crate::stability::lumped::Lumped;
use crate::units::RAD_S_PER_RPM;

/// An evenly spaced axis "MIN:MAX:COUNT" (both ends included).
pub fn parse_axis(text: &str, field: &str) -> Result<Vec<f64>> {
    let parts: Vec<&str> = text.split(':').collect();
    let bad = |why: &str| {
        Error::setting(
            field,
            format!("'{text}': {why} (expected MIN:MAX:COUNT, e.g. 20:200:91)"),
        )
    };
    if parts.len() != 3 {
        return Err(bad("three fields needed"));
    }
    let lo: f64 = parts[0].trim().parse().map_err(|_| bad("MIN is not a number"))?;
    let hi: f64 = parts[1].trim().parse().map_err(|_| bad("MAX is not a number"))?;
    let n: usize = parts[2]
        .trim()
        .parse()
        .map_err(|_| bad("COUNT is not a whole number"))?;
    if !(lo.is_finite() && hi.is_finite() && lo > 0.0 && hi > lo) {
        return Err(bad("need 0 < MIN < MAX"));
    }
    if !(2..=100_000).contains(&n) {
        return Err(bad("COUNT must lie in 2..=100000"));
    }
    Ok((0..n).map(|i| lo + (hi - lo) * i as f64 / (n - 1) as f64).collect())
}

/// The critical weight on bit W* (N) of one parameter set at top-drive speed `omega_rad_s`:
/// `None` when dT/dw(Ω) ≥ 0 (no weight on bit destabilises), `Some(NaN)` when the law's
/// torque has no slope there (a law file's torque without a value: stability is unknown,
/// never assumed). `params_si` in N·m, `critical_nms` = c_b* (< 0, N·m·s/rad).
pub fn critical_wob_n(law: Law, params_si: &[f64], omega_rad_s: f64, critical_nms: f64, w_ref_n: f64) -> Option<f64> {
    let slope = law.dtorque_dw(params_si, omega_rad_s, 1.0);
    if !(slope.is_finite() && law.torque(params_si, omega_rad_s, 1.0).is_finite()) {
        return Some(f64::NAN);
    }
    (slope < 0.0).then(|| w_ref_n * critical_nms / slope)
}

/// Whether the law's torque and its slope both have a value at `omega_rad_s` (a law file's
/// torque may have none: a logarithm of a negative number).
fn has_value(law: Law, params_si: &[f64], omega_rad_s: f64) -> bool {
    law.torque(params_si, omega_rad_s, 1.0).is_finite() && law.dtorque_dw(params_si, omega_rad_s, 1.0).is_finite()
}

/// Per speed of `omega_rpm`: whether some sample's torque (or its slope) has no value there,
/// which makes that speed's boundaries and every cell of its row unknown.
pub fn unknown_speeds(law: Law, samples: &[Vec<f64>], omega_rpm: &[f64]) -> Vec<bool> {
    omega_rpm
        .iter()
        .map(|&rpm| samples.iter().any(|s| !has_value(law, s, rpm * RAD_S_PER_RPM)))
        .collect()
}

/// The q-quantile (type 7) of critical weights where `None` (never unstable) counts as +∞;
/// `None` when the quantile is infinite.
fn quantile_with_infinity(mut values: Vec<f64>, q: f64) -> Option<f64> {
    values.sort_by(f64::total_cmp);
    let h = q * (values.len() - 1) as f64;
    let (lo, hi) = (h.floor() as usize, h.ceil() as usize);
    let (a, b) = (values[lo], values[hi]);
    if !a.is_finite() || !b.is_finite() {
        return None;
    }
    Some(a + (h - lo as f64) * (b - a))
}

/// Boundary W (kN) per speed of the `p` percentile over `samples` (each a parameter set, SI):
/// the weight on bit above which at least a share p of the samples are unstable.
pub fn percentile_boundary_kn(
    law: Law,
    samples: &[Vec<f64>],
    omega_rpm: &[f64],
    critical_nms: f64,
    w_ref_n: f64,
    p: f64,
) -> Vec<Option<f64>> {
    omega_rpm
        .iter()
        .map(|&rpm| {
            let w: Vec<f64> = samples
                .iter()
                .map(|s| critical_wob_n(law, s, rpm * RAD_S_PER_RPM, critical_nms, w_ref_n).unwrap_or(f64::INFINITY))
                .collect();
            if w.iter().any(|v| v.is_nan()) {
                return Some(f64::NAN);
            }
            quantile_with_infinity(w, p).map(|v| v / 1000.0)
        })
        .collect()
}

/// The deterministic boundary (kN) of one parameter set (e.g. the MAP) per speed.
pub fn deterministic_boundary_kn(
    law: Law,
    params_si: &[f64],
    omega_rpm: &[f64],
    critical_nms: f64,
    w_ref_n: f64,
) -> Vec<Option<f64>> {
    omega_rpm
        .iter()
        .map(|&rpm| critical_wob_n(law, params_si, rpm * RAD_S_PER_RPM, critical_nms, w_ref_n).map(|w| w / 1000.0))
        .collect()
}

/// The mixture's boundary (kN) at percentile `p`: the weight on bit W where
/// Σ_k π_k · P_k(W* ≤ W) = p, with each law's samples weighted by its probability π_k.
pub fn mixture_boundary_kn(
    components: &[(f64, Law, &[Vec<f64>])],
    omega_rpm: &[f64],
    critical_nms: f64,
    w_ref_n: f64,
    p: f64,
) -> Vec<Option<f64>> {
    let total: f64 = components.iter().map(|c| c.0).sum();
    omega_rpm
        .iter()
        .map(|&rpm| {
            let mut weighted: Vec<(f64, f64)> = Vec::new();
            for &(weight, law, samples) in components {
                let each = weight / total / samples.len() as f64;
                for s in samples {
                    let w = critical_wob_n(law, s, rpm * RAD_S_PER_RPM, critical_nms, w_ref_n).unwrap_or(f64::INFINITY);
                    if w.is_nan() {
                        return Some(f64::NAN);
                    }
                    weighted.push((w, each));
                }
            }
            weighted.sort_by(|a, b| a.0.total_cmp(&b.0));
            let mut cumulative = 0.0;
            for (w, share) in weighted {
                cumulative += share;
                if cumulative >= p - 1e-12 {
                    return w.is_finite().then_some(w / 1000.0);
                }
            }
            None
        })
        .collect()
}

/// One law's inputs to the maps: its posterior probability, its MAP (or the given parameters)
/// and posterior samples, SI. Shared by `bitrock stability` and the report
/// ([`crate::abc::posterior::map_inputs`] of a population).
#[derive(Clone, Debug)]
pub struct LawSamples {
    pub law: Law,
    pub probability: f64,
    pub map_si: Vec<f64>,
    pub samples_si: Vec<Vec<f64>>,
    /// Each sample's string [ω_n rad/s, ξ], where the posterior inferred it with the law (a
    /// surface run's); empty otherwise. The simulated strings take it
    /// ([`crate::run::strings::SimulatedSettings::string`]); the linear maps do not.
    /// [`crate::abc::posterior::law_samples_of`] makes them of particles.
    pub strings: Vec<[f64; 2]>,
}

/// One law's boundaries (kN per speed, `None` where no weight on bit destabilises).
#[derive(Clone, Debug)]
pub struct LawBoundaries {
    pub law: Law,
    pub probability: f64,
    pub samples: usize,
    /// Deterministic boundary of the MAP.
    pub map_wob_kn: Vec<Option<f64>>,
    /// Percentile boundary over the samples.
    pub p_wob_kn: Vec<Option<f64>>,
}

/// The boundaries of a set of laws: each law's, and their mixture's when there is more than one.
#[derive(Clone, Debug)]
pub struct Boundaries {
    pub laws: Vec<LawBoundaries>,
    /// [`mixture_boundary_kn`] of all the laws weighted by their probability.
    pub mixture_wob_kn: Option<Vec<Option<f64>>>,
}

impl Boundaries {
    /// What a map of these boundaries (at the speeds `omega_rpm`, percentile `p`) over the
    /// weights `wob_kn` on `criterion` draws nothing of: each law whose MAP or percentile
    /// boundary lies wholly off the map ([`OffTheMap`]), said once per law, and the mixture's
    /// where some law's boundary is on it.
    pub fn off_the_map(&self, omega_rpm: &[f64], wob_kn: &[f64], criterion: &Criterion, p: f64) -> Vec<String> {
        let mut out = Vec::new();
        let percent = p * 100.0;
        for l in &self.laws {
            let map = OffTheMap::of(&l.map_wob_kn, omega_rpm, wob_kn);
            let pct = OffTheMap::of(&l.p_wob_kn, omega_rpm, wob_kn);
            match (map, pct) {
                (Some(off), _) => out.push(off.describe(&format!("law {}'s MAP boundary", l.law), wob_kn, criterion)),
                (None, Some(off)) => out.push(off.describe(
                    &format!("law {}'s {percent} % percentile boundary", l.law),
                    wob_kn,
                    criterion,
                )),
                (None, None) => {}
            }
        }
        if out.len() < self.laws.len()
            && let Some(off) = self
                .mixture_wob_kn
                .as_ref()
                .and_then(|m| OffTheMap::of(m, omega_rpm, wob_kn))
        {
            out.push(off.describe(&format!("the mixture's {percent} % boundary"), wob_kn, criterion));
        }
        out
    }
}

/// Deterministic, percentile (`p`) and mixture boundaries of `inputs` at `omega_rpm`.
pub fn boundaries(inputs: &[LawSamples], omega_rpm: &[f64], critical_nms: f64, w_ref_n: f64, p: f64) -> Boundaries {
    let laws = inputs
        .iter()
        .map(|input| LawBoundaries {
            law: input.law,
            probability: input.probability,
            samples: input.samples_si.len(),
            map_wob_kn: deterministic_boundary_kn(input.law, &input.map_si, omega_rpm, critical_nms, w_ref_n),
            p_wob_kn: percentile_boundary_kn(input.law, &input.samples_si, omega_rpm, critical_nms, w_ref_n, p),
        })
        .collect();
    let mixture_wob_kn = (inputs.len() > 1).then(|| {
        let components: Vec<(f64, Law, &[Vec<f64>])> = inputs
            .iter()
            .map(|i| (i.probability, i.law, i.samples_si.as_slice()))
            .collect();
        mixture_boundary_kn(&components, omega_rpm, critical_nms, w_ref_n, p)
    });
    Boundaries { laws, mixture_wob_kn }
}

/// Where a boundary lies when no part of it crosses a map's weights on bit: the map is then
/// one colour, and its figure draws no curve.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum OffTheMap {
    /// Above the map's highest weight at every speed, or nowhere: stable throughout. The
    /// lowest boundary weight (kN) and its speed (rpm), where there is one.
    Above { lowest: Option<(f64, f64)> },
    /// Below the map's lowest weight at every speed: unstable throughout. The highest
    /// boundary weight (kN) and its speed (rpm).
    Below { highest: (f64, f64) },
}

impl OffTheMap {
    /// Where `boundary` (kN per speed of `omega_rpm`; `None`: never unstable) lies against the
    /// weights on bit `wob_kn` (ascending), when it lies wholly to one side of them; `None`
    /// where it crosses them, lies on both sides, or is unknown somewhere.
    pub fn of(boundary: &[Option<f64>], omega_rpm: &[f64], wob_kn: &[f64]) -> Option<Self> {
        let (&lo, &hi) = (wob_kn.first()?, wob_kn.last()?);
        if boundary.iter().flatten().any(|w| w.is_nan()) {
            return None;
        }
        let finite = || {
            boundary
                .iter()
                .zip(omega_rpm)
                .filter_map(|(w, &rpm)| w.map(|w| (w, rpm)))
        };
        if finite().all(|(w, _)| w > hi) {
            let lowest = finite().min_by(|a, b| a.0.total_cmp(&b.0));
            return Some(Self::Above { lowest });
        }
        if boundary.iter().all(|w| w.is_some_and(|w| w < lo)) {
            let highest = finite().max_by(|a, b| a.0.total_cmp(&b.0))?;
            return Some(Self::Below { highest });
        }
        None
    }

    /// What a reader of a map drawn on `criterion` over the weights `wob_kn` must be told
    /// about the boundary `what` ("m2's MAP boundary").
    pub fn describe(&self, what: &str, wob_kn: &[f64], criterion: &Criterion) -> String {
        let (lo, hi) = (wob_kn[0], wob_kn[wob_kn.len() - 1]);
        let string = match criterion {
            Criterion::Lumped(l) if *l == Lumped::default() => {
                "; it is drawn for the paper's 5 km field string: a laboratory rig or another well needs its own string (the 1-DOF string's inertia, natural frequency and damping ratio, or a finite-element string file), and a record's torque unit read wrongly moves it a thousandfold"
            }
            _ => "; the string and the record's torque unit set where it lies",
        };
        match self {
            Self::Above { lowest: Some((w, rpm)) } => format!(
                "{what} lies above the map's highest weight on bit ({hi} kN) at every speed (lowest {w:.4e} kN, at {rpm} rpm): the whole map is stable and draws no boundary{string}"
            ),
            Self::Above { lowest: None } => format!(
                "{what} does not exist at any speed of the map (the bit damping is positive there): the whole map is stable and draws no boundary"
            ),
            Self::Below { highest: (w, rpm) } => format!(
                "{what} lies below the map's lowest weight on bit ({lo} kN) at every speed (highest {w:.4e} kN, at {rpm} rpm): the whole map is unstable and draws no boundary{string}"
            ),
        }
    }
}

/// What decides stability at a cell: the 1-DOF closed form or a critical bit damping.
#[derive(Clone, Copy, Debug)]
pub enum Criterion {
    /// The 2×2 Jacobian of the 1-DOF model: unstable when its largest eigenvalue real part ≥ 0.
    Lumped(Lumped),
    /// Unstable when c_b ≤ c_b* (the finite-element string's critical bit damping, N·m·s/rad).
    Critical(f64),
}

impl Criterion {
    /// c_b*, N·m·s/rad.
    pub fn critical_nms(&self) -> f64 {
        match self {
            Criterion::Lumped(l) => l.critical_bit_damping_nms(),
            Criterion::Critical(c) => *c,
        }
    }

    fn unstable(&self, bit_damping_nms: f64) -> bool {
        match self {
            Criterion::Lumped(l) => l.is_unstable(bit_damping_nms),
            Criterion::Critical(c) => bit_damping_nms <= *c,
        }
    }
}

/// One law's stability grid as asked of either backend: its `samples` (SI parameter vectors)
/// judged by `criterion` at every top-drive speed (rpm) × weight on bit (kN), the law's torque
/// scaled by W / `w_ref_n` (N).
#[derive(Clone, Copy, Debug)]
pub struct Grid<'a> {
    pub law: Law,
    pub samples: &'a [Vec<f64>],
    pub omega_rpm: &'a [f64],
    pub wob_kn: &'a [f64],
    pub criterion: Criterion,
    pub w_ref_n: f64,
}

/// Share of `samples` unstable at every cell (NaN, unknown, in a speed's row where a sample's
/// torque has no slope), row-major over (Ω, W): the CPU twin of
/// `shaders/stability.wgsl`. Speeds in rpm, weights in kN.
pub fn probability_grid(grid: &Grid) -> Vec<f64> {
    let mut pace = crate::limits::Pace::unchecked();
    probability_grid_with(grid, &mut pace).expect("an unchecked pace never refuses")
}

/// [`probability_grid`], counting each speed's cell-samples on `pace` (which may refuse the
/// rest of the work once it has measured this machine's speed).
pub fn probability_grid_with(grid: &Grid, pace: &mut crate::limits::Pace) -> Result<Vec<f64>> {
    let (law, samples) = (grid.law, grid.samples);
    let mut out = Vec::with_capacity(grid.omega_rpm.len() * grid.wob_kn.len());
    for &rpm in grid.omega_rpm {
        pace.advance((grid.wob_kn.len() * samples.len()) as u64)?;
        let slopes: Vec<f64> = samples
            .iter()
            .map(|s| law.dtorque_dw(s, rpm * RAD_S_PER_RPM, 1.0))
            .collect();
        let unknown = slopes.iter().any(|s| !s.is_finite())
            || samples
                .iter()
                .any(|s| !law.torque(s, rpm * RAD_S_PER_RPM, 1.0).is_finite());
        for &kn in grid.wob_kn {
            let r = kn * 1000.0 / grid.w_ref_n;
            let unstable = slopes
                .iter()
                .filter(|&&slope| grid.criterion.unstable(r * slope))
                .count();
            out.push(if unknown {
                f64::NAN
            } else {
                unstable as f64 / samples.len() as f64
            });
        }
    }
    Ok(out)
}

/// P(unstable) of the mixture of `inputs` (each law weighted by its probability, over their
/// total) at every (Ω, W), row-major over Ω: [`probability_grid`] of each law, mixed.
pub fn mixture_probability_grid(
    inputs: &[LawSamples],
    omega_rpm: &[f64],
    wob_kn: &[f64],
    criterion: Criterion,
    w_ref_n: f64,
) -> Vec<f64> {
    let total: f64 = inputs.iter().map(|m| m.probability).sum();
    let mut grid = vec![0.0; omega_rpm.len() * wob_kn.len()];
    for m in inputs {
        let g = probability_grid(&Grid {
            law: m.law,
            samples: &m.samples_si,
            omega_rpm,
            wob_kn,
            criterion,
            w_ref_n,
        });
        for (cell, p) in grid.iter_mut().zip(g) {
            *cell += m.probability / total * p;
        }
    }
    grid
}

/// Bytes of one grid cell as the maps hold and print it: the f64 probability per law and the
/// mixture, the u32 count the GPU returns, and up to 24 characters of JSON.
const GRID_CELL_BYTES: f64 = 8.0 + 4.0 + 24.0;
/// Cell-samples per second above any device's: the time estimate is a lower bound.
const FASTEST_CELL_SAMPLES_PER_S: f64 = 1e11;

/// Refuses, before any work, a probability grid of `cells` (Ω × W) for `laws` laws of
/// `samples` samples each that would not fit in memory or could not finish in a day; the
/// flags of the axes and the sample count are named.
pub fn check_grid_size(cells: usize, laws: usize, samples: usize) -> Result<()> {
    let grids = cells as f64 * (laws as f64 + 1.0);
    crate::limits::check_memory(
        "omega_rpm/wob_kn",
        grids * GRID_CELL_BYTES,
        &format!("a grid of {cells} cells for {laws} laws"),
    )?;
    crate::limits::check_work(
        "samples",
        cells as f64 * laws as f64 * samples as f64,
        FASTEST_CELL_SAMPLES_PER_S,
        &format!("{cells} cells × {samples} samples × {laws} laws"),
    )
}

/// Largest real part of the 1-DOF Jacobian's eigenvalues (1/s) at every cell for one
/// parameter set: the growth-rate map. Row-major over (Ω, W).
pub fn growth_rate_grid(
    law: Law,
    params_si: &[f64],
    omega_rpm: &[f64],
    wob_kn: &[f64],
    lumped: &Lumped,
    w_ref_n: f64,
) -> Vec<f64> {
    let mut out = Vec::with_capacity(omega_rpm.len() * wob_kn.len());
    for &rpm in omega_rpm {
        let slope = law.dtorque_dw(params_si, rpm * RAD_S_PER_RPM, 1.0);
        for &kn in wob_kn {
            out.push(lumped.growth_rate(kn * 1000.0 / w_ref_n * slope));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    #[test]
    fn a_boundary_wholly_off_the_map_is_said_with_where_it_lies() {
        use super::{Criterion, Lumped, OffTheMap};
        let (omega, wob) = ([20.0, 120.0, 220.0], [20.0, 700.0]);
        // A laboratory record's torques on the field string: hundreds of thousands of kN.
        let above = OffTheMap::of(&[Some(1.9e9), Some(3.1e5), Some(282_716.0)], &omega, &wob);
        assert_eq!(
            above,
            Some(OffTheMap::Above {
                lowest: Some((282_716.0, 220.0))
            })
        );
        let words = above
            .unwrap()
            .describe("law m2's MAP boundary", &wob, &Criterion::Lumped(Lumped::default()));
        assert!(words.starts_with("law m2's MAP boundary lies above the map's highest weight on bit (700 kN) at every speed (lowest 2.8272e5 kN, at 220 rpm): the whole map is stable"), "{words}");
        assert!(words.contains("the paper's 5 km field string"), "{words}");
        let own = Lumped {
            inertia_kg_m2: 0.05,
            ..Lumped::default()
        };
        assert!(
            !above
                .unwrap()
                .describe("b", &wob, &Criterion::Lumped(own))
                .contains("5 km")
        );
        // Never unstable at any speed, and below the lowest weight everywhere.
        assert_eq!(
            OffTheMap::of(&[None, None, None], &omega, &wob),
            Some(OffTheMap::Above { lowest: None })
        );
        assert_eq!(
            OffTheMap::of(&[Some(3.0), Some(1.0), Some(19.9)], &omega, &wob),
            Some(OffTheMap::Below { highest: (19.9, 220.0) })
        );
        // On the map somewhere, on both sides, or unknown somewhere: nothing to say.
        assert_eq!(OffTheMap::of(&[Some(1e6), Some(500.0), None], &omega, &wob), None);
        assert_eq!(OffTheMap::of(&[Some(1e6), Some(5.0), Some(1e6)], &omega, &wob), None);
        assert_eq!(
            OffTheMap::of(&[Some(1e6), Some(f64::NAN), Some(1e6)], &omega, &wob),
            None
        );
        assert_eq!(OffTheMap::of(&[Some(5.0), None, Some(5.0)], &omega, &wob), None);
    }

    use super::*;

    fn m2_nm() -> Vec<f64> {
        Law::M2.scale_torque(Law::M2.paper_estimate().unwrap(), 1000.0)
    }

    #[test]
    fn axes_parse_and_refuse_nonsense() {
        assert_eq!(parse_axis("10:30:3", "omega_rpm").unwrap(), vec![10.0, 20.0, 30.0]);
        for bad in ["10:30", "30:10:5", "0:10:5", "a:10:5", "1:10:1", "1:10:x"] {
            assert!(
                parse_axis(bad, "omega_rpm")
                    .unwrap_err()
                    .to_string()
                    .starts_with("`omega_rpm`:"),
                "{bad}"
            );
        }
    }

    #[test]
    fn the_critical_weight_is_the_closed_form_of_the_paper_criterion() {
        // m2: dT/dw = -(tsb - tcb) g exp(-g Ω); 1-DOF: unstable when r dT/dw ≤ -c_eq.
        let lumped = Lumped::default();
        let c = lumped.critical_bit_damping_nms();
        let omega = 60.0 * RAD_S_PER_RPM;
        let slope = -(13e3 - 6.5e3) * 0.3 * (-0.3 * omega).exp();
        let w = critical_wob_n(Law::M2, &m2_nm(), omega, c, 244.2e3).unwrap();
        assert!((w - 244.2e3 * c / slope).abs() < 1e-9 * w);
        // Just above W* the growth rate is positive, just below negative.
        assert!(lumped.growth_rate(w * 1.0001 / 244.2e3 * slope) > 0.0);
        assert!(lumped.growth_rate(w * 0.9999 / 244.2e3 * slope) < 0.0);
        // m3 rises on its bump below a2 = 0.09 rad/s: no weight on bit destabilises there.
        let m3 = Law::M3.scale_torque(Law::M3.paper_estimate().unwrap(), 1000.0);
        assert!(Law::M3.dtorque_dw(&m3, 0.01, 1.0) > 0.0);
        assert!(critical_wob_n(Law::M3, &m3, 0.01, c, 244.2e3).is_none());
    }

    #[test]
    fn the_grid_agrees_with_the_reduction_on_every_cell() {
        let omega = parse_axis("20:200:37", "x").unwrap();
        let wob = parse_axis("20:600:59", "y").unwrap();
        let lumped = Lumped::default();
        let samples: Vec<Vec<f64>> = (0..50)
            .map(|i| Law::M2.scale_torque(&[13.0, 6.5, 0.2 + 0.004 * i as f64], 1000.0))
            .collect();
        let grid = probability_grid(&Grid {
            law: Law::M2,
            samples: &samples,
            omega_rpm: &omega,
            wob_kn: &wob,
            criterion: Criterion::Lumped(lumped),
            w_ref_n: 244.2e3,
        });
        let c = lumped.critical_bit_damping_nms();
        for (i, &rpm) in omega.iter().enumerate() {
            for (j, &kn) in wob.iter().enumerate() {
                let by_reduction = samples
                    .iter()
                    .filter(|s| {
                        critical_wob_n(Law::M2, s, rpm * RAD_S_PER_RPM, c, 244.2e3).is_some_and(|w| kn * 1000.0 >= w)
                    })
                    .count() as f64
                    / 50.0;
                assert!((grid[i * wob.len() + j] - by_reduction).abs() < 1e-12, "({rpm}, {kn})");
            }
        }
    }

    #[test]
    fn percentile_and_mixture_boundaries() {
        let omega = [60.0];
        let c = Lumped::default().critical_bit_damping_nms();
        let samples: Vec<Vec<f64>> = (0..101)
            .map(|i| Law::M2.scale_torque(&[13.0, 6.5, 0.2 + 0.002 * i as f64], 1000.0))
            .collect();
        let w: Vec<f64> = samples
            .iter()
            .map(|s| critical_wob_n(Law::M2, s, 2.0 * std::f64::consts::PI, c, 244.2e3).unwrap())
            .collect();
        let p2 = percentile_boundary_kn(Law::M2, &samples, &omega, c, 244.2e3, 0.02)[0].unwrap();
        assert!((p2 - crate::numerics::quantile(&w, 0.02) / 1000.0).abs() < 1e-9);
        // A mixture of one law with itself is that law (up to the step of the empirical CDF).
        let mix = mixture_boundary_kn(
            &[(0.4, Law::M2, &samples), (0.6, Law::M2, &samples)],
            &omega,
            c,
            244.2e3,
            0.02,
        )[0]
        .unwrap();
        let mut sorted = w.clone();
        sorted.sort_by(f64::total_cmp);
        assert!(
            (mix - sorted[2] / 1000.0).abs() < 1e-9,
            "{mix} vs {}",
            sorted[2] / 1000.0
        );
        // The MAP boundary is the deterministic one.
        let det = deterministic_boundary_kn(Law::M2, &samples[50], &omega, c, 244.2e3)[0].unwrap();
        assert!((det - w[50] / 1000.0).abs() < 1e-9);
    }
}
