//! `bitrock fe` and `bitrock stability`: the structure's critical bit damping, then maps over
//! (Ω, W) from an ABC run directory or from one law's parameters.

use crate::cli::{FeArgs, FeCmd, LumpedArgs, StabilityCmd, Structure};
use bitrock::eval::Backend;
use bitrock::stability::fe::DrillString;
use bitrock::stability::lumped::Lumped;
use bitrock::stability::map::{self, Criterion, LawSamples};
use bitrock::{Error, Law};
use serde_json::json;
use std::io::Write;
use std::path::Path;

/// The drill string from the file (or the paper's) with the flags' overrides, validated.
fn drill_string(args: &FeArgs) -> anyhow::Result<DrillString> {
    let mut s = match &args.fe_file {
        Some(path) => DrillString::from_toml_file(path)?,
        None => DrillString::default(),
    };
    if let Some(n) = args.dp_elements {
        s.dp_elements = n;
    }
    if let Some(n) = args.bha_elements {
        s.bha_elements = n;
    }
    if let Some(a) = args.alpha {
        s.alpha = a;
    }
    if let Some(b) = args.beta {
        s.beta = b;
    }
    s.validate()?;
    Ok(s)
}

fn lumped(args: &LumpedArgs) -> anyhow::Result<Lumped> {
    let l = args.lumped();
    l.validate()?;
    Ok(l)
}

pub fn fe_cmd(cmd: &FeCmd) -> anyhow::Result<()> {
    let mut string = drill_string(&cmd.fe)?;
    let lumped = lumped(&cmd.lumped)?;
    let mut matched_beta = None;
    if cmd.match_1dof {
        let (beta, _) = string.match_lumped_beta(&lumped)?;
        string.beta = beta;
        matched_beta = Some(beta);
    }
    let modes = string.modes()?;
    let critical = string.critical_bit_damping()?;
    let mut out = std::io::stdout().lock();
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
        serde_json::to_writer_pretty(&mut out, &v)?;
        writeln!(out)?;
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
    Ok(())
}

/// Reads the last population of a run directory's store: each law's MAP and probability and
/// `samples` of its particles ([`bitrock::abc::posterior::law_samples`]: the first ones, or a
/// systematic resample by weight for an SMC population), SI.
fn read_run(dir: &Path, samples: usize) -> anyhow::Result<Vec<LawSamples>> {
    let store = bitrock::store::RunStore::open(dir)?;
    let populations = store.load_populations()?;
    let last = populations.last().ok_or_else(|| Error::Data {
        path: dir.to_path_buf(),
        message: "the run has no completed population yet; continue it with `bitrock abc --resume`".into(),
    })?;
    let laws: Vec<Law> = last.record.per_law.iter().map(|l| l.law).collect();
    let posterior = bitrock::abc::posterior::summarize(&last.particles, &laws);
    Ok(posterior
        .laws
        .iter()
        .map(|summary| LawSamples {
            law: summary.law,
            probability: summary.probability,
            map_si: summary.map.clone(),
            samples_si: bitrock::abc::posterior::law_samples(&last.particles, summary.law, samples)
                .into_iter()
                .map(|p| p.params.clone())
                .collect(),
        })
        .collect())
}

/// Share of unstable samples per cell on the chosen backend.
fn probability_grid(
    input: &LawSamples,
    omega: &[f64],
    wob: &[f64],
    criterion: Criterion,
    w_ref_n: f64,
    backend: Backend,
) -> anyhow::Result<Vec<f64>> {
    if backend != Backend::Cpu {
        match bitrock::eval::gpu::stability::stability_grid(
            input.law,
            &input.samples_si,
            omega,
            wob,
            criterion,
            w_ref_n,
        ) {
            Ok((counts, _)) => {
                return Ok(counts
                    .iter()
                    .map(|&c| f64::from(c) / input.samples_si.len() as f64)
                    .collect());
            }
            Err(e) if backend == Backend::Gpu => return Err(e.into()),
            Err(e) => eprintln!("no usable GPU ({e}); computing the grid on the CPU"),
        }
    }
    Ok(map::probability_grid(
        input.law,
        &input.samples_si,
        omega,
        wob,
        criterion,
        w_ref_n,
    ))
}

