//! `bitrock stability`: maps over (Ω, W) from an ABC run directory, a posterior's particles or
//! one law's parameters: deterministic, percentile and mixture boundaries, and the probability grids.

use super::args::StructureArgs;
use super::args::finite_number;
use bitrock::Error;
use bitrock::data::BitSeen;
use bitrock::eval::Backend;
use bitrock::eval::strings::Ran;
use bitrock::eval::surface::InferredString;
use bitrock::laws::PAPER_W_REF_N;
use bitrock::run;
use bitrock::run::advice::{self, Adviser};
use bitrock::run::stability::{DEFAULT_OMEGA_RPM, DEFAULT_PERCENT, DEFAULT_SAMPLES, DEFAULT_WOB_KN, Structure};
use bitrock::run::stability::{MapSource, StabilityJob};
use bitrock::run::strings::{self, Grid, OperatingPoint, SimulatedJob, SimulatedMaps, SimulatedSettings};
use bitrock::simulate::strings::Chain;
use bitrock::stability::map::{self, Criterion, LawSamples};
use bitrock::units::TorqueUnit;
use clap::Args;
use serde_json::json;
use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

/// Which structure decides stability.

#[derive(Debug, Args)]
pub struct StabilityCmd {
    /// ABC run directory (from `bitrock abc`): MAP, posterior samples and law probabilities;
    /// an evidence directory (`bitrock evidence --out`) or a surface directory (`bitrock
    /// surface --out`): its posterior, on the string it was computed for.
    #[arg(long, value_name = "DIR", conflicts_with_all = ["law", "params", "posterior"])]
    pub run: Option<PathBuf>,
    /// Weighted posterior particles as CSV (`bitrock evidence --posterior-out`, `bitrock export
    /// --population G`, or any sampler's in that layout): each law's share of the weight is
    /// its probability.
    #[arg(long, value_name = "FILE", conflicts_with_all = ["law", "params"])]
    pub posterior: Option<PathBuf>,
    #[arg(long, requires = "params", help = concat!(
        "A law for a what-if map without a run (one of ",
        bitrock::built_in_law_list!(),
        ", or a --law-file's law by its name)"
    ))]
    pub law: Option<String>,
    /// The law's parameters in its order, torques in --torque-unit.
    #[arg(long, value_parser = finite_number, value_delimiter = ',', allow_hyphen_values = true, value_name = "P1,P2,...")]
    pub params: Option<Vec<f64>>,
    /// Unit of the torque-valued parameters in --params.
    #[arg(long, value_enum, default_value_t = TorqueUnit::KNm)]
    pub torque_unit: TorqueUnit,
    #[command(flatten)]
    pub string: StructureArgs,
    /// Reference weight on bit W_ref of the law's parameters, kN [default: the paper's 244.2;
    /// an evidence directory's own where its evidence scaled each torque by WOB / W_ref; a
    /// surface directory's own, or its record's mean weight on bit].
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, value_name = "KN")]
    pub w_ref_kn: Option<f64>,
    /// Top-drive speeds, rpm, as MIN:MAX:COUNT.
    #[arg(long, default_value = DEFAULT_OMEGA_RPM, value_name = "MIN:MAX:COUNT")]
    pub omega_rpm: String,
    /// Weights on bit, kN, as MIN:MAX:COUNT.
    #[arg(long, default_value = DEFAULT_WOB_KN, value_name = "MIN:MAX:COUNT")]
    pub wob_kn: String,
    /// Percentile of the stochastic boundary, %: the weight on bit above which at least this
    /// share of the posterior samples is unstable (the paper's 2 %).
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, default_value_t = DEFAULT_PERCENT, value_name = "PERCENT")]
    pub percentile: f64,
    /// Posterior samples per law for the stochastic maps (the paper's 700).
    #[arg(long, default_value_t = DEFAULT_SAMPLES, value_name = "S")]
    pub samples: usize,
    /// Where the probability grids are computed (auto, gpu, cpu).
    #[arg(long, value_enum, default_value_t = Backend::Auto)]
    pub backend: Backend,
    /// Write the boundaries as CSV to FILE.
    #[arg(long, short, value_name = "FILE")]
    pub out: Option<PathBuf>,
    /// Replace FILE even when bitrock did not write it (or it was changed since); without it
    /// only bitrock's own unchanged output is replaced.
    #[arg(long, requires = "out")]
    pub force: bool,
    /// Print JSON (boundaries and probability grids) instead of a table.
    #[arg(long)]
    pub json: bool,
    /// Also map stick-slip by simulating the string in time for every posterior sample and
    /// cell: the onset from steady rotation kicked by a tenth of the speed, and from the
    /// operating point (--at-rpm and --at-kn, or the record's) the escape from the state the
    /// bit is in there, the bistable band between them, and the nearest speed and weight on
    /// bit that end the stick-slip.
    #[arg(long)]
    pub simulate: bool,
    /// Top-drive speed the rig turns at now, rpm: where the escape map and the advice start
    /// [default: a run's or an evidence's record's mean bit speed and weight on bit].
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, requires_all = ["simulate", "at_kn"], value_name = "RPM")]
    pub at_rpm: Option<f64>,
    /// Weight on bit the rig drills with now, kN.
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, requires_all = ["simulate", "at_rpm"], value_name = "KN")]
    pub at_kn: Option<f64>,
    /// Top-drive speeds of the simulated maps, rpm, as MIN:MAX:COUNT.
    #[arg(long, default_value = strings::DEFAULT_OMEGA_RPM, value_name = "MIN:MAX:COUNT")]
    pub sim_omega_rpm: String,
    /// Weights on bit of the simulated maps, kN, as MIN:MAX:COUNT.
    #[arg(long, default_value = strings::DEFAULT_WOB_KN, value_name = "MIN:MAX:COUNT")]
    pub sim_wob_kn: String,
    /// Posterior samples per law simulated in every cell.
    #[arg(long, default_value_t = strings::DEFAULT_SAMPLES, value_name = "S")]
    pub sim_samples: usize,
    /// Integration step of the simulated strings, s (checked against the string's fastest mode).
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, default_value_t = bitrock::run::strings::DEFAULT_DT_S, value_name = "S")]
    pub dt_s: f64,
}

