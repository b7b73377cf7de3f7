//! `bitrock stability`: maps over (Ω, W) from an ABC run directory, a posterior's particles or
//! one law's parameters: deterministic, percentile and mixture boundaries, and the probability grids.

use super::args::StructureArgs;
use super::args::finite_number;
use bitrock::Error;
use bitrock::eval::Backend;
use bitrock::laws::PAPER_W_REF_N;
use bitrock::pipeline::stability::{DEFAULT_OMEGA_RPM, DEFAULT_PERCENT, DEFAULT_SAMPLES, DEFAULT_WOB_KN, Structure};
use bitrock::pipeline::{MapSource, StabilityJob};
use bitrock::stability::map::{self, Criterion};
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
    /// or an evidence directory (`bitrock evidence --out`): its posterior.
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
    /// an evidence directory's own where its evidence scaled each torque by WOB / W_ref].
    #[arg(long, value_parser = finite_number, value_name = "KN")]
    pub w_ref_kn: Option<f64>,
    /// Top-drive speeds, rpm, as MIN:MAX:COUNT.
    #[arg(long, default_value = DEFAULT_OMEGA_RPM, value_name = "MIN:MAX:COUNT")]
    pub omega_rpm: String,
    /// Weights on bit, kN, as MIN:MAX:COUNT.
    #[arg(long, default_value = DEFAULT_WOB_KN, value_name = "MIN:MAX:COUNT")]
    pub wob_kn: String,
    /// Percentile of the stochastic boundary, %: the weight on bit above which at least this
    /// share of the posterior samples is unstable (the paper's 2 %).
    #[arg(long, value_parser = finite_number, default_value_t = DEFAULT_PERCENT, value_name = "PERCENT")]
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
}

/// A named boundary column of the table and the CSV: kN per speed, `None` where none.
type Column = (String, Vec<Option<f64>>);

pub fn run(cmd: &StabilityCmd) -> anyhow::Result<ExitCode> {
    let omega = map::parse_axis(&cmd.omega_rpm, "omega_rpm")?;
    let wob = map::parse_axis(&cmd.wob_kn, "wob_kn")?;
    if let Some(path) = &cmd.out {
        bitrock::run::dir::check_output_file(path, "out", cmd.force)?;
    }
    let (source, own_w_ref_n) = map_source(cmd)?;
    let w_ref_n = match (cmd.w_ref_kn, own_w_ref_n) {
        (Some(kn), _) => kn * 1000.0,
        (None, Some(n)) => {
            super::print::note(format_args!(
                "note: the posterior's torque parameters are for W_ref = {:.3} kN (its evidence scaled each torque by WOB / W_ref): mapped at that reference",
                n / 1000.0
            ));
            n
        }
        (None, None) => PAPER_W_REF_N,
    };
    let job = StabilityJob {
        source,
        omega_rpm: omega,
        wob_kn: wob,
        criterion: Criterion::Lumped(cmd.string.lumped.lumped()),
        w_ref_n,
        percentile: cmd.percentile / 100.0,
        samples: cmd.samples,
        backend: cmd.backend,
    }
    .on(
        cmd.string.structure,
        cmd.string.lumped.lumped(),
        &cmd.string.fe.settings(),
    )?;
    let maps = job.run(&mut |line| super::print::note(line))?;
    if let (MapSource::Run(dir), Some(why)) = (&job.source, &maps.early_end) {
        super::print::note(format_args!("note: {}: {why}", dir.display()));
    }
    let (omega, wob) = (&job.omega_rpm, &job.wob_kn);
    let c = job.criterion.critical_nms();
    let mut boundaries = serde_json::Map::new();
    let mut grids = serde_json::Map::new();
    let mut columns: Vec<Column> = Vec::new();
    for ((input, b), grid) in maps.inputs.iter().zip(maps.boundaries.laws).zip(&maps.grids) {
        // Unknown boundaries (the torque has no value) are null as "none" is: named here.
        let unknown: Vec<f64> = omega
            .iter()
            .zip(b.map_wob_kn.iter().zip(&b.p_wob_kn))
            .filter(|(_, (m, p))| m.is_some_and(f64::is_nan) || p.is_some_and(f64::is_nan))
            .map(|(rpm, _)| *rpm)
            .collect();
        boundaries.insert(input.law.name().into(), json!({"map_wob_kn": b.map_wob_kn, "p_wob_kn": b.p_wob_kn, "probability": b.probability, "samples": b.samples, "unknown_omega_rpm": unknown}));
        grids.insert(
            input.law.name().into(),
            json!(grid.chunks(wob.len()).collect::<Vec<_>>()),
        );
        columns.push((format!("{}_map_wob_kn", input.law), b.map_wob_kn));
        columns.push((format!("{}_p_wob_kn", input.law), b.p_wob_kn));
    }
    if let Some(mixture) = maps.boundaries.mixture_wob_kn {
        boundaries.insert("mixture".into(), json!({"p_wob_kn": mixture}));
        columns.push(("mixture_p_wob_kn".into(), mixture));
    }
    if let Some(path) = &cmd.out {
        bitrock::run::dir::write_whole(path, "out", cmd.force, |file| {
            file.write_all(&boundaries_csv(omega, &columns))
        })?;
    }
    let mut out = super::print::stdout();
    if cmd.json {
        let v = json!({
            "structure": match cmd.string.structure { Structure::Lumped => "1dof", Structure::Fe => "fe" },
            "critical_bit_damping_nms": c,
            "percentile": cmd.percentile,
            "omega_rpm": omega,
            "wob_kn": wob,
            "boundaries": boundaries,
            "probability_unstable": grids,
        });
        super::print::json(&mut out, v)?;
    } else {
        print_table(&mut out, cmd.string.structure, c, omega, &columns)?;
    }
    Ok(ExitCode::SUCCESS)
}

/// Whose maps: `--run` (a run or an evidence directory), `--posterior`, or `--law` at
/// `--params` (in `--torque-unit`, made SI here); and the W_ref (N) an evidence directory's
/// torque parameters are for, where its evidence scaled them.
fn map_source(cmd: &StabilityCmd) -> anyhow::Result<(MapSource, Option<f64>)> {
    if let Some(path) = &cmd.posterior {
        return Ok((
            MapSource::Posterior(bitrock::documents::read_particles_csv(path)?),
            None,
        ));
    }
    match (&cmd.run, &cmd.law, &cmd.params) {
        (Some(dir), _, _) if bitrock::run::dir::is_evidence_dir(dir) => {
            let (particles, w_ref_n) = bitrock::pipeline::evidence::dir::posterior(dir)?;
            Ok((MapSource::Posterior(particles), w_ref_n))
        }
        (Some(dir), _, _) => Ok((MapSource::Run(dir.clone()), None)),
        (None, Some(law), Some(params)) => Ok((
            MapSource::law(super::args::parse_law(law)?, params, cmd.torque_unit)?,
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
