//! The directories bitrock writes, named in one place: a run directory (its store, summary
//! files and selection check), a report directory, and what bitrock counts as its own in each.
//! Every command that replaces or writes into such a directory asks [`Owned`] first, so that
//! only files bitrock wrote are ever replaced ([`crate::files::refuse_foreign`]).

use std::path::{Component, Path};

/// The run store (SQLite): everything that defines a run and every population.
pub const STORE_FILE: &str = "run.sqlite";

/// The run's summary document (settings, fits, prior, populations, posterior).
pub const RUN_JSON: &str = "run.json";
/// The predictive envelopes of the summarised population.
pub const ENVELOPES_CSV: &str = "envelopes.csv";
/// The record as the run used it (SI units, calibration and validation rows).
pub const DATA_CSV: &str = "data.csv";
/// SQLite's companions of the store while it is written.
pub const STORE_COMPANIONS: [&str; 3] = ["run.sqlite-journal", "run.sqlite-wal", "run.sqlite-shm"];
/// The directory of a run's selection check.
pub const SELECTION_DIR: &str = "selection";
/// The selection check's document inside [`SELECTION_DIR`].
pub const SELECTION_JSON: &str = "selection.json";
/// Every file of a selection check.
pub const SELECTION_FILES: [&str; 5] = [
    SELECTION_JSON,
    "matrix.csv",
    "replicates.csv",
    "confusion.svg",
    "confusion.png",
];
/// A report's document.
pub const REPORT_MD: &str = "report.md";
/// A report's figures directory (SVG and PNG).
pub const FIGURES_DIR: &str = "figures";

/// What bitrock wrote in a kind of directory, judged by relative path (`is_dir` for a
/// directory): anything else in it is the user's and is never replaced.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Owned {
    /// A run directory: the store and its companions, the summary files, the selection check.
    Run,
    /// A report directory: report.md and figures/*.svg|png.
    Report,
    /// A selection check's directory (inside a run directory).
    Selection,
}

impl Owned {
    /// True when `rel` (relative to the directory) is something bitrock writes there.
    pub fn owns(self, rel: &Path, is_dir: bool) -> bool {
        let parts: Vec<&str> = rel
            .components()
            .map(|c| match c {
                Component::Normal(s) => s.to_str().unwrap_or("\u{0}"),
                _ => "\u{0}",
            })
            .collect();
        match (self, parts.as_slice()) {
            (Owned::Run, [name]) if !is_dir => {
                [STORE_FILE, RUN_JSON, ENVELOPES_CSV, DATA_CSV].contains(name) || STORE_COMPANIONS.contains(name)
            }
            (Owned::Run, [SELECTION_DIR]) => is_dir,
            (Owned::Run, [SELECTION_DIR, rest @ ..]) => {
                Owned::Selection.owns(&rest.iter().collect::<std::path::PathBuf>(), is_dir)
            }
            (Owned::Selection, [name]) => !is_dir && SELECTION_FILES.contains(name),
            (Owned::Report, [REPORT_MD]) => !is_dir,
            (Owned::Report, [FIGURES_DIR]) => is_dir,
            (Owned::Report, [FIGURES_DIR, name]) => {
                !is_dir && (name.ends_with(".svg") || name.ends_with(".png")) && !name.starts_with('.')
            }
            _ => false,
        }
    }
}

/// True when `dir` holds a run store (a file named [`STORE_FILE`]).
pub fn is_run_dir(dir: &Path) -> bool {
    dir.join(STORE_FILE).is_file()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ownership_by_kind_of_directory() {
        let p = Path::new;
        assert!(Owned::Run.owns(p("run.sqlite"), false));
        assert!(Owned::Run.owns(p("selection/matrix.csv"), false));
        assert!(!Owned::Run.owns(p("selection/notes.txt"), false));
        assert!(!Owned::Run.owns(p("notes.txt"), false));
        assert!(!Owned::Run.owns(p("run.json"), true));
        assert!(Owned::Report.owns(p("figures/fits.png"), false));
        assert!(!Owned::Report.owns(p("figures/my-notes.md"), false));
        assert!(!Owned::Report.owns(p("my-notes.md"), false));
        assert!(!Owned::Report.owns(p("figures/sub"), true));
    }
}
