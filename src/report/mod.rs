//! The paper's figures and a Markdown report from in-memory results: the data with the
//! least-squares fits, model probabilities and tolerances per population for several prior
//! widths δ, posterior marginals and correlations, 98 % predictive envelopes, deterministic and
//! stochastic stability maps and the appendix's 1-DOF / finite-element comparison.
//!
//! Every figure is written as SVG and PNG (sizes in [`FigureInfo`]), drawn by plotters with the
//! embedded DejaVu Sans font so that no system font is needed. The report is rendered whole in
//! memory and only then moved into the target directory, so a failure leaves no half-written
//! report. The same input gives the same bytes.
//!
//! Weights: probabilities come from the population records (each law's share of the weight),
//! histograms add the particles' weights, and the summaries, envelopes and maps, which take
//! equally weighted particles, get a population with unequal weights (ABC-SMC) as a systematic
//! resample; a rejection population (weights all 1/N) is used as it is.

mod evidence;
pub(crate) mod figures;
pub(crate) mod plot;
mod runs;
mod stats;
mod surface;

pub use evidence::write_evidence_report;
pub use runs::{read_run_dirs, write_paper_report};
pub use surface::write_surface_report;

use figures::confusion_figure;

/// Draws a selection check's heat map and writes the check into its run directory
/// ([`crate::run::selection::write`]); returns the check's directory.
pub fn write_selection(
    run: &crate::run::selection::CheckedRun,
    check: &crate::run::selection::SelectionCheck,
) -> Result<PathBuf> {
    let (svg, png) = confusion_figure(check)?;
    crate::run::selection::write(run, check, svg, png)
}

use crate::abc::Population;
use crate::abc::posterior::{self, PosteriorSummary};
use crate::data::FieldData;
use crate::error::{Error, Result};
use crate::fit::LawFit;
use crate::laws::{Law, PAPER_W_REF_N};
use crate::run::advice::Advice;
use crate::run::strings::SimulatedMaps;
use crate::stability::fe::DrillString;
use crate::stability::lumped::Lumped;
use crate::stability::map::{self, Criterion, LawSamples};
use crate::units::RAD_S_PER_RPM;
use std::borrow::Cow;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// One ABC run (one prior width δ) to report.
#[derive(Clone, Debug)]
pub struct ReportRun {
    /// How the figures name the run, e.g. "δ = 0.4".
    pub label: String,
    /// The prior half-width δ of φ̂(1 ± δ).
    pub delta: f64,
    /// The laws that competed, in the order the tables list them.
    pub laws: Vec<Law>,
    /// Every population in order; the last one is the posterior.
    pub populations: Vec<Population>,
    /// The reference weight on bit W_ref (N) the run's parameters refer to when the fit scaled
    /// each sample by r = WOB / W_ref (`FitOptions::w_ref_n`); `None` takes the maps'
    /// [`StabilitySettings::w_ref_n`].
    pub w_ref_n: Option<f64>,
    /// `posterior::summarize(last population, laws)` when the caller has it already (the
    /// demo does), so that its kernel density estimate is not computed twice; `None`: computed
    /// here.
    pub summary: Option<PosteriorSummary>,
    /// The run's selection check (`bitrock check-selection`), when its directory holds one,
    /// and why it no longer describes the run when it does not.
    pub selection: Option<(crate::run::selection::SelectionCheck, Option<String>)>,
    /// How the run ended when not by its own stopping rules (interrupted, or stopped on a
    /// budget): said in the report ([`crate::run::abc::Store::early_end`]).
    pub early_end: Option<String>,
    /// The last population's answer to "which law, how sure" ([`crate::run::abc::answer`]).
    pub answer: Option<crate::run::answer::Answer>,
}

/// The structures and axes of the stability maps. [`Default`] is the paper's.
#[derive(Clone, Debug)]
pub struct StabilitySettings {
    /// The 1-DOF string of every map.
    pub lumped: Lumped,
    /// Finite-element strings compared with the 1-DOF one (the appendix).
    pub strings: Vec<DrillString>,
    /// W_ref (N): the laws' torque is scaled by r = W / W_ref.
    pub w_ref_n: f64,
    /// Top-drive speeds of the maps (rpm, ascending).
    pub omega_rpm: Vec<f64>,
    /// Weights on bit of the maps (kN, ascending).
    pub wob_kn: Vec<f64>,
    /// Percentile of the stochastic boundaries, as a share (the paper's 2 % is 0.02).
    pub percentile: f64,
    /// Posterior samples per law for the stochastic maps (the paper's 700).
    pub samples_per_law: usize,
    /// Speeds (rpm) of the boundary table in report.md.
    pub table_omega_rpm: Vec<f64>,
    /// Where the strings of the record's advice (and the simulated maps) are integrated.
    pub backend: crate::eval::Backend,
    /// The maps by simulated strings (onset, escape from the record's operating point, the
    /// bistable band) and their figure; `None`: the advice line only.
    pub simulated: Option<SimulatedReport>,
}

