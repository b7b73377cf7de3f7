//! `bitrock coupled`: the coupled axial-torsional bit (RGD) on the 1-DOF string, one string as
//! a record with its summary, or `--map` a regime map over top-drive speed and weight on bit
//! (or feed), one simulated string per cell, or `--well` one string drilled through formations.

use super::args::{LumpedArgs, finite_number};
use bitrock::data::drilling::{DrillingOptions, DrillingRecord};
use bitrock::data::surface::{SurfaceOptions, SurfaceRecord};
use bitrock::eval::Backend;
use bitrock::fit::coupled::CoupledCalibration;
use bitrock::run::choice::{self, Choice};
use bitrock::run::coupled::{self, Map, One, PosteriorMap, Settings};
use bitrock::simulate::coupled::well::CoupledWell;
use bitrock::simulate::coupled::{Bit, Regime, Sample};
use bitrock::units::{AccelerationUnit, ForceUnit, RateUnit, SpeedUnit, TorqueUnit};
use clap::Args;
use serde_json::json;
use std::io::Write;
use std::process::ExitCode;

#[derive(Debug, Args)]
#[command(group(clap::ArgGroup::new("drilling_record").args(["calibrate", "select"])))]
pub struct CoupledCmd {
    /// A well file (TOML): segments in drilling order, each with its rock, top-drive speed and
    /// weight or feed (a value, or [from, to] for a ramp), drilled by one string carried from
    /// each into the next; the record gains the column segment, its top_drive_rpm following the
    /// segments (format in docs/coupled.md).
    #[arg(long, value_name = "FILE", conflicts_with_all = [
        "omega_rpm", "wob_kn", "feed_m_h", "radius_m", "intrinsic_energy_mpa", "zeta", "contact_stress_mpa",
        "wear_flat_mm", "friction", "gamma", "blades", "inertia_kg_m2", "omega_n_rad_s", "damping_ratio",
        "mass_kg", "axial_stiffness_kn_m", "axial_damping_kns_m", "duration_s", "settle_s", "sample_hz", "dt_s",
        "kick_rpm", "map", "calibrate", "select", "seed", "backend",
    ])]
    pub well: Option<std::path::PathBuf>,
    /// Top-drive speed Omega_0, rpm [default: 60]; with --select, the top drive's speed while
    /// the record was made, needed.
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, value_name = "RPM")]
    pub omega_rpm: Option<f64>,
    /// A constant weight on the bit assembly (the hook held at a set weight), kN.
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, value_name = "KN", conflicts_with = "feed_m_h")]
    pub wob_kn: Option<f64>,
    /// Or the top fed down at a constant rate on the string's axial spring, m/h [default: 30].
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, value_name = "M_H")]
    pub feed_m_h: Option<f64>,
    /// Bit radius a, m.
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, default_value_t = Settings::default().bit.radius_m, value_name = "M")]
    pub radius_m: f64,
    /// Intrinsic specific energy of the rock epsilon, MPa.
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, default_value_t = Settings::default().bit.intrinsic_energy_mpa, value_name = "MPA")]
    pub intrinsic_energy_mpa: f64,
    /// Ratio zeta of the cutting force's axial to its tangential component.
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, default_value_t = Settings::default().bit.zeta)]
    pub zeta: f64,
    /// Contact stress sigma on the wear flats, MPa.
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, default_value_t = Settings::default().bit.contact_stress_mpa, value_name = "MPA")]
    pub contact_stress_mpa: f64,
    /// Total wear-flat length l of the blades, mm.
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, default_value_t = Settings::default().bit.wear_flat_mm, value_name = "MM")]
    pub wear_flat_mm: f64,
    /// Friction coefficient mu of the wear flats on the rock.
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, default_value_t = Settings::default().bit.friction)]
    pub friction: f64,
    /// Bit geometry factor gamma.
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, default_value_t = Settings::default().bit.gamma)]
    pub gamma: f64,
    /// Blades N.
    #[arg(long, default_value_t = Settings::default().bit.blades)]
    pub blades: u32,
    #[command(flatten)]
    pub lumped: LumpedArgs,
    /// Mass of the bit assembly M, kg.
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, default_value_t = Settings::default().mass_kg, value_name = "KG")]
    pub mass_kg: f64,
    /// Axial stiffness of the string K_a (felt under a feed), kN/m.
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, default_value_t = Settings::default().axial_stiffness_kn_m, value_name = "KN_M")]
    pub axial_stiffness_kn_m: f64,
    /// Axial damping on the bit assembly C_a, kN·s/m.
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, default_value_t = Settings::default().axial_damping_kns_m, value_name = "KNS_M")]
    pub axial_damping_kns_m: f64,
    /// Recorded duration, s.
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, default_value_t = Settings::default().duration_s, value_name = "SECONDS")]
    pub duration_s: f64,
    /// Simulated time discarded before recording starts (lets the motion settle), s.
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, default_value_t = Settings::default().settle_s, value_name = "SECONDS")]
    pub settle_s: f64,
    /// Output sample rate, Hz.
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, default_value_t = Settings::default().sample_hz, value_name = "HZ")]
    pub sample_hz: f64,
    /// Integration step, s (the stuck share converges to about 1 % at 1e-4 s).
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, default_value_t = Settings::default().dt_s, value_name = "SECONDS")]
    pub dt_s: f64,
    /// Bit-speed kick from steady drilling at t = 0, rpm.
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, default_value_t = Settings::default().kick_rpm, value_name = "RPM")]
    pub kick_rpm: f64,
    /// A regime map instead of one string: one string per cell of --map-rpm × --map-wob-kn with
    /// --wob-kn, or × --map-feed-m-h under a feed (the drive without --wob-kn).
    #[arg(long)]
    pub map: bool,
    /// With --map: the escape map, every cell continued from where the bit is at --omega-rpm
    /// under its weight or feed (settled for --settle-s and --duration-s), and the way out of
    /// the motion it is in; with --calibrate, each posterior draw's bit from where it is.
    #[arg(long, requires = "map")]
    pub escape: bool,
    /// The map's top-drive speeds, rpm, as MIN:MAX:COUNT.
    #[arg(long, default_value_t = Settings::default().map_rpm, value_name = "MIN:MAX:COUNT", requires = "map")]
    pub map_rpm: String,
    /// The map's weights on bit, kN, as MIN:MAX:COUNT (with --wob-kn).
    #[arg(long, default_value_t = Settings::default().map_wob_kn, value_name = "MIN:MAX:COUNT", requires = "map")]
    pub map_wob_kn: String,
    /// The map's feeds, m/h, as MIN:MAX:COUNT (under a feed: without --wob-kn).
    #[arg(long, default_value_t = Settings::default().map_feed_m_h, value_name = "MIN:MAX:COUNT", requires = "map")]
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
    /// Which structure a bit record (bit speed, torque on bit, weight on bit; recorded at
    /// --sample-hz while the top drive turned at --omega-rpm) shows: a torsional law m1-m4 or
    /// the coupled bit (RGD), each candidate's string simulated at the record's drive (the
    /// weight --wob-kn, or the record's mean), by their shares of the candidates nearest the
    /// record, checked by re-simulation. The bit's --radius-m, --contact-stress-mpa, --gamma and
    /// --blades and the string stay as given.
    #[arg(long, value_name = "RECORD", conflicts_with_all = [
        "map", "feed_m_h", "out", "intrinsic_energy_mpa", "zeta", "wear_flat_mm", "friction", "duration_s",
        "samples", "backend", "axial_acceleration_col", "acceleration_unit",
    ])]
    pub select: Option<std::path::PathBuf>,
    /// Candidates of each structure in the choice's reference table (with --select).
    #[arg(long, default_value_t = Settings::default().reference, value_name = "N", requires = "select")]
    pub reference: usize,
    /// Records re-simulated from each structure to check the choice (with --select).
    #[arg(long, default_value_t = Settings::default().replicates, value_name = "R", requires = "select")]
    pub replicates: usize,
    /// With --select: the record is what a rig streams (time, top-drive speed, surface torque
    /// and, where recorded, weight on bit), the structures compared by their surface torque at
    /// the record's steady top-drive speed (its mean), on its clock, under --wob-kn or the
    /// record's mean weight on bit; each law's candidates drawn from `bitrock surface`'s prior.
    #[arg(long, requires = "select", conflicts_with_all = [
        "omega_rpm", "sample_hz", "speed_col", "torque_col", "rop_col", "axial_speed_col", "speed_unit",
        "rop_unit", "axial_acceleration_col", "acceleration_unit",
    ])]
    pub from_surface: bool,
    #[command(flatten)]
    pub surface_columns: SurfaceColumnArgs,
    #[command(flatten)]
    pub columns: DrillingArgs,
    /// Posterior draws each map cell is simulated for (with --calibrate --map).
    #[arg(long, default_value_t = Settings::default().samples, value_name = "S", requires = "calibrate")]
    pub samples: usize,
    /// Seed of the posterior draws.
    #[arg(long, default_value_t = Settings::default().seed)]
    pub seed: u64,
    /// The record (one string or a well: time, what a rig streams, top-drive speed and surface
    /// torque, then bit speed, torque on bit, WOB, axial speed and acceleration, rate of
    /// penetration; a well's with each sample's segment) or the map (one row per cell) as CSV.
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
    #[arg(long, value_name = "NAME", requires = "drilling_record")]
    pub speed_col: Option<String>,
    /// Torque-on-bit column [default: the one whose name holds 'torque'].
    #[arg(long, value_name = "NAME", requires = "drilling_record")]
    pub torque_col: Option<String>,
    /// Weight-on-bit column [default: the one whose name holds 'wob'].
    #[arg(long, value_name = "NAME", requires = "drilling_record")]
    pub wob_col: Option<String>,
    /// Rate-of-penetration column [default: the one whose name holds 'rop' or 'penetration'].
    #[arg(long, value_name = "NAME", requires = "drilling_record")]
    pub rop_col: Option<String>,
    /// The bit's axial speed column [default: the one whose name holds 'axial' and not 'acc', if any].
    #[arg(long, value_name = "NAME", requires = "drilling_record")]
    pub axial_speed_col: Option<String>,
    /// The bit's axial acceleration column, where the record has no axial speed: the bit's rests
    /// on it tell the samples moving down [default: the one whose name holds 'axial' and 'acc',
    /// if any].
    #[arg(long, value_name = "NAME", requires = "calibrate")]
    pub axial_acceleration_col: Option<String>,
    /// Unit of the bit speed [default: from its name's suffix].
    #[arg(long, value_enum, requires = "drilling_record")]
    pub speed_unit: Option<SpeedUnit>,
    /// Unit of the torque on bit, or with --from-surface of the surface torque [default: from
    /// its name's suffix].
    #[arg(long, value_enum, requires = "drilling_record")]
    pub torque_unit: Option<TorqueUnit>,
    /// Unit of the weight on bit [default: from its name's suffix].
    #[arg(long, value_enum, requires = "drilling_record")]
    pub wob_unit: Option<ForceUnit>,
    /// Unit of the rate of penetration and axial speed [default: from their names' suffixes].
    #[arg(long, value_enum, requires = "drilling_record")]
    pub rop_unit: Option<RateUnit>,
    /// Unit of the axial acceleration [default: from its name's suffix].
    #[arg(long, value_enum, requires = "calibrate")]
    pub acceleration_unit: Option<AccelerationUnit>,
}

