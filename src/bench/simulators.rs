//! `bitrock parity`'s simulator sections: the same strings integrated by the kernels and by
//! their CPU twins, compared by the rules the kernels are held to. The integration tests compare
//! by these functions too, so that the command checks a user's GPU as the tests check lavapipe.

use super::DIFFERENCES_SHOWN;
use crate::Law;
use crate::error::Result;
use crate::eval::{Backend, coupled as coupled_backend, strings as strings_backend};
use crate::simulate::coupled::{self, Assembly, Axial, Bit, CoupledJob, CoupledSummary, Regime};
use crate::simulate::strings::{Chain, Schedule, StringJob, StringState, Summary, padded, steady_start};
use crate::stability::lumped::Lumped;
use crate::units::RAD_S_PER_RPM;
use serde::Serialize;

/// Torsional strings whose stick-slip verdicts may differ, as a share: f32 against f64 through
/// a chaotic cycle, a string on the edge may go either way.
pub const STRINGS_VERDICTS_MAY_DIFFER: f64 = 0.01;
/// Where the verdicts agree, the largest difference of stuck shares.
pub const STRINGS_STUCK_SHARE: f64 = 0.01;
/// Where the verdicts agree, the largest difference of the lowest and highest bit speeds, as a
/// share of the larger of the highest speed and the top drive's.
pub const STRINGS_SPEED: f64 = 0.01;

/// Strings over every built-in law at its paper estimate (torque in N·m), 20 to 200 rpm, weight
/// ratios r = W/W_ref from 0.4 to 1.6, each kicked by 10 % of Ω from steady rotation on `chain`:
/// stick-slip and steady rotation side by side.
pub fn string_parity_jobs(chain: &Chain) -> Vec<StringJob> {
    let mut out = Vec::new();
    for law in Law::ALL {
        let p = padded(&law.scale_torque(law.paper_estimate().expect("built-in laws have estimates"), 1000.0));
        for k in 0..10 {
            let omega = (20.0 + 20.0 * f64::from(k)) * RAD_S_PER_RPM;
            for r in [0.4, 0.7, 1.0, 1.3, 1.6] {
                out.push(StringJob {
                    law,
                    params_nm: p,
                    omega_rad_s: omega,
                    ratio: r,
                    start: steady_start(chain, law, &p, omega, r, 0.1 * omega),
                });
            }
        }
    }
    out
}

/// The schedule [`strings_parity`] integrates on: 0.01 s steps, 40 s settled, 20 s recorded.
pub fn string_parity_schedule() -> Schedule {
    Schedule::new(0.01, 50.0, 40.0, 20.0).expect("a valid schedule")
}

/// How the kernel's torsional strings agree with the CPU twin's.
#[derive(Clone, Debug, Serialize)]
pub struct StringsParity {
    pub strings: usize,
    /// Strings whose count of samples or whose divergence differs: none may.
    pub samples_or_divergence_differ: usize,
    /// Strings whose stick-slip verdict differs ([`STRINGS_VERDICTS_MAY_DIFFER`] may).
    pub verdicts_differ: usize,
    /// Strings whose verdicts agree but whose stuck share or speeds differ beyond their rule (or
    /// are not numbers): none may.
    pub beyond_tolerance: usize,
    /// Where the verdicts agree: the largest difference of stuck shares.
    pub max_stuck_share_diff: f64,
    /// Where the verdicts agree: the largest difference of the speed extremes, relative.
    pub max_speed_diff: f64,
    /// The first strings beyond a rule, or whose verdicts differ, described.
    pub first_differences: Vec<String>,
    pub pass: bool,
}

