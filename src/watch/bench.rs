//! `bitrock bench --watch`: a watch on a simulated well of three formations
//! (`examples/wells/formations.toml`), its evidence started warm (each window from the one
//! before's posterior, the default) and cold (every window from the boxes), and by the paper's
//! ABC on each window (rejection, 4,000 particles): per-window latency, candidates scored, the
//! changes declared, and how far the two starts' law probabilities lie apart.

use super::source::{Rows, Source};
use super::{FollowOptions, Update, WatchSettings, follow};
use crate::error::{Error, Result};
use crate::eval::Backend;
use serde::Serialize;
use std::path::Path;

/// The well the bench watches: claystone (m2), sandstone (m3), claystone again, 120 s each.
const WELL: &str = include_str!("../../examples/wells/formations.toml");

/// One start's watch of the well.
#[derive(Clone, Debug, Serialize)]
pub struct WatchRun {
    /// "warm" or "cold" (the evidence), or "abc" (the paper's ABC).
    pub start: String,
    pub windows: usize,
    /// Seconds from a window's last row to its update (rows read as fast as the file gives
    /// them, so this is the window's computing time): median, 90th and 99th percentiles.
    pub latency_median_s: f64,
    pub latency_p90_s: f64,
    pub latency_p99_s: f64,
    /// Candidates scored per window (median) and over the record.
    pub candidates_median: u64,
    pub candidates_total: u64,
    /// Windows that declared a change of formation.
    pub changes: Vec<usize>,
    /// Wall time of the whole watch, s.
    pub seconds: f64,
}

/// The watch bench.
#[derive(Clone, Debug, Serialize)]
pub struct WatchBench {
    /// The well and its windows, in words.
    pub record: String,
    pub runs: Vec<WatchRun>,
    /// Windows where the two starts' carried probabilities differ by at most 0.05 (every law),
    /// and where they rank the same law first.
    pub agree_within_005: usize,
    pub same_most_probable: usize,
}

/// Watches the bench's well (with `quick`, its first two formations cut to 60 s each) from a
/// file written in `scratch`, warm and cold, on `backend`.
pub fn run(quick: bool, backend: Backend, scratch: &Path, note: &mut dyn FnMut(String)) -> Result<WatchBench> {
    let mut well = crate::simulate::Well::parse(WELL, Path::new("examples/wells/formations.toml"))?;
    if quick {
        well.segments.truncate(2);
        for segment in &mut well.segments {
            segment.duration_s = segment.duration_s.min(60.0);
        }
    }
    let trace = crate::simulate::simulate_well_with(&well, &mut |_, _| {})?;
    let path = scratch.join("bench-well.csv");
    let file = std::fs::File::create(&path).map_err(|source| Error::Write {
        path: path.clone(),
        source,
    })?;
    crate::simulate::write_well_csv_in(
        &trace,
        &well,
        crate::units::TorqueUnit::KNm,
        std::io::BufWriter::new(file),
    )
    .map_err(|source| Error::Write {
        path: path.clone(),
        source,
    })?;
    let mut runs = Vec::new();
    let mut updates: Vec<Vec<Update>> = Vec::new();
    let abc = super::abc_config(crate::run::abc::Sampler::Rejection, None, None, None)?;
    for (start, warm, abc) in [("warm", true, None), ("cold", false, None), ("abc", true, Some(abc))] {
        let settings = WatchSettings {
            backend,
            warm_start: warm,
            abc,
            ..WatchSettings::default()
        };
        note(format!("watching the bench well ({start})"));
        let mut rows = Rows::open(
            &Source::File {
                path: path.clone(),
                follow: false,
            },
            &settings.data,
            &settings.wits,
            &|| false,
        )?;
        let started = std::time::Instant::now();
        let mut given = Vec::new();
        follow(
            &mut rows,
            settings,
            FollowOptions::default(),
            &mut crate::abc::Silent,
            &mut |u| {
                given.push(u.clone());
                Ok(())
            },
        )?;
        let mut latencies: Vec<f64> = given.iter().map(|u| u.latency_s).collect();
        latencies.sort_by(f64::total_cmp);
        let mut candidates: Vec<u64> = given.iter().map(|u| u.candidates_scored).collect();
        candidates.sort_unstable();
        let q = |p: f64| crate::numerics::quantile(&latencies, p);
        runs.push(WatchRun {
            start: start.into(),
            windows: given.len(),
            latency_median_s: q(0.5),
            latency_p90_s: q(0.9),
            latency_p99_s: q(0.99),
            candidates_median: candidates.get(candidates.len() / 2).copied().unwrap_or(0),
            candidates_total: candidates.iter().sum(),
            changes: given.iter().filter(|u| u.change).map(|u| u.window).collect(),
            seconds: started.elapsed().as_secs_f64(),
        });
        updates.push(given);
    }
    let pairs = || updates[0].iter().zip(&updates[1]);
    let agree_within_005 = pairs()
        .filter(|(a, b)| {
            a.laws
                .iter()
                .zip(&b.laws)
                .all(|(x, y)| (x.probability - y.probability).abs() <= 0.05)
        })
        .count();
    let same_most_probable = pairs().filter(|(a, b)| a.most_probable == b.most_probable).count();
    let (length, step) = (
        updates[0].first().map_or(0.0, |u| u.end_s - u.start_s),
        updates[0].get(1).map_or(0.0, |u| u.start_s) - updates[0].first().map_or(0.0, |u| u.start_s),
    );
    Ok(WatchBench {
        record: format!(
            "examples/wells/formations.toml{} ({} s at {} Hz), windows of {length} s every {step} s, four laws, evidence of {} × {} particles, ABC of {}",
            if quick {
                ", its first two formations cut to 60 s"
            } else {
                ""
            },
            well.duration_s().round(),
            well.recording.sample_hz,
            WatchSettings::default().evidence.islands,
            WatchSettings::default().evidence.particles,
            super::ABC_PARTICLES,
        ),
        runs,
        agree_within_005,
        same_most_probable,
    })
}
