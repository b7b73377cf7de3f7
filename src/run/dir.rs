//! A run directory's lifecycle and the directories bitrock writes, named in one place: a run
//! directory (its store, summary files and selection check), a report directory, and what
//! bitrock counts as its own in each. A new run's directory is checked ([`check_new`]) and
//! then claimed under its lock, checked again there, and staged beside a run it replaces
//! (`Claim`); outputs elsewhere are kept out of runs ([`refuse_inside_kept_dir`],
//! [`check_output_file`]). Every command that replaces or writes into such a directory asks
//! [`Owned`] first, so that only files bitrock wrote are ever replaced
//! ([`crate::files::refuse_foreign`]).

use super::abc::store::Store;
use super::abc::store::{STORE_COMPANIONS, STORE_FILE};
use crate::error::{Error, Result};
use crate::files::{self, Authorship};
use std::fs::File;
use std::io::{Read, Write};
use std::path::{Component, Path, PathBuf};

/// The run's summary document (settings, fits, prior, populations, posterior).
pub const RUN_JSON: &str = "run.json";
/// The predictive envelopes of the summarised population.
pub const ENVELOPES_CSV: &str = "envelopes.csv";
/// The record as the run used it (SI units, calibration and validation rows).
pub const DATA_CSV: &str = "data.csv";
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
/// A watch directory's store (SQLite; see `crate::watch::store`).
pub const WATCH_STORE_FILE: &str = "watch.sqlite";
/// SQLite's companions of the watch store while it is written.
pub const WATCH_STORE_COMPANIONS: [&str; 3] = ["watch.sqlite-journal", "watch.sqlite-wal", "watch.sqlite-shm"];
/// An evidence directory's document (`bitrock evidence --out`): the evidence, its fits, boxes
/// and each law's posterior sets.
pub const EVIDENCE_JSON: &str = "evidence.json";
/// An evidence directory's posterior particles (every law's sets weighed by its P(m | y)), the
/// particle CSV `bitrock stability` reads.
pub const POSTERIOR_CSV: &str = "posterior.csv";
/// An evidence directory's record, whole (the samples and their units and columns), to
/// compute the evidence again: its check by re-simulation.
pub const RECORD_JSON: &str = "record.json";
/// An evidence directory's job and the text of its law files: what computes it again.
pub const JOB_JSON: &str = "job.json";
/// Where an evidence directory keeps an evidence under way: its job and record (as
/// [`JOB_JSON`] and [`RECORD_JSON`]) and the samplers' progress ([`PROGRESS_BIN`]), gone once
/// the evidence is written.
pub const UNFINISHED_DIR: &str = "unfinished";
/// The samplers' progress of an evidence under way (postcard bytes).
pub const PROGRESS_BIN: &str = "progress.bin";
/// A surface directory's document (`bitrock surface --out DIR`): the inference, its check and
/// what it implies at the bit.
pub const SURFACE_JSON: &str = "surface.json";
/// A surface directory's job (settings, columns, the prior file's and law files' texts).
pub const SURFACE_JOB_JSON: &str = "surface-job.json";
/// A surface directory's record: the bytes of the CSV it was started on.
pub const RECORD_CSV: &str = "record.csv";
/// A surface directory's sampler populations (postcard bytes), stored as each completes.
pub const POPULATIONS_BIN: &str = "populations.bin";
/// A surface directory's predicted bit speed per sample (median and 90 % band).
pub const SURFACE_BIT_CSV: &str = "bit.csv";
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
    /// A watch directory: the watch store and its companions.
    Watch,
    /// An evidence directory: evidence.json, posterior.csv and data.csv.
    Evidence,
    /// A surface directory: surface.json, posterior.csv, bit.csv, record.csv, its job and
    /// populations.
    Surface,
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
            (Owned::Watch, [name]) => !is_dir && (*name == WATCH_STORE_FILE || WATCH_STORE_COMPANIONS.contains(name)),
            (Owned::Evidence, [name]) => {
                (!is_dir && [EVIDENCE_JSON, POSTERIOR_CSV, DATA_CSV, RECORD_JSON, JOB_JSON].contains(name))
                    || (is_dir && *name == UNFINISHED_DIR)
            }
            (Owned::Evidence, [UNFINISHED_DIR, name]) => {
                !is_dir && [JOB_JSON, RECORD_JSON, PROGRESS_BIN].contains(name)
            }
            (Owned::Surface, [name]) => {
                !is_dir
                    && [
                        SURFACE_JSON,
                        POSTERIOR_CSV,
                        SURFACE_BIT_CSV,
                        RECORD_CSV,
                        SURFACE_JOB_JSON,
                        POPULATIONS_BIN,
                    ]
                    .contains(name)
            }
            (Owned::Report, [REPORT_MD]) => !is_dir,
            (Owned::Report, [FIGURES_DIR]) => is_dir,
            (Owned::Report, [FIGURES_DIR, name]) => {
                !is_dir && (name.ends_with(".svg") || name.ends_with(".png")) && !name.starts_with('.')
            }
            _ => false,
        }
    }
}

