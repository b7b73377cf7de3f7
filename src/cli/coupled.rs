//! `bitrock coupled`: the coupled axial-torsional bit (RGD) on the 1-DOF string, one string as
//! a record with its summary, or `--map` a regime map over top-drive speed and weight on bit
//! (or feed), one simulated string per cell.

use super::args::{LumpedArgs, finite_number};
use bitrock::eval::Backend;
use bitrock::eval::strings::Ran;
use bitrock::simulate::coupled::{self, Assembly, Axial, Bit, CoupledJob, CoupledSummary, Sample, Schedule};
use bitrock::stability::map;
use bitrock::data::drilling::{DrillingOptions, DrillingRecord};
use bitrock::fit::coupled::{CoupledCalibration, bit_of, calibrate};
use bitrock::units::{ForceUnit, RAD_S_PER_RPM, RateUnit, SpeedUnit, TorqueUnit};
use clap::Args;
use serde_json::json;
use std::io::Write;
use std::process::ExitCode;

/// m/h in m/s.
const M_S_PER_M_H: f64 = 1.0 / 3600.0;

/// Posterior draws a calibration's intervals are read from.
const CALIBRATION_DRAWS: usize = 4_000;

#[derive(Debug, Args)]
pub struct CoupledCmd {
    /// Top-drive speed Omega_0, rpm.
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, default_value_t = 60.0, value_name = "RPM")]
    pub omega_rpm: f64,
    /// A constant weight on the bit assembly (the hook held at a set weight), kN.
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, value_name = "KN", conflicts_with = "feed_m_h")]
    pub wob_kn: Option<f64>,
    /// Or the top fed down at a constant rate on the string's axial spring, m/h [default: 30].
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, value_name = "M_H")]
    pub feed_m_h: Option<f64>,
    /// Bit radius a, m.
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, default_value_t = Bit::default().radius_m, value_name = "M")]
    pub radius_m: f64,
    /// Intrinsic specific energy of the rock epsilon, MPa.
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, default_value_t = Bit::default().intrinsic_energy_mpa, value_name = "MPA")]
    pub intrinsic_energy_mpa: f64,
    /// Ratio zeta of the cutting force's axial to its tangential component.
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, default_value_t = Bit::default().zeta)]
    pub zeta: f64,
    /// Contact stress sigma on the wear flats, MPa.
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, default_value_t = Bit::default().contact_stress_mpa, value_name = "MPA")]
    pub contact_stress_mpa: f64,
    /// Total wear-flat length l of the blades, mm.
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, default_value_t = Bit::default().wear_flat_mm, value_name = "MM")]
    pub wear_flat_mm: f64,
    /// Friction coefficient mu of the wear flats on the rock.
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, default_value_t = Bit::default().friction)]
    pub friction: f64,
    /// Bit geometry factor gamma.
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, default_value_t = Bit::default().gamma)]
    pub gamma: f64,
    /// Blades N.
    #[arg(long, default_value_t = Bit::default().blades)]
    pub blades: u32,
    #[command(flatten)]
    pub lumped: LumpedArgs,
    /// Mass of the bit assembly M, kg.
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, default_value_t = Assembly::default().mass_kg, value_name = "KG")]
    pub mass_kg: f64,
    /// Axial stiffness of the string K_a (felt under a feed), kN/m.
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, default_value_t = Assembly::default().axial_stiffness_n_per_m / 1e3, value_name = "KN_M")]
    pub axial_stiffness_kn_m: f64,
    /// Axial damping on the bit assembly C_a, kN·s/m.
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, default_value_t = Assembly::default().axial_damping_ns_per_m / 1e3, value_name = "KNS_M")]
    pub axial_damping_kns_m: f64,
    /// Recorded duration, s.
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, default_value_t = 60.0, value_name = "SECONDS")]
    pub duration_s: f64,
    /// Simulated time discarded before recording starts (lets the motion settle), s.
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, default_value_t = 30.0, value_name = "SECONDS")]
    pub settle_s: f64,
    /// Output sample rate, Hz.
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, default_value_t = 50.0, value_name = "HZ")]
    pub sample_hz: f64,
    /// Integration step, s (the stuck share converges to about 1 % at 1e-4 s).
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, default_value_t = 1e-4, value_name = "SECONDS")]
    pub dt_s: f64,
    /// Bit-speed kick from steady drilling at t = 0, rpm.
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, default_value_t = 1.0, value_name = "RPM")]
    pub kick_rpm: f64,
    /// A regime map instead of one string: one string per cell of --map-rpm × --map-wob-kn (or
    /// --map-feed-m-h with --feed-m-h).
    #[arg(long)]
    pub map: bool,
    /// The map's top-drive speeds, rpm, as MIN:MAX:COUNT.
    #[arg(long, default_value = "20:200:10", value_name = "MIN:MAX:COUNT", requires = "map")]
    pub map_rpm: String,
    /// The map's weights on bit, kN, as MIN:MAX:COUNT.
    #[arg(long, default_value = "80:280:9", value_name = "MIN:MAX:COUNT", requires = "map")]
    pub map_wob_kn: String,
    /// The map's feeds, m/h, as MIN:MAX:COUNT (with --feed-m-h).
    #[arg(long, default_value = "10:60:6", value_name = "MIN:MAX:COUNT", requires = "map")]
    pub map_feed_m_h: String,
    /// Where the map's strings are integrated: gpu, cpu, or auto (the GPU when an adapter
    /// exists, else the CPU, saying so).
    #[arg(long, value_enum, default_value_t = Backend::Auto)]
    pub backend: Backend,
    /// Calibrate the bit on a drilling record (bit speed, torque on bit, weight on bit, rate of
    /// penetration; the bit's axial speed where present): ε, ζ, the wear flats' contact force
    /// and μ·γ, with 90 % intervals; with --map, the regimes' probabilities over the posterior.
    /// --radius-m, --contact-stress-mpa, --gamma and --blades stay as given.
    #[arg(long, value_name = "RECORD")]
    pub calibrate: Option<std::path::PathBuf>,
    #[command(flatten)]
    pub columns: DrillingArgs,
    /// Posterior draws each map cell is simulated for (with --calibrate --map).
    #[arg(long, default_value_t = 20, value_name = "S", requires = "calibrate")]
    pub samples: usize,
    /// Seed of the posterior draws.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// The record (one string: time, bit speed, torque, WOB, axial speed, rate of penetration)
    /// or the map (one row per cell) as CSV.
    #[arg(long, value_name = "FILE")]
    pub out: Option<std::path::PathBuf>,
    /// Overwrite --out if it exists.
    #[arg(long)]
    pub force: bool,
    /// Print JSON instead of a table.
    #[arg(long)]
    pub json: bool,
}