/// A named boundary column of the table and the CSV: kN per speed, `None` where none.
type Column = (String, Vec<Option<f64>>);

pub fn run(cmd: &StabilityCmd) -> anyhow::Result<ExitCode> {
    let omega = map::parse_axis(&cmd.omega_rpm, "omega_rpm")?;
    let wob = map::parse_axis(&cmd.wob_kn, "wob_kn")?;
    if let Some(path) = &cmd.out {
        bitrock::run::dir::check_output_file(path, "out", cmd.force)?;
    }
    let (source, own_w_ref_n, evidence_bit) = map_source(cmd)?;
    let w_ref_n = map_w_ref_n(cmd.w_ref_kn, own_w_ref_n);
    // A run's own string, under what the flags give.
    let stored = cmd
        .run
        .as_deref()
        .map(run::stability::stored_string)
        .transpose()?
        .flatten();
    // A surface run that inferred its string: every sample's own for the simulated strings.
    let sample_strings = cmd
        .run
        .as_deref()
        .map(|dir| run::stability::sample_strings(dir, &cmd.string.given()))
        .transpose()?
        .flatten();
    if let Some(string) = &stored {
        super::print::note(format_args!("note: the run's own drill string: {}", string.describe()));
    }
    if sample_strings.is_some() {
        super::print::note(format_args!(
            "note: the run inferred its string with the laws: the linear maps take the posterior medians above, the simulated strings each sample's own"
        ));
    }
    let (structure, lumped, fe) = cmd.string.over(stored.as_ref());
    let job = StabilityJob {
        source,
        omega_rpm: omega,
        wob_kn: wob,
        criterion: Criterion::Lumped(lumped),
        w_ref_n,
        percentile: cmd.percentile / 100.0,
        samples: cmd.samples,
        backend: cmd.backend,
    }
    .on(structure, lumped, &fe, &mut |line| super::print::note(line))?;
    let maps = job.run(&mut |line| super::print::note(line))?;
    if let (MapSource::Run(dir), Some(why)) = (&job.source, &maps.early_end) {
        super::print::note(format_args!("note: {}: {why}", dir.display()));
    }
    let (omega, wob) = (&job.omega_rpm, &job.wob_kn);
    let c = job.criterion.critical_nms();
    let (boundaries, grids, columns) = boundary_columns(&maps, omega, wob.len());
    if let Some(path) = &cmd.out {
        bitrock::run::dir::write_whole(path, "out", cmd.force, |file| {
            file.write_all(&boundaries_csv(omega, &columns))
        })?;
    }
    let record_bit = maps.record_bit.or(evidence_bit);
    if cmd.run.is_some() && record_bit.is_none() {
        super::print::note(format_args!(
            "note: the directory's record was kept without what its bit did (stored by an older bitrock): no advice for its operating point"
        ));
    }
    // A string the simulator cannot hold is refused where the simulated maps are asked for;
    // the record's advice then says only what the linear maps can.
    let chain = strings::chain(structure, &lumped, &fe);
    // At the record, the parameters are for the W_ref its posterior was scaled to, or for
    // the weight on bit it drilled with.
    let scaled_w_ref_n = cmd
        .w_ref_kn
        .map(|kn| kn * 1000.0)
        .or(own_w_ref_n.map(|(n, _)| n))
        .or(maps.run_w_ref_n);
    let at_record = record_bit.map(|seen| (seen, advice::params_w_ref_n(scaled_w_ref_n, &seen, w_ref_n)));
    // Each sample's string, where the run inferred it, for the simulated strings.
    let sim_inputs = match (&sample_strings, &cmd.run) {
        (Some(_), Some(dir)) => run::stability::with_sample_strings(dir, &maps.inputs, cmd.samples)?,
        _ => maps.inputs.clone(),
    };
    let advice = at_record.map(|(seen, record_w_ref_n)| {
        let adviser = Adviser::for_record(job.criterion, chain.as_ref().ok().cloned(), cmd.backend)
            .with_sample_strings(sample_strings);
        (seen, adviser.advise_record(&sim_inputs, record_w_ref_n, &seen))
    });
    let simulated = if cmd.simulate {
        let (at, sim_w_ref_n) = match (cmd.at_rpm, cmd.at_kn, at_record) {
            (Some(omega_rpm), Some(wob_kn), _) => (Some(OperatingPoint { omega_rpm, wob_kn }), w_ref_n),
            (_, _, Some((seen, record_w_ref_n))) => (Some(advice::record_point(&seen, record_w_ref_n)), record_w_ref_n),
            _ => (None, w_ref_n),
        };
        Some(simulate(cmd, chain?, sample_strings, at, &sim_inputs, sim_w_ref_n)?)
    } else {
        None
    };
    let mut out = super::print::stdout();
    if cmd.json {
        let mut v = json!({
            "structure": match structure { Structure::Lumped => "1dof", Structure::Fe => "fe" },
            "critical_bit_damping_nms": c,
            "percentile": cmd.percentile,
            "omega_rpm": omega,
            "wob_kn": wob,
            "boundaries": boundaries,
            "probability_unstable": grids,
        });
        if let Some(sim) = &simulated {
            v["simulated"] = simulated_json(sim);
        }
        if let Some((seen, advice)) = &advice {
            v["record"] = json!(seen);
            v["advice"] = json!(advice);
        }
        super::print::json(&mut out, v)?;
    } else {
        print_table(&mut out, structure, c, omega, &columns)?;
        if let Some(sim) = &simulated {
            print_simulated(sim, &mut out)?;
        }
        if let Some((_, advice)) = &advice {
            writeln!(out, "\nadvice at the record's operating point: {}", advice.words)?;
        }
    }
    Ok(ExitCode::SUCCESS)
}

