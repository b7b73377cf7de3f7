//! The report: every figure exists as SVG (an XML document with an <svg> root of the stated
//! size) and PNG (decodes, stated size), report.md names every figure and carries the model
//! probabilities, the SVGs are the same bytes for the same input, and a population with unequal
//! weights is accepted.

use bitrock::Law;
use bitrock::abc::rejection::{self, RejectionConfig};
use bitrock::abc::schedule::Schedule;
use bitrock::data::{DataOptions, FieldData, demo_field_data};
use bitrock::eval::Problem;
use bitrock::eval::cpu::CpuEvaluator;
use bitrock::fit::{FitOptions, LawFit, fit_laws};
use bitrock::prior::Prior;
use bitrock::report::{ReportInput, ReportRun, SimulatedReport, StabilitySettings, write_report};
use std::path::Path;

/// The demo record (thinned for speed), its fits and one small rejection run per δ.
fn runs(particles: usize, deltas: &[f64], thin: usize) -> (FieldData, Vec<LawFit>, Vec<ReportRun>) {
    let config = RejectionConfig::from(Schedule {
        particles,
        eps_min: 0.02,
        max_populations: 4,
        ..Schedule::default()
    });
    runs_with(&config, deltas, thin)
}

/// The demo record thinned by `thin`, its fits and one rejection run with `config` per δ.
fn runs_with(config: &RejectionConfig, deltas: &[f64], thin: usize) -> (FieldData, Vec<LawFit>, Vec<ReportRun>) {
    let data = demo_field_data(&DataOptions {
        thin,
        ..DataOptions::default()
    })
    .unwrap();
    let fits = fit_laws(&Law::ALL, &data.calibration, &data.validation, &FitOptions::default()).unwrap();
    let runs = deltas
        .iter()
        .map(|&delta| {
            let prior = Prior::from_fits(&fits, delta, None, data.torque_unit.newton_metres()).unwrap();
            let evaluator = CpuEvaluator::new(Problem::new(prior, 2023, &data.calibration, None));
            let run = rejection::run(&evaluator, config).unwrap();
            ReportRun {
                label: format!("δ = {delta}"),
                delta,
                laws: Law::ALL.to_vec(),
                populations: run.populations,
                w_ref_n: None,
                summary: None,
                selection: None,
                early_end: None,
                answer: None,
            }
        })
        .collect();
    (data, fits, runs)
}

/// (width, height) attributes of an SVG document's root, which must be <svg>.
fn svg_size(path: &Path) -> (u32, u32) {
    let text = std::fs::read_to_string(path).unwrap();
    let reader = xml::reader::EventReader::new(text.as_bytes());
    let mut root = None;
    for event in reader {
        match event.unwrap_or_else(|e| panic!("{}: not XML: {e}", path.display())) {
            xml::reader::XmlEvent::StartElement { name, attributes, .. } if root.is_none() => {
                assert_eq!(name.local_name, "svg", "{}", path.display());
                let get = |key: &str| -> u32 {
                    attributes
                        .iter()
                        .find(|a| a.name.local_name == key)
                        .unwrap_or_else(|| panic!("{}: no {key}", path.display()))
                        .value
                        .parse()
                        .unwrap()
                };
                root = Some((get("width"), get("height")));
            }
            _ => {}
        }
    }
    root.unwrap_or_else(|| panic!("{}: no root element", path.display()))
}

fn png_size(path: &Path) -> (u32, u32) {
    let decoder = png::Decoder::new(std::fs::File::open(path).unwrap());
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buf).unwrap();
    (info.width, info.height)
}

