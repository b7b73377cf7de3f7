//! The `bitrock` binary: parse, validate, call the library, print. Bad input exits with
//! status 2 and a message naming the file, line, column or flag; other failures exit 1.

mod cli;
mod output;

use anyhow::Context;
use bitrock::data::{self, FieldData};
use bitrock::fit::{self, FitOptions};
use bitrock::simulate::{self, Initial, SimConfig};
use bitrock::stability::lumped::Lumped;
use bitrock::units::{RAD_S_PER_RPM, TorqueUnit};
use bitrock::{Error, Law};
use clap::Parser;
use cli::{Cli, Command, FitArgs};
use std::io::Write;
use std::process::ExitCode;

fn main() -> ExitCode {
    match run(Cli::parse()) {
        Ok(code) => code,
        Err(err) => {
            eprintln!("error: {err:#}");
            let bad_input = err
                .chain()
                .any(|e| e.downcast_ref::<Error>().is_some_and(Error::is_bad_input));
            ExitCode::from(if bad_input { 2 } else { 1 })
        }
    }
}

fn run(cli: Cli) -> anyhow::Result<ExitCode> {
    match cli.command {
        Command::Fit(cmd) => {
            let opts = cmd.data_args.options();
            let data = match &cmd.data {
                Some(path) => data::read_field_data(path, &opts)?,
                None => {
                    eprintln!("note: no DATA given; using the embedded synthetic demo record");
                    data::demo_field_data(&opts)?
                }
            };
            fit_and_print(&data, &cmd.fit, cmd.json)?;
        }
        Command::Simulate(cmd) => simulate_cmd(&cmd)?,
        Command::Demo(cmd) => {
            let data = data::demo_field_data(&data::DataOptions::default())?;
            if !cmd.json {
                println!(
                    "bitrock demo: the embedded record is synthetic (made by `bitrock simulate`, see data/README.md);"
                );
                println!("the paper's field data are not public.\n");
            }
            fit_and_print(&data, &cmd.fit, cmd.json)?;
        }
    }
    Ok(ExitCode::SUCCESS)
}

/// Validated fit options from the flags.
fn fit_options(args: &FitArgs, data: &FieldData) -> anyhow::Result<FitOptions> {
    if !(args.w_ref_kn.is_finite() && args.w_ref_kn > 0.0) {
        return Err(Error::arg(
            "--w-ref-kn",
            format!("must be a positive number of kN, got {}", args.w_ref_kn),
        )
        .into());
    }
    if args.starts == 0 {
        return Err(Error::arg("--starts", "must be at least 1").into());
    }
    if args.scale_by_wob && data.calibration.wob_n.is_none() {
        return Err(Error::arg(
            "--scale-by-wob",
            "the record has no weight-on-bit column (name one with --wob-col)",
        )
        .into());
    }
    Ok(FitOptions {
        bounded: !args.no_bounds,
        starts: args.starts,
        w_ref_n: args.scale_by_wob.then_some(args.w_ref_kn * 1000.0),
    })
}

fn fit_and_print(data: &FieldData, args: &FitArgs, json: bool) -> anyhow::Result<()> {
    let opts = fit_options(args, data)?;
    let fits = fit::fit_laws(&args.laws, &data.calibration, &data.validation, &opts)?;
    let mut out = std::io::stdout().lock();
    if json {
        serde_json::to_writer_pretty(&mut out, &output::fit_json(data, &fits))?;
        writeln!(out)?;
    } else {
        output::print_fit_tables(&mut out, data, &fits)?;
    }
    Ok(())
}

fn simulate_cmd(cmd: &cli::SimulateCmd) -> anyhow::Result<()> {
    let law: Law = cmd.law;
    let params = cmd.params.clone().unwrap_or_else(|| {
        let p = law.paper_estimate();
        law.scale_torque(
            p,
            TorqueUnit::KNm.newton_metres() / cmd.param_torque_unit.newton_metres(),
        )
    });
    let config = SimConfig {
        law,
        params_nm: law.scale_torque(&params, cmd.param_torque_unit.newton_metres()),
        structure: Lumped {
            inertia_kg_m2: cmd.inertia_kg_m2,
            omega_n_rad_s: cmd.omega_n_rad_s,
            damping_ratio: cmd.damping_ratio,
        },
        omega_rad_s: cmd.omega_rpm * RAD_S_PER_RPM,
        wob_n: cmd.wob_kn * 1000.0,
        w_ref_n: cmd.w_ref_kn * 1000.0,
        duration_s: cmd.duration_s,
        settle_s: cmd.settle_s,
        sample_hz: cmd.sample_hz,
        dt_s: cmd.dt_s,
        initial: match cmd.initial {
            cli::InitialState::Equilibrium => Initial::Equilibrium {
                speed_perturbation_rad_s: cmd.kick_rpm * RAD_S_PER_RPM,
            },
            cli::InitialState::Rest => Initial::Rest,
        },
        noise_torque_nm: cmd.noise_torque_knm * 1000.0,
        noise_speed_rad_s: cmd.noise_speed_rpm * RAD_S_PER_RPM,
        wob_fluctuation_n: cmd.wob_fluctuation_kn * 1000.0,
        wob_correlation_s: cmd.wob_correlation_s,
        seed: cmd.seed,
    };
    config.validate()?;
    let trace = simulate::simulate(&config)?;
    match &cmd.out {
        None => simulate::write_csv(&trace, std::io::stdout().lock())?,
        Some(path) => {
            // Write beside the target and rename, so a failure leaves nothing half-written.
            let dir = path
                .parent()
                .filter(|d| !d.as_os_str().is_empty())
                .unwrap_or(std::path::Path::new("."));
            let mut tmp = tempfile::NamedTempFile::new_in(dir).map_err(|source| Error::Write {
                path: path.clone(),
                source,
            })?;
            simulate::write_csv(&trace, &mut tmp)?;
            tmp.persist(path)
                .map_err(|e| Error::Write {
                    path: path.clone(),
                    source: e.error,
                })
                .with_context(|| format!("saving the simulation to {}", path.display()))?;
        }
    }
    Ok(())
}