/// The report's maps by simulated strings, on the 1-DOF string.
#[derive(Clone, Debug)]
pub struct SimulatedReport {
    /// Top-drive speeds (rpm) and weights on bit (kN) of the maps, ascending.
    pub omega_rpm: Vec<f64>,
    pub wob_kn: Vec<f64>,
    /// Posterior samples per law simulated in every cell.
    pub samples: usize,
}

impl Default for SimulatedReport {
    /// 21 speeds of 20–220 rpm × 18 weights of 20–700 kN, 8 samples per law.
    fn default() -> Self {
        Self {
            omega_rpm: axis(20.0, 220.0, 21),
            wob_kn: axis(20.0, 700.0, 18),
            samples: 8,
        }
    }
}

impl Default for StabilitySettings {
    /// The paper's 1-DOF string; its 2-DOF finite-element string (α = 0.5 1/s, β = 0.006 s) and
    /// 10-DOF one (8 + 2 elements) with β = 0.006 s and β = 0.0021 s; W_ref = 244.2 kN;
    /// Ω 20–220 rpm, W 20–700 kN; the 2 % percentile over 700 samples per law.
    fn default() -> Self {
        let two = DrillString::default();
        let ten = DrillString {
            dp_elements: 8,
            bha_elements: 2,
            ..DrillString::default()
        };
        Self {
            lumped: Lumped::default(),
            strings: vec![two, ten.clone(), DrillString { beta: 0.0021, ..ten }],
            w_ref_n: PAPER_W_REF_N,
            omega_rpm: axis(20.0, 220.0, 101),
            wob_kn: axis(20.0, 700.0, 69),
            percentile: 0.02,
            samples_per_law: 700,
            table_omega_rpm: vec![40.0, 60.0, 80.0, 100.0, 120.0, 160.0, 200.0],
            backend: crate::eval::Backend::Auto,
            simulated: None,
        }
    }
}

fn axis(lo: f64, hi: f64, n: usize) -> Vec<f64> {
    posterior::speed_grid(lo, hi, n)
}

/// Everything a report is made from.
#[derive(Clone, Debug)]
pub struct ReportInput<'a> {
    /// The record (calibration and validation samples, SI; its torque unit is the display unit).
    pub data: &'a FieldData,
    /// The least-squares estimates of every law.
    pub fits: &'a [LawFit],
    /// The runs, at least one. The first is the reference case the single-run figures
    /// (correlations, envelopes, stability maps) are drawn for, as the paper draws its δ = 0.4.
    pub runs: &'a [ReportRun],
    pub stability: StabilitySettings,
    /// The model evidence of the record's laws, where it was computed: shown beside the runs'
    /// probabilities.
    pub evidence: Option<&'a crate::abc::evidence::Evidence>,
}

/// One figure as written: `figures/{stem}.svg` and `figures/{stem}.png`.
#[derive(Clone, Debug, PartialEq)]
pub struct FigureInfo {
    pub stem: String,
    pub caption: String,
    /// Pixels of the PNG and user units of the SVG's width and height attributes.
    pub width: u32,
    pub height: u32,
}

/// What [`write_report`] wrote.
#[derive(Clone, Debug)]
pub struct ReportSummary {
    /// The report directory.
    pub dir: PathBuf,
    /// Files written, relative to `dir`, sorted: `report.md` and every figure's SVG and PNG.
    pub files: Vec<PathBuf>,
    pub figures: Vec<FigureInfo>,
    /// Wall time of [`write_report`] (s).
    pub seconds: f64,
    /// The advice at the record's operating point, in words, where the report gives one.
    pub advice: Option<String>,
}

/// Figure size (px) of the single- and multi-panel figures.
pub const FIGURE_SIZE: (u32, u32) = (1200, 800);
/// Size of the correlation matrices, square so that the panels are.
pub const CORRELATION_SIZE: (u32, u32) = (1200, 1200);

/// The least particles a law needs in the reference run's posterior for its correlation matrix.
const MIN_CORRELATION_PARTICLES: usize = 20;
/// The least probability a law needs to be drawn on the stochastic map (the paper leaves out the
/// laws that die out).
const MIN_MAP_PROBABILITY: f64 = 0.01;

/// Writes `report.md` and the figures under `dir/figures/`: everything is rendered in memory
/// first, then `dir` is replaced as a whole ([`crate::files::replace_dir`]), so it never mixes
/// figures of two reports. A `dir` holding anything but a report is refused.
pub fn write_report(dir: &Path, input: &ReportInput) -> Result<ReportSummary> {
    let start = Instant::now();
    let prepared = Prepared::new(input)?;
    let rendered = figures::render_all(&prepared)?;
    let markdown = prepared.markdown(&rendered.iter().map(|r| r.info.clone()).collect::<Vec<_>>());
    Ok(ReportSummary {
        advice: prepared.record_advice.as_ref().map(|(_, a)| a.words.clone()),
        ..replace_report(dir, markdown, rendered, start)?
    })
}