/// The columns of a surface record (with --from-surface) and their units; its surface torque's
/// unit is --torque-unit's, its weight on bit --wob-col's.
#[derive(Debug, Args)]
pub struct SurfaceColumnArgs {
    /// Time column (s; ms where its name ends in _ms) of the surface record, or of the record
    /// calibrated, where it has an axial acceleration and no axial speed (its clock checks the
    /// bit's travel) [default: the one whose name holds "time"].
    #[arg(long = "time-col", value_name = "NAME")]
    pub time_column: Option<String>,
    /// Top-drive speed column [default: the one whose name holds "top_drive" or "rotary"].
    #[arg(long = "top-drive-col", value_name = "NAME")]
    pub top_drive_column: Option<String>,
    /// Surface torque column [default: the surface channel whose name holds "torque"].
    #[arg(long = "surface-torque-col", value_name = "NAME")]
    pub surface_torque_column: Option<String>,
    /// Unit of the top-drive speed [default: from the column's suffix].
    #[arg(long, value_enum)]
    pub top_drive_unit: Option<SpeedUnit>,
}

impl DrillingArgs {
    /// The drilling record's columns; its clock named by `time_column` (--time-col), its axial
    /// acceleration read where `calibrating`.
    fn options(&self, time_column: Option<String>, calibrating: bool) -> DrillingOptions {
        DrillingOptions {
            time_column,
            read_axial_acceleration: calibrating,
            speed_column: self.speed_col.clone(),
            torque_column: self.torque_col.clone(),
            wob_column: self.wob_col.clone(),
            rop_column: self.rop_col.clone(),
            axial_speed_column: self.axial_speed_col.clone(),
            axial_acceleration_column: self.axial_acceleration_col.clone(),
            speed_unit: self.speed_unit,
            torque_unit: self.torque_unit,
            wob_unit: self.wob_unit,
            rop_unit: self.rop_unit,
            acceleration_unit: self.acceleration_unit,
        }
    }
}