/// W_ref of the maps, N: the one given, else the posterior's own (said), else the paper's.
fn map_w_ref_n(w_ref_kn: Option<f64>, own_w_ref_n: Option<OwnWRef>) -> f64 {
    match (w_ref_kn, own_w_ref_n) {
        (Some(kn), _) => kn * 1000.0,
        (None, Some((n, why))) => {
            super::print::note(format_args!(
                "note: the posterior's torque parameters are for W_ref = {:.3} kN ({why}): mapped at that reference",
                n / 1000.0
            ));
            n
        }
        (None, None) => PAPER_W_REF_N,
    }
}

/// Each law's boundaries (and the mixture's) as JSON and as the table's columns, and each
/// law's probability grid over `omega` × `n_wob` cells; an unknown boundary (the torque has
/// no value there) named by its speed.
fn boundary_columns(
    maps: &bitrock::run::stability::StabilityMaps,
    omega: &[f64],
    n_wob: usize,
) -> (
    serde_json::Map<String, serde_json::Value>,
    serde_json::Map<String, serde_json::Value>,
    Vec<Column>,
) {
    let mut boundaries = serde_json::Map::new();
    let mut grids = serde_json::Map::new();
    let mut columns: Vec<Column> = Vec::new();
    for ((input, b), grid) in maps.inputs.iter().zip(maps.boundaries.laws.clone()).zip(&maps.grids) {
        // Unknown boundaries (the torque has no value) are null as "none" is: named here.
        let unknown: Vec<f64> = omega
            .iter()
            .zip(b.map_wob_kn.iter().zip(&b.p_wob_kn))
            .filter(|(_, (m, p))| m.is_some_and(f64::is_nan) || p.is_some_and(f64::is_nan))
            .map(|(rpm, _)| *rpm)
            .collect();
        boundaries.insert(input.law.name().into(), json!({"map_wob_kn": b.map_wob_kn, "p_wob_kn": b.p_wob_kn, "probability": b.probability, "samples": b.samples, "unknown_omega_rpm": unknown}));
        grids.insert(input.law.name().into(), json!(grid.chunks(n_wob).collect::<Vec<_>>()));
        columns.push((format!("{}_map_wob_kn", input.law), b.map_wob_kn));
        columns.push((format!("{}_p_wob_kn", input.law), b.p_wob_kn));
    }
    if let Some(mixture) = maps.boundaries.mixture_wob_kn.clone() {
        boundaries.insert("mixture".into(), json!({"p_wob_kn": mixture}));
        columns.push(("mixture_p_wob_kn".into(), mixture));
    }
    (boundaries, grids, columns)
}