pub fn stability_cmd(cmd: &StabilityCmd) -> anyhow::Result<()> {
    let omega = map::parse_axis(&cmd.omega_rpm, "--omega-rpm")?;
    let wob = map::parse_axis(&cmd.wob_kn, "--wob-kn")?;
    if !(cmd.percentile > 0.0 && cmd.percentile < 100.0) {
        return Err(Error::arg(
            "--percentile",
            format!("must lie in (0, 100) %, got {}", cmd.percentile),
        )
        .into());
    }
    if !(cmd.w_ref_kn.is_finite() && cmd.w_ref_kn > 0.0) {
        return Err(Error::arg(
            "--w-ref-kn",
            format!("must be a positive number of kN, got {}", cmd.w_ref_kn),
        )
        .into());
    }
    if cmd.samples == 0 {
        return Err(Error::arg("--samples", "must be at least 1").into());
    }
    let w_ref_n = cmd.w_ref_kn * 1000.0;
    let p = cmd.percentile / 100.0;
    let lumped = lumped(&cmd.lumped)?;
    let criterion = match cmd.structure {
        Structure::Lumped => Criterion::Lumped(lumped),
        Structure::Fe => Criterion::Critical(drill_string(&cmd.fe)?.critical_bit_damping()?.critical_bit_damping_nms),
    };
    let inputs = match (&cmd.run, cmd.law, &cmd.params) {
        (Some(dir), _, _) => read_run(dir, cmd.samples)?,
        (None, Some(law), Some(params)) => {
            if params.len() != law.n_params() {
                return Err(Error::arg(
                    "--params",
                    format!(
                        "{law} takes {} parameters ({}), got {}",
                        law.n_params(),
                        law.param_names().join(", "),
                        params.len()
                    ),
                )
                .into());
            }
            let si = law.scale_torque(params, cmd.torque_unit.newton_metres());
            vec![LawSamples {
                law,
                probability: 1.0,
                map_si: si.clone(),
                samples_si: vec![si],
            }]
        }
        _ => {
            return Err(Error::arg(
                "--run",
                "give a run directory (--run DIR) or a law (--law L --params P1,P2,...)",
            )
            .into());
        }
    };
    let c = criterion.critical_nms();
    let mut boundaries = serde_json::Map::new();
    let mut grids = serde_json::Map::new();
    let mut columns: Vec<(String, Vec<Option<f64>>)> = Vec::new();
    let computed = map::boundaries(&inputs, &omega, c, w_ref_n, p);
    for (input, b) in inputs.iter().zip(computed.laws) {
        let grid = probability_grid(input, &omega, &wob, criterion, w_ref_n, cmd.backend)?;
        boundaries.insert(input.law.name().into(), json!({"map_wob_kn": b.map_wob_kn, "p_wob_kn": b.p_wob_kn, "probability": b.probability, "samples": b.samples}));
        grids.insert(
            input.law.name().into(),
            json!(grid.chunks(wob.len()).collect::<Vec<_>>()),
        );
        columns.push((format!("{}_map_wob_kn", input.law), b.map_wob_kn));
        columns.push((format!("{}_p_wob_kn", input.law), b.p_wob_kn));
    }
    if let Some(mixture) = computed.mixture_wob_kn {
        boundaries.insert("mixture".into(), json!({"p_wob_kn": mixture}));
        columns.push(("mixture_p_wob_kn".into(), mixture));
    }
    if let Some(path) = &cmd.out {
        let mut w = csv::Writer::from_path(path).map_err(|e| Error::Write {
            path: path.clone(),
            source: e.into(),
        })?;
        let mut header = vec!["omega_rpm".to_string()];
        header.extend(columns.iter().map(|c| c.0.clone()));
        w.write_record(&header)?;
        for (i, rpm) in omega.iter().enumerate() {
            let mut row = vec![format!("{rpm}")];
            row.extend(
                columns
                    .iter()
                    .map(|c| c.1[i].map(|v| format!("{v:.4}")).unwrap_or_default()),
            );
            w.write_record(&row)?;
        }
        w.flush()?;
    }
    let mut out = std::io::stdout().lock();
    if cmd.json {
        let v = json!({
            "structure": match cmd.structure { Structure::Lumped => "1dof", Structure::Fe => "fe" },
            "critical_bit_damping_nms": c,
            "percentile": cmd.percentile,
            "omega_rpm": omega,
            "wob_kn": wob,
            "boundaries": boundaries,
            "probability_unstable": grids,
        });
        serde_json::to_writer_pretty(&mut out, &v)?;
        writeln!(out)?;
    } else {
        writeln!(
            out,
            "critical bit damping c_b* = {c:.3} N·m·s/rad ({}); boundaries: weight on bit (kN) above which steady rotation is unstable",
            match cmd.structure {
                Structure::Lumped => "1-DOF",
                Structure::Fe => "finite elements",
            }
        )?;
        write!(out, "{:>9}", "omega_rpm")?;
        for (name, _) in &columns {
            write!(out, "  {name:>18}")?;
        }
        writeln!(out)?;
        let step = (omega.len() / 20).max(1);
        for i in (0..omega.len()).step_by(step) {
            write!(out, "{:>9.1}", omega[i])?;
            for (_, values) in &columns {
                write!(
                    out,
                    "  {:>18}",
                    values[i].map(|v| format!("{v:.1}")).unwrap_or_else(|| "—".into())
                )?;
            }
            writeln!(out)?;
        }
    }
    Ok(())
}