impl CoupledCmd {
    /// The surface record's columns (with --from-surface).
    fn surface_options(&self) -> SurfaceOptions {
        let s = &self.surface_columns;
        SurfaceOptions {
            time_column: s.time_column.clone(),
            top_drive_column: s.top_drive_column.clone(),
            surface_torque_column: s.surface_torque_column.clone(),
            wob_column: self.columns.wob_col.clone(),
            top_drive_unit: s.top_drive_unit,
            torque_unit: self.columns.torque_unit,
            wob_unit: self.columns.wob_unit,
            // The choice compares the surface torque alone.
            ignore_downhole: true,
            ..SurfaceOptions::default()
        }
    }

    /// The run's settings from the flags.
    fn settings(&self) -> Settings {
        let lumped = self.lumped.lumped();
        Settings {
            omega_rpm: self.omega_rpm.unwrap_or(Settings::default().omega_rpm),
            wob_kn: self.wob_kn,
            feed_m_h: self.feed_m_h,
            bit: Bit {
                radius_m: self.radius_m,
                intrinsic_energy_mpa: self.intrinsic_energy_mpa,
                zeta: self.zeta,
                contact_stress_mpa: self.contact_stress_mpa,
                wear_flat_mm: self.wear_flat_mm,
                friction: self.friction,
                gamma: self.gamma,
                blades: self.blades,
            },
            inertia_kg_m2: lumped.inertia_kg_m2,
            omega_n_rad_s: lumped.omega_n_rad_s,
            damping_ratio: lumped.damping_ratio,
            mass_kg: self.mass_kg,
            axial_stiffness_kn_m: self.axial_stiffness_kn_m,
            axial_damping_kns_m: self.axial_damping_kns_m,
            duration_s: self.duration_s,
            settle_s: self.settle_s,
            sample_hz: self.sample_hz,
            dt_s: self.dt_s,
            kick_rpm: self.kick_rpm,
            map_rpm: self.map_rpm.clone(),
            map_wob_kn: self.map_wob_kn.clone(),
            map_feed_m_h: self.map_feed_m_h.clone(),
            escape: self.escape,
            samples: self.samples,
            reference: self.reference,
            replicates: self.replicates,
            seed: self.seed,
            backend: self.backend,
        }
    }
}

