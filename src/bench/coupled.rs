//! `bitrock bench --coupled`: the coupled axial-torsional bit's batched simulator, throughput
//! (string-seconds simulated per second of wall time) per backend, on a spread of speeds and
//! weights that covers steady drilling, stick-slip and bit bounce.

use crate::error::Result;
use crate::eval::Backend;
use crate::eval::strings::Ran;
use crate::simulate::coupled::{Assembly, Axial, Bit, CoupledJob, Regime, Schedule};
use crate::units::RAD_S_PER_RPM;

/// What to measure.
#[derive(Clone, Debug)]
pub struct CoupledBenchOptions {
    pub strings: usize,
    /// Simulated seconds per string (all recorded).
    pub seconds: f64,
    /// Integration step (s).
    pub dt_s: f64,
    pub backends: Vec<Backend>,
    pub repetitions: usize,
}

/// One measurement.
#[derive(Clone, Debug, serde::Serialize)]
pub struct CoupledThroughput {
    #[serde(flatten)]
    pub throughput: super::SimulatedThroughput,
    pub dt_s: f64,
    /// Share of the strings in each regime (a check that the backends did the same work):
    /// steady, stick-slip, bit bounce, both.
    pub regimes: [f64; 4],
    /// On a GPU: whether the kernel's lanes left their steps together by a subgroup vote (the
    /// device has subgroup operations), else each alone.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub subgroup_vote: Option<bool>,
}

/// The public bit on the default string at 40–160 rpm and 100–260 kN.
fn batch(n: usize) -> Vec<CoupledJob> {
    (0..n)
        .map(|i| CoupledJob {
            bit: Bit::default(),
            omega_rad_s: (40.0 + 120.0 * ((i % 97) as f64 / 96.0)) * RAD_S_PER_RPM,
            axial: Axial::Weight {
                wob_n: 1e3 * (100.0 + 160.0 * ((i % 89) as f64 / 88.0)),
            },
            kick_rad_s: RAD_S_PER_RPM,
        })
        .collect()
}

/// Every measurement of `opts`.
pub fn run(opts: &CoupledBenchOptions, log: &mut dyn FnMut(String)) -> Result<Vec<CoupledThroughput>> {
    let assembly = Assembly::default();
    let schedule = Schedule::new(opts.dt_s, 50.0, 0.0, opts.seconds)?;
    let jobs = batch(opts.strings);
    jobs.iter().try_for_each(|j| j.check_step(schedule.dt_s))?;
    let mut out = Vec::new();
    for &backend in &opts.backends {
        let mut walls = Vec::new();
        let mut ran = Ran::Cpu;
        let mut regimes = [0.0; 4];
        for _ in 0..opts.repetitions {
            let t = std::time::Instant::now();
            let (summaries, r) =
                crate::eval::coupled::integrate(&assembly, &schedule, &jobs, None, backend, &mut |l| log(l))?;
            walls.push(t.elapsed().as_secs_f64());
            regimes = [0.0; 4];
            for s in &summaries {
                let k = match s.regime() {
                    Regime::Steady => 0,
                    Regime::StickSlip => 1,
                    Regime::BitBounce => 2,
                    Regime::Both | Regime::Diverged => 3,
                };
                regimes[k] += 1.0 / summaries.len() as f64;
            }
            ran = r;
        }
        let subgroup_vote = match ran {
            Ran::Gpu(_) => Some(crate::eval::gpu::context()?.has_subgroups()),
            Ran::Cpu => None,
        };
        let m = CoupledThroughput {
            throughput: super::SimulatedThroughput::of(
                super::strings::name(&Some(ran)),
                opts.strings,
                schedule.seconds(),
                &walls,
            ),
            dt_s: schedule.dt_s,
            regimes,
            subgroup_vote,
        };
        log(format!("coupled {:#}", m.throughput));
        out.push(m);
    }
    Ok(out)
}