/// Moves a report rendered in memory into `dir`, replacing it as a whole.
pub(crate) fn replace_report(
    dir: &Path,
    markdown: String,
    rendered: Vec<figures::Rendered>,
    start: Instant,
) -> Result<ReportSummary> {
    let figures = Path::new(crate::run::dir::FIGURES_DIR);
    let mut files: Vec<(PathBuf, Vec<u8>)> = vec![(PathBuf::from(crate::run::dir::REPORT_MD), markdown.into_bytes())];
    for r in rendered.iter() {
        files.push((figures.join(format!("{}.svg", r.info.stem)), r.svg.as_bytes().to_vec()));
        files.push((figures.join(format!("{}.png", r.info.stem)), r.png.clone()));
    }
    crate::run::dir::refuse_inside_kept_dir(dir, "out")?;
    crate::files::replace_dir(
        dir,
        "out",
        &|rel, is_dir| crate::run::dir::owns_unchanged(crate::run::dir::Owned::Report, dir, rel, is_dir),
        &files,
    )?;
    let mut names: Vec<PathBuf> = files.into_iter().map(|f| f.0).collect();
    names.sort();
    Ok(ReportSummary {
        dir: dir.to_path_buf(),
        files: names,
        figures: rendered.into_iter().map(|r| r.info).collect(),
        seconds: start.elapsed().as_secs_f64(),
        advice: None,
    })
}

/// What the record's bit did, and the advice at its operating point.
type RecordAdvice = (crate::data::BitSeen, Advice);

/// The advice at the record's operating point under the reference run's `inputs` (torque
/// parameters for `scaled_w_ref_n` where its fit scaled them), and the maps by simulated strings
/// where the settings ask for them (escape from the record's operating point where known).
fn simulated_advice(
    input: &ReportInput,
    scaled_w_ref_n: Option<f64>,
    inputs: &[LawSamples],
) -> Result<(Option<RecordAdvice>, Option<SimulatedMaps>)> {
    use crate::run::advice::{Adviser, params_w_ref_n, record_point};
    use crate::run::strings::{SimulatedJob, SimulatedSettings};
    let s = &input.stability;
    let chain = crate::simulate::strings::Chain::one_dof(&s.lumped);
    let inputs: Vec<LawSamples> = inputs
        .iter()
        .filter(|m| m.probability >= MIN_MAP_PROBABILITY)
        .cloned()
        .collect();
    let at_record = input
        .data
        .bit
        .map(|seen| (seen, params_w_ref_n(scaled_w_ref_n, &seen, s.w_ref_n)));
    let advice = at_record.map(|(seen, w_ref_n)| {
        let adviser = Adviser::for_record(Criterion::Lumped(s.lumped), Some(chain.clone()), s.backend);
        (seen, adviser.advise_record(&inputs, w_ref_n, &seen))
    });
    let Some(sim) = &s.simulated else {
        return Ok((advice, None));
    };
    let w_ref_n = at_record.map_or(scaled_w_ref_n.unwrap_or(s.w_ref_n), |a| a.1);
    let job = SimulatedJob {
        settings: SimulatedSettings::new(chain, w_ref_n, s.backend),
        omega_rpm: sim.omega_rpm.clone(),
        wob_kn: sim.wob_kn.clone(),
        samples: sim.samples,
        at: at_record.map(|(seen, w)| record_point(&seen, w)),
    };
    Ok((advice, Some(job.run(&inputs, &mut |_| {})?)))
}

/// One run with its posterior read off.
struct RunView<'a> {
    run: &'a ReportRun,
    /// The last population.
    last: &'a Population,
    /// Its particles with their weights (the summaries and envelopes weigh them).
    particles: Cow<'a, [crate::abc::Particle]>,
    summary: PosteriorSummary,
    /// P(law | data) of the last population per law of `run.laws`, from the record.
    probabilities: Vec<(Law, f64)>,
}

/// A structure of the maps and its critical bit damping.
struct StructureView {
    label: String,
    /// For a panel caption.
    short_label: String,
    critical_nms: f64,
}

/// Everything the figures and the Markdown need, computed once.
struct Prepared<'a> {
    input: &'a ReportInput<'a>,
    /// N·m per display torque unit.
    torque_scale: f64,
    unit: &'static str,
    runs: Vec<RunView<'a>>,
    /// 1-DOF first, then the finite-element strings.
    structures: Vec<StructureView>,
    /// The reference run's laws for the maps (MAP, samples, probability), SI; laws with
    /// particles only.
    map_inputs: Vec<LawSamples>,
    /// The deterministic map's parameters per law: the reference run's MAP, or the least-squares
    /// estimate for a law that died out (flagged `true`).
    deterministic: Vec<(Law, Vec<f64>, bool)>,
    w_ref_n: f64,
    /// What the record's bit did and the advice at its operating point, where the record
    /// keeps an account of its bit.
    record_advice: Option<RecordAdvice>,
    /// The maps by simulated strings, where asked for.
    simulated: Option<SimulatedMaps>,
    /// What the 1-DOF string's maps draw nothing of: boundaries wholly off their weights on
    /// bit ([`map::Boundaries::off_the_map`]), said in report.md and the maps' captions.
    off_the_map: Vec<String>,
}