pub fn run(cmd: &CoupledCmd) -> anyhow::Result<ExitCode> {
    let s = &cmd.surface_columns;
    let surface_columns_given = (s.time_column.is_some() && cmd.calibrate.is_none())
        || s.top_drive_column.is_some()
        || s.surface_torque_column.is_some()
        || s.top_drive_unit.is_some();
    if surface_columns_given && !cmd.from_surface {
        return Err(bitrock::Error::setting(
            "from_surface",
            "`top_drive_column`, `surface_torque_column` and `top_drive_unit` name a surface record's columns, and `time_column` a surface record's clock or that of a record calibrated: give the record",
        )
        .into());
    }
    if let Some(path) = &cmd.well {
        return run_well(cmd, &CoupledWell::load(path)?);
    }
    let settings = cmd.settings();
    settings.assembly()?;
    // From the surface, the record's clock is the schedule's (checked by the choice).
    if !cmd.from_surface {
        settings.schedule()?;
    }
    if let Some(path) = &cmd.out {
        bitrock::run::dir::check_output_file(path, "out", cmd.force)?;
    }
    let note = &mut |line: String| super::print::note(format_args!("{line}"));
    if let Some(path) = &cmd.select {
        let choice = if cmd.from_surface {
            let record = SurfaceRecord::read(path, &cmd.surface_options())?;
            choice::surface_choice(&record, &settings, note)?
        } else {
            if cmd.omega_rpm.is_none() {
                return Err(bitrock::Error::setting(
                    "omega_rpm",
                    "the top drive's speed while the record was made is needed to simulate the candidates at it",
                )
                .into());
            }
            let record = DrillingRecord::read(
                path,
                &cmd.columns.options(cmd.surface_columns.time_column.clone(), false),
            )?;
            choice::choice(&record, &settings, note)?
        };
        let mut out = super::print::stdout();
        if cmd.json {
            writeln!(out, "{}", serde_json::to_string_pretty(&choice)?)?;
        } else {
            print_choice(&mut out, &choice)?;
        }
        return Ok(ExitCode::SUCCESS);
    }
    coupled::check_escape_start(&settings, cmd.map, cmd.calibrate.is_some(), cmd.omega_rpm.is_some())?;
    let calibration = match &cmd.calibrate {
        Some(path) => {
            let record = DrillingRecord::read(
                path,
                &cmd.columns.options(cmd.surface_columns.time_column.clone(), true),
            )?;
            let c = coupled::calibration(&record, &settings)?;
            for line in c.notes() {
                note(line);
            }
            Some(c)
        }
        None => None,
    };
    let mut out = super::print::stdout();
    match (cmd.map, &calibration) {
        (true, Some(c)) if cmd.escape => {
            let map = coupled::posterior_escape_map(&settings, c, note)?;
            if let Some(path) = &cmd.out {
                bitrock::run::dir::write_whole(path, "out", cmd.force, |file| write_posterior_map(&map.map, file))?;
            }
            if cmd.json {
                let value = json!({"map": map, "calibration": c});
                writeln!(out, "{}", serde_json::to_string_pretty(&value)?)?;
            } else {
                print_estimates(&mut out, c)?;
                writeln!(
                    out,
                    "each draw's bit settled at {} rpm and {} {}, every cell continued from where it is",
                    map.from.omega_rpm,
                    map.from.drive,
                    map.map.axes.drive_axis().1
                )?;
                print_posterior_map(&mut out, &map.map)?;
                writeln!(out, "{}", map.advice.words)?;
            }
        }
        (true, Some(c)) => {
            let map = coupled::posterior_map(&settings, c, note)?;
            if let Some(path) = &cmd.out {
                bitrock::run::dir::write_whole(path, "out", cmd.force, |file| write_posterior_map(&map, file))?;
            }
            if cmd.json {
                let value = json!({"map": map, "calibration": c});
                writeln!(out, "{}", serde_json::to_string_pretty(&value)?)?;
            } else {
                print_estimates(&mut out, c)?;
                print_posterior_map(&mut out, &map)?;
            }
        }
        (true, None) if cmd.escape => {
            let map = coupled::escape_map(&settings, note)?;
            if let Some(path) = &cmd.out {
                bitrock::run::dir::write_whole(path, "out", cmd.force, |file| write_map(&map.map, file))?;
            }
            if cmd.json {
                writeln!(out, "{}", serde_json::to_string_pretty(&map)?)?;
            } else {
                writeln!(
                    out,
                    "from {} at {} rpm and {} {}: stuck {:.1} % of the time, off bottom {:.1} %",
                    map.from.summary.regime.name(),
                    map.from.omega_rpm,
                    map.from.drive,
                    map.map.axes.drive_axis().1,
                    100.0 * map.from.summary.stuck_share,
                    100.0 * map.from.summary.off_bottom_share
                )?;
                print_map(&mut out, &map.map, &settings)?;
                writeln!(out, "{}", map.advice.words)?;
            }
        }
        (true, None) => {
            let map = coupled::map(&settings, note)?;
            if let Some(path) = &cmd.out {
                bitrock::run::dir::write_whole(path, "out", cmd.force, |file| write_map(&map, file))?;
            }
            if cmd.json {
                writeln!(out, "{}", serde_json::to_string_pretty(&map)?)?;
            } else {
                print_map(&mut out, &map, &settings)?;
            }
        }
        (false, Some(c)) => {
            if cmd.json {
                writeln!(out, "{}", serde_json::to_string_pretty(c)?)?;
            } else {
                print_estimates(&mut out, c)?;
            }
        }
        (false, None) => {
            let mut samples = Vec::new();
            let one = coupled::one(&settings, &mut |s| {
                if cmd.out.is_some() {
                    samples.push(*s)
                }
            })?;
            if let Some(w) = &one.warning {
                note(format!("warning: {w}"));
            }
            if let Some(path) = &cmd.out {
                bitrock::run::dir::write_whole(path, "out", cmd.force, |file| {
                    write_record(&samples, settings.omega_rpm, file)
                })?;
            }
            if cmd.json {
                writeln!(out, "{}", serde_json::to_string_pretty(&one)?)?;
            } else {
                print_one(&mut out, &one, settings.omega_rpm)?;
            }
        }
    }
    Ok(ExitCode::SUCCESS)
}