/// True when `dir` holds an evidence under way (its [`UNFINISHED_DIR`] with a job) and no run
/// store.
pub fn is_unfinished_evidence_dir(dir: &Path) -> bool {
    dir.join(UNFINISHED_DIR).join(JOB_JSON).is_file() && !is_run_dir(dir)
}

/// Refuses, naming it, a directory that holds an evidence under way where a finished run or
/// evidence is wanted: it says how to continue it.
pub fn refuse_unfinished_evidence(dir: &Path) -> Result<()> {
    if is_unfinished_evidence_dir(dir) && !dir.join(EVIDENCE_JSON).is_file() {
        return Err(Error::Data {
            path: dir.to_path_buf(),
            message: format!(
                "holds an evidence under way, not finished; continue it with `bitrock evidence --resume {}` (Python: `bitrock.resume_evidence`)",
                dir.display()
            ),
        });
    }
    Ok(())
}

/// True when `dir` holds an evidence (a file named [`EVIDENCE_JSON`]) and no run store.
pub fn is_evidence_dir(dir: &Path) -> bool {
    dir.join(EVIDENCE_JSON).is_file() && !is_run_dir(dir)
}

/// True when `dir` holds a run store (a file named [`STORE_FILE`]).
pub fn is_run_dir(dir: &Path) -> bool {
    dir.join(STORE_FILE).is_file()
}

/// Where a run is written.
#[derive(Clone, Debug, PartialEq)]
pub struct Dir {
    pub path: PathBuf,
    /// Replace the bitrock run the directory holds (`--force`); without it such a directory
    /// is refused before any work. A directory holding anything bitrock did not write is
    /// refused either way.
    pub replace: bool,
}

/// What a run directory holds, once [`check_new`] accepted it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DirState {
    /// Missing, empty, or holding only bitrock's temporaries: the run is written in place.
    Fresh,
    /// A bitrock run, to be replaced (`--force`) once the new run's first population is stored.
    Replace,
}

/// Refuses, before any work and naming `--out`, a run directory that cannot be written: one
/// that holds anything bitrock did not write (even with `replace`), the current directory or
/// one holding the record `input` (the record is never deleted), a bitrock run without
/// `replace`, a store that is not a bitrock store.
pub fn check_new(dir: &Dir, input: Option<&Path>) -> Result<DirState> {
    let path = dir.path.as_path();
    files::check_output_dir(path, "out")?;
    crate::run::dir::refuse_inside_kept_dir(path, "out")?;
    let refuse = |why: String| Err(Error::setting("out", format!("{}: {why}", path.display())));
    let Ok(real) = path.canonicalize() else {
        return Ok(DirState::Fresh);
    };
    if let Some(input) = input.and_then(|i| i.canonicalize().ok())
        && input.starts_with(&real)
    {
        return refuse(format!(
            "holds the record {}; write the run to a directory of its own",
            input.display()
        ));
    }
    let has_store = crate::run::dir::is_run_dir(path);
    // Without a store nothing in the directory is a run's: only bitrock's temporaries may be there.
    files::refuse_foreign(path, "out", &|rel, is_dir| {
        has_store && crate::run::dir::Owned::Run.owns(rel, is_dir)
    })?;
    if !has_store {
        return Ok(DirState::Fresh);
    }
    if let Err(e) = Store::open(path) {
        return refuse(format!(
            "its {STORE_FILE} cannot be read as a bitrock run ({e}); remove the directory yourself if it can go"
        ));
    }
    if !dir.replace {
        return refuse("holds a bitrock run; pass `force` to replace it".into());
    }
    if std::env::current_dir().is_ok_and(|cwd| cwd.canonicalize().is_ok_and(|cwd| cwd == real)) {
        return refuse(
            "is the current directory, which is never replaced; give the run directory's path from its parent".into(),
        );
    }
    Ok(DirState::Replace)
}