#[test]
fn the_report_has_every_figure_in_both_formats_and_the_tables() {
    let (data, fits, runs) = runs(1000, &[0.4, 0.8], 4);
    let input = ReportInput {
        data: &data,
        fits: &fits,
        runs: &runs,
        stability: StabilitySettings {
            simulated: Some(SimulatedReport {
                omega_rpm: vec![40.0, 80.0, 160.0],
                wob_kn: vec![100.0, 250.0, 500.0],
                samples: 2,
            }),
            ..StabilitySettings::default()
        },
        evidence: None,
    };
    let dir = tempfile::tempdir().unwrap();
    let summary = write_report(dir.path(), &input).unwrap();

    let stems: Vec<&str> = summary.figures.iter().map(|f| f.stem.as_str()).collect();
    for expected in [
        "fig01_data_and_fits",
        "fig02_model_probabilities",
        "fig03_final_probabilities",
        "fig04_tolerance",
        "fig07_envelopes",
        "fig08_map_deterministic",
        "fig08_map_stochastic",
        "fig09_structures",
        "fig11_stick_slip_simulated",
    ] {
        assert!(stems.contains(&expected), "{expected} missing from {stems:?}");
    }
    assert!(stems.iter().any(|s| s.starts_with("fig05_marginals_")), "{stems:?}");
    assert!(stems.iter().any(|s| s.starts_with("fig06_correlation_")), "{stems:?}");

    let markdown = std::fs::read_to_string(dir.path().join("report.md")).unwrap();
    for f in &summary.figures {
        let expected = if f.stem.starts_with("fig06") {
            (1200, 1200)
        } else {
            (1200, 800)
        };
        assert_eq!((f.width, f.height), expected, "{}", f.stem);
        let svg = dir.path().join("figures").join(format!("{}.svg", f.stem));
        let png = dir.path().join("figures").join(format!("{}.png", f.stem));
        assert_eq!(svg_size(&svg), expected, "{}", svg.display());
        assert_eq!(png_size(&png), expected, "{}", png.display());
        assert!(markdown.contains(&format!("figures/{}.svg", f.stem)), "{}", f.stem);
        assert!(markdown.contains(&format!("figures/{}.png", f.stem)), "{}", f.stem);
    }
    // Exactly the files the summary lists, and no staging directory left behind.
    let mut on_disk: Vec<String> = std::fs::read_dir(dir.path().join("figures"))
        .unwrap()
        .map(|e| format!("figures/{}", e.unwrap().file_name().to_string_lossy()))
        .collect();
    on_disk.push("report.md".into());
    on_disk.sort();
    let listed: Vec<String> = summary.files.iter().map(|p| p.display().to_string()).collect();
    assert_eq!(on_disk, listed);
    assert_eq!(
        std::fs::read_dir(dir.path()).unwrap().count(),
        2,
        "report.md and figures/ only"
    );

    // The last population's probabilities: in the table, as printed, and summing to 1.
    let table_start = markdown.find("### Last population").unwrap();
    for run in &runs {
        let last = run.populations.last().unwrap();
        let total: f64 = last.record.per_law.iter().map(|l| l.probability).sum();
        assert!((total - 1.0).abs() < 1e-9, "{total}");
        let row = markdown[table_start..]
            .lines()
            .find(|l| l.starts_with(&format!("| {} |", run.label)))
            .unwrap_or_else(|| panic!("no row for {}", run.label));
        let cells: Vec<&str> = row.split('|').map(str::trim).filter(|c| !c.is_empty()).collect();
        let printed: Vec<f64> = cells[4..].iter().map(|c| c.parse().unwrap()).collect();
        assert_eq!(printed.len(), 4, "{row}");
        for (law, p) in Law::ALL.iter().zip(&printed) {
            let record = last
                .record
                .per_law
                .iter()
                .find(|l| l.law == *law)
                .map_or(0.0, |l| l.probability);
            assert!((p - record).abs() <= 5e-7, "{law}: {p} vs {record}");
        }
        assert!((printed.iter().sum::<f64>() - 1.0).abs() <= 4.0 * 5e-7, "{row}");
    }
    // The demo record stick-slips: its advice says so and the way out, never "steady".
    let advice = markdown
        .lines()
        .find(|l| l.starts_with("**Advice at the record's operating point**"))
        .unwrap_or_else(|| panic!("no advice line in {markdown}"));
    assert!(advice.contains("stick-slip now at 80 rpm and 243 kN"), "{advice}");
    assert!(!advice.contains("steady"), "{advice}");
    for section in [
        "## Least-squares fits",
        "## Posterior estimates",
        "## Stability",
        "| Ω (rpm) |",
        "| Ω (rpm) | develops | persists |",
    ] {
        assert!(markdown.contains(section), "{section}");
    }

    // Same input, same bytes (SVG and Markdown); a second write replaces the first.
    let again = tempfile::tempdir().unwrap();
    write_report(again.path(), &input).unwrap();
    for f in &summary.files {
        let (a, b) = (
            std::fs::read(dir.path().join(f)).unwrap(),
            std::fs::read(again.path().join(f)).unwrap(),
        );
        assert!(a == b, "{} differs between two writes", f.display());
    }
}

