//! `bitrock parity`: the same candidates scored and the same strings simulated on the CPU and the
//! GPU, and their agreement.

use super::args::finite_number;
use super::args::{DataArgs, load_data};
use clap::Args;
use std::io::Write;
use std::process::ExitCode;

#[derive(Debug, Args)]
pub struct ParityCmd {
    #[command(flatten)]
    pub data_args: DataArgs,
    /// Laws to compare, comma-separated, built-in and --law-file laws (priors from their
    /// least-squares fits, δ = 0.4).
    #[arg(long, default_value = bitrock::built_in_law_list!(), value_name = "LAWS")]
    pub laws: String,
    /// Candidates scored per law on each backend.
    #[arg(long, default_value_t = bitrock::bench::PARITY_CANDIDATES, value_name = "N")]
    pub candidates: usize,
    /// Tolerance at which accept/reject decisions are compared [default: each law's median ρ].
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, value_name = "EPS")]
    pub epsilon: Option<f64>,
    /// Seed of the candidate stream.
    #[arg(long, default_value_t = bitrock::bench::PARITY_SEED)]
    pub seed: u64,
    /// Print JSON instead of a table.
    #[arg(long)]
    pub json: bool,
}

pub fn run(cmd: &ParityCmd) -> anyhow::Result<ExitCode> {
    let data = load_data(&cmd.data_args)?;
    let report = bitrock::bench::parity_on(
        &data,
        &super::args::parse_laws(&cmd.laws)?,
        cmd.candidates,
        cmd.epsilon,
        cmd.seed,
    )?;
    let mut out = super::print::stdout();
    if cmd.json {
        serde_json::to_writer_pretty(&mut out, &report)?;
        writeln!(out)?;
    } else {
        writeln!(out, "adapter: {}", report.adapter)?;
        writeln!(
            out,
            "data: {} points; tolerance on the relative difference of ρ: {:e}",
            data.calibration.len(),
            report.tolerance
        )?;
        writeln!(
            out,
            "law  candidates  max rel.diff  median rel.diff     epsilon  decisions differ (near ε)"
        )?;
        for l in &report.laws {
            writeln!(
                out,
                "{:<3}  {:>10}  {:>12.3e}  {:>15.3e}  {:>10.5}  {:>8} ({})",
                l.law,
                l.candidates,
                l.max_rel_diff,
                l.median_rel_diff,
                l.epsilon,
                l.decisions_differ,
                l.decisions_differ_near_threshold
            )?;
        }
        let p = &report.philox;
        writeln!(
            out,
            "Philox: {} of {} words differ; candidates: {} of {} differ",
            p.words_differ, p.words_compared, p.candidates_differ, p.candidates_compared
        )?;
        for d in &p.first_differences {
            writeln!(out, "  {d}")?;
        }
        print_simulators(&mut out, &report)?;
        for l in report.laws.iter().filter(|l| l.ill_conditioned_in_f32) {
            writeln!(
                out,
                "law {}: ill-conditioned in f32: its ρ computed in f32 on the CPU differs from f64 by up to {:.3e} (the GPU by {:.3e}); the law loses the digits, not the GPU: score it with --backend cpu, or rewrite it to avoid cancellation",
                l.law,
                l.f32_rel_diff.unwrap_or(f64::NAN),
                l.max_rel_diff
            )?;
        }
        writeln!(
            out,
            "{}",
            if report.pass {
                "PASS: this GPU agrees with the CPU reference"
            } else if report.gpu_agrees {
                "FAIL: a law is ill-conditioned in f32 (above); this GPU agrees with the CPU on the others and computes f32 as the CPU does"
            } else {
                "FAIL: do not trust this GPU's results"
            }
        )?;
    }
    Ok(if report.pass {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(super::exit::DIFFERENCE)
    })
}

/// The simulators' sections of the table: each figure against its rule.
fn print_simulators(out: &mut impl Write, report: &bitrock::bench::ParityReport) -> std::io::Result<()> {
    use bitrock::bench::simulators as sim;
    let s = &report.strings;
    writeln!(
        out,
        "torsional strings (m1-m4 at the paper's estimates, 20-200 rpm, 1-DOF string): {}; samples or divergence differ: {}; stick-slip verdicts differ: {} ({} allowed); largest differences: stuck share {:.4} ({} allowed), speed extremes {:.2e} of the top speed ({} allowed) — {}",
        s.strings,
        s.samples_or_divergence_differ,
        s.verdicts_differ,
        (sim::STRINGS_VERDICTS_MAY_DIFFER * s.strings as f64).floor(),
        s.max_stuck_share_diff,
        sim::STRINGS_STUCK_SHARE,
        s.max_speed_diff,
        sim::STRINGS_SPEED,
        if s.pass { "ok" } else { "differs" }
    )?;
    for d in &s.first_differences {
        writeln!(out, "  {d}")?;
    }
    writeln!(
        out,
        "coupled bit (public bit, 20 s settled + 40 s at 1e-4 s; cpu / gpu; differences allowed: rate of penetration {} %, {} % bouncing; stuck share {}; off bottom {}; mean WOB and torque {} %)",
        100.0 * sim::COUPLED_RATE,
        100.0 * sim::COUPLED_RATE_BOUNCING,
        sim::COUPLED_STUCK_SHARE,
        sim::COUPLED_OFF_BOTTOM_SHARE,
        100.0 * sim::COUPLED_MEANS
    )?;
    for c in &report.coupled.cells {
        let regime = if c.regime.0 == c.regime.1 {
            c.regime.0.name().to_string()
        } else {
            format!("{} / {}", c.regime.0.name(), c.regime.1.name())
        };
        writeln!(
            out,
            "  {:>5} rpm {:>8}  {:<12} ROP {:.2} / {:.2} m/h  stuck {:.3} / {:.3}  off bottom {:.3} / {:.3}  WOB {:.1} / {:.1} kN  torque {:.2} / {:.2} kN·m  {}",
            c.omega_rpm,
            c.drive,
            regime,
            c.rop_m_h.0,
            c.rop_m_h.1,
            c.stuck_share.0,
            c.stuck_share.1,
            c.off_bottom_share.0,
            c.off_bottom_share.1,
            c.wob_mean_kn.0,
            c.wob_mean_kn.1,
            c.torque_mean_knm.0,
            c.torque_mean_knm.1,
            if c.pass { "ok" } else { "differs" }
        )?;
    }
    Ok(())
}