/// Claims the directory `dir` (named by the setting `field`) for a new output of any kind: what
/// `check` refuses is refused before the directory exists, then the directory is created and
/// locked (one writer at a time) and `check` runs again under the lock, where another process
/// may have written since; the temporaries of an interrupted writer are removed. Returns the
/// lock and what the check under the lock found.
pub fn claim<T>(dir: &Path, field: &str, check: impl Fn() -> Result<T>) -> Result<(files::DirLock, T)> {
    check()?;
    std::fs::create_dir_all(dir).map_err(|source| Error::output(field, dir, source))?;
    let lock = files::DirLock::acquire(dir)?;
    let found = check()?;
    files::remove_stale(dir);
    Ok((lock, found))
}

/// A run directory being written: its lock, and for a replacement the staging directory beside
/// it that the new run is written to until its first population is stored.
pub(super) struct Claim {
    pub(super) dir: PathBuf,
    /// The run directory's lock; `None` once handed to the outcome.
    lock: Option<files::DirLock>,
    /// The new run's directory and lock while it is staged; `None` once in place.
    staged: Option<(PathBuf, files::DirLock)>,
}

impl Claim {
    /// Claims `dir` ([`claim`]: checked, created, locked, checked again); stages the new run
    /// beside a run it replaces.
    pub(super) fn new(dir: &Dir, input: Option<&Path>) -> Result<Self> {
        let path = dir.path.clone();
        let (lock, state) = claim(&path, "out", || check_new(dir, input))?;
        let staged = match state {
            DirState::Fresh => None,
            DirState::Replace => {
                let parent = files::parent_dir(&path);
                files::remove_stale(parent);
                let staging = tempfile::Builder::new()
                    .prefix(files::STAGING_PREFIX)
                    .tempdir_in(parent)
                    .map_err(|source| Error::output("out", &path, source))?
                    .keep();
                let staging_lock = files::DirLock::acquire(&staging)?;
                Some((staging, staging_lock))
            }
        };
        Ok(Self {
            dir: path,
            lock: Some(lock),
            staged,
        })
    }

    /// Where the store is created: the staging directory, or the run directory itself.
    pub(super) fn store_dir(&self) -> &Path {
        self.staged.as_ref().map_or(&self.dir, |(staging, _)| staging)
    }

    /// Swaps a staged run into place (its first population is stored) and removes the old
    /// run; the store must then be reopened at its new place. No-op for a run in place.
    /// True while the new run is staged beside the run it replaces.
    pub(super) fn is_staged(&self) -> bool {
        self.staged.is_some()
    }

    pub(super) fn put_in_place(&mut self) -> Result<bool> {
        let Some((staging, staging_lock)) = self.staged.take() else {
            return Ok(false);
        };
        files::exchange_dirs(&self.dir, &staging).map_err(|source| Error::output("out", &self.dir, source))?;
        files::sync_dir(files::parent_dir(&self.dir));
        // The staging name now holds the old run, still locked by us: gone before the lock is.
        let old_lock = self.lock.replace(staging_lock);
        std::fs::remove_dir_all(&staging).map_err(|source| Error::output("out", &staging, source))?;
        drop(old_lock);
        Ok(true)
    }

