//! `bitrock simulate`: the 1-DOF string with a bit-rock law, written as a field-like CSV; or a
//! well of formations (`--well FILE`), one continuous string through them.

use super::args::LumpedArgs;
use super::args::finite_number;
use bitrock::Law;
use bitrock::laws::PAPER_W_REF_N;
use bitrock::simulate::{self, Initial, Recording, SimConfig};
use bitrock::units::{RAD_S_PER_RPM, TorqueUnit};
use clap::{Args, ValueEnum};
use std::path::PathBuf;
use std::process::ExitCode;

/// Where the simulation starts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum InitialState {
    /// Steady rotation at the top-drive speed, with the bit speed kicked by --kick-rpm.
    Equilibrium,
    /// Everything at rest; the top drive starts at the set speed at t = 0.
    Rest,
}

#[derive(Debug, Args)]
pub struct SimulateCmd {
    /// A well file (TOML): segments in drilling order, each with its law, parameters, top-drive
    /// speed and weight on bit (values or ramps), simulated as one string; the record gains the
    /// columns top_drive_rpm and segment (format in docs/commands.md).
    #[arg(long, value_name = "FILE", conflicts_with_all = ["law", "params", "omega_rpm", "wob_kn", "duration_s", "settle_s", "sample_hz", "dt_s", "initial", "kick_rpm", "noise_torque_knm", "noise_speed_rpm", "wob_fluctuation_kn", "wob_correlation_s", "seed", "w_ref_kn", "param_torque_unit", "inertia_kg_m2", "omega_n_rad_s", "damping_ratio"])]
    pub well: Option<PathBuf>,
    #[arg(long, required_unless_present = "well", help = concat!(
        "Bit-rock law (one of ",
        bitrock::built_in_law_list!(),
        ", or a --law-file's law by its name)"
    ))]
    pub law: Option<String>,
    /// The law's parameters in its order (m2: tsb,tcb,g), torques in --param-torque-unit
    /// [default: the paper's least-squares estimate].
    #[arg(long, value_parser = finite_number, value_delimiter = ',', allow_hyphen_values = true, value_name = "P1,P2,...")]
    pub params: Option<Vec<f64>>,
    /// Torque unit of the torque-valued parameters in --params.
    #[arg(long, value_enum, default_value_t = TorqueUnit::KNm)]
    pub param_torque_unit: TorqueUnit,
    /// Top-drive (rotary table) speed Omega, rpm.
    #[arg(long, value_parser = finite_number, value_name = "RPM", required_unless_present = "well", allow_hyphen_values = true)]
    pub omega_rpm: Option<f64>,
    /// Weight on bit W, kN.
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, default_value_t = PAPER_W_REF_N / 1000.0, value_name = "KN")]
    pub wob_kn: f64,
    /// Reference weight on bit W_ref at which the law's parameters hold, kN.
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, default_value_t = PAPER_W_REF_N / 1000.0, value_name = "KN")]
    pub w_ref_kn: f64,
    #[command(flatten)]
    pub lumped: LumpedArgs,
    /// Recorded duration, s.
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, default_value_t = 60.0, value_name = "SECONDS")]
    pub duration_s: f64,
    /// Simulated time discarded before recording starts (lets a limit cycle settle), s.
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, default_value_t = 0.0, value_name = "SECONDS")]
    pub settle_s: f64,
    /// Output sample rate, Hz (the paper's downhole tool records at 50 Hz).
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, default_value_t = 50.0, value_name = "HZ")]
    pub sample_hz: f64,
    /// Integration step of the RK4 scheme, s.
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, default_value_t = 1e-3, value_name = "SECONDS")]
    pub dt_s: f64,
    /// Initial state.
    #[arg(long, value_enum, default_value_t = InitialState::Equilibrium)]
    pub initial: InitialState,
    /// Bit-speed kick added to steady rotation at t = 0 (with --initial equilibrium), rpm.
    #[arg(long, value_parser = finite_number, default_value_t = simulate::DEFAULT_KICK_RPM, value_name = "RPM", allow_hyphen_values = true)]
    pub kick_rpm: f64,
    /// Standard deviation of Gaussian noise added to the recorded torque, kN·m.
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, default_value_t = 0.0, value_name = "KNM")]
    pub noise_torque_knm: f64,
    /// Standard deviation of Gaussian noise added to the recorded bit speed, rpm.
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, default_value_t = 0.0, value_name = "RPM")]
    pub noise_speed_rpm: f64,
    /// Standard deviation of a slow random fluctuation of the weight on bit, kN.
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, default_value_t = 0.0, value_name = "KN")]
    pub wob_fluctuation_kn: f64,
    /// Correlation time of the weight-on-bit fluctuation, s.
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, default_value_t = 20.0, value_name = "SECONDS")]
    pub wob_correlation_s: f64,
    /// Seed of the noise and fluctuation generator.
    #[arg(long, default_value_t = simulate::DEFAULT_SEED)]
    pub seed: u64,
    /// Scale of the output's torque and weight on bit: knm writes torque_knm and wob_kn (field
    /// records), nm writes torque_nm and wob_n (laboratory rigs, whose torques of a few N·m
    /// need the finer resolution).
    #[arg(long, value_enum, default_value_t = TorqueUnit::KNm)]
    pub torque_unit: TorqueUnit,
    /// Channels recorded: the bit's (a downhole memory tool's), the surface's (what a rig
    /// streams: top_drive_rpm, surface_torque_knm, wob_kn), all of them, or the surface's with
    /// an MWD tool's stick-slip channels (downhole_min_rpm, downhole_max_rpm: the bit speed's
    /// least and greatest since the sample before).
    #[arg(long, value_enum, default_value_t = simulate::Channels::Bit)]
    pub channels: simulate::Channels,
    /// Output CSV (time_s, bit_speed_rpm, torque_knm, wob_kn; torque_nm, wob_n with
    /// --torque-unit nm; see --channels) [default: standard output].
    #[arg(long, short, value_name = "FILE")]
    pub out: Option<PathBuf>,
    /// Replace FILE even when bitrock did not write it (or it was changed since); without it
    /// only bitrock's own unchanged output is replaced.
    #[arg(long, requires = "out")]
    pub force: bool,
}