/// A parameter the record does not identify can wander to 10¹⁰ (m3's a0 on physical boxes):
/// its axes count in a power of ten, so that no tick reads 1.000e10 over its neighbour.
#[test]
fn long_numbers_are_counted_in_a_power_of_ten_on_the_marginals() {
    let (data, fits, mut runs) = runs(400, &[0.4], 8);
    for population in &mut runs[0].populations {
        for particle in population.particles.iter_mut().filter(|q| q.law == Law::M3) {
            particle.params[0] *= 1e10;
        }
    }
    let input = ReportInput {
        data: &data,
        fits: &fits,
        runs: &runs,
        stability: StabilitySettings::default(),
        evidence: None,
    };
    let dir = tempfile::tempdir().unwrap();
    write_report(dir.path(), &input).unwrap();
    for stem in ["fig05_marginals_m3", "fig06_correlation_m3"] {
        let svg = std::fs::read_to_string(dir.path().join("figures").join(format!("{stem}.svg"))).unwrap();
        assert!(svg.contains("a0 (10¹⁰ kN·m)"), "{stem}: no power of ten on a0's axis");
        assert!(
            !svg.contains("e10<") && !svg.contains("e9<"),
            "{stem}: a tick in e-notation"
        );
    }
    let marginals = std::fs::read_to_string(dir.path().join("figures/fig05_marginals_m3.svg")).unwrap();
    assert!(marginals.contains("density (10⁻¹⁰)"), "a0's density counts in 10⁻¹⁰");
}

#[test]
fn unequal_weights_and_refused_input() {
    let (data, fits, mut runs) = runs(400, &[0.6], 8);
    // Reweight the last population as an SMC sampler would: the weights change the figures'
    // histograms and the resampled summaries, and the report still comes out whole.
    let last = runs[0].populations.last_mut().unwrap();
    let n = last.particles.len();
    let raw: Vec<f64> = (0..n).map(|i| 1.0 + (i % 7) as f64).collect();
    let total: f64 = raw.iter().sum();
    for (p, w) in last.particles.iter_mut().zip(&raw) {
        p.weight = w / total;
    }
    let input = ReportInput {
        data: &data,
        fits: &fits,
        runs: &runs,
        stability: StabilitySettings::default(),
        evidence: None,
    };
    let dir = tempfile::tempdir().unwrap();
    write_report(dir.path(), &input).unwrap();
    let markdown = std::fs::read_to_string(dir.path().join("report.md")).unwrap();
    // The posterior means are the weighted means: every parameter without a torque unit (shown
    // as stored) of every law is the weighted mean of its particles to the 3-4 digits shown,
    // and for some the equal-weight mean is not.
    let last = runs[0].populations.last().unwrap();
    let mut weights_matter = false;
    for law in Law::ALL {
        let section = format!("### {} — {law} (", runs[0].label);
        let at = markdown
            .find(&section)
            .unwrap_or_else(|| panic!("no section {section}"));
        let table = &markdown[at..];
        let particles: Vec<_> = last.particles.iter().filter(|p| p.law == law).collect();
        let total: f64 = particles.iter().map(|p| p.weight).sum();
        for (j, spec) in law.params().iter().enumerate().filter(|(_, s)| s.torque_power == 0) {
            let weighted = particles.iter().map(|p| p.weight * p.params[j]).sum::<f64>() / total;
            let plain = particles.iter().map(|p| p.params[j]).sum::<f64>() / particles.len() as f64;
            let row = table
                .lines()
                .find(|l| l.starts_with(&format!("| {} |", spec.name)))
                .unwrap_or_else(|| panic!("no row for {}", spec.name));
            let shown: f64 = row.split('|').nth(4).unwrap().trim().parse().unwrap();
            let close = |v: f64| (shown - v).abs() <= 1e-3 * v.abs() + 1e-4;
            assert!(
                close(weighted),
                "{law} {}: shows {shown}, weighted mean {weighted}",
                spec.name
            );
            weights_matter |= !close(plain);
        }
    }
    assert!(weights_matter, "no mean moved with the weights: the check is blind");

    // No run, or a bad percentile: refused before anything is written, naming why.
    let empty = tempfile::tempdir().unwrap();
    let target = empty.path().join("report");
    let none = ReportInput {
        runs: &[],
        ..input.clone()
    };
    let err = write_report(&target, &none).unwrap_err();
    assert!(err.is_bad_input(), "{err}");
    assert!(err.to_string().contains("no run to report"), "{err}");
    let bad = ReportInput {
        stability: StabilitySettings {
            percentile: 2.0,
            ..StabilitySettings::default()
        },
        ..input
    };
    let err = write_report(&target, &bad).unwrap_err();
    assert!(err.is_bad_input(), "{err}");
    assert!(err.to_string().contains("the percentile 2 is not in (0, 1)"), "{err}");
    assert!(!target.exists());
}

