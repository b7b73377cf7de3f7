//! `bitrock bench --surface`: a surface record's inference end to end, timed: a 10-minute record
//! at 1 Hz of m2 at 60 rpm (the bit stuck half the time, 0.2 kN·m of noise on the surface
//! torque), four laws, a final population of 2,000, on one backend; the strings it simulated
//! per particle, against what rejection ABC would simulate to the same tolerance.

use crate::data::surface::{SurfaceColumns, SurfaceRecord};
use crate::error::Result;
use crate::eval::Backend;
use crate::laws::{Law, PAPER_W_REF_N};
use crate::run::surface::{SurfaceSettings, infer};
use crate::simulate::{self, Initial, Recording, SimConfig};
use crate::units::{RAD_S_PER_RPM, SpeedUnit, TorqueUnit};

/// What to measure.
#[derive(Clone, Debug)]
pub struct SurfaceBenchOptions {
    /// Record length (s) at 1 Hz.
    pub record_s: f64,
    pub particles: usize,
    pub repetitions: usize,
    /// Where the strings are simulated.
    pub backend: Backend,
}

/// The measurement.
#[derive(Clone, Debug, serde::Serialize)]
pub struct SurfaceBench {
    pub record: String,
    /// Where the strings were simulated: `CPU` or `GPU <adapter>`.
    pub backend: String,
    pub laws: Vec<Law>,
    pub particles: usize,
    /// Wall seconds of the whole inference (pilot, scout, sampler, check, predictive; no
    /// advice), median and range over the repetitions.
    pub wall_s: super::Spread,
    /// Strings simulated in all.
    pub strings: u64,
    pub strings_per_particle: f64,
    pub rejection_strings_per_particle: Option<f64>,
    /// Each law's probability and the verdict of the check.
    pub probabilities: Vec<(Law, f64)>,
    pub verdict: String,
}

/// The benchmark's record: m2 at its paper estimate and 60 rpm, surface channels at 1 Hz.
pub fn record(seconds: f64) -> Result<SurfaceRecord> {
    let law = Law::M2;
    let params = law.scale_torque(law.paper_estimate().expect("m2 has one"), 1000.0);
    let cfg = SimConfig {
        duration_s: seconds,
        recording: Recording {
            settle_s: 60.0,
            sample_hz: 1.0,
            dt_s: 2e-3,
            initial: Initial::Equilibrium {
                speed_perturbation_rad_s: simulate::DEFAULT_KICK_RPM * RAD_S_PER_RPM,
            },
            noise_torque_nm: 200.0,
            seed: 1,
            ..Recording::default()
        },
        ..SimConfig::new(law, params, 60.0 * RAD_S_PER_RPM, PAPER_W_REF_N)
    };
    let trace = simulate::simulate_record_with(&cfg, &mut |_, _| {})?;
    Ok(SurfaceRecord {
        source: "m2 at 60 rpm (simulated)".into(),
        columns: SurfaceColumns {
            time: "time_s".into(),
            top_drive: "top_drive_rpm".into(),
            surface_torque: "surface_torque_knm".into(),
            wob: Some("wob_kn".into()),
            bit: Vec::new(),
            downhole_min: None,
            downhole_max: None,
        },
        top_drive_unit: SpeedUnit::Rpm,
        torque_unit: TorqueUnit::KNm,
        time_s: trace.trace.time_s.clone(),
        top_drive_rad_s: trace.top_drive_rad_s.clone(),
        surface_torque_nm: trace.surface_torque_nm.clone(),
        wob_n: Some(trace.trace.wob_n.clone()),
        sample_period_s: 1.0,
        downhole: None,
    })
}

/// Runs the benchmark, reporting each repetition to `log`.
pub fn run(opts: &SurfaceBenchOptions, log: &mut dyn FnMut(String)) -> Result<SurfaceBench> {
    let record = record(opts.record_s)?;
    let laws = Law::ALL.to_vec();
    let mut settings = SurfaceSettings::new(laws.clone());
    settings.smc.schedule.particles = opts.particles;
    settings.advice = false;
    settings.backend = opts.backend;
    let mut walls = Vec::new();
    let mut last = None;
    for rep in 0..opts.repetitions {
        let t = std::time::Instant::now();
        let result = infer(&record, &settings, 1, &mut |l| log(l))?;
        walls.push(t.elapsed().as_secs_f64());
        log(format!(
            "surface {}: {:.1} s, {} strings ({:.1} per particle)",
            rep + 1,
            walls[rep],
            result.simulations,
            result.cost.strings_per_particle
        ));
        last = Some(result);
    }
    let result = last.expect("at least one repetition");
    Ok(SurfaceBench {
        backend: result.backend.clone(),
        record: format!("{} s of m2 at 60 rpm, 1 Hz, 0.2 kN·m of noise", opts.record_s),
        laws,
        particles: opts.particles,
        wall_s: super::Spread::of(&walls),
        strings: result.simulations,
        strings_per_particle: result.cost.strings_per_particle,
        rejection_strings_per_particle: result.cost.rejection_strings_per_particle,
        probabilities: result.laws.iter().map(|l| (l.law, l.probability)).collect(),
        verdict: result.check.verdict,
    })
}