/// The columns of a drilling record and their units.
#[derive(Debug, Args)]
pub struct DrillingArgs {
    /// Bit speed column [default: the one whose name holds 'speed', not 'axial'].
    #[arg(long, value_name = "NAME", requires = "calibrate")]
    pub speed_col: Option<String>,
    /// Torque-on-bit column [default: the one whose name holds 'torque'].
    #[arg(long, value_name = "NAME", requires = "calibrate")]
    pub torque_col: Option<String>,
    /// Weight-on-bit column [default: the one whose name holds 'wob'].
    #[arg(long, value_name = "NAME", requires = "calibrate")]
    pub wob_col: Option<String>,
    /// Rate-of-penetration column [default: the one whose name holds 'rop' or 'penetration'].
    #[arg(long, value_name = "NAME", requires = "calibrate")]
    pub rop_col: Option<String>,
    /// The bit's axial speed column [default: the one whose name holds 'axial', if any].
    #[arg(long, value_name = "NAME", requires = "calibrate")]
    pub axial_speed_col: Option<String>,
    /// Unit of the bit speed [default: from its name's suffix].
    #[arg(long, value_enum, requires = "calibrate")]
    pub speed_unit: Option<SpeedUnit>,
    /// Unit of the torque on bit [default: from its name's suffix].
    #[arg(long, value_enum, requires = "calibrate")]
    pub torque_unit: Option<TorqueUnit>,
    /// Unit of the weight on bit [default: from its name's suffix].
    #[arg(long, value_enum, requires = "calibrate")]
    pub wob_unit: Option<ForceUnit>,
    /// Unit of the rate of penetration and axial speed [default: from their names' suffixes].
    #[arg(long, value_enum, requires = "calibrate")]
    pub rop_unit: Option<RateUnit>,
}