/// The simulated maps on `chain` (each sample's own string where `sample_strings` is set),
/// the escape map and its advice from `at` where known.
fn simulate(
    cmd: &StabilityCmd,
    chain: Chain,
    sample_strings: Option<InferredString>,
    at: Option<OperatingPoint>,
    inputs: &[LawSamples],
    w_ref_n: f64,
) -> anyhow::Result<SimulatedMaps> {
    let job = SimulatedJob {
        settings: SimulatedSettings {
            dt_s: cmd.dt_s,
            string: sample_strings,
            ..SimulatedSettings::new(chain, w_ref_n, cmd.backend)
        },
        omega_rpm: map::parse_axis(&cmd.sim_omega_rpm, "sim_omega_rpm")?,
        wob_kn: map::parse_axis(&cmd.sim_wob_kn, "sim_wob_kn")?,
        samples: cmd.sim_samples,
        at,
    };
    Ok(job.run(inputs, &mut |line| super::print::note(line))?)
}

/// Where the strings ran, in words.
fn ran(maps: &SimulatedMaps) -> String {
    maps.ran.as_ref().unwrap_or(&Ran::Cpu).to_string()
}

fn grid_json(grid: &Grid) -> serde_json::Value {
    let rows: Vec<Vec<Option<f64>>> = grid
        .probability
        .chunks(grid.wob_kn.len())
        .map(|r| r.iter().map(|p| (!p.is_nan()).then_some(*p)).collect())
        .collect();
    let diverged: Vec<&[f64]> = grid.diverged_weight.chunks(grid.wob_kn.len()).collect();
    json!({"omega_rpm": grid.omega_rpm, "wob_kn": grid.wob_kn, "probability": rows, "diverged_strings": grid.diverged, "diverged_share": diverged})
}

