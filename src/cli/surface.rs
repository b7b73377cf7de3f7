//! `bitrock surface`: the law at the bit inferred from what the rig streams (top-drive speed
//! and surface torque) through simulated strings; what the surface implies at the bit.

use super::args::{finite_number, parse_laws, set_threads};
use super::print;
use bitrock::Law;
use bitrock::data::surface::{SurfaceOptions, SurfaceRecord};
use bitrock::eval::Backend;
use bitrock::run::Scoring;
use bitrock::run::surface::dir::{self, Sampled, SurfaceDir};
use bitrock::run::surface::{
    self, AtTheBit, StringParam, StringPosterior, SurfaceResult, SurfaceSettings, ValueOrBounds,
};
use bitrock::simulate::surface::Integration;
use bitrock::units::{ForceUnit, SpeedUnit, TorqueUnit};
use clap::Args;
use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Debug, Args)]
pub struct SurfaceCmd {
    /// Surface record (CSV with a header): a time column, the top-drive speed, the surface
    /// torque and, where recorded, the weight on bit, on a regular clock.
    #[arg(required_unless_present = "resume")]
    pub data: Option<PathBuf>,
    /// Time column (s; ms where its name ends in _ms) [default: the one whose name holds "time"].
    #[arg(long = "time-col", value_name = "NAME")]
    pub time_column: Option<String>,
    /// Top-drive speed column [default: the one whose name holds "top_drive" or "rotary"].
    #[arg(long = "top-drive-col", value_name = "NAME")]
    pub top_drive_column: Option<String>,
    /// Surface torque column [default: the surface channel whose name holds "torque"].
    #[arg(long = "surface-torque-col", value_name = "NAME")]
    pub surface_torque_column: Option<String>,
    /// Weight-on-bit column [default: the one whose name holds "wob", if any].
    #[arg(long = "wob-col", value_name = "NAME")]
    pub wob_column: Option<String>,
    /// Unit of the top-drive speed [default: from the column's suffix].
    #[arg(long, value_enum)]
    pub top_drive_unit: Option<SpeedUnit>,
    /// Unit of the surface torque (and of torque bounds in --prior) [default: from the column's suffix].
    #[arg(long, value_enum)]
    pub torque_unit: Option<TorqueUnit>,
    /// Unit of the weight on bit [default: from the column's suffix].
    #[arg(long, value_enum)]
    pub wob_unit: Option<ForceUnit>,
    /// An MWD tool's downhole minimum bit speed column, compared with each string's [default:
    /// the downhole speed whose name says "min", if any].
    #[arg(long = "downhole-min-col", value_name = "NAME")]
    pub downhole_min_column: Option<String>,
    /// The MWD tool's downhole maximum bit speed column [default: the downhole speed whose
    /// name says "max", if any].
    #[arg(long = "downhole-max-col", value_name = "NAME")]
    pub downhole_max_column: Option<String>,
    /// Unit of the downhole minimum and maximum [default: from the column's suffix].
    #[arg(long, value_enum)]
    pub downhole_unit: Option<SpeedUnit>,
    /// The window the MWD tool takes its minimum and maximum over, s [default: the record's
    /// clock period].
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, value_name = "SECONDS")]
    pub downhole_window_s: Option<f64>,
    #[arg(long, value_name = "LAWS", help = concat!(
        "Laws to infer, comma-separated: the built-in laws (",
        bitrock::built_in_law_list!(),
        ") and the laws of --law-file by their names [default: every built-in law and every --law-file's law]"
    ))]
    pub laws: Option<String>,
    /// A prior file (TOML) with bounds per law and law weights, torques in the record's unit.
    #[arg(long, value_name = "FILE")]
    pub prior: Option<PathBuf>,
    /// Width of the prior boxes: k of each parameter's scale from its physical bound.
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, default_value_t = surface::DEFAULT_PRIOR_SCALE, value_name = "K")]
    pub prior_scale: f64,
    /// Equivalent moment of inertia I_eq of the 1-DOF string, kg·m² [default: the paper's 383.33].
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, value_name = "KG_M2")]
    pub inertia_kg_m2: Option<f64>,
    /// The string's natural frequency omega_n, rad/s: a value, or LO:HI to infer it with the
    /// law within those bounds [default: the paper's 0.85].
    #[arg(long, allow_hyphen_values = true, value_name = "RAD_S|LO:HI")]
    pub omega_n_rad_s: Option<ValueOrBounds>,
    /// The string's damping ratio xi: a value, or LO:HI to infer it with the law within those
    /// bounds [default: the paper's 0.25].
    #[arg(long, allow_hyphen_values = true, value_name = "XI|LO:HI")]
    pub damping_ratio: Option<ValueOrBounds>,
    /// Reference weight on bit W_ref of the laws' parameters, kN: the recorded weight scales the
    /// law's torque by r = W/W_ref [default: r = 1 throughout].
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, value_name = "KN")]
    pub w_ref_kn: Option<f64>,
    /// Standard deviation of the surface torque's noise, kN·m [default: estimated from the record].
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, value_name = "KNM")]
    pub noise_sd_knm: Option<f64>,
    /// Particles per population.
    #[arg(long, default_value_t = 2000, value_name = "N")]
    pub particles: usize,
    /// Most populations, the first included [default: 8; with --resume, the run's own].
    #[arg(long, value_name = "COUNT")]
    pub max_populations: Option<usize>,
    /// Wall-time budget of the sampler, s (the population in progress is dropped).
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, value_name = "SECONDS")]
    pub max_seconds: Option<f64>,
    /// Prior simulations that scale the distance, train --semi-automatic's regressions and
    /// stand for a law lost from the populations in the check.
    #[arg(long, default_value_t = surface::DEFAULT_PILOT, value_name = "N")]
    pub pilot: usize,
    /// Records re-simulated per law to check the model choice [default: 10; with --resume,
    /// the run's own].
    #[arg(long, value_name = "K")]
    pub check_replicates: Option<usize>,
    /// Posterior draws simulated for the bit's predicted speed.
    #[arg(long, default_value_t = surface::DEFAULT_PREDICTIVE_DRAWS, value_name = "N")]
    pub predictive_draws: usize,
    /// Skip the simulated escape advice.
    #[arg(long)]
    pub no_advice: bool,
    /// Largest integration step of the simulated strings, s.
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, default_value_t = Integration::default().dt_s, value_name = "SECONDS")]
    pub dt_s: f64,
    /// Time each simulated string settles before the record's first sample, s.
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, default_value_t = Integration::default().settle_s, value_name = "SECONDS")]
    pub settle_s: f64,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Where the strings are simulated: gpu, cpu, or auto (a hardware GPU where one exists,
    /// else the CPU, saying so: a software driver runs more slowly than the CPU's own lanes)
    /// [default: auto; with --resume, the run's own].
    #[arg(long, value_enum)]
    pub backend: Option<Backend>,
    /// Semi-automatic ABC: compare what linear regressions on the pilot strings nearest the
    /// record predict from the summaries (each law's parameters, the string's where inferred,
    /// each law's probability), each with its adjusted R², instead of the summaries themselves.
    #[arg(long)]
    pub semi_automatic: bool,
    /// Worker threads [default: all cores].
    #[arg(long, value_name = "N")]
    pub threads: Option<usize>,
    /// The bit's predicted speed per sample (time_s, bit_speed_rpm_p05, _p50, _p95) as CSV.
    #[arg(long, value_name = "FILE")]
    pub bit_out: Option<PathBuf>,
    /// The final population's particles as CSV (each law's share of the weight its
    /// probability; the string's natural frequency and damping ratio after the laws'
    /// parameters where inferred): `bitrock stability --posterior FILE` maps the laws'
    /// parameters on the string its flags give.
    #[arg(long, value_name = "FILE")]
    pub posterior_out: Option<PathBuf>,
    /// A surface directory to write: surface.json (the whole result), posterior.csv, bit.csv,
    /// and what continues the run (record.csv, surface-job.json, and populations.bin, stored
    /// as each population completes).
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Replace a surface run in --out, and --bit-out and --posterior-out files even when
    /// bitrock did not write them.
    #[arg(long)]
    pub force: bool,
    /// Continue the surface run in DIR (killed or finished) after its last stored population:
    /// more --max-populations, a new --max-seconds, --backend or --check-replicates (kept for
    /// the next continuation). On the same backend the populations are exactly those an
    /// uninterrupted run gives; the check and the bit are computed again and DIR written anew.
    #[arg(long, value_name = "DIR", conflicts_with_all = [
        "data", "out", "time_column", "top_drive_column", "surface_torque_column", "wob_column",
        "top_drive_unit", "torque_unit", "wob_unit", "downhole_min_column", "downhole_max_column",
        "downhole_unit", "downhole_window_s", "laws", "prior", "inertia_kg_m2", "omega_n_rad_s",
        "damping_ratio", "w_ref_kn", "noise_sd_knm", "no_advice", "semi_automatic", "prior_scale",
        "particles", "pilot", "predictive_draws", "dt_s", "settle_s", "seed",
    ])]
    pub resume: Option<PathBuf>,
    /// Print JSON instead of tables.
    #[arg(long)]
    pub json: bool,
}