/// For each of `laws`, whether its probability in the population is 0 by construction (ε at
/// or below its best least-squares ρ; see `LawRecord::reachable`).
fn record_zero_by_construction(population: &Population, laws: &[Law]) -> Vec<bool> {
    laws.iter()
        .map(|&law| {
            population
                .record
                .per_law
                .iter()
                .any(|r| r.law == law && r.zero_by_construction())
        })
        .collect()
}

/// A probability in a table: 6 decimals, or `0*` when it is 0 by construction.
fn probability_text(p: f64, by_construction: bool) -> String {
    if by_construction {
        "0*".into()
    } else {
        format!("{p:.6}")
    }
}

/// The footnote of tables and figures that show `0*`.
const BY_CONSTRUCTION_NOTE: &str = "0* = 0 by construction: ε is at or below the law's best least-squares ρ, so none of its candidates could be accepted; it is not evidence against the law.";

/// P(law) of a population's record for each of `laws` (0 for a law not in the record).
fn record_probabilities(population: &Population, laws: &[Law]) -> Vec<(Law, f64)> {
    laws.iter()
        .map(|&law| (law, population.record.probability_of(law)))
        .collect()
}

/// Refuses, naming the report, what cannot be reported: no run, a percentile outside (0, 1),
/// no samples per law, an axis that is not ascending and positive.
fn check_settings(input: &ReportInput) -> Result<()> {
    let s = &input.stability;
    let bad = |message: String| Error::setting("report", message);
    if input.runs.is_empty() {
        return Err(bad("no run to report".into()));
    }
    if !(s.percentile > 0.0 && s.percentile < 1.0) {
        return Err(bad(format!("the percentile {} is not in (0, 1)", s.percentile)));
    }
    if s.samples_per_law == 0 {
        return Err(bad("samples_per_law must be at least 1".into()));
    }
    for (name, axis) in [("omega_rpm", &s.omega_rpm), ("wob_kn", &s.wob_kn)] {
        if axis.len() < 2
            || axis.iter().any(|v| !v.is_finite())
            || axis.windows(2).any(|w| w[1] <= w[0])
            || axis[0] <= 0.0
        {
            return Err(bad(format!(
                "the {name} axis must hold at least two ascending positive values"
            )));
        }
    }
    Ok(())
}

/// The strings the report maps: the 1-DOF string and each finite-element string, with their
/// critical bit damping.
fn structures(s: &StabilitySettings) -> Result<Vec<StructureView>> {
    let mut structures = vec![StructureView {
        label: format!(
            "1-DOF (ω_n = {} rad/s, ξ = {})",
            s.lumped.omega_n_rad_s, s.lumped.damping_ratio
        ),
        short_label: "1-DOF".into(),
        critical_nms: s.lumped.critical_bit_damping_nms(),
    }];
    for string in &s.strings {
        structures.push(StructureView {
            label: format!(
                "FE {} + {} elements, α = {} 1/s, β = {} s",
                string.dp_elements, string.bha_elements, string.alpha, string.beta
            ),
            short_label: format!(
                "FE {}+{}, β = {} s",
                string.dp_elements, string.bha_elements, string.beta
            ),
            critical_nms: string.critical_bit_damping()?.critical_bit_damping_nms,
        });
    }
    Ok(structures)
}

impl<'a> Prepared<'a> {
    fn new(input: &'a ReportInput<'a>) -> Result<Self> {
        let s = &input.stability;
        let bad = |message: String| Error::setting("report", message);
        check_settings(input)?;
        s.lumped.validate()?;
        let mut runs = Vec::with_capacity(input.runs.len());
        for run in input.runs {
            let last = run
                .populations
                .last()
                .filter(|p| !p.particles.is_empty())
                .ok_or_else(|| bad(format!("run '{}' has no population with particles", run.label)))?;
            let particles = Cow::Borrowed(&last.particles[..]);
            let summary = match &run.summary {
                Some(summary) => summary.clone(),
                None => posterior::summarize(&particles, &run.laws),
            };
            runs.push(RunView {
                run,
                last,
                probabilities: record_probabilities(last, &run.laws),
                particles,
                summary,
            });
        }
        let structures = structures(s)?;
        let reference = &runs[0];
        let map_inputs: Vec<LawSamples> = reference
            .summary
            .laws
            .iter()
            .map(|law_summary| {
                let law = law_summary.law;
                let probability = reference
                    .probabilities
                    .iter()
                    .find(|p| p.0 == law)
                    .map_or(law_summary.probability, |p| p.1);
                crate::abc::posterior::law_samples_of(
                    law,
                    probability,
                    law_summary.map.clone(),
                    &posterior::law_samples(&reference.last.particles, law, s.samples_per_law),
                )
            })
            .collect();
        let laws: std::collections::BTreeSet<Law> =
            Law::ALL.into_iter().chain(input.fits.iter().map(|f| f.law)).collect();
        let deterministic = laws
            .into_iter()
            .filter_map(|law| {
                if let Some(m) = map_inputs.iter().find(|m| m.law == law) {
                    Some((law, m.map_si.clone(), false))
                } else {
                    input
                        .fits
                        .iter()
                        .find(|f| f.law == law)
                        .map(|f| (law, f.params_si.clone(), true))
                }
            })
            .collect();
        let w_ref_n = reference.run.w_ref_n.unwrap_or(s.w_ref_n);
        let (record_advice, simulated) = simulated_advice(input, reference.run.w_ref_n, &map_inputs)?;
        let mut prepared = Self {
            input,
            torque_scale: input.data.torque_unit.newton_metres(),
            unit: input.data.torque_unit.label(),
            w_ref_n,
            runs,
            structures,
            map_inputs,
            deterministic,
            record_advice,
            simulated,
            off_the_map: Vec::new(),
        };
        prepared.off_the_map = prepared.boundaries_off_the_map();
        Ok(prepared)
    }