impl DrillingArgs {
    fn options(&self) -> DrillingOptions {
        DrillingOptions {
            speed_column: self.speed_col.clone(),
            torque_column: self.torque_col.clone(),
            wob_column: self.wob_col.clone(),
            rop_column: self.rop_col.clone(),
            axial_speed_column: self.axial_speed_col.clone(),
            speed_unit: self.speed_unit,
            torque_unit: self.torque_unit,
            wob_unit: self.wob_unit,
            rop_unit: self.rop_unit,
        }
    }
}

impl CoupledCmd {
    fn bit(&self) -> Bit {
        Bit {
            radius_m: self.radius_m,
            intrinsic_energy_mpa: self.intrinsic_energy_mpa,
            zeta: self.zeta,
            contact_stress_mpa: self.contact_stress_mpa,
            wear_flat_mm: self.wear_flat_mm,
            friction: self.friction,
            gamma: self.gamma,
            blades: self.blades,
        }
    }

    fn assembly(&self) -> anyhow::Result<Assembly> {
        let a = Assembly {
            torsion: self.lumped.lumped(),
            mass_kg: self.mass_kg,
            axial_stiffness_n_per_m: self.axial_stiffness_kn_m * 1e3,
            axial_damping_ns_per_m: self.axial_damping_kns_m * 1e3,
        };
        a.validate()?;
        Ok(a)
    }

    fn axial(&self, value: Option<f64>) -> Axial {
        match (self.wob_kn, self.feed_m_h) {
            (Some(wob), _) => Axial::Weight {
                wob_n: value.unwrap_or(wob) * 1e3,
            },
            (None, feed) => Axial::Feed {
                rate_m_s: value.or(feed).unwrap_or(30.0) * M_S_PER_M_H,
            },
        }
    }

    fn job(&self, omega_rpm: f64, axial: Option<f64>) -> anyhow::Result<CoupledJob> {
        self.job_with(self.bit(), omega_rpm, axial)
    }

    fn job_with(&self, bit: Bit, omega_rpm: f64, axial: Option<f64>) -> anyhow::Result<CoupledJob> {
        let job = CoupledJob {
            bit,
            omega_rad_s: omega_rpm * RAD_S_PER_RPM,
            axial: self.axial(axial),
            kick_rad_s: self.kick_rpm * RAD_S_PER_RPM,
        };
        job.validate()?;
        Ok(job)
    }
}

