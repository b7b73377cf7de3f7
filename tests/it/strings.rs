//! The batched string simulator: the kernel against its CPU twin, string by string, and the
//! escape from stick-slip where independent simulations put it.

use crate::gpu::require_gpu;
use bitrock::Law;
use bitrock::eval::Backend;
use bitrock::simulate::strings::{Chain, Schedule, StringJob, Summary, padded, steady_start};
use bitrock::stability::fe::DrillString;
use bitrock::stability::lumped::Lumped;
use bitrock::units::RAD_S_PER_RPM;

/// Strings over every built-in law at its paper estimate, 20 to 200 rpm, r from 0.4 to 1.6,
/// kicked by 10 % of Ω from steady rotation.
fn jobs(chain: &Chain) -> Vec<StringJob> {
    let mut out = Vec::new();
    for law in Law::ALL {
        let p = padded(&law.scale_torque(law.paper_estimate().unwrap(), 1000.0));
        for k in 0..10 {
            let omega = (20.0 + 20.0 * k as f64) * RAD_S_PER_RPM;
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

fn compare(chain: &Chain, schedule: &Schedule) {
    let jobs = jobs(chain);
    let (cpu, _) = bitrock::eval::strings::integrate(chain, schedule, &jobs, Backend::Cpu, &mut |_| {}).unwrap();
    let (gpu, _) = bitrock::eval::strings::integrate(chain, schedule, &jobs, Backend::Gpu, &mut |_| {}).unwrap();
    let mut agree = 0;
    for (i, ((c, _), (g, _))) in cpu.iter().zip(&gpu).enumerate() {
        let j = &jobs[i];
        let same = c.stick_slips() == g.stick_slips() && c.diverged == g.diverged;
        agree += usize::from(same);
        let show = |s: &Summary| {
            format!(
                "share {:.4} max {:.3} min {:.3} sev {:.3} div {}",
                s.stuck_share(),
                s.speed_max_rad_s,
                s.speed_min_rad_s,
                s.severity(),
                s.diverged
            )
        };
        eprintln!(
            "{} {:.1} rpm r {}: cpu {} | gpu {}",
            j.law,
            j.omega_rad_s / RAD_S_PER_RPM,
            j.ratio,
            show(c),
            show(g)
        );
    }
    eprintln!("agree {agree} of {}", jobs.len());
}

#[test]
#[cfg_attr(skip_gpu_tests, ignore = "BITROCK_SKIP_GPU_TESTS=1")]
fn explore_parity() {
    require_gpu();
    let schedule = Schedule::new(0.01, 50.0, 40.0, 20.0).unwrap();
    compare(&Chain::one_dof(&Lumped::default()), &schedule);
    compare(&Chain::lumped_fe(&DrillString::default()).unwrap(), &schedule);
}