/// The simulated maps in `--json`.
fn simulated_json(maps: &SimulatedMaps) -> serde_json::Value {
    let mut v = json!({
        "onset": grid_json(&maps.onset),
        "onset_boundary_wob_kn": maps.onset.boundary_wob_kn(0.5),
        "strings": maps.strings,
        "simulated_string_s": maps.simulated_s,
        "wall_s": maps.wall_s,
        "backend": ran(maps),
    });
    if let Some((grid, advice)) = &maps.escape {
        v["escape"] = grid_json(grid);
        v["escape_boundary_wob_kn"] = json!(grid.boundary_wob_kn(0.5));
        v["advice"] = json!({
            "at_rpm": advice.point.omega_rpm,
            "at_kn": advice.point.wob_kn,
            "stick_slip_probability": advice.stick_slip_probability,
            "speed_rpm": advice.speed_rpm.map(|w| w.to),
            "speed_end_probability": advice.speed_rpm.map(|w| w.ends_probability),
            "speed_diverged_share": advice.speed_rpm.map(|w| w.diverged_share),
            "wob_kn": advice.wob_kn.map(|w| w.to),
            "wob_end_probability": advice.wob_kn.map(|w| w.ends_probability),
            "wob_diverged_share": advice.wob_kn.map(|w| w.diverged_share),
            "text": advice.text(),
        });
    }
    v
}

/// The simulated maps as a table: per speed, the lightest weight from which stick-slip
/// develops and persists, and the advice.
fn print_simulated(maps: &SimulatedMaps, out: &mut impl Write) -> std::io::Result<()> {
    writeln!(
        out,
        "\nsimulated strings ({} strings, {:.3e} string-seconds in {:.1} s on the {}): weight on bit (kN) from which stick-slip",
        maps.strings,
        maps.simulated_s,
        maps.wall_s,
        ran(maps)
    )?;
    let onset = maps.onset.boundary_wob_kn(0.5);
    let escape = maps.escape.as_ref().map(|(g, _)| g.boundary_wob_kn(0.5));
    write!(out, "{:>9}  {:>22}", "omega_rpm", "develops (P ≥ 0.5)")?;
    if escape.is_some() {
        write!(out, "  {:>22}", "persists (P ≥ 0.5)")?;
    }
    writeln!(out)?;
    let cell = |v: Option<f64>| {
        v.map(|v| unknown_or(v, format!("{v:.0}")))
            .unwrap_or_else(|| "—".into())
    };
    for (i, rpm) in maps.onset.omega_rpm.iter().enumerate() {
        write!(out, "{rpm:>9.1}  {:>22}", cell(onset[i]))?;
        if let Some(e) = &escape {
            write!(out, "  {:>22}", cell(e[i]))?;
        }
        writeln!(out)?;
    }
    if let Some((_, advice)) = &maps.escape {
        if escape.is_some() {
            writeln!(
                out,
                "(persists: from the state the bit is in at {:.0} rpm and {:.0} kN; between the columns lies the bistable band)",
                advice.point.omega_rpm, advice.point.wob_kn
            )?;
        }
        if advice.stick_slip_probability >= 0.5 {
            writeln!(out, "advice: {}", advice.text())?;
        } else {
            writeln!(
                out,
                "advice: steady rotation at {:.0} rpm and {:.0} kN (simulated P(stick-slip) = {:.2})",
                advice.point.omega_rpm, advice.point.wob_kn, advice.stick_slip_probability
            )?;
        }
    }
    Ok(())
}