pub fn run(cmd: &CoupledCmd) -> anyhow::Result<ExitCode> {
    let assembly = cmd.assembly()?;
    let schedule = Schedule::new(cmd.dt_s, cmd.sample_hz, cmd.settle_s, cmd.duration_s)?;
    if let Some(path) = &cmd.out {
        bitrock::run::dir::check_output_file(path, "out", cmd.force)?;
    }
    let calibration = match &cmd.calibrate {
        Some(path) => {
            let record = DrillingRecord::read(path, &cmd.columns.options())?;
            cmd.bit().validate()?;
            let c = calibrate(&record, cmd.radius_m, CALIBRATION_DRAWS, cmd.seed)?;
            if let Some(w) = &c.warning {
                super::print::note(format_args!("warning: {w}"));
            }
            Some(c)
        }
        None => None,
    };
    if cmd.map {
        return run_map(cmd, &assembly, &schedule, calibration.as_ref());
    }
    if let Some(c) = &calibration {
        return print_calibration(cmd, c);
    }
    let job = cmd.job(cmd.omega_rpm, None)?;
    let mut samples = Vec::new();
    let summary = coupled::integrate_with(&assembly, &schedule, &job, &mut |s| {
        if cmd.out.is_some() {
            samples.push(*s)
        }
    });
    if let Some(path) = &cmd.out {
        bitrock::run::dir::write_whole(path, "out", cmd.force, |file| write_record(&samples, file))?;
    }
    let steady = job.steady(&assembly);
    let mut out = super::print::stdout();
    if cmd.json {
        let mut value = summary_json(&summary, cmd.sample_hz);
        value["steady"] = json!({
            "depth_of_cut_mm": 1e3 * f64::from(job.bit.blades) * steady.depth_per_blade_m,
            "rop_m_h": steady.rate_m_s * 3600.0,
            "wob_kn": steady.wob_n / 1e3,
            "torque_knm": steady.torque_nm / 1e3,
        });
        writeln!(out, "{}", serde_json::to_string_pretty(&value)?)?;
    } else {
        writeln!(
            out,
            "{} at {} rpm: rate of penetration {:.1} m/h (steady drilling {:.1}), stuck {:.1} % of the time, off bottom {:.1} %",
            summary.regime().name(),
            cmd.omega_rpm,
            summary.rate_m_s() * 3600.0,
            steady.rate_m_s * 3600.0,
            100.0 * summary.stuck_share(),
            100.0 * summary.off_bottom_share()
        )?;
        writeln!(
            out,
            "bit speed {:.0}-{:.0} rpm, WOB {:.0}-{:.0} kN (mean {:.0}), torque {:.2}-{:.2} kN·m (mean {:.2}){}",
            summary.speed_min_rad_s / RAD_S_PER_RPM,
            summary.speed_max_rad_s / RAD_S_PER_RPM,
            summary.wob_min_n / 1e3,
            summary.wob_max_n / 1e3,
            summary.wob_mean_n() / 1e3,
            summary.torque_min_nm / 1e3,
            summary.torque_max_nm / 1e3,
            summary.torque_mean_nm() / 1e3,
            summary
                .period_s(cmd.sample_hz)
                .map_or(String::new(), |p| format!(", stick-slip period {p:.2} s"))
        )?;
    }
    Ok(ExitCode::SUCCESS)
}

/// A summary as the JSON of the command and of each map cell.
fn summary_json(s: &CoupledSummary, sample_hz: f64) -> serde_json::Value {
    json!({
        "regime": s.regime(),
        "rop_m_h": s.rate_m_s() * 3600.0,
        "stuck_share": s.stuck_share(),
        "off_bottom_share": s.off_bottom_share(),
        "backward_share": f64::from(s.backward) / f64::from(s.samples.max(1)),
        "period_s": s.period_s(sample_hz),
        "bit_speed_rpm": {"min": s.speed_min_rad_s / RAD_S_PER_RPM, "max": s.speed_max_rad_s / RAD_S_PER_RPM, "mean": s.speed_mean_rad_s() / RAD_S_PER_RPM},
        "wob_kn": {"min": s.wob_min_n / 1e3, "max": s.wob_max_n / 1e3, "mean": s.wob_mean_n() / 1e3},
        "torque_knm": {"min": s.torque_min_nm / 1e3, "max": s.torque_max_nm / 1e3, "mean": s.torque_mean_nm() / 1e3},
        "samples": s.samples,
        "diverged": s.diverged,
    })
}

/// The record's columns, units in their names.
fn write_record(samples: &[Sample], out: &mut dyn Write) -> std::io::Result<()> {
    let mut w = csv::Writer::from_writer(out);
    w.write_record([
        "time_s",
        "bit_speed_rpm",
        "torque_on_bit_knm",
        "wob_kn",
        "axial_speed_m_h",
        "rop_m_h",
        "depth_of_cut_mm",
    ])?;
    for s in samples {
        w.write_record(
            [
                s.time_s,
                s.bit_speed_rad_s / RAD_S_PER_RPM,
                s.torque_nm / 1e3,
                s.wob_n / 1e3,
                s.axial_speed_m_s * 3600.0,
                s.cutting_rate_m_s * 3600.0,
                s.depth_per_blade_m * 1e3,
            ]
            .map(|v| format!("{v:.6}")),
        )?;
    }
    w.flush()
}