    /// Parameters in display units (torques in the record's unit).
    fn display(&self, law: Law, si: &[f64]) -> Vec<f64> {
        law.scale_torque(si, 1.0 / self.torque_scale)
    }

    /// The laws of any run, in [`Law`]'s order.
    fn all_laws(&self) -> Vec<Law> {
        let laws: std::collections::BTreeSet<Law> = self.runs.iter().flat_map(|r| r.run.laws.iter().copied()).collect();
        laws.into_iter().collect()
    }

    /// The stochastic map's laws: those of the reference run with probability ≥ 1 %.
    fn map_laws(&self) -> Vec<&LawSamples> {
        self.map_inputs
            .iter()
            .filter(|m| m.probability >= MIN_MAP_PROBABILITY)
            .collect()
    }

    /// P(unstable) of the mixture of the reference run's laws at every (Ω, W), row-major over Ω.
    fn mixture_grid(&self) -> Vec<f64> {
        let s = &self.input.stability;
        map::mixture_probability_grid(
            &self.map_inputs,
            &s.omega_rpm,
            &s.wob_kn,
            Criterion::Lumped(s.lumped),
            self.w_ref_n,
        )
    }

    /// The text of report.md, section by section, with `figures` listed at the end.
    fn markdown(&self, figures: &[FigureInfo]) -> String {
        let mut md = String::new();
        self.record_markdown(&mut md);
        self.fits_markdown(&mut md);
        self.probabilities_markdown(&mut md);
        self.evidence_markdown(&mut md);
        self.populations_markdown(&mut md);
        self.posterior_markdown(&mut md);
        self.selection_markdown(&mut md);
        self.stability_markdown(&mut md);
        self.boundaries_markdown(&mut md);
        figures_markdown(&mut md, figures);
        md
    }
}