/// The paper's scale: N = 25,000 particles, δ ∈ {0.4, 0.6, 0.8}, the whole record. Prints how
/// long `write_report` takes and leaves the report in target/report-paper for inspection.
/// `cargo test --release report_at_paper_scale -- --ignored --nocapture`
#[test]
#[ignore]
fn report_at_paper_scale() {
    let start = std::time::Instant::now();
    let (data, fits, runs) = runs_with(&RejectionConfig::default(), &[0.4, 0.6, 0.8], 1);
    let abc = start.elapsed().as_secs_f64();
    let input = ReportInput {
        data: &data,
        fits: &fits,
        runs: &runs,
        stability: StabilitySettings::default(),
        evidence: None,
    };
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("target/report-paper");
    let summary = write_report(&dir, &input).unwrap();
    println!(
        "fits + 3 ABC runs: {abc:.2} s; write_report: {:.2} s ({} files) in {}",
        summary.seconds,
        summary.files.len(),
        dir.display()
    );
}

#[test]
fn the_report_shows_the_model_evidence_beside_the_runs_when_it_was_computed() {
    use bitrock::abc::evidence::{Evidence, EvidenceConfig, LawEvidence};
    let (data, fits, runs) = runs(1000, &[0.4], 4);
    let law = |law: Law, ln_z: f64, island_ln_z: Vec<f64>, probability: f64| LawEvidence {
        law,
        ln_z,
        ln_z_error: 0.5,
        island_spread: island_ln_z.iter().copied().fold(f64::NEG_INFINITY, f64::max)
            - island_ln_z.iter().copied().fold(f64::INFINITY, f64::min),
        island_ln_z,
        prior_probability: 0.5,
        probability,
        probability_error: 0.0,
        refinements: 0,
        stages: vec![3, 3],
        candidates_scored: 100,
        best_rho: 0.01,
        posterior: Vec::new(),
        posterior_island: Vec::new(),
        cut_by_box: Vec::new(),
        starts: Vec::new(),
        mean_ln_l: None,
        box_changes: Vec::new(),
        curve: None,
    };
    let evidence = Evidence {
        laws: vec![
            law(Law::M2, -1234.5678, vec![-1234.0, -1235.0], 0.75),
            law(Law::M3, -1235.6664, vec![-1230.0, -1237.0], 0.25),
        ],
        data_points: 1000,
        config: EvidenceConfig::default(),
        candidates_scored: 200,
        evaluations: 200_000,
        seconds: 1.0,
        backend: "cpu".into(),
    };
    let input = ReportInput {
        data: &data,
        fits: &fits,
        runs: &runs,
        stability: StabilitySettings::default(),
        evidence: Some(&evidence),
    };
    let dir = tempfile::tempdir().unwrap();
    write_report(dir.path(), &input).unwrap();
    let markdown = std::fs::read_to_string(dir.path().join("report.md")).unwrap();
    assert!(markdown.contains("## Model evidence"), "{markdown}");
    assert!(
        markdown.contains("| m2 | -1234.568 | 0.500 | 0.7500 | yes |"),
        "{markdown}"
    );
    assert!(
        markdown.contains("| m3 | -1235.666 | 0.500 | 0.2500 | no: 7.0 nats apart |"),
        "{markdown}"
    );
    let without = tempfile::tempdir().unwrap();
    write_report(
        without.path(),
        &ReportInput {
            evidence: None,
            ..input
        },
    )
    .unwrap();
    let plain = std::fs::read_to_string(without.path().join("report.md")).unwrap();
    assert!(!plain.contains("## Model evidence"));
}