/// Compares the summaries of `jobs` from the CPU twin and the kernel, string by string: the
/// count of samples and the divergence of every string; the verdicts and, where they agree,
/// the stuck shares and the speed extremes of every string that recorded samples and did not
/// run away (one that did has no figures to compare).
pub fn compare_strings(
    jobs: &[StringJob],
    cpu: &[(Summary, StringState)],
    gpu: &[(Summary, StringState)],
) -> StringsParity {
    let mut report = StringsParity {
        strings: jobs.len(),
        samples_or_divergence_differ: 0,
        verdicts_differ: 0,
        beyond_tolerance: 0,
        max_stuck_share_diff: 0.0,
        max_speed_diff: 0.0,
        first_differences: Vec::new(),
        pass: false,
    };
    for ((j, (c, _)), (g, _)) in jobs.iter().zip(cpu).zip(gpu) {
        let mut differs = c.samples != g.samples || c.diverged != g.diverged;
        if differs {
            report.samples_or_divergence_differ += 1;
        } else if c.diverged || c.samples == 0 {
            // Both ran away, or recorded nothing: no figures to compare.
        } else if c.stick_slips() != g.stick_slips() {
            report.verdicts_differ += 1;
            differs = true;
        } else {
            let scale = c.speed_max_rad_s.abs().max(j.omega_rad_s);
            let stuck = (c.stuck_share() - g.stuck_share()).abs();
            // Each compared on its own: `f64::max` would drop a NaN.
            let speeds = [
                (c.speed_max_rad_s - g.speed_max_rad_s).abs() / scale,
                (c.speed_min_rad_s - g.speed_min_rad_s).abs() / scale,
            ];
            report.max_stuck_share_diff = report.max_stuck_share_diff.max(stuck);
            report.max_speed_diff = speeds.iter().fold(report.max_speed_diff, |m, &d| m.max(d));
            differs = !(stuck <= STRINGS_STUCK_SHARE && speeds.iter().all(|&d| d <= STRINGS_SPEED));
            report.beyond_tolerance += usize::from(differs);
        }
        if differs && report.first_differences.len() < DIFFERENCES_SHOWN {
            report.first_differences.push(format!(
                "{} at {:.0} rpm, r = {}: stuck share cpu {:.4}, gpu {:.4}; bit speed cpu {:.2}..{:.2}, gpu {:.2}..{:.2} rad/s; samples cpu {}, gpu {}{}",
                j.law,
                j.omega_rad_s / RAD_S_PER_RPM,
                j.ratio,
                c.stuck_share(),
                g.stuck_share(),
                c.speed_min_rad_s,
                c.speed_max_rad_s,
                g.speed_min_rad_s,
                g.speed_max_rad_s,
                c.samples,
                g.samples,
                if c.diverged != g.diverged { "; one diverged" } else { "" }
            ));
        }
    }
    report.pass = cpu.len() == jobs.len()
        && gpu.len() == jobs.len()
        && report.samples_or_divergence_differ == 0
        && report.beyond_tolerance == 0
        && report.verdicts_differ as f64 <= STRINGS_VERDICTS_MAY_DIFFER * jobs.len() as f64;
    if !(cpu.len() == jobs.len() && gpu.len() == jobs.len()) {
        report.first_differences.push(format!(
            "{} strings: {} summaries from the cpu, {} from the gpu",
            jobs.len(),
            cpu.len(),
            gpu.len()
        ));
    }
    report
}

/// [`string_parity_jobs`] on the paper's 1-DOF string, on both backends, compared.
pub fn strings_parity() -> Result<StringsParity> {
    let chain = Chain::one_dof(&Lumped::default());
    let (jobs, schedule) = (string_parity_jobs(&chain), string_parity_schedule());
    let (cpu, _) = strings_backend::integrate(&chain, &schedule, &jobs, Backend::Cpu, &mut |_| {})?;
    let (gpu, _) = strings_backend::integrate(&chain, &schedule, &jobs, Backend::Gpu, &mut |_| {})?;
    Ok(compare_strings(&jobs, &cpu, &gpu))
}

/// Coupled bit: each figure agrees where its difference is below these. The rate of
/// penetration, relative, where the bit does not bounce.
pub const COUPLED_RATE: f64 = 0.01;
/// The rate of penetration, relative, where the bit bounces: its motion is irregular, a
/// minute's rate moves by 1-2 % with the rounding as with the step.
pub const COUPLED_RATE_BOUNCING: f64 = 0.03;
/// The stuck share.
pub const COUPLED_STUCK_SHARE: f64 = 0.01;
/// The off-bottom share.
pub const COUPLED_OFF_BOTTOM_SHARE: f64 = 0.015;
/// The mean weight on bit and torque, relative.
pub const COUPLED_MEANS: f64 = 0.01;