pub fn run(cmd: &SimulateCmd) -> anyhow::Result<ExitCode> {
    if let Some(path) = &cmd.well {
        return run_well(cmd, path);
    }
    let law: Law = super::args::parse_law(cmd.law.as_deref().expect("clap requires --law without --well"))?;
    let omega_rpm = cmd.omega_rpm.expect("clap requires --omega-rpm without --well");
    let params = match (&cmd.params, law.paper_estimate()) {
        (Some(params), _) => params.clone(),
        (None, Some(p)) => law.scale_torque(
            p,
            TorqueUnit::KNm.newton_metres() / cmd.param_torque_unit.newton_metres(),
        ),
        (None, None) => {
            return Err(bitrock::Error::setting(
                "params",
                format!("law {law} has no reference values to default to; give its parameters"),
            )
            .into());
        }
    };
    let params_nm = law.scale_torque(&params, cmd.param_torque_unit.newton_metres());
    if let Some(warning) = law.implausible_torque(&params_nm, "param_torque_unit") {
        super::print::note(format_args!("warning: {warning}"));
    }
    let config = SimConfig {
        law,
        params_nm,
        structure: cmd.lumped.lumped(),
        omega_rad_s: omega_rpm * RAD_S_PER_RPM,
        wob_n: cmd.wob_kn * 1000.0,
        w_ref_n: cmd.w_ref_kn * 1000.0,
        duration_s: cmd.duration_s,
        recording: Recording {
            settle_s: cmd.settle_s,
            sample_hz: cmd.sample_hz,
            dt_s: cmd.dt_s,
            initial: match cmd.initial {
                InitialState::Equilibrium => Initial::Equilibrium {
                    speed_perturbation_rad_s: cmd.kick_rpm * RAD_S_PER_RPM,
                },
                InitialState::Rest => Initial::Rest,
            },
            noise_torque_nm: cmd.noise_torque_knm * 1000.0,
            noise_speed_rad_s: cmd.noise_speed_rpm * RAD_S_PER_RPM,
            wob_fluctuation_n: cmd.wob_fluctuation_kn * 1000.0,
            wob_correlation_s: cmd.wob_correlation_s,
            seed: cmd.seed,
        },
    };
    config.validate()?;
    if let Some(path) = &cmd.out {
        bitrock::run::dir::check_output_file(path, "out", cmd.force)?;
    }
    let mut progress = super::progress::WorkProgress::new("simulating");
    let record = simulate::simulate_record_with(&config, &mut |done, total| progress.update(done, total))?;
    drop(progress);
    write(cmd, &record, None)
}

/// The record's chosen channels to `--out` or standard output.
fn write(cmd: &SimulateCmd, record: &simulate::WellTrace, well: Option<&simulate::Well>) -> anyhow::Result<ExitCode> {
    let csv =
        |out: &mut dyn std::io::Write| simulate::write_record_csv(record, well, cmd.channels, cmd.torque_unit, out);
    match &cmd.out {
        None => csv(&mut super::print::stdout())?,
        Some(path) => bitrock::run::dir::write_whole(path, "out", cmd.force, |file| csv(file))?,
    }
    Ok(ExitCode::SUCCESS)
}

/// `--well FILE`: the well's record, with its top-drive speed and segment columns.
fn run_well(cmd: &SimulateCmd, path: &std::path::Path) -> anyhow::Result<ExitCode> {
    let well = simulate::Well::load(path)?;
    if let Some(path) = &cmd.out {
        bitrock::run::dir::check_output_file(path, "out", cmd.force)?;
    }
    let mut progress = super::progress::WorkProgress::new("simulating");
    let record = simulate::simulate_well_with(&well, &mut |done, total| progress.update(done, total))?;
    drop(progress);
    write(cmd, &record, Some(&well))
}