    /// The lock of the run directory once sampling ended. A staged run that stored no
    /// population is discarded: the old run stays.
    pub(super) fn finish(&mut self) -> Result<files::DirLock> {
        if let Some((staging, staging_lock)) = self.staged.take() {
            let _ = std::fs::remove_dir_all(&staging);
            drop(staging_lock);
            return Err(Error::Incomplete(format!(
                "the new run stored no population; {} still holds the run it held",
                self.dir.display()
            )));
        }
        Ok(self.lock.take().expect("the lock is handed over once"))
    }
}

impl Drop for Claim {
    /// A staged run abandoned by an error is removed; the old run stays.
    fn drop(&mut self) {
        if let Some((staging, _)) = &self.staged {
            let _ = std::fs::remove_dir_all(staging);
        }
    }
}

/// Refuses, naming `flag`, an output file that cannot be written or is not bitrock's to
/// replace: a directory, a dangling symbolic link, a path in a directory that does not exist,
/// one of bitrock's own lock or temporary files, any file inside a run, evidence or watch
/// directory (each keeps to its own files, its store above all; [`refuse_inside_kept_dir`]),
/// and, unless `force`, an existing file that
/// is not bitrock's own unchanged output ([`files::authorship`]). A symbolic link is written through:
/// the file it points to is the target, checked by the same rule ([`files::output_target`]).
pub fn check_output_file(target: &Path, field: &str, force: bool) -> Result<()> {
    files::check_not_dangling(target, field)?;
    let real = files::output_target(target);
    if real.is_dir() {
        return Err(Error::setting(
            field,
            format!("{} is a directory; give a file name", target.display()),
        ));
    }
    let dir = files::parent_dir(&real);
    if !dir.is_dir() {
        return Err(Error::setting(
            field,
            format!("{}: the directory {} does not exist", target.display(), dir.display()),
        ));
    }
    if is_run_store(&real) {
        return Err(Error::setting(
            field,
            format!(
                "{} is a run's store ({}); it is never overwritten: give another file",
                target.display(),
                STORE_FILE
            ),
        ));
    }
    if real
        .file_name()
        .and_then(|n| n.to_str())
        .is_some_and(files::is_bitrock_scratch)
    {
        return Err(Error::setting(
            field,
            format!(
                "{} is one of bitrock's lock or temporary files; give another file",
                target.display()
            ),
        ));
    }
    refuse_inside_kept_dir(&real, field)?;
    if force || !real.exists() {
        return Ok(());
    }
    let why = match files::authorship(&real) {
        Authorship::Own => return Ok(()),
        Authorship::Changed => "was written by bitrock but changed since",
        Authorship::Unmarked => "is not a file bitrock wrote",
        Authorship::Unknowable => {
            "lies on a file system that keeps no extended attributes, so bitrock cannot tell whether it wrote it"
        }
    };
    Err(Error::setting(
        field,
        format!(
            "{} exists and {why}; it is not replaced: give another file, or pass `force` to replace it",
            target.display()
        ),
    ))
}

/// Writes the user's output file `target` (named by `flag`) whole or not at all: checked by
/// [`check_output_file`] (a symbolic link is written through; `force` replaces a file bitrock
/// did not write), then [`files::write_own`].
pub fn write_whole(
    target: &Path,
    field: &str,
    force: bool,
    write: impl FnOnce(&mut dyn Write) -> std::io::Result<()>,
) -> Result<()> {
    check_output_file(target, field, force)?;
    files::write_own(&files::output_target(target), field, write)
}

/// Refuses, naming `field`, an output path inside a directory bitrock keeps whole (at any
/// depth): a run's (its `selection/` included), an evidence's (finished or under way) or a
/// watch's. Each holds only what bitrock writes there as that kind of directory; an output of
/// another command would replace or lie beside its files.
pub fn refuse_inside_kept_dir(path: &Path, field: &str) -> Result<()> {
    match enclosing_kept_dir(path) {
        Some((dir, kind)) => Err(Error::setting(
            field,
            format!(
                "{} lies inside the {kind} directory {}, which holds only what bitrock writes there as {kind}; write it outside that directory",
                path.display(),
                dir.display()
            ),
        )),
        None => Ok(()),
    }
}