/// The public bit on the paper's string in cells whose motion is regular (kicks 10⁻⁵ of
/// themselves apart move the CPU's stuck share by 0.002 at most: tested): stick-slip at 45 and
/// 60 rpm, bit bounce at 80, steady at 120 under a weight, and steady under a feed; 20 s
/// settled and 40 s recorded at 1e-4 s, so 600,000 steps a string in f32 against f64. Near the
/// edge of stick-slip many cells' motion is irregular: at 40 rpm under 150 kN kicks of 1.00001
/// rpm and 1 rpm move the CPU's stuck share by 0.011, as a rounding would; where the bit
/// bounces some cells hold two motions and the rounding picks one. Those are no cells for a
/// parity check.
pub fn coupled_parity_cells() -> ([(f64, Axial); 5], coupled::Schedule) {
    let cells = [
        (45.0, Axial::Weight { wob_n: 140e3 }),
        (60.0, Axial::Weight { wob_n: 160e3 }),
        (80.0, Axial::Weight { wob_n: 200e3 }),
        (120.0, Axial::Weight { wob_n: 200e3 }),
        (
            30.0,
            Axial::Feed {
                rate_m_s: 30.0 / 3600.0,
            },
        ),
    ];
    (
        cells,
        coupled::Schedule::new(1e-4, 50.0, 20.0, 40.0).expect("a valid schedule"),
    )
}

/// The public bit at `rpm` under `axial`, kicked by the default kick from steady drilling.
pub fn coupled_parity_job(rpm: f64, axial: Axial) -> CoupledJob {
    CoupledJob {
        bit: Bit::default(),
        omega_rad_s: rpm * RAD_S_PER_RPM,
        axial,
        kick_rad_s: coupled::DEFAULT_KICK_RPM * RAD_S_PER_RPM,
    }
}

/// One cell of the coupled bit on both backends: each figure as (CPU, GPU).
#[derive(Clone, Debug, Serialize)]
pub struct CoupledCellParity {
    pub omega_rpm: f64,
    /// The drive, with its unit: "140 kN" or "30 m/h".
    pub drive: String,
    pub regime: (Regime, Regime),
    pub samples: (u32, u32),
    pub rop_m_h: (f64, f64),
    pub stuck_share: (f64, f64),
    pub off_bottom_share: (f64, f64),
    pub wob_mean_kn: (f64, f64),
    pub torque_mean_knm: (f64, f64),
    pub pass: bool,
}

/// How the coupled kernel's cells agree with the CPU twin's.
#[derive(Clone, Debug, Serialize)]
pub struct CoupledParity {
    pub cells: Vec<CoupledCellParity>,
    pub pass: bool,
}

/// Compares the CPU twin's summaries of `cells` with the kernel's, cell by cell (a summary
/// missing on either side fails it).
pub fn compare_coupled(cells: &[(f64, Axial)], cpu: &[CoupledSummary], gpu: &[CoupledSummary]) -> CoupledParity {
    let within = |c: f64, g: f64, share: f64| (c - g).abs() < share * c.abs();
    let cells: Vec<CoupledCellParity> = cells
        .iter()
        .zip(cpu.iter().zip(gpu))
        .map(|(&(rpm, axial), (c, g))| {
            let rate = if c.regime() == Regime::BitBounce {
                COUPLED_RATE_BOUNCING
            } else {
                COUPLED_RATE
            };
            let pass = c.regime() == g.regime()
                && c.samples == g.samples
                && within(c.rate_m_s(), g.rate_m_s(), rate)
                && (c.stuck_share() - g.stuck_share()).abs() < COUPLED_STUCK_SHARE
                && (c.off_bottom_share() - g.off_bottom_share()).abs() < COUPLED_OFF_BOTTOM_SHARE
                && within(c.wob_mean_n(), g.wob_mean_n(), COUPLED_MEANS)
                && within(c.torque_mean_nm(), g.torque_mean_nm(), COUPLED_MEANS);
            let both = |f: &dyn Fn(&CoupledSummary) -> f64| (f(c), f(g));
            CoupledCellParity {
                omega_rpm: rpm,
                drive: match axial {
                    Axial::Weight { wob_n } => format!("{} kN", wob_n / 1e3),
                    Axial::Feed { rate_m_s } => format!("{} m/h", rate_m_s * 3600.0),
                },
                regime: (c.regime(), g.regime()),
                samples: (c.samples, g.samples),
                rop_m_h: both(&|s| s.rate_m_s() * 3600.0),
                stuck_share: both(&|s| s.stuck_share()),
                off_bottom_share: both(&|s| s.off_bottom_share()),
                wob_mean_kn: both(&|s| s.wob_mean_n() / 1e3),
                torque_mean_knm: both(&|s| s.torque_mean_nm() / 1e3),
                pass,
            }
        })
        .collect();
    let pass = cpu.len() == cells.len() && gpu.len() == cells.len() && cells.iter().all(|c| c.pass);
    CoupledParity { cells, pass }
}