impl SurfaceCmd {
    fn laws(&self) -> anyhow::Result<Vec<Law>> {
        match &self.laws {
            Some(list) => parse_laws(list),
            None => Ok(Law::ALL
                .into_iter()
                .chain(bitrock::laws::file::registered_laws())
                .collect()),
        }
    }

    /// The run's settings as the flags give them.
    fn given(&self) -> surface::Settings {
        surface::Settings {
            prior_file: self.prior.clone(),
            prior_scale: self.prior_scale,
            inertia_kg_m2: self.inertia_kg_m2,
            omega_n_rad_s: self.omega_n_rad_s,
            damping_ratio: self.damping_ratio,
            w_ref_kn: self.w_ref_kn,
            noise_sd_knm: self.noise_sd_knm,
            particles: self.particles,
            max_populations: self.max_populations.unwrap_or(surface::DEFAULT_MAX_POPULATIONS),
            max_seconds: self.max_seconds,
            pilot: self.pilot,
            check_replicates: self.check_replicates.unwrap_or(surface::DEFAULT_CHECK_REPLICATES),
            predictive_draws: self.predictive_draws,
            advice: !self.no_advice,
            dt_s: self.dt_s,
            settle_s: self.settle_s,
            seed: self.seed,
            backend: self.backend.unwrap_or_default(),
            semi_automatic: self.semi_automatic,
        }
    }