/// A well drilled through its segments: a table of them (or JSON), and the record with `--out`.
fn run_well(cmd: &CoupledCmd, well: &CoupledWell) -> anyhow::Result<ExitCode> {
    if let Some(path) = &cmd.out {
        bitrock::run::dir::check_output_file(path, "out", cmd.force)?;
        well.check_record_memory()?;
    }
    let mut samples = Vec::new();
    let segments = coupled::well(well, &mut |i, s| {
        if cmd.out.is_some() {
            samples.push((i, *s));
        }
    })?;
    if let Some(path) = &cmd.out {
        bitrock::run::dir::write_whole(path, "out", cmd.force, |file| write_well_record(well, &samples, file))?;
    }
    for s in &segments {
        if let Some(w) = &s.warning {
            super::print::note(format_args!("warning: segment {}: {w}", s.name));
        }
    }
    let mut out = super::print::stdout();
    if cmd.json {
        writeln!(
            out,
            "{}",
            serde_json::to_string_pretty(&json!({ "segments": segments }))?
        )?;
        return Ok(ExitCode::SUCCESS);
    }
    let width = segments
        .iter()
        .map(|s| s.name.chars().count())
        .max()
        .unwrap_or(0)
        .max(7);
    let drives: Vec<String> = segments
        .iter()
        .map(|s| match (s.drive.wob_kn, s.drive.feed_m_h) {
            (Some(kn), _) => format!("{kn} kN"),
            (None, Some(m_h)) => format!("{m_h} m/h"),
            (None, None) => String::new(),
        })
        .collect();
    // A ramp (`60→120`) widens its columns.
    let rpm_width = segments
        .iter()
        .map(|s| s.omega_rpm.to_string().chars().count())
        .fold(6, usize::max);
    let drive_width = drives.iter().map(|d| d.chars().count()).fold(9, usize::max);
    writeln!(
        out,
        "{:<width$} {:>7} {:>rpm_width$} {:>drive_width$} {:<11} {:>8} {:>8} {:>8} {:>9}",
        "segment", "from s", "rpm", "drive", "regime", "ROP m/h", "steady", "stuck %", "off bot %"
    )?;
    for (s, drive) in segments.iter().zip(&drives) {
        writeln!(
            out,
            "{:<width$} {:>7.1} {:>rpm_width$} {:>drive_width$} {:<11} {:>8.1} {:>8.1} {:>8.1} {:>9.1}",
            s.name,
            s.start_s,
            s.omega_rpm.to_string(),
            drive,
            s.summary.regime.name(),
            s.summary.rop_m_h,
            s.steady.rop_m_h,
            100.0 * s.summary.stuck_share,
            100.0 * s.summary.off_bottom_share
        )?;
    }
    if segments.len() < well.segments.len() {
        writeln!(
            out,
            "the bit ran away in segment {}: the segments after it were not drilled",
            segments.len()
        )?;
    }
    Ok(ExitCode::SUCCESS)
}