/// The kind of directory bitrock keeps whole that `dir` is ("a run", "an evidence", "a
/// watch"), if any.
fn kept_kind(dir: &Path) -> Option<&'static str> {
    if is_run_dir(dir) {
        Some("run")
    } else if is_evidence_dir(dir) || is_unfinished_evidence_dir(dir) {
        Some("evidence")
    } else if dir.join(WATCH_STORE_FILE).is_file() {
        Some("watch")
    } else if crate::run::surface::dir::is_surface_dir(dir) {
        Some("surface")
    } else {
        None
    }
}

/// The directory bitrock keeps whole that `path` lies in, at any depth, and its kind, if any;
/// `path` itself is not inside itself. A path that does not exist yet is judged by the nearest
/// directory above it that does.
fn enclosing_kept_dir(path: &Path) -> Option<(PathBuf, &'static str)> {
    let absolute = std::path::absolute(path).ok()?;
    let mut above = absolute.parent();
    while let Some(dir) = above {
        if let Ok(real) = dir.canonicalize() {
            return real
                .ancestors()
                .find_map(|d| kept_kind(d).map(|kind| (d.to_path_buf(), kind)));
        }
        above = dir.parent();
    }
    None
}

/// What bitrock owns in a directory of kind `owned` ([`Owned::owns`]), and for
/// the files it writes whole there, their mark: a report's files only while their mark matches
/// (a `report.md` the user wrote or edited is the user's); a selection check's unless changed
/// since bitrock wrote them (its five names inside a run are bitrock's, and checks written
/// before marks existed stay replaceable). `dir` is the directory `rel` is relative to. A run's
/// files are judged by name (its store is what makes it a run).
pub fn owns_unchanged(owned: Owned, dir: &Path, rel: &Path, is_dir: bool) -> bool {
    if !owned.owns(rel, is_dir) {
        return false;
    }
    if is_dir || owned == Owned::Run {
        return true;
    }
    matches!(
        (owned, files::authorship(&dir.join(rel))),
        (_, Authorship::Own | Authorship::Unknowable) | (Owned::Selection, Authorship::Unmarked)
    )
}

/// True when `path` is an existing run store: named like one and holding an SQLite database.
fn is_run_store(path: &Path) -> bool {
    let Ok(real) = path.canonicalize() else {
        return false;
    };
    let mut magic = [0u8; 16];
    real.file_name().is_some_and(|n| n == STORE_FILE)
        && File::open(&real)
            .and_then(|mut f| f.read_exact(&mut magic))
            .is_ok_and(|()| &magic == b"SQLite format 3\0")
}

// Job files: what computes a directory's result again (an evidence's, a surface run's), with
// the text of every law file whose law it names, so that the directory computes without them.

/// The key of a job file's law files: each law file's text by its law's name.
const LAW_FILES: &str = "law_files";
/// The key of a job file's job.
const JOB: &str = "job";
/// The most a job file may hold, bytes.
const MAX_JOB_BYTES: u64 = 1 << 30;

/// A JSON document as bitrock writes it: indented, with a final newline.
pub(crate) fn pretty_json(document: &serde_json::Value) -> Vec<u8> {
    let mut json = serde_json::to_vec_pretty(document).expect("a document serialises");
    json.push(b'\n');
    json
}

/// The JSON document at `path` (`what` it is, named in errors), refused above `max_bytes`.
pub(crate) fn read_json_file(path: &Path, what: &str, max_bytes: u64) -> Result<serde_json::Value> {
    let text = files::read_text(path, what, max_bytes)?;
    serde_json::from_str(&text).map_err(|e| Error::Data {
        path: path.to_path_buf(),
        message: format!("not {what}: {e}"),
    })
}

/// A job file's bytes: `job` and the text of each law file among `laws`.
pub(crate) fn job_file(job: &impl serde::Serialize, laws: &[crate::laws::Law]) -> Vec<u8> {
    let law_files: serde_json::Map<String, serde_json::Value> = laws
        .iter()
        .filter_map(|law| law.file())
        .map(|file| (file.name.clone(), file.source.clone().into()))
        .collect();
    pretty_json(&serde_json::json!({ JOB: job, LAW_FILES: law_files }))
}