/// A directory's own W_ref (N) and why it holds, in words.
type OwnWRef = (f64, &'static str);

/// Whose maps: `--run` (a run, an evidence or a surface directory), `--posterior`, or `--law`
/// at `--params` (in `--torque-unit`, made SI here); the W_ref (N) an evidence or a surface
/// directory's torque parameters are for, where it has its own, and why; and what its
/// record's bit did (a surface run's: as the surface implies it).
fn map_source(cmd: &StabilityCmd) -> anyhow::Result<(MapSource, Option<OwnWRef>, Option<BitSeen>)> {
    if let Some(path) = &cmd.posterior {
        return Ok((
            MapSource::Posterior(bitrock::documents::read_particles_csv(path)?),
            None,
            None,
        ));
    }
    match (&cmd.run, &cmd.law, &cmd.params) {
        (Some(dir), _, _) if bitrock::run::dir::is_evidence_dir(dir) => {
            let (particles, w_ref_n) = bitrock::run::evidence::dir::posterior(dir)?;
            let bit = bitrock::run::evidence::dir::record(dir)?.bit;
            let own = w_ref_n.map(|n| (n, "its evidence scaled each torque by WOB / W_ref"));
            Ok((MapSource::Posterior(particles), own, bit))
        }
        (Some(dir), _, _) if bitrock::run::surface::dir::is_surface_dir(dir) => {
            let finished = bitrock::run::surface::dir::Finished::read(dir)?;
            let (particles, w_ref_n, why) = finished.posterior()?;
            let bit = finished.bit()?;
            super::print::note(format_args!(
                "note: the bit as the surface implies it (posterior medians): stuck {:.2} of the time at {:.1} rpm",
                bit.stuck_share, bit.mean_speed_rpm
            ));
            Ok((MapSource::Posterior(particles), Some((w_ref_n, why)), Some(bit)))
        }
        (Some(dir), _, _) => Ok((MapSource::Run(dir.clone()), None, None)),
        (None, Some(law), Some(params)) => Ok((
            MapSource::law(super::args::parse_law(law)?, params, cmd.torque_unit)?,
            None,
            None,
        )),
        _ => Err(Error::setting(
            "run",
            "give a run directory (--run DIR), a posterior (--posterior FILE) or a law (--law L --params P1,P2,...)",
        )
        .into()),
    }
}

/// `text`, or "unknown" where the boundary `v` is unknown (NaN: the torque has no value there).
fn unknown_or(v: f64, text: String) -> String {
    if v.is_nan() { "unknown".into() } else { text }
}

/// `--out`: one row per speed, the boundaries in kN to 4 decimals (empty where none, "unknown"
/// where the torque has no value).
fn boundaries_csv(omega_rpm: &[f64], columns: &[Column]) -> Vec<u8> {
    let mut w = csv::Writer::from_writer(Vec::new());
    let mut header = vec!["omega_rpm".to_string()];
    header.extend(columns.iter().map(|c| c.0.clone()));
    w.write_record(&header).expect("CSV into memory");
    for (i, rpm) in omega_rpm.iter().enumerate() {
        let mut row = vec![format!("{rpm}")];
        row.extend(
            columns
                .iter()
                .map(|c| c.1[i].map(|v| unknown_or(v, format!("{v:.4}"))).unwrap_or_default()),
        );
        w.write_record(&row).expect("CSV into memory");
    }
    w.into_inner().expect("CSV into memory")
}

/// The boundaries at about 20 of the speeds, for people.
fn print_table(
    out: &mut impl Write,
    structure: Structure,
    critical_nms: f64,
    omega_rpm: &[f64],
    columns: &[Column],
) -> std::io::Result<()> {
    writeln!(
        out,
        "critical bit damping c_b* = {critical_nms:.3} N·m·s/rad ({}); boundaries: weight on bit (kN) above which steady rotation is unstable",
        match structure {
            Structure::Lumped => "1-DOF",
            Structure::Fe => "finite elements",
        }
    )?;
    write!(out, "{:>9}", "omega_rpm")?;
    for (name, _) in columns {
        write!(out, "  {name:>18}")?;
    }
    writeln!(out)?;
    let step = (omega_rpm.len() / 20).max(1);
    for i in (0..omega_rpm.len()).step_by(step) {
        write!(out, "{:>9.1}", omega_rpm[i])?;
        for (_, values) in columns {
            write!(
                out,
                "  {:>18}",
                values[i]
                    .map(|v| unknown_or(v, format!("{v:.1}")))
                    .unwrap_or_else(|| "—".into())
            )?;
        }
        writeln!(out)?;
    }
    Ok(())
}
