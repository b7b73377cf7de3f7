//! `bitrock fe`: natural frequencies, modal damping and critical bit damping of the
//! finite-element drill string.

use super::args::{FeArgs, LumpedArgs};
use bitrock::stability::fe::{SOLVES_PER_CRITICAL, SOLVES_TO_MATCH_BETA};
use clap::Args;
use serde_json::json;
use std::cell::RefCell;
use std::io::Write;
use std::process::ExitCode;

#[derive(Debug, Args)]
pub struct FeCmd {
    #[command(flatten)]
    pub fe: FeArgs,
    #[command(flatten)]
    pub lumped: LumpedArgs,
    /// Find β (keeping α) so that the string's critical bit damping equals the 1-DOF model's:
    /// the appendix's damping adjustment.
    #[arg(long)]
    pub match_1dof: bool,
    /// Print JSON instead of a table.
    #[arg(long)]
    pub json: bool,
}

/// Work estimated above this many seconds is announced before it starts.
const NOTE_ABOVE_S: f64 = 10.0;

pub fn run(cmd: &FeCmd) -> anyhow::Result<ExitCode> {
    let mut string = cmd.fe.settings().drill_string()?;
    let lumped = cmd.lumped.validated()?;
    let mut matched_beta = None;
    let solves = if cmd.match_1dof {
        SOLVES_TO_MATCH_BETA
    } else {
        SOLVES_PER_CRITICAL
    };
    let seconds = string.estimate_seconds(solves);
    if seconds > NOTE_ABOVE_S {
        super::print::note(format_args!(
            "note: about {solves:.0} eigenvalue solves of a {}-DOF string: about {} on this machine",
            string.dofs(),
            bitrock::limits::human_seconds(seconds)
        ));
    }
    let progress = RefCell::new((0u64, super::progress::WorkProgress::new("eigenvalue solves")));
    let tick = || {
        let (done, bar) = &mut *progress.borrow_mut();
        *done += 1;
        bar.update(*done, solves as u64);
    };
    if cmd.match_1dof {
        let (beta, _) = string.match_lumped_beta_with(&lumped, &tick)?;
        string.beta = beta;
        matched_beta = Some(beta);
    }
    let modes = string.modes()?;
    let critical = string.critical_bit_damping_with(&tick)?;
    drop(progress);
    let mut out = super::print::stdout();
    if cmd.json {
        let v = json!({
            "dofs": string.dofs(),
            "alpha_per_s": string.alpha,
            "beta_s": string.beta,
            "matched_beta_s": matched_beta,
            "frequencies_rad_s": modes.frequencies_rad_s,
            "damping_ratios": modes.damping_ratios,
            "critical_bit_damping_nms": critical.critical_bit_damping_nms,
            "critical_bit_damping_1dof_nms": lumped.critical_bit_damping_nms(),
            "sign_changes": critical.sign_changes,
            "bracket_nms": [critical.bracket_nms.0, critical.bracket_nms.1],
        });
        super::print::json(&mut out, v)?;
    } else {
        writeln!(
            out,
            "finite-element string: {} + {} elements ({} DOF), α = {} 1/s, β = {} s{}",
            string.dp_elements,
            string.bha_elements,
            string.dofs(),
            string.alpha,
            string.beta,
            if matched_beta.is_some() {
                " (β matched to the 1-DOF model)"
            } else {
                ""
            }
        )?;
        writeln!(out, "mode  frequency_rad_s  damping_ratio")?;
        for (i, (w, xi)) in modes.frequencies_rad_s.iter().zip(&modes.damping_ratios).enumerate() {
            writeln!(out, "{:>4}  {:>15.4}  {:>13.4}", i + 1, w, xi)?;
        }
        writeln!(
            out,
            "critical bit damping c_b* = {:.3} N·m·s/rad (single crossing: {} sign change over [{:.1}, 0]); 1-DOF: {:.3}",
            critical.critical_bit_damping_nms,
            critical.sign_changes,
            2.0 * critical.bracket_nms.0,
            lumped.critical_bit_damping_nms()
        )?;
    }
    Ok(ExitCode::SUCCESS)
}