    fn columns(&self) -> SurfaceOptions {
        SurfaceOptions {
            time_column: self.time_column.clone(),
            top_drive_column: self.top_drive_column.clone(),
            surface_torque_column: self.surface_torque_column.clone(),
            wob_column: self.wob_column.clone(),
            top_drive_unit: self.top_drive_unit,
            torque_unit: self.torque_unit,
            wob_unit: self.wob_unit,
            downhole_min_column: self.downhole_min_column.clone(),
            downhole_max_column: self.downhole_max_column.clone(),
            downhole_unit: self.downhole_unit,
            downhole_window_s: self.downhole_window_s,
            ignore_downhole: false,
        }
    }

    /// Refuses, before any work, files and a directory that cannot be written.
    fn check_outputs(&self) -> anyhow::Result<()> {
        for (path, field) in [(&self.bit_out, "bit_out"), (&self.posterior_out, "posterior_out")] {
            if let Some(path) = path {
                bitrock::run::dir::check_output_file(path, field, self.force)?;
            }
        }
        Ok(())
    }
}

pub fn run(cmd: &SurfaceCmd) -> anyhow::Result<ExitCode> {
    set_threads(cmd.threads)?;
    if let Some(dir) = &cmd.resume {
        return resume(cmd, dir);
    }
    let data = cmd.data.as_ref().expect("clap asks for the record without --resume");
    // The prior file read once, into the job a surface directory keeps.
    let job = dir::Job::new(cmd.laws()?, cmd.given(), cmd.columns(), data)?;
    let settings = job.config()?;
    cmd.check_outputs()?;
    if let Some(out) = &cmd.out {
        dir::check_out(out, cmd.force)?;
    }
    let record = SurfaceRecord::read(data, &job.columns)?;
    print::note(format_args!("{}: {}", data.display(), record.roles_text()));
    print::note(format_args!(
        "simulating the string for every candidate: {} particles, up to {} populations",
        settings.smc.schedule.particles, settings.smc.schedule.max_populations
    ));
    let mut note = |line| print::note(format_args!("note: {line}"));
    match &cmd.out {
        Some(out) => {
            // The record as the directory keeps it, read from its bytes.
            let (run, record) = SurfaceDir::start(out, cmd.force, job)?;
            let result = run.run(&record, &settings, Sampled::default(), false, Scoring::Here, &mut note)?;
            run.finish(&record, &result)?;
            report(cmd, &record, &settings, &result)
        }
        None => {
            let result = surface::infer(&record, &settings, cmd.seed, &mut note)?;
            report(cmd, &record, &settings, &result)
        }
    }
}

/// Continues the surface run in `path` with the stopping rules and backend the flags give.
fn resume(cmd: &SurfaceCmd, path: &std::path::Path) -> anyhow::Result<ExitCode> {
    cmd.check_outputs()?;
    let (mut run, record, sampled) = SurfaceDir::open(path)?;
    let more = dir::Continuation {
        max_populations: cmd.max_populations,
        max_seconds: cmd.max_seconds,
        backend: cmd.backend,
        check_replicates: cmd.check_replicates,
    };
    let stored = sampled.populations.len();
    let settings = run.continued(&more, stored)?;
    let from = match stored {
        0 => "from its first population (none stored)".to_string(),
        n => format!("after population {} ({n} stored)", n - 1),
    };
    print::note(format_args!(
        "continuing {} {from}, up to {} populations",
        path.display(),
        settings.smc.schedule.max_populations
    ));
    let result = run.run(&record, &settings, sampled, false, Scoring::Here, &mut |line| {
        print::note(format_args!("note: {line}"))
    })?;
    run.finish(&record, &result)?;
    report(cmd, &record, &settings, &result)
}