/// `--map`: one string per cell, the regimes as a table (speeds down, weights across) or JSON,
/// the cells to `--out`.
/// The map's speeds (rpm) and its second axis (values, name, unit): weights or feeds.
fn axes(cmd: &CoupledCmd) -> anyhow::Result<(Vec<f64>, Vec<f64>, &'static str, &'static str)> {
    let rpm = map::parse_axis(&cmd.map_rpm, "map_rpm")?;
    Ok(if cmd.wob_kn.is_none() {
        (rpm, map::parse_axis(&cmd.map_feed_m_h, "map_feed_m_h")?, "feed_m_h", "m/h")
    } else {
        (rpm, map::parse_axis(&cmd.map_wob_kn, "map_wob_kn")?, "wob_kn", "kN")
    })
}

/// Every job's summary on the command's backend, and where they ran.
fn integrate(
    cmd: &CoupledCmd,
    assembly: &Assembly,
    schedule: &Schedule,
    jobs: &[CoupledJob],
) -> anyhow::Result<(Vec<CoupledSummary>, String)> {
    let (summaries, ran) = bitrock::eval::coupled::integrate(assembly, schedule, jobs, cmd.backend, &mut |line| {
        super::print::note(format_args!("{line}"))
    })?;
    let ran = match ran {
        Ran::Gpu(name) => format!("GPU {name}"),
        Ran::Cpu => "CPU".to_string(),
    };
    Ok((summaries, ran))
}

fn run_map(
    cmd: &CoupledCmd,
    assembly: &Assembly,
    schedule: &Schedule,
    calibration: Option<&CoupledCalibration>,
) -> anyhow::Result<ExitCode> {
    if let Some(c) = calibration {
        return run_posterior_map(cmd, assembly, schedule, c);
    }
    let (rpm, axis, axis_name, axis_unit) = axes(cmd)?;
    let mut jobs = Vec::with_capacity(rpm.len() * axis.len());
    for &r in &rpm {
        for &a in &axis {
            jobs.push(cmd.job(r, Some(a))?);
        }
    }
    let (summaries, ran) = integrate(cmd, assembly, schedule, &jobs)?;
    if let Some(path) = &cmd.out {
        bitrock::run::dir::write_whole(path, "out", cmd.force, |file| {
            let mut w = csv::Writer::from_writer(file);
            w.write_record([
                "omega_rpm",
                axis_name,
                "regime",
                "stuck_share",
                "off_bottom_share",
                "rop_m_h",
                "period_s",
                "wob_mean_kn",
                "torque_mean_knm",
            ])?;
            for (k, s) in summaries.iter().enumerate() {
                let (r, a) = (rpm[k / axis.len()], axis[k % axis.len()]);
                w.write_record([
                    format!("{r}"),
                    format!("{a}"),
                    s.regime().name().to_string(),
                    format!("{:.4}", s.stuck_share()),
                    format!("{:.4}", s.off_bottom_share()),
                    format!("{:.3}", s.rate_m_s() * 3600.0),
                    s.period_s(cmd.sample_hz).map_or(String::new(), |p| format!("{p:.3}")),
                    format!("{:.3}", s.wob_mean_n() / 1e3),
                    format!("{:.4}", s.torque_mean_nm() / 1e3),
                ])?;
            }
            w.flush()
        })?;
    }
    let mut out = super::print::stdout();
    if cmd.json {
        let cells: Vec<_> = summaries.iter().map(|s| summary_json(s, cmd.sample_hz)).collect();
        let grid: Vec<_> = cells.chunks(axis.len()).map(<[serde_json::Value]>::to_vec).collect();
        writeln!(
            out,
            "{}",
            serde_json::to_string_pretty(&json!({"omega_rpm": rpm, axis_name: axis, "cells": grid, "backend": ran}))?
        )?;
        return Ok(ExitCode::SUCCESS);
    }
    writeln!(
        out,
        "regimes ({} s after {} s settling, {} strings on the {ran}; . steady, S stick-slip, B bit bounce, X both, ! diverged)",
        cmd.duration_s,
        cmd.settle_s,
        jobs.len()
    )?;
    write!(out, "{:>9}", format!("rpm\\{axis_unit}"))?;
    for a in &axis {
        write!(out, " {a:>5}")?;
    }
    writeln!(out)?;
    for (i, r) in rpm.iter().enumerate() {
        write!(out, "{r:>9.1}")?;
        for s in &summaries[i * axis.len()..(i + 1) * axis.len()] {
            write!(out, " {:>5}", mark(s.regime()))?;
        }
        writeln!(out)?;
    }
    Ok(ExitCode::SUCCESS)
}