/// The job of the job file at `path` ([`job_file`]), its law files' laws registered in this
/// process; `None` where there is no such file (a directory an earlier bitrock wrote without
/// one).
pub(crate) fn read_job_file(path: &Path) -> Result<Option<serde_json::Value>> {
    if !path.exists() {
        return Ok(None);
    }
    let mut stored = read_json_file(path, "a job file", MAX_JOB_BYTES)?;
    if let Some(law_files) = stored.get(LAW_FILES) {
        let law_files = law_files.as_object().ok_or_else(|| Error::Data {
            path: path.to_path_buf(),
            message: format!("'{LAW_FILES}' is not a table of law files' texts by name"),
        })?;
        for (name, source) in law_files {
            let source = source.as_str().ok_or_else(|| Error::Data {
                path: path.to_path_buf(),
                message: format!("{LAW_FILES}: the law file of '{name}' is not a text"),
            })?;
            let origin = path.join(format!("{LAW_FILES}/{name}"));
            crate::laws::file::register(crate::laws::file::LawFile::parse(source, &origin)?)?;
        }
    }
    Ok(stored.get_mut(JOB).map(serde_json::Value::take))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A claim refuses before the directory exists what its check refuses, and refuses again
    /// under the lock what another writer put there in between; a claim that holds the lock
    /// keeps every other claim out until it is dropped.
    #[test]
    fn a_claim_checks_before_the_directory_exists_and_again_under_its_lock() {
        let root = tempfile::tempdir().unwrap();
        let dir = root.path().join("out");
        let refused = claim(&dir, "out", || Err::<(), _>(Error::setting("out", "refused")));
        assert!(refused.is_err());
        assert!(!dir.exists(), "nothing made for a refused claim");
        // Passes the first check; the second finds what another writer wrote meanwhile.
        let calls = std::cell::Cell::new(0);
        let raced = claim(&dir, "out", || {
            calls.set(calls.get() + 1);
            match calls.get() {
                1 => Ok(()),
                _ => Err(Error::setting("out", "written meanwhile")),
            }
        });
        assert_eq!(calls.get(), 2);
        assert!(raced.unwrap_err().to_string().contains("written meanwhile"));
        let (held, found) = claim(&dir, "out", || Ok(7)).unwrap();
        assert_eq!(found, 7);
        assert!(claim(&dir, "out", || Ok(())).is_err(), "a second writer is kept out");
        drop(held);
        assert!(claim(&dir, "out", || Ok(())).is_ok());
    }

    #[test]
    fn ownership_by_kind_of_directory() {
        let p = Path::new;
        assert!(Owned::Run.owns(p("run.sqlite"), false));
        assert!(Owned::Run.owns(p("selection/matrix.csv"), false));
        assert!(!Owned::Run.owns(p("selection/notes.txt"), false));
        assert!(!Owned::Run.owns(p("notes.txt"), false));
        assert!(!Owned::Run.owns(p("run.json"), true));
        assert!(Owned::Evidence.owns(p("evidence.json"), false));
        assert!(Owned::Evidence.owns(p("posterior.csv"), false));
        assert!(!Owned::Evidence.owns(p("run.sqlite"), false) && !Owned::Evidence.owns(p("evidence.json"), true));
        assert!(
            Owned::Evidence.owns(p("unfinished"), true) && Owned::Evidence.owns(p("unfinished/progress.bin"), false)
        );
        assert!(
            !Owned::Evidence.owns(p("unfinished/notes.txt"), false) && !Owned::Evidence.owns(p("unfinished"), false)
        );
        assert!(Owned::Report.owns(p("figures/fits.png"), false));
        assert!(!Owned::Report.owns(p("figures/my-notes.md"), false));
        assert!(!Owned::Report.owns(p("my-notes.md"), false));
        assert!(!Owned::Report.owns(p("figures/sub"), true));
    }
}