/// Warnings, the extra files the flags ask for, and the result on stdout.
fn report(
    cmd: &SurfaceCmd,
    record: &SurfaceRecord,
    settings: &SurfaceSettings,
    result: &SurfaceResult,
) -> anyhow::Result<ExitCode> {
    for warning in &result.warnings {
        print::note(format_args!("warning: {}", super::fields::as_flags(warning)));
    }
    if let Some(path) = &cmd.bit_out {
        bitrock::run::dir::write_whole(path, "bit_out", cmd.force, |file| result.bit_csv(record, file))?;
    }
    if let Some(path) = &cmd.posterior_out {
        let csv = result
            .posterior_csv(&settings.laws, record.torque_unit)
            .expect("a finished run keeps its populations");
        bitrock::run::dir::write_whole(path, "posterior_out", cmd.force, |file| file.write_all(&csv))?;
    }
    let mut out = print::stdout();
    if cmd.json {
        print::json(&mut out, serde_json::to_value(result)?)?;
    } else {
        tables(&mut out, record, result)?;
    }
    Ok(ExitCode::SUCCESS)
}

/// The result as people read it: what the record shows, the laws with the check, the
/// posteriors and the bit.
fn tables(out: &mut impl Write, record: &SurfaceRecord, r: &SurfaceResult) -> std::io::Result<()> {
    let unit = record.torque_unit;
    let per_unit = unit.newton_metres();
    let how = match r.noise.how {
        "bounded" => {
            "bounded above: the clock is too coarse for the cycle to tell noise from signal; give --noise-sd-knm where the tool's noise is known"
        }
        "estimated" => "estimated from the record",
        "wind_up" => {
            "read on the record's wind-ups: the clock is too coarse for the cycle to tell noise from signal elsewhere; give --noise-sd-knm where the tool's noise is known"
        }
        _ => "given",
    };
    writeln!(
        out,
        "surface torque noise: {:.4} {} ({how})",
        r.noise.sd_nm / per_unit,
        unit.label()
    )?;
    match r.cycle.period_s {
        Some(p) => writeln!(
            out,
            "stick-slip cycle at the surface: period {p:.2} s, {:.1} cycles in the record",
            r.cycle.cycles
        )?,
        None => writeln!(out, "no stick-slip cycle at the surface")?,
    }
    writeln!(
        out,
        "mean surface torque {:.3} {} at {:.1} rpm: T(Ω) at the record's speed",
        r.mean_torque_nm / per_unit,
        unit.label(),
        r.mean_top_drive_rpm
    )?;
    writeln!(
        out,
        "ABC-SMC on simulated strings: {} populations, final ε {} (the noise's own distance {:.4}), {} strings simulated in {:.1} s on the {} ({})",
        r.populations,
        r.final_epsilon.map_or("∞".into(), |e| format!("{e:.4}")),
        r.noise_floor,
        r.simulations,
        r.seconds,
        r.backend,
        r.stop
    )?;
    let c = &r.cost;
    writeln!(
        out,
        "strings per particle: {:.1}; rejection ABC to the same ε: {}",
        c.strings_per_particle,
        match c.rejection_strings_per_particle {
            Some(n) => format!("{n:.0} ({} of {} pilot strings below it)", c.pilot_below, c.pilot),
            None => format!("more than {} (no pilot string below it)", c.pilot),
        }
    )?;
    if let Some(p) = &r.projection {
        let fitted: Vec<String> = p
            .features
            .iter()
            .map(|f| format!("{} {:.2}", f.name, f.adjusted_r_squared))
            .collect();
        writeln!(
            out,
            "semi-automatic summaries, adjusted R² of each regression on the {} pilot strings nearest the record (a law's parameters on its own strings): {}",
            p.training,
            fitted.join(", ")
        )?;
    }
    writeln!(out)?;
    check_table(out, r)?;
    writeln!(out)?;
    posterior_lines(out, unit, r)?;
    at_the_bit_lines(out, &r.at_the_bit)
}