impl Prepared<'_> {
    /// The title and what the record holds.
    fn record_markdown(&self, md: &mut String) {
        let data = self.input.data;
        let unit = self.unit;
        let _ = writeln!(md, "# bitrock report\n");
        let _ = writeln!(
            md,
            "Record: `{}`: {} rows read, {} used ({} calibration, {} validation samples); torques in {unit}, \
             speeds in rpm, weights on bit in kN.\n",
            data.source.display(),
            data.rows_read,
            data.rows_used,
            data.calibration.len(),
            data.validation.len()
        );
    }

    /// The section of the least-squares fits: each law's estimate and ρ.
    fn fits_markdown(&self, md: &mut String) {
        let _ = writeln!(md, "## Least-squares fits\n");
        let _ = writeln!(md, "| law | T(w) | estimate | ρ calibration | ρ validation |");
        let _ = writeln!(md, "|---|---|---|---|---|");
        for fit in self.input.fits {
            let shown = self.display(fit.law, &fit.params_si);
            let params: Vec<String> = fit
                .law
                .params()
                .iter()
                .zip(&shown)
                .map(|(spec, v)| format!("{} = {} {}", spec.name, plot::short(*v), plot::unit(spec, self.unit)))
                .collect();
            let _ = writeln!(
                md,
                "| {} | {} | {} | {:.5} | {} |",
                fit.law,
                fit.law.formula(),
                params.join(", "),
                fit.rho,
                fit.validation_rho.map_or("—".into(), |r| format!("{r:.5}"))
            );
        }
    }

    /// The model probabilities of each run's last population, with the notes on how runs
    /// ended early, on `0*` and the records' caveats.
    fn probabilities_markdown(&self, md: &mut String) {
        let _ = writeln!(md, "\n## Model probabilities by the paper's ABC\n");
        let _ = writeln!(
            md,
            "P(m | ρ < ε): the share of each law's prior box whose misfit ρ falls below the tolerance ε. \
             They weigh the record only where ε lies near its likelihood scale.\n"
        );
        let _ = writeln!(md, "### Last population\n");
        let laws = self.all_laws();
        let _ = write!(md, "| run | δ | population | ε |");
        for law in &laws {
            let _ = write!(md, " P({law} \\| ρ < ε) |");
        }
        let _ = writeln!(md, "\n|---|---|---|---|{}", "---|".repeat(laws.len()));
        for r in &self.runs {
            let _ = write!(
                md,
                "| {} | {} | {} | {} |",
                r.run.label,
                r.run.delta,
                r.last.record.index,
                epsilon_text(r.last.record.epsilon)
            );
            let zero = record_zero_by_construction(r.last, &laws);
            for (law, zero) in laws.iter().zip(zero) {
                let p = r.probabilities.iter().find(|p| p.0 == *law).map(|p| p.1);
                let _ = write!(md, " {} |", p.map_or("—".into(), |p| probability_text(p, zero)));
            }
            let _ = writeln!(md);
        }
        for r in &self.runs {
            if let Some(answer) = &r.run.answer {
                let _ = writeln!(md, "\n**{}, answer:** {}.", r.run.label, answer.sentence());
            }
        }
        for r in &self.runs {
            if let Some(why) = &r.run.early_end {
                let _ = writeln!(md, "\n> **{}:** {why}.", r.run.label);
            }
        }
        let any_zero = self.runs.iter().any(|r| {
            r.run
                .populations
                .iter()
                .any(|p| !p.record.unreachable_laws().is_empty())
        });
        if any_zero {
            let _ = writeln!(md, "\n{BY_CONSTRUCTION_NOTE}");
        }
        for r in &self.runs {
            for caveat in r.last.record.probability_caveats() {
                let _ = writeln!(md, "\n{}: {caveat}", r.run.label);
            }
        }
        let best_rho = self.input.fits.iter().map(|f| f.rho).fold(f64::INFINITY, f64::min);
        for r in &self.runs {
            let caveat = r.last.record.epsilon.and_then(|epsilon| {
                crate::abc::prior_volume_caveat(epsilon, best_rho, self.input.data.calibration.len())
            });
            if let Some(caveat) = caveat {
                let _ = writeln!(md, "\n{}: {caveat}.", r.run.label);
            }
        }
    }

    /// The model evidence of each law beside the runs' probabilities, where it was computed.
    fn evidence_markdown(&self, md: &mut String) {
        let Some(evidence) = self.input.evidence else {
            return;
        };
        let _ = writeln!(md, "\n## Model evidence\n");
        let _ = writeln!(
            md,
            "Marginal likelihood of each law (tempered SMC per law, {} islands × {} particles; {}; ln Z with torques \
             in N·m) and the posterior law probabilities it gives.\n",
            evidence.config.islands,
            evidence.config.particles,
            evidence.config.noise.describe()
        );
        let _ = writeln!(md, "| law | ln Z | ± Monte-Carlo error | P(m \\| y) | islands agree |");
        let _ = writeln!(md, "|---|---|---|---|---|");
        for law in &evidence.laws {
            let agree = if law.converged() {
                "yes".to_string()
            } else {
                format!("no: {:.1} nats apart", law.island_spread)
            };
            let _ = writeln!(
                md,
                "| {} | {:.3} | {:.3} | {:.4} | {agree} |",
                law.law, law.ln_z, law.ln_z_error, law.probability
            );
        }
    }

    /// One table per run of every population: ε, acceptances, draws, ESS and P(law).
    fn populations_markdown(&self, md: &mut String) {
        for r in &self.runs {
            let _ = writeln!(md, "\n### {}: every population\n", r.run.label);
            let _ = write!(md, "| population | ε | accepted | drawn | ESS |");
            for law in &r.run.laws {
                let _ = write!(md, " P({law}) |");
            }
            let _ = writeln!(md, "\n|---|---|---|---|---|{}", "---|".repeat(r.run.laws.len()));
            for p in &r.run.populations {
                let _ = write!(
                    md,
                    "| {} | {} | {} | {} | {:.0}{} |",
                    p.record.index,
                    epsilon_text(p.record.epsilon),
                    p.record.accepted,
                    p.record.draws,
                    p.record.ess,
                    if p.record.thin() { " (thin)" } else { "" }
                );
                let zero = record_zero_by_construction(p, &r.run.laws);
                for ((_, prob), zero) in record_probabilities(p, &r.run.laws).into_iter().zip(zero) {
                    let _ = write!(md, " {} |", probability_text(prob, zero));
                }
                let _ = writeln!(md);
            }
            if r.run.populations.iter().any(|p| p.record.thin()) {
                let _ = writeln!(
                    md,
                    "\n(thin): effective sample size below {:.0} % of the particles; that population's estimates rest on a few heavily weighted particles.",
                    crate::abc::MIN_ESS_SHARE * 100.0
                );
            }
        }
    }

    /// The section of the posterior estimates: MAP, mean and 98 % interval per run, law and
    /// parameter.
    fn posterior_markdown(&self, md: &mut String) {
        let _ = writeln!(md, "\n## Posterior estimates (last population)\n");
        let _ = writeln!(
            md,
            "MAP: mode of a kernel density estimate; mean and the central 98 % interval (1 % and 99 % \
             quantiles) over the law's particles.\n"
        );
        for r in &self.runs {
            for ls in &r.summary.laws {
                let _ = writeln!(
                    md,
                    "### {} — {} ({} particles, P = {:.4})\n",
                    r.run.label,
                    ls.law,
                    ls.count,
                    r.probabilities
                        .iter()
                        .find(|p| p.0 == ls.law)
                        .map_or(ls.probability, |p| p.1)
                );
                let _ = writeln!(md, "| parameter | unit | MAP | mean | 1 % | 99 % |");
                let _ = writeln!(md, "|---|---|---|---|---|---|");
                let (map, mean, lo, hi) = (
                    self.display(ls.law, &ls.map),
                    self.display(ls.law, &ls.mean),
                    self.display(ls.law, &ls.q01),
                    self.display(ls.law, &ls.q99),
                );
                for (j, spec) in ls.law.params().iter().enumerate() {
                    let _ = writeln!(
                        md,
                        "| {}{} | {} | {} | {} | {} | {} |",
                        spec.name,
                        if ls.identified[j] {
                            ""
                        } else {
                            " (not identified: its 98 % interval spans most of its prior box)"
                        },
                        plot::unit(spec, self.unit),
                        plot::short(map[j]),
                        plot::short(mean[j]),
                        plot::short(lo[j]),
                        plot::short(hi[j])
                    );
                }
                let _ = writeln!(md);
            }
        }
    }

    /// The section of the runs that hold a selection check: the confusion matrix, the
    /// distribution of the generating law's own probability and the verdicts.
    fn selection_markdown(&self, md: &mut String) {
        let checked: Vec<(&RunView, &crate::run::selection::SelectionCheck, &Option<String>)> = self
            .runs
            .iter()
            .filter_map(|r| r.run.selection.as_ref().map(|(c, stale)| (r, c, stale)))
            .collect();
        if checked.is_empty() {
            return;
        }
        let _ = writeln!(md, "## Can the selection be trusted? (`bitrock check-selection`)\n");
        let _ = writeln!(
            md,
            "Synthetic records made by each law at the record's speeds (parameters from the law's posterior, \
             noise resampled from its least-squares residuals), each run through the same fits, prior and \
             sampler. Rows: the law that made the records; columns: mean posterior probability / share of \
             replicates ranking the law first.\n"
        );
        for (r, check, stale) in checked {
            let _ = writeln!(
                md,
                "### {}: {} replicates per law, N = {}, backend {}, {:.1} s\n",
                r.run.label, check.replicates, check.particles, check.backend, check.seconds
            );
            if let Some(why) = stale {
                let _ = writeln!(md, "> **Stale:** {why}.\n");
            }
            let _ = write!(md, "| data from |");
            for law in &check.laws {
                let _ = write!(md, " P({law}) / first |");
            }
            let _ = writeln!(md, " P(own): 10 % / median / 90 % |");
            let _ = writeln!(md, "|---|{}---|", "---|".repeat(check.laws.len()));
            for row in &check.rows {
                let _ = write!(md, "| {} |", row.law);
                for (p, f) in row.mean_probability.iter().zip(&row.first_share) {
                    let _ = write!(md, " {p:.3} / {f:.2} |");
                }
                let q = &row.own_probability;
                let _ = writeln!(md, " {:.3} / {:.3} / {:.3} |", q.q10, q.median, q.q90);
            }
            let _ = writeln!(md);
            for row in &check.rows {
                let _ = writeln!(md, "- {}", row.verdict);
            }
            let _ = writeln!(md);
        }
    }

    /// The stability section's opening: the reference run, W_ref and each structure's critical
    /// bit damping.
    fn stability_markdown(&self, md: &mut String) {
        let _ = writeln!(md, "## Stability\n");
        let _ = writeln!(
            md,
            "Run {}; W_ref = {} kN; critical bit damping c_b* per structure (steady rotation is unstable \
             when r·dT/dw(Ω) ≤ c_b*):\n",
            self.runs[0].run.label,
            self.w_ref_n / 1000.0
        );
        let _ = writeln!(md, "| structure | c_b* (N·m·s/rad) |");
        let _ = writeln!(md, "|---|---|");
        for st in &self.structures {
            let _ = writeln!(md, "| {} | {:.2} |", st.label, st.critical_nms);
        }
        for warning in &self.off_the_map {
            let _ = writeln!(md, "\n> **Off the map:** {warning}.");
        }
        self.advice_markdown(md);
    }

    /// The advice at the record's operating point, and the simulated maps' table.
    fn advice_markdown(&self, md: &mut String) {
        if let Some((seen, advice)) = &self.record_advice {
            let _ = writeln!(
                md,
                "\n**Advice at the record's operating point** (its mean bit speed and weight on bit, over its {} \
                 samples): {}.",
                seen.samples, advice.words
            );
            let _ = writeln!(
                md,
                "\nA bit stuck at least 1 % of the time stick-slips, whatever the linear criterion says of steady \
                 rotation; what ends it is found by simulating the 1-DOF string from the state the bit is in \
                 (the settled cycle), for {} posterior samples of each law at least {} probable.",
                crate::run::advice::RECORD_ESCAPE_SAMPLES,
                crate::run::advice::RECORD_ESCAPE_MIN_PROBABILITY
            );
        }
        let Some(sim) = &self.simulated else {
            return;
        };
        let onset = sim.onset.boundary_wob_kn(0.5);
        let escape = sim.escape.as_ref().map(|(g, _)| g.boundary_wob_kn(0.5));
        let _ = writeln!(
            md,
            "\nStick-slip by simulated strings ({} strings of the 1-DOF string, {:.2e} string-seconds): the weight on \
             bit (kN) from which it develops from steady rotation kicked by a tenth of the speed (P ≥ 0.5){}; \
             between the two lies the bistable band (— : none on the grid, unknown: strings left physical bounds).\n",
            sim.strings,
            sim.simulated_s,
            if escape.is_some() {
                " and from which it persists once the bit is in it at the record's operating point"
            } else {
                ""
            }
        );
        let kn = |v: Option<f64>| match v {
            None => "—".to_string(),
            Some(v) if v.is_nan() => "unknown".to_string(),
            Some(v) => format!("{v:.0}"),
        };
        let _ = writeln!(
            md,
            "| Ω (rpm) | develops |{}\n|---|---|{}",
            if escape.is_some() { " persists |" } else { "" },
            if escape.is_some() { "---|" } else { "" }
        );
        for (i, rpm) in sim.onset.omega_rpm.iter().enumerate() {
            let _ = write!(md, "| {rpm} | {} |", kn(onset[i]));
            if let Some(e) = &escape {
                let _ = write!(md, " {} |", kn(e[i]));
            }
            let _ = writeln!(md);
        }
    }

    /// The boundaries of the 1-DOF string's maps wholly off their weights on bit, in words.
    fn boundaries_off_the_map(&self) -> Vec<String> {
        let s = &self.input.stability;
        let inputs: Vec<LawSamples> = self.map_laws().into_iter().cloned().collect();
        let criterion = map::Criterion::Lumped(s.lumped);
        map::boundaries(
            &inputs,
            &s.omega_rpm,
            criterion.critical_nms(),
            self.w_ref_n,
            s.percentile,
        )
        .off_the_map(&s.omega_rpm, &s.wob_kn, &criterion, s.percentile)
    }

    /// The table of the 1-DOF string's boundaries at the table's speeds: MAP and percentile per
    /// law, and the mixture's.
    fn boundaries_markdown(&self, md: &mut String) {
        let s = &self.input.stability;
        let c = self.structures[0].critical_nms;
        let inputs: Vec<LawSamples> = self.map_laws().into_iter().cloned().collect();
        let b = map::boundaries(&inputs, &s.table_omega_rpm, c, self.w_ref_n, s.percentile);
        let _ = writeln!(
            md,
            "\nBoundaries of the 1-DOF string, W* (kN) above which steady rotation is unstable (— : none \
             destabilises): MAP, the {} % percentile over {} samples per law, and the mixture of the laws \
             weighted by their probability.\n",
            s.percentile * 100.0,
            s.samples_per_law
        );
        let _ = write!(md, "| Ω (rpm) |");
        for l in &b.laws {
            let _ = write!(md, " {} MAP | {} {} % |", l.law, l.law, s.percentile * 100.0);
        }
        if b.mixture_wob_kn.is_some() {
            let _ = write!(md, " mixture {} % |", s.percentile * 100.0);
        }
        let columns = 2 * b.laws.len() + usize::from(b.mixture_wob_kn.is_some());
        let _ = writeln!(md, "\n|---|{}", "---|".repeat(columns));
        let kn = |v: Option<f64>| match v {
            None => "—".to_string(),
            Some(v) if v.is_nan() => "unknown".to_string(),
            Some(v) => format!("{v:.1}"),
        };
        for (i, rpm) in s.table_omega_rpm.iter().enumerate() {
            let _ = write!(md, "| {rpm} |");
            for l in &b.laws {
                let _ = write!(md, " {} | {} |", kn(l.map_wob_kn[i]), kn(l.p_wob_kn[i]));
            }
            if let Some(m) = &b.mixture_wob_kn {
                let _ = write!(md, " {} |", kn(m[i]));
            }
            let _ = writeln!(md);
        }
    }
}

/// The section listing each figure with its caption, size and links to its SVG and PNG.
pub(crate) fn figures_markdown(md: &mut String, figures: &[FigureInfo]) {
    let _ = writeln!(md, "\n## Figures\n");
    for f in figures {
        let _ = writeln!(
            md,
            "### {}\n\n![{}](figures/{}.svg)\n\n{} ({} × {} px; [PNG](figures/{}.png), [SVG](figures/{}.svg))\n",
            f.stem, f.stem, f.stem, f.caption, f.width, f.height, f.stem, f.stem
        );
    }
}

fn epsilon_text(e: Option<f64>) -> String {
    e.map_or("∞".into(), |e| format!("{e:.5}"))
}

/// rpm of a speed in rad/s.
fn rpm(w: f64) -> f64 {
    w / RAD_S_PER_RPM
}