/// The regime's mark in the printed maps.
fn mark(regime: coupled::Regime) -> &'static str {
    match regime {
        coupled::Regime::Steady => ".",
        coupled::Regime::StickSlip => "S",
        coupled::Regime::BitBounce => "B",
        coupled::Regime::Both => "X",
        coupled::Regime::Diverged => "!",
    }
}

/// The regimes counted, in the order steady, stick-slip, bit bounce, both, diverged.
const REGIMES: [coupled::Regime; 5] = [
    coupled::Regime::Steady,
    coupled::Regime::StickSlip,
    coupled::Regime::BitBounce,
    coupled::Regime::Both,
    coupled::Regime::Diverged,
];

/// `--calibrate --map`: every cell simulated for each of `--samples` posterior draws; each
/// regime's probability per cell.
fn run_posterior_map(
    cmd: &CoupledCmd,
    assembly: &Assembly,
    schedule: &Schedule,
    calibration: &CoupledCalibration,
) -> anyhow::Result<ExitCode> {
    if cmd.samples == 0 {
        return Err(bitrock::Error::setting("samples", "must be at least 1").into());
    }
    let template = cmd.bit();
    let bits: Vec<Bit> = calibration
        .draws
        .iter()
        .map(|d| bit_of(d, &template))
        .filter(|b| b.validate().is_ok())
        .take(cmd.samples)
        .collect();
    if bits.len() < cmd.samples {
        return Err(bitrock::Error::setting(
            "samples",
            format!(
                "the calibration's draws give only {} bits within the physical bounds",
                bits.len()
            ),
        )
        .into());
    }
    let (rpm, axis, axis_name, axis_unit) = axes(cmd)?;
    let mut jobs = Vec::with_capacity(rpm.len() * axis.len() * bits.len());
    for &r in &rpm {
        for &a in &axis {
            for b in &bits {
                jobs.push(cmd.job_with(*b, r, Some(a))?);
            }
        }
    }
    let (summaries, ran) = integrate(cmd, assembly, schedule, &jobs)?;
    // Per cell: each regime's share of the draws, and the median rate of penetration (m/h).
    let cells: Vec<([f64; 5], f64)> = summaries
        .chunks(bits.len())
        .map(|draws| {
            let mut p = [0.0; 5];
            for s in draws {
                let k = REGIMES.iter().position(|r| *r == s.regime()).expect("a regime");
                p[k] += 1.0 / draws.len() as f64;
            }
            let rates: Vec<f64> = draws.iter().map(|s| s.rate_m_s() * 3600.0).collect();
            (p, bitrock::numerics::quantile(&rates, 0.5))
        })
        .collect();
    if let Some(path) = &cmd.out {
        bitrock::run::dir::write_whole(path, "out", cmd.force, |file| {
            let mut w = csv::Writer::from_writer(file);
            w.write_record([
                "omega_rpm",
                axis_name,
                "p_steady",
                "p_stick_slip",
                "p_bit_bounce",
                "p_both",
                "p_diverged",
                "rop_median_m_h",
            ])?;
            for (k, (p, rop)) in cells.iter().enumerate() {
                let mut row = vec![format!("{}", rpm[k / axis.len()]), format!("{}", axis[k % axis.len()])];
                row.extend(p.iter().map(|v| format!("{v:.4}")));
                row.push(format!("{rop:.3}"));
                w.write_record(row)?;
            }
            w.flush()
        })?;
    }
    let mut out = super::print::stdout();
    if cmd.json {
        let grid: Vec<Vec<serde_json::Value>> = cells
            .chunks(axis.len())
            .map(|row| {
                row.iter()
                    .map(|(p, rop)| {
                        json!({"steady": p[0], "stick_slip": p[1], "bit_bounce": p[2], "both": p[3], "diverged": p[4], "rop_median_m_h": rop})
                    })
                    .collect()
            })
            .collect();
        writeln!(
            out,
            "{}",
            serde_json::to_string_pretty(&json!({"omega_rpm": rpm, axis_name: axis, "samples": bits.len(), "probabilities": grid, "backend": ran, "calibration": calibration_json(calibration)}))?
        )?;
        return Ok(ExitCode::SUCCESS);
    }
    print_estimates(&mut out, calibration)?;
    writeln!(
        out,
        "probability the bit vibrates (stick-slip, bounce or both), % of {} posterior draws per cell; \
         {} strings on the {ran}",
        bits.len(),
        jobs.len()
    )?;
    write!(out, "{:>9}", format!("rpm\\{axis_unit}"))?;
    for a in &axis {
        write!(out, " {a:>5}")?;
    }
    writeln!(out)?;
    for (i, r) in rpm.iter().enumerate() {
        write!(out, "{r:>9.1}")?;
        for (p, _) in &cells[i * axis.len()..(i + 1) * axis.len()] {
            write!(out, " {:>5.0}", 100.0 * p[1..].iter().sum::<f64>())?;
        }
        writeln!(out)?;
    }
    Ok(ExitCode::SUCCESS)
}