/// Each law's probability with its re-simulated records recognised, and the verdict.
pub(super) fn check_table(out: &mut impl Write, r: &SurfaceResult) -> std::io::Result<()> {
    writeln!(out, "law   P(law)   re-simulated records recognised as it")?;
    for law in &r.laws {
        let row = r.check.rows.iter().find(|c| c.law == law.law);
        let recognised = row.map_or("no particle".to_string(), |c| {
            format!("{:.0} % of {}", 100.0 * c.recognised, c.replicates)
        });
        writeln!(
            out,
            "{:<5} {:>6.3}   {recognised}",
            law.law.to_string(),
            law.probability
        )?;
    }
    writeln!(out, "verdict: {}", super::fields::as_flags(&r.check.verdict))
}

/// Each law's posterior medians and 90 % intervals, in the record's torque unit.
fn posterior_lines(out: &mut impl Write, unit: TorqueUnit, r: &SurfaceResult) -> std::io::Result<()> {
    let per_unit = unit.newton_metres();
    for law in r.laws.iter().filter(|l| l.particles > 0) {
        let params: Vec<String> = law
            .params
            .iter()
            .zip(law.law.params())
            .map(|(p, spec)| {
                let scale = per_unit.powi(spec.torque_power);
                format!(
                    "{} {:.4} [{:.4}, {:.4}] {}{}",
                    p.name,
                    p.median / scale,
                    p.q05 / scale,
                    p.q95 / scale,
                    spec.unit(unit.label()),
                    match (p.identified, &law.prior_curve) {
                        (true, _) => "",
                        (false, None) => " (not identified: the prior box sets it)",
                        (false, Some(_)) => " (not identified: the prior, its box cut to its curves, sets it)",
                    }
                )
            })
            .collect();
        writeln!(out, "{} (P = {:.3}): {}", law.law, law.probability, params.join(", "))?;
    }
    for law in &r.laws {
        if let Some(c) = &law.prior_curve {
            writeln!(
                out,
                "{}'s prior: its box cut to the curves within {} times the record's largest surface torque ({:.4} {}) from rest to {:.2} rad/s ({:.1} % of the box)",
                law.law,
                c.within,
                c.limit_nm / per_unit,
                unit.label(),
                c.speed_high_rad_s,
                100.0 * c.share
            )?;
        }
    }
    string_line(out, &r.string)
}

/// The string the candidates were simulated with: inferred (its posterior) or given.
fn string_line(out: &mut impl Write, s: &StringPosterior) -> std::io::Result<()> {
    let part = |p: &StringParam, unit: &str| {
        let (given, p) = (p.given, &p.posterior);
        if given {
            format!("{} {:.4}{unit} (given)", p.name, p.median)
        } else {
            format!(
                "{} {:.4} [{:.4}, {:.4}]{unit}{}",
                p.name,
                p.median,
                p.q05,
                p.q95,
                if p.identified {
                    ""
                } else {
                    " (not identified: its bounds set it)"
                }
            )
        }
    };
    let k = s.stiffness_knm_per_rad;
    writeln!(
        out,
        "string{}: I_eq {} kg·m² (given), {}, {}; stiffness {:.4} [{:.4}, {:.4}] kN·m/rad",
        if s.inferred {
            ", inferred with the laws"
        } else {
            " (given)"
        },
        s.inertia_kg_m2,
        part(&s.omega_n_rad_s, " rad/s"),
        part(&s.damping_ratio, ""),
        k[1],
        k[0],
        k[2]
    )
}

/// What the surface implies at the bit: its stuck share, severity and the advice.
fn at_the_bit_lines(out: &mut impl Write, b: &AtTheBit) -> std::io::Result<()> {
    writeln!(out)?;
    writeln!(
        out,
        "at the bit ({} posterior draws): stuck {:.2} [{:.2}, {:.2}] of the time, severity {:.2} [{:.2}, {:.2}], P(stick-slip) {:.2}",
        b.draws,
        b.stuck_share[1],
        b.stuck_share[0],
        b.stuck_share[2],
        b.severity[1],
        b.severity[0],
        b.severity[2],
        b.stick_slip_probability
    )?;
    if b.stuck_share_by_law.len() > 1 {
        let by_law: Vec<String> = b
            .stuck_share_by_law
            .iter()
            .map(|(law, n, q)| format!("{law} {:.2} [{:.2}, {:.2}] ({n} draws)", q[1], q[0], q[2]))
            .collect();
        writeln!(out, "stuck share by law: {}", by_law.join(", "))?;
    }
    if b.diverged > 0 {
        writeln!(
            out,
            "{} draws' strings left physical bounds and are not counted",
            b.diverged
        )?;
    }
    if let Some(advice) = &b.advice {
        writeln!(out, "advice: {advice}")?;
    }
    Ok(())
}
