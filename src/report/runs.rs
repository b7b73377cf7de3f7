//! The report's runs from where they live: run directories (`bitrock report`) or runs just
//! finished (`bitrock demo`), labelled by their δ; then the report with the paper's maps.

use super::{ReportInput, ReportRun, ReportSummary, StabilitySettings, write_report};
use crate::abc::Population;
use crate::abc::posterior::PosteriorSummary;
use crate::error::{Error, Result};
use crate::run;

use std::path::{Path, PathBuf};

impl ReportRun {
    /// One run of a report, labelled by its δ (and its directory `dir` when an `earlier` run
    /// has the same δ). `summary`: the last population's summary when the caller has it.
    pub fn new(
        earlier: &[ReportRun],
        dir: &Path,
        config: &run::abc::Config,
        populations: Vec<Population>,
        summary: Option<PosteriorSummary>,
    ) -> Self {
        let same_delta = earlier.iter().any(|r| r.delta.to_bits() == config.delta.to_bits());
        let label = if same_delta {
            format!("δ = {} ({})", config.delta, dir.display())
        } else {
            format!("δ = {}", config.delta)
        };
        ReportRun {
            label,
            delta: config.delta,
            laws: config.laws.clone(),
            populations,
            w_ref_n: config.fit.w_ref_n,
            summary,
            selection: None,
            early_end: None,
            answer: None,
        }
    }
}

/// Reads run directories into the report's runs, with the set-up (record, fits) of the first.
/// Refuses an empty list, a run without a completed population, and runs of different records
/// (the figures draw one data set).
pub fn read_run_dirs(dirs: &[PathBuf]) -> Result<(run::abc::Setup, Vec<ReportRun>)> {
    let mut runs = Vec::new();
    let mut first: Option<run::abc::Setup> = None;
    for dir in dirs {
        // The report draws the last population's particles and every population's record.
        run::dir::refuse_unfinished_evidence(dir)?;
        let store = run::abc::Store::open(dir)?;
        let stored = store.load_with_last_particles()?;
        let early_end = store.early_end()?;
        if stored.populations.is_empty() {
            return Err(Error::Data {
                path: dir.clone(),
                message: format!(
                    "the run has no completed population yet; {}",
                    run::abc::resume_advice(dir)
                ),
            });
        }
        let config: run::abc::Config =
            serde_json::from_value(stored.setup.config.clone()).map_err(|e| Error::Data {
                path: dir.clone(),
                message: format!("the stored configuration is not one this bitrock reads: {e}"),
            })?;
        if let Some(reference) = &first
            && (reference.data.calibration != stored.setup.data.calibration
                || reference.data.validation != stored.setup.data.validation)
        {
            return Err(Error::Data {
                path: dir.clone(),
                message: format!(
                    "its record differs from that of {}; a report draws runs of one record",
                    dirs[0].display()
                ),
            });
        }
        let now = stored.state();
        // The summary here, where the run's boxes are known, to mark what they set.
        let summary = stored.populations.last().map(|last| {
            let mut summary = crate::abc::posterior::summarize(&last.particles, &config.laws);
            summary.mark_identified(&stored.setup.prior);
            summary
        });
        let answer = match (stored.populations.last(), &summary) {
            (Some(last), Some(summary)) => {
                run::abc::answer(&stored.setup, &config.fit, &last.record, &summary.model_probabilities)?.1
            }
            _ => None,
        };
        let mut run = ReportRun::new(&runs, dir, &config, stored.populations, summary);
        run.early_end = early_end;
        run.answer = answer;
        run.selection = crate::run::selection::read(dir)?.map(|check| {
            let stale = check.stale(&now);
            (check, stale)
        });
        runs.push(run);
        first.get_or_insert(stored.setup);
    }
    let setup = first.ok_or_else(|| Error::setting("DIR", "give at least one run directory"))?;
    Ok((setup, runs))
}

/// The report of `runs` (all of the record and fits in `setup`) with the maps `stability`
/// describes (the string, the axes, the maps by simulated strings), written into `out`.
pub fn write_paper_report(
    out: &Path,
    setup: &run::abc::Setup,
    runs: &[ReportRun],
    evidence: Option<&crate::abc::evidence::Evidence>,
    stability: StabilitySettings,
) -> Result<ReportSummary> {
    let input = ReportInput {
        data: &setup.data,
        fits: &setup.fits,
        runs,
        stability,
        evidence,
    };
    write_report(out, &input)
}