/// A well's record: each sample's time, its segment's name, then the other columns.
fn write_well_record(well: &CoupledWell, samples: &[(usize, Sample)], out: &mut dyn Write) -> std::io::Result<()> {
    let (segments, columns) = coupled::well_record_columns(well, samples);
    let mut w = csv::Writer::from_writer(out);
    let mut header = vec![columns[0].0, "segment"];
    header.extend(columns.iter().skip(1).map(|(name, _)| *name));
    w.write_record(&header)?;
    for (k, i) in segments.iter().enumerate() {
        let mut row = vec![format!("{:.6}", columns[0].1[k]), well.segments[*i].name.clone()];
        row.extend(columns.iter().skip(1).map(|(_, values)| format!("{:.6}", values[k])));
        w.write_record(&row)?;
    }
    w.flush()
}

fn print_one(out: &mut dyn Write, one: &One, omega_rpm: f64) -> std::io::Result<()> {
    let s = &one.summary;
    writeln!(
        out,
        "{} at {omega_rpm} rpm: rate of penetration {:.1} m/h (steady drilling {:.1}), stuck {:.1} % of the time, off bottom {:.1} %",
        s.regime.name(),
        s.rop_m_h,
        one.steady.rop_m_h,
        100.0 * s.stuck_share,
        100.0 * s.off_bottom_share
    )?;
    writeln!(
        out,
        "bit speed {:.0}-{:.0} rpm, WOB {:.0}-{:.0} kN (mean {:.0}), torque {:.2}-{:.2} kN·m (mean {:.2}){}",
        s.bit_speed_rpm.min,
        s.bit_speed_rpm.max,
        s.wob_kn.min,
        s.wob_kn.max,
        s.wob_kn.mean,
        s.torque_knm.min,
        s.torque_knm.max,
        s.torque_knm.mean,
        s.period_s
            .map_or(String::new(), |p| format!(", stick-slip period {p:.2} s"))
    )
}