/// [`coupled_parity_cells`] on both backends, compared.
pub fn coupled_parity() -> Result<CoupledParity> {
    let (cells, schedule) = coupled_parity_cells();
    let jobs: Vec<CoupledJob> = cells
        .iter()
        .map(|&(rpm, axial)| coupled_parity_job(rpm, axial))
        .collect();
    let assembly = Assembly::default();
    let cpu = coupled::integrate_batch(&assembly, &schedule, &jobs, None);
    let (gpu, _) = coupled_backend::integrate(&assembly, &schedule, &jobs, None, Backend::Gpu, &mut |_| {})?;
    Ok(compare_coupled(&cells, &cpu, &gpu))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn compare_strings_counts_what_differs_and_fails_beyond_a_tolerance() {
        let chain = Chain::one_dof(&Lumped::default());
        let jobs: Vec<StringJob> = string_parity_jobs(&chain).into_iter().take(4).collect();
        let schedule = Schedule::new(0.01, 50.0, 1.0, 2.0).unwrap();
        let cpu = crate::simulate::strings::integrate_batch(&chain, &schedule, &jobs);
        let same = compare_strings(&jobs, &cpu, &cpu);
        assert!(same.pass && same.first_differences.is_empty(), "{same:?}");
        assert_eq!((same.max_stuck_share_diff, same.max_speed_diff), (0.0, 0.0));

        let mut gpu = cpu.clone();
        gpu[1].0.speed_max_rad_s += 0.02 * gpu[1].0.speed_max_rad_s.abs().max(jobs[1].omega_rad_s);
        gpu[2].0.samples += 1;
        let off = compare_strings(&jobs, &cpu, &gpu);
        assert!(!off.pass);
        assert_eq!(off.samples_or_divergence_differ, 1);
        assert!((off.max_speed_diff - 0.02).abs() < 1e-9, "{off:?}");
        assert_eq!(off.first_differences.len(), 2, "{off:?}");
        assert!(off.first_differences[0].starts_with(&format!("{} at 20 rpm, r = 0.7", jobs[1].law)));
        // A speed that is not a number fails; so does a summary missing.
        let mut nan = cpu.clone();
        nan[0].0.speed_min_rad_s = f64::NAN;
        let not_a_number = compare_strings(&jobs, &cpu, &nan);
        assert!(
            !not_a_number.pass && not_a_number.beyond_tolerance == 1,
            "{not_a_number:?}"
        );
        assert!(!compare_strings(&jobs, &cpu, &cpu[..3]).pass);
    }

    #[test]
    fn compare_coupled_fails_a_cell_beyond_a_tolerance_and_only_that_cell() {
        let (cells, _) = coupled_parity_cells();
        let cells = &cells[3..];
        let schedule = coupled::Schedule::new(1e-4, 50.0, 0.5, 1.0).unwrap();
        let jobs: Vec<CoupledJob> = cells.iter().map(|&(rpm, a)| coupled_parity_job(rpm, a)).collect();
        let cpu = coupled::integrate_batch(&Assembly::default(), &schedule, &jobs, None);
        let same = compare_coupled(cells, &cpu, &cpu);
        assert!(same.pass, "{same:?}");
        assert_eq!(same.cells[0].drive, "200 kN");
        assert_eq!(same.cells[1].drive, "30 m/h");
        // The mean torque 1.1 % off, in the second cell.
        let mut gpu = cpu.clone();
        gpu[1].torque_sum_nm *= 1.011;
        let off = compare_coupled(cells, &cpu, &gpu);
        assert!(!off.pass && off.cells[0].pass && !off.cells[1].pass, "{off:?}");
        assert!((off.cells[1].torque_mean_knm.1 / off.cells[1].torque_mean_knm.0 - 1.011).abs() < 1e-12);
        assert!(!compare_coupled(cells, &cpu, &cpu[..1]).pass);
    }
}
