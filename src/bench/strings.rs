//! `bitrock bench --strings`: the batched string simulator's throughput (string-seconds
//! simulated per second of wall time) on the 1-DOF string and the lumped finite-element one,
//! and the time of an escape map, per backend.

use crate::error::Result;
use crate::eval::Backend;
use crate::eval::strings::Ran;
use crate::laws::{Law, PAPER_W_REF_N};
use crate::run::strings::{OperatingPoint, SimulatedSettings, Simulator};
use crate::simulate::strings::{Chain, Schedule, StringJob, padded, steady_start};
use crate::stability::fe::DrillString;
use crate::stability::lumped::Lumped;
use crate::stability::map::LawSamples;
use crate::units::RAD_S_PER_RPM;

/// What to measure.
#[derive(Clone, Debug)]
pub struct StringsBenchOptions {
    /// Strings per batch.
    pub strings: usize,
    /// Simulated seconds per string (all recorded).
    pub seconds: f64,
    /// Integration step (s).
    pub dt_s: f64,
    /// Escape map: speeds × weights × posterior samples.
    pub map: (usize, usize, usize),
    pub backends: Vec<Backend>,
    pub repetitions: usize,
    /// Measure the GPU only where `auto` would simulate on it: a software driver's row for a
    /// chain `auto` leaves to the CPU is left out, saying so (the command sets it where no
    /// backend or `auto` is named); false measures every chain on every backend.
    pub gpu_where_auto_takes_it: bool,
}

/// One measurement.
#[derive(Clone, Debug, serde::Serialize)]
pub struct StringsThroughput {
    /// `throughput` or `escape map`.
    pub what: String,
    /// `1dof` or `fe` (the paper's 10-element string lumped).
    pub string: String,
    #[serde(flatten)]
    pub throughput: super::SimulatedThroughput,
    /// Stuck share averaged over the strings (a check that both backends did the same work).
    pub mean_stuck_share: f64,
}

/// The strings of a throughput batch: m2 at the paper's estimate and a spread of speeds
/// (40–160 rpm) and weights (0.5–1.5 W_ref), half of them in stick-slip.
fn batch(chain: &Chain, n: usize) -> Vec<StringJob> {
    let law = Law::M2;
    let p = padded(&law.scale_torque(law.paper_estimate().expect("m2 has one"), 1000.0));
    (0..n)
        .map(|i| {
            let omega = (40.0 + 120.0 * ((i % 97) as f64 / 96.0)) * RAD_S_PER_RPM;
            let ratio = 0.5 + (i % 89) as f64 / 88.0;
            StringJob {
                law,
                params_nm: p,
                omega_rad_s: omega,
                ratio,
                start: steady_start(chain, law, &p, omega, ratio, 0.1 * omega),
            }
        })
        .collect()
}

fn chains() -> Result<Vec<(&'static str, Chain)>> {
    let fe = DrillString {
        dp_elements: 8,
        bha_elements: 2,
        ..DrillString::default()
    };
    Ok(vec![
        ("1dof", Chain::one_dof(&Lumped::default())),
        ("fe", Chain::lumped_fe(&fe)?),
    ])
}

pub(super) fn name(ran: &Option<Ran>) -> String {
    match ran {
        Some(Ran::Gpu(name)) => format!("gpu ({name})"),
        _ => "cpu".into(),
    }
}

/// Every measurement of `opts`.
pub fn run(opts: &StringsBenchOptions, log: &mut dyn FnMut(String)) -> Result<Vec<StringsThroughput>> {
    let mut out = Vec::new();
    let schedule = Schedule::new(opts.dt_s, 50.0, 0.0, opts.seconds)?;
    for (string, chain) in chains()? {
        chain.check_step(opts.dt_s)?;
        let jobs = batch(&chain, opts.strings);
        for &backend in &opts.backends {
            if backend == Backend::Gpu
                && opts.gpu_where_auto_takes_it
                && let Some(adapter) = crate::eval::strings::software_gpu_passed_over(chain.nodes())
            {
                log(format!(
                    "strings {string} on the GPU not measured: {adapter} is a software driver, and `auto` simulates a chain of {} nodes on the CPU (measured with `backend` gpu)",
                    chain.nodes()
                ));
                continue;
            }
            let mut walls = Vec::new();
            let mut ran = None;
            let mut stuck = 0.0;
            for _ in 0..opts.repetitions {
                let t = std::time::Instant::now();
                let (results, r) = crate::eval::strings::integrate(&chain, &schedule, &jobs, backend, &mut |l| log(l))?;
                walls.push(t.elapsed().as_secs_f64());
                stuck = results.iter().map(|r| r.0.stuck_share()).sum::<f64>() / results.len() as f64;
                ran = Some(r);
            }
            let m = StringsThroughput {
                what: "throughput".into(),
                string: string.into(),
                throughput: super::SimulatedThroughput::of(name(&ran), opts.strings, schedule.seconds(), &walls),
                mean_stuck_share: stuck,
            };
            log(format!("strings {string} {:#}", m.throughput));
            out.push(m);
        }
    }
    // The escape map: m2 around the paper's estimate, from stick-slip at 60 rpm and 244 kN.
    let (speeds, weights, samples) = opts.map;
    let law = Law::M2;
    let paper = law.scale_torque(law.paper_estimate().expect("m2 has one"), 1000.0);
    let inputs = vec![LawSamples {
        law,
        probability: 1.0,
        map_si: paper.clone(),
        samples_si: (0..samples)
            .map(|k| {
                paper
                    .iter()
                    .map(|v| v * (0.95 + 0.1 * k as f64 / samples.max(2) as f64))
                    .collect()
            })
            .collect(),
        strings: Vec::new(),
    }];
    let omega: Vec<f64> = (0..speeds)
        .map(|i| 20.0 + 200.0 * i as f64 / (speeds.max(2) - 1) as f64)
        .collect();
    let wob: Vec<f64> = (0..weights)
        .map(|j| 20.0 + 680.0 * j as f64 / (weights.max(2) - 1) as f64)
        .collect();
    for &backend in &opts.backends {
        let settings = SimulatedSettings::new(Chain::one_dof(&Lumped::default()), PAPER_W_REF_N, backend);
        let mut walls = Vec::new();
        let mut ran = None;
        let mut strings = 0;
        let mut seconds = 0.0;
        let mut share = 0.0;
        for _ in 0..opts.repetitions {
            let t = std::time::Instant::now();
            let mut note = |l: String| log(l);
            let mut sim = Simulator::new(&settings, &inputs, &mut note)?;
            let at = sim.at_point(OperatingPoint {
                omega_rpm: 60.0,
                wob_kn: 244.2,
            })?;
            let grid = sim.escape(&at, &omega, &wob)?;
            walls.push(t.elapsed().as_secs_f64());
            strings = sim.strings as usize;
            seconds = sim.simulated_s;
            share = grid.probability.iter().filter(|p| p.is_finite()).sum::<f64>() / grid.probability.len() as f64;
            ran = sim.ran.clone();
        }
        let m = StringsThroughput {
            what: format!("escape map {speeds}×{weights}×{samples}"),
            string: "1dof".into(),
            throughput: super::SimulatedThroughput::of(name(&ran), strings, seconds / strings as f64, &walls),
            mean_stuck_share: share,
        };
        log(format!(
            "{} {}: {:.3} s",
            m.what, m.throughput.backend, m.throughput.wall_s.median
        ));
        out.push(m);
    }
    Ok(out)
}