/// The record of a string driven at `omega_rpm`, units in the columns' names.
fn write_record(samples: &[Sample], omega_rpm: f64, out: &mut dyn Write) -> std::io::Result<()> {
    let columns = coupled::record_columns(samples, &|_| omega_rpm);
    let mut w = csv::Writer::from_writer(out);
    w.write_record(columns.iter().map(|(name, _)| *name))?;
    for k in 0..samples.len() {
        w.write_record(columns.iter().map(|(_, values)| format!("{:.6}", values[k])))?;
    }
    w.flush()
}

fn write_map(map: &Map, file: &mut dyn Write) -> std::io::Result<()> {
    let mut w = csv::Writer::from_writer(file);
    w.write_record([
        "omega_rpm",
        map.axes.drive_axis().0,
        "regime",
        "stuck_share",
        "off_bottom_share",
        "rop_m_h",
        "period_s",
        "wob_mean_kn",
        "torque_mean_knm",
    ])?;
    let drive = map.axes.drive();
    for (row, r) in map.cells.iter().zip(&map.axes.omega_rpm) {
        for (s, a) in row.iter().zip(drive) {
            w.write_record([
                format!("{r}"),
                format!("{a}"),
                s.regime.name().to_string(),
                format!("{:.4}", s.stuck_share),
                format!("{:.4}", s.off_bottom_share),
                format!("{:.3}", s.rop_m_h),
                s.period_s.map_or(String::new(), |p| format!("{p:.3}")),
                format!("{:.3}", s.wob_kn.mean),
                format!("{:.4}", s.torque_knm.mean),
            ])?;
        }
    }
    w.flush()
}

/// The map's header row: the drive's values across.
fn print_header(out: &mut dyn Write, unit: &str, drive: &[f64]) -> std::io::Result<()> {
    write!(out, "{:>9}", format!("rpm\\{unit}"))?;
    for a in drive {
        write!(out, " {a:>5}")?;
    }
    writeln!(out)
}

fn print_map(out: &mut dyn Write, map: &Map, settings: &Settings) -> std::io::Result<()> {
    writeln!(
        out,
        "regimes ({} s after {} s settling, {} strings on the {}; . steady, S stick-slip, B bit bounce, X both, ! diverged)",
        settings.duration_s, settings.settle_s, map.axes.strings, map.axes.backend
    )?;
    print_header(out, map.axes.drive_axis().1, map.axes.drive())?;
    for (row, r) in map.cells.iter().zip(&map.axes.omega_rpm) {
        write!(out, "{r:>9.1}")?;
        for s in row {
            write!(out, " {:>5}", mark(s.regime))?;
        }
        writeln!(out)?;
    }
    Ok(())
}

/// The regime's mark in the printed maps.
fn mark(regime: Regime) -> &'static str {
    match regime {
        Regime::Steady => ".",
        Regime::StickSlip => "S",
        Regime::BitBounce => "B",
        Regime::Both => "X",
        Regime::Diverged => "!",
    }
}

fn write_posterior_map(map: &PosteriorMap, file: &mut dyn Write) -> std::io::Result<()> {
    let mut w = csv::Writer::from_writer(file);
    let drive_name = map.axes.drive_axis().0;
    w.write_record([
        "omega_rpm",
        drive_name,
        "p_steady",
        "p_stick_slip",
        "p_bit_bounce",
        "p_both",
        "p_diverged",
        "rop_median_m_h",
    ])?;
    for (row, r) in map.probabilities.iter().zip(&map.axes.omega_rpm) {
        for (p, a) in row.iter().zip(map.axes.drive()) {
            let mut cells = vec![format!("{r}"), format!("{a}")];
            cells.extend(
                [p.steady, p.stick_slip, p.bit_bounce, p.both, p.diverged]
                    .iter()
                    .map(|v| format!("{v:.4}")),
            );
            cells.push(format!("{:.3}", p.rop_median_m_h));
            w.write_record(cells)?;
        }
    }
    w.flush()
}

fn print_posterior_map(out: &mut dyn Write, map: &PosteriorMap) -> std::io::Result<()> {
    writeln!(
        out,
        "probability the bit vibrates (stick-slip, bounce or both), % of {} posterior draws per cell; {} strings on the {}",
        map.samples, map.axes.strings, map.axes.backend
    )?;
    print_header(out, map.axes.drive_axis().1, map.axes.drive())?;
    for (row, r) in map.probabilities.iter().zip(&map.axes.omega_rpm) {
        write!(out, "{r:>9.1}")?;
        for p in row {
            write!(out, " {:>5.0}", 100.0 * p.vibrating())?;
        }
        writeln!(out)?;
    }
    Ok(())
}