/// A calibration as JSON: its estimates, lines and samples.
fn calibration_json(c: &CoupledCalibration) -> serde_json::Value {
    json!({
        "samples": c.samples,
        "cutting_samples": c.cutting_samples,
        "depth_of_cut_mm": [c.depth_of_cut_mm.0, c.depth_of_cut_mm.1],
        "weight_line": c.weight_line,
        "torque_line": c.torque_line,
        "estimates": c.estimates,
        "draws_out_of_bounds": c.draws_out_of_bounds,
        "warning": c.warning,
    })
}

/// The estimates with their intervals, and what they came from.
fn print_estimates(out: &mut dyn Write, c: &CoupledCalibration) -> std::io::Result<()> {
    writeln!(
        out,
        "{} of {} samples cutting, depth of cut {:.2}-{:.2} mm a turn (5th-95th percentile); \
         weight line R² {:.3}, torque line R² {:.3}",
        c.cutting_samples, c.samples, c.depth_of_cut_mm.0, c.depth_of_cut_mm.1, c.weight_line.r_squared, c.torque_line.r_squared
    )?;
    for e in &c.estimates {
        writeln!(
            out,
            "{:<22} {:>10.4} {:<4} 90 % [{:.4}, {:.4}]",
            e.name, e.value, if e.unit == "1" { "" } else { e.unit }, e.lo, e.hi
        )?;
    }
    Ok(())
}

/// `--calibrate` without `--map`: the estimates.
fn print_calibration(cmd: &CoupledCmd, c: &CoupledCalibration) -> anyhow::Result<ExitCode> {
    let mut out = super::print::stdout();
    if cmd.json {
        writeln!(out, "{}", serde_json::to_string_pretty(&calibration_json(c))?)?;
    } else {
        print_estimates(&mut out, c)?;
    }
    Ok(ExitCode::SUCCESS)
}
