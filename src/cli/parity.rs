//! `bitrock parity`: the same candidates scored on the CPU and the GPU, and their agreement.

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