/// The estimates with their intervals, and what they came from.
fn print_estimates(out: &mut dyn Write, c: &CoupledCalibration) -> std::io::Result<()> {
    writeln!(
        out,
        "{} of {} samples cutting, {}{}; depth of cut {:.2}-{:.2} mm a turn (5th-95th \
         percentile); weight line R² {:.3}, torque line R² {:.3}",
        c.cutting_samples,
        c.samples,
        c.cutting_by.describe(),
        c.weight_edge_noise_kn
            .zip(c.weight_edge_scatter_kn)
            .map(|(sd, scatter)| format!(
                " (the weight's noise about it {sd:.2} kN; averaged over neighbours in one state, \
                 told by {scatter:.2} kN)"
            ))
            .or(c.axial_rests.as_ref().map(|r| format!(
                " ({} rests, {} samples, reading {:.3} m/s² with {:.3} m/s² of noise{}{})",
                r.rests,
                r.rest_samples,
                r.rest_m_s2,
                r.noise_m_s2,
                if r.upward_positive {
                    "; the channel reads upward positive"
                } else {
                    ""
                },
                r.travel_m
                    .zip(r.depth_cut_m)
                    .map_or(String::new(), |(moved, cut)| format!(
                        "; the bit travelled {moved:.2} m from its first rest to its last, the rate of \
                     penetration cut {cut:.2} m"
                    ))
            )))
            .unwrap_or_default(),
        c.depth_of_cut_mm.0,
        c.depth_of_cut_mm.1,
        c.weight_line.r_squared,
        c.torque_line.r_squared
    )?;
    for e in &c.estimates {
        writeln!(
            out,
            "{:<22} {:>10.4} {:<4} 90 % [{:.4}, {:.4}]",
            e.name,
            e.value,
            if e.unit == "1" { "" } else { e.unit },
            e.lo,
            e.hi
        )?;
    }
    Ok(())
}

/// The structures' probabilities, the check's rows and the verdict.
fn print_choice(out: &mut dyn Write, c: &Choice) -> std::io::Result<()> {
    let d = &c.drive;
    let noise = match (d.noise_speed_rpm, d.noise_wob_kn) {
        (Some(speed), Some(wob)) => format!("{speed:.2} rpm, {:.3} kN·m, {wob:.2} kN", d.noise_torque_knm),
        _ => format!("{:.3} kN·m of surface torque", d.noise_torque_knm),
    };
    writeln!(
        out,
        "{} samples ({:.1} s) at {:.1} rpm under {:.1} kN; the record's apparent noise: {noise}",
        d.samples, d.duration_s, d.omega_rpm, d.wob_kn
    )?;
    writeln!(
        out,
        "{} candidates simulated, the {} nearest the record decide",
        c.reference, c.accepted
    )?;
    // "near": its re-simulations from the candidates accepted near the record recognised as
    // it; "table": its candidates anywhere in the table, each left out of its own vote.
    writeln!(
        out,
        "{:<10} {:>6} {:>6} {:>6}  re-simulated records taken for",
        "structure", "P", "near", "table"
    )?;
    for s in &c.structures {
        let row = c.check.iter().find(|r| r.structure == s.structure);
        let recognised = row.map_or("-".to_string(), |r| format!("{:.0} %", 100.0 * r.recognised));
        let in_table = c
            .table_check
            .iter()
            .find(|r| r.structure == s.structure)
            .map_or("-".to_string(), |r| format!("{:.0} %", 100.0 * r.recognised));
        let taken = row.map_or(String::new(), |r| {
            r.classified_as
                .iter()
                .filter(|x| x.1 > 0)
                .map(|x| format!("{} {}", x.0, x.1))
                .collect::<Vec<_>>()
                .join(", ")
        });
        writeln!(
            out,
            "{:<10} {:>6.2} {:>6} {:>6}  {}",
            s.structure.to_string(),
            s.probability,
            recognised,
            in_table,
            taken
        )?;
    }
    writeln!(out, "the structure: {}", c.verdict)?;
    writeln!(out, "the family: {}", c.family.verdict)?;
    if let Some(s) = c.decided.and_then(|d| c.structures.iter().find(|s| s.structure == d)) {
        let medians: Vec<String> = s
            .estimates
            .iter()
            .map(|e| match e.unit.as_str() {
                "1" => format!("{} {:.4}", e.name, e.median),
                unit => format!("{} {:.4} {unit}", e.name, e.median),
            })
            .collect();
        writeln!(
            out,
            "{}'s accepted candidates, medians: {}",
            s.structure,
            medians.join(", ")
        )?;
    }
    Ok(())
}
