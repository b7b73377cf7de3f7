//! An evidence directory (`bitrock evidence --out DIR`, `bitrock.evidence(..., out=DIR)`): the
//! evidence's document with each law's posterior sets (`evidence.json`, what
//! `bitrock.read_evidence` reads), the posterior particles (`posterior.csv`, what
//! `bitrock stability --run DIR` maps), the samples it was computed on (`data.csv`, what
//! `bitrock report DIR` draws them against), and what computes it again: the record whole
//! (`record.json`), the job and the text of every law file whose law it compares (`job.json`),
//! written together or not at all. The directory is read, reported and mapped without the law
//! files, and computed again and checked by re-simulation ([`check_dir`],
//! `bitrock check-selection DIR`).
//!
//! While the evidence is computed, the directory keeps it under way in `unfinished/`
//! ([`Unfinished`]): its job and record at the start, the samplers' progress as they go. An
//! evidence killed part-way is continued from there (`bitrock evidence --resume DIR`) to the
//! evidence the uninterrupted job gives, bit for bit; writing the finished evidence removes it.

use super::check::{EvidenceCheck, check, check_replicates, check_size};
use super::{EvidenceAnalysis, Job, Progress, Saving};
use crate::abc::Observer;
use crate::abc::Particle;
use crate::data::FieldData;
use crate::error::{Error, Result};
use crate::eval::Backend;
use crate::files;
use crate::run::Scoring;
use crate::run::dir::{
    DATA_CSV, EVIDENCE_JSON, JOB_JSON, Owned, POSTERIOR_CSV, PROGRESS_BIN, RECORD_JSON, UNFINISHED_DIR, is_run_dir,
    is_unfinished_evidence_dir, job_file, owns_unchanged, pretty_json, read_job_file, read_json_file,
    refuse_inside_kept_dir,
};
use crate::units::TorqueUnit;
use std::path::{Path, PathBuf};

/// Refuses, before any work and naming `out`, a directory the evidence cannot be written to:
/// a file, a run directory or one inside it, one holding anything bitrock did not write
/// there, and an evidence directory without `force`.
pub fn check_out(dir: &Path, force: bool) -> Result<()> {
    files::check_output_dir(dir, "out")?;
    refuse_inside_kept_dir(dir, "out")?;
    if is_run_dir(dir) {
        return Err(Error::setting(
            "out",
            format!(
                "{} holds an ABC run: write the evidence to a directory of its own",
                dir.display()
            ),
        ));
    }
    files::refuse_foreign(dir, "out", &|rel, is_dir| {
        owns_unchanged(Owned::Evidence, dir, rel, is_dir)
    })?;
    if is_unfinished_evidence_dir(dir) && !force {
        return Err(Error::setting(
            "out",
            format!(
                "{0} holds an evidence under way; continue it with `bitrock evidence --resume {0}` (Python: `bitrock.resume_evidence`), or pass `force` to start again",
                dir.display()
            ),
        ));
    }
    if dir.join(EVIDENCE_JSON).is_file() && !force {
        return Err(Error::setting(
            "out",
            format!("{} holds an evidence; pass `force` to replace it", dir.display()),
        ));
    }
    Ok(())
}

/// Least seconds between two saves of an evidence's progress within one of its parts.
pub const SAVE_EVERY_S: f64 = 10.0;

/// An evidence under way in its directory: the directory locked (one writer at a time), the
/// job and record kept in `unfinished/`, the samplers' progress saved there as they go.
pub struct Unfinished {
    dir: PathBuf,
    _lock: files::DirLock,
    /// Least seconds between two saves ([`SAVE_EVERY_S`]).
    pub every_s: f64,
}

impl Unfinished {
    /// Starts `job`'s evidence on `data` in `dir` (refused as [`check_out`] refuses, before the
    /// directory exists and again under its lock: [`crate::run::dir::claim`]): the job and
    /// record written to `unfinished/`, any
    /// progress of an earlier evidence there dropped. An evidence the directory already holds
    /// stays until this one is written ([`Self::finish`]).
    pub fn start(dir: &Path, force: bool, job: &Job, data: &FieldData) -> Result<Self> {
        // Refused before the directory exists (the job checks again when it runs).
        job.sampler.check_memory(&job.laws)?;
        let (lock, ()) = crate::run::dir::claim(dir, "out", || check_out(dir, force))?;
        let unfinished = dir.join(UNFINISHED_DIR);
        std::fs::create_dir_all(&unfinished).map_err(|source| Error::output("out", dir, source))?;
        match std::fs::remove_file(unfinished.join(PROGRESS_BIN)) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => return Err(Error::output("out", dir, e)),
            _ => {}
        }
        // Streamed: a long record is not held twice in memory.
        files::write_own(&unfinished.join(RECORD_JSON), "out", |out| {
            serde_json::to_writer(out, data).map_err(std::io::Error::from)
        })?;
        files::write_own(&unfinished.join(JOB_JSON), "out", |out| {
            out.write_all(&job_file(job, &job.laws))
        })?;
        Ok(Self {
            dir: dir.to_path_buf(),
            _lock: lock,
            every_s: SAVE_EVERY_S,
        })
    }

    /// The evidence under way in `dir`, locked: with its job (its law files' laws registered
    /// in this process), its record and its progress (none yet where it was killed before its
    /// first save).
    pub fn open(dir: &Path) -> Result<(Self, Job, FieldData, Progress)> {
        let unfinished = dir.join(UNFINISHED_DIR);
        if !is_unfinished_evidence_dir(dir) {
            let message = if dir.join(EVIDENCE_JSON).is_file() {
                "holds a finished evidence, with nothing under way to continue"
            } else {
                "holds no evidence under way (`bitrock evidence --out DIR` starts one; Python: `bitrock.evidence(..., out=DIR)`)"
            };
            return Err(Error::setting("resume", format!("{} {message}", dir.display())));
        }
        let lock = files::DirLock::acquire(dir)?;
        let job_path = unfinished.join(JOB_JSON);
        let stored = read_job_file(&job_path)?.ok_or_else(|| Error::Data {
            path: job_path.clone(),
            message: "no job in it".to_string(),
        })?;
        let job: Job = serde_json::from_value(stored).map_err(|e| Error::Data {
            path: job_path.clone(),
            message: format!("its job does not read: {e}"),
        })?;
        let data = read_record(&unfinished.join(RECORD_JSON))?;
        let progress_path = unfinished.join(PROGRESS_BIN);
        let progress = match std::fs::read(&progress_path) {
            Ok(bytes) => postcard::from_bytes(&bytes).map_err(|e| Error::Data {
                path: progress_path.clone(),
                message: format!("not the progress of an evidence bitrock wrote: {e}"),
            })?,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Progress::default(),
            Err(source) => {
                return Err(Error::Read {
                    path: progress_path,
                    source,
                });
            }
        };
        Ok((
            Self {
                dir: dir.to_path_buf(),
                _lock: lock,
                every_s: SAVE_EVERY_S,
            },
            job,
            data,
            progress,
        ))
    }

    /// Computes `job`'s evidence on `data` from `progress` where `scoring` says, saving its
    /// progress as it goes ([`Job::run_saving`]).
    pub fn run(
        &self,
        job: &Job,
        data: &FieldData,
        progress: Progress,
        scoring: Scoring,
        observer: &mut dyn Observer,
    ) -> Result<EvidenceAnalysis> {
        let path = self.dir.join(UNFINISHED_DIR).join(PROGRESS_BIN);
        let mut save = |progress: &Progress| {
            let bytes = postcard::to_stdvec(progress).expect("an evidence's progress serialises");
            files::write_own(&path, "out", |out| out.write_all(&bytes))
        };
        let saving = Saving {
            progress,
            origin: &path,
            every_s: self.every_s,
            save: &mut save,
        };
        job.run_saving(data, scoring, Some(saving), observer)
    }

    /// Writes the finished evidence ([`save`]), replacing what the directory held: the
    /// evidence under way goes with it.
    pub fn finish(
        self,
        document: &serde_json::Value,
        analysis: &EvidenceAnalysis,
        job: &Job,
        data: &FieldData,
    ) -> Result<()> {
        save(
            &self.dir,
            true,
            document,
            &analysis.posterior_csv(&job.laws, data),
            job,
            data,
        )
    }
}

/// The record an evidence directory's evidence was computed on, whole.
pub fn record(dir: &Path) -> Result<FieldData> {
    read_record(&dir.join(RECORD_JSON))
}

/// The record of an evidence directory's [`RECORD_JSON`] at `path`.
fn read_record(path: &Path) -> Result<FieldData> {
    let text = files::read_text(path, "an evidence's record", MAX_RECORD_BYTES)?;
    serde_json::from_str(&text).map_err(|e| Error::Data {
        path: path.to_path_buf(),
        message: format!("not a record bitrock wrote: {e}"),
    })
}

/// Writes the evidence directory `dir` (checked by [`check_out`]) of `job` on `data`:
/// `document` (the evidence's document with each law's posterior sets), the posterior's
/// particle CSV (`posterior_csv`, [`EvidenceAnalysis::posterior_csv`]), the samples, the
/// record, and the job with the text of its law files, replacing what an earlier evidence
/// wrote there in one step.
pub fn save(
    dir: &Path,
    force: bool,
    document: &serde_json::Value,
    posterior_csv: &[u8],
    job: &Job,
    data: &FieldData,
) -> Result<()> {
    check_out(dir, force)?;
    let record = serde_json::to_vec(data).expect("a record serialises");
    let contents = [
        (PathBuf::from(EVIDENCE_JSON), pretty_json(document)),
        (PathBuf::from(POSTERIOR_CSV), posterior_csv.to_vec()),
        (PathBuf::from(DATA_CSV), crate::documents::data_csv(data)),
        (PathBuf::from(RECORD_JSON), record),
        (PathBuf::from(JOB_JSON), job_file(job, &job.laws)),
    ];
    files::replace_dir(
        dir,
        "out",
        &|rel, is_dir| owns_unchanged(Owned::Evidence, dir, rel, is_dir),
        &contents,
    )
}

/// Checks the evidence of the evidence directory `dir` by re-simulation ([`check`]):
/// `replicates` synthetic records per law, on `backend` (default: the evidence's), scored
/// where `scoring` says (here, or on a pool of workers: the same check). The evidence is
/// computed again from the job and the record the directory keeps (the same numbers on the
/// same backend; said where they differ), then checked, and the check written into the
/// document (`check`, as `bitrock evidence --check` writes it), the rest of the directory
/// unchanged. Returns the check.
pub fn check_dir(
    dir: &Path,
    replicates: usize,
    backend: Option<Backend>,
    scoring: &mut Scoring,
    progress: &mut dyn FnMut(usize, usize),
    observer: &mut dyn Observer,
) -> Result<EvidenceCheck> {
    check_replicates(replicates, "replicates")?;
    // The check is written into the directory's document: a directory bitrock may not write
    // (files copied without their marks, or changed) is refused before the work.
    let owned = |rel: &Path, is_dir: bool| owns_unchanged(Owned::Evidence, dir, rel, is_dir);
    files::refuse_foreign(dir, "run", &owned)?;
    let stored = read_job_file(&dir.join(JOB_JSON))?;
    let mut document = read_json_file(&dir.join(EVIDENCE_JSON), "an evidence document", MAX_DOCUMENT_BYTES)?;
    let path = dir.join(JOB_JSON);
    let refuse = |message: String| Error::Data {
        path: path.clone(),
        message,
    };
    let mut job: Job = match stored {
        Some(job) => serde_json::from_value(job).map_err(|e| refuse(format!("its job does not read: {e}")))?,
        None => {
            return Err(refuse(
                "missing: an earlier bitrock wrote this evidence without its job; compute it again (`bitrock evidence` checks it, `--check K` sets its size; `check=K` in Python)".into(),
            ));
        }
    };
    if let Some(prior_file) = job.prior_file.as_ref().filter(|_| job.prior_text.is_none()) {
        return Err(refuse(format!(
            "its boxes came from the prior file {0}, which an earlier bitrock did not keep in the directory: compute it again (`bitrock evidence --prior {0}` checks it, `--check K` sets its size; `prior=\"{0}\", check=K` in Python)",
            prior_file.display()
        )));
    }
    let data = read_record(&dir.join(RECORD_JSON))?;
    check_size(replicates, "replicates", &job, &data)?;
    if let Some(backend) = backend {
        job.backend = backend;
    }
    let analysis = job.run(&data, scoring.reborrow(), observer)?;
    let stored_ln_z: Vec<Option<f64>> = document["laws"]
        .as_array()
        .map(|laws| laws.iter().map(|law| law["ln_z"].as_f64()).collect())
        .unwrap_or_default();
    let now_ln_z: Vec<Option<f64>> = analysis.evidence.laws.iter().map(|law| Some(law.ln_z)).collect();
    if stored_ln_z != now_ln_z {
        observer.note(format!(
            "the evidence computed again on {} differs from the one stored in {} (another backend or build): the check is of the evidence computed now",
            analysis.evidence.backend,
            dir.display()
        ));
    }
    let check = check(&job, &data, &analysis, replicates, scoring, progress, observer)?;
    analysis.with_check(&mut document, &check);
    // Still the evidence's alone after the work; only its document changes (written whole).
    files::refuse_foreign(dir, "run", &owned)?;
    let json = pretty_json(&document);
    files::write_own(&dir.join(EVIDENCE_JSON), "run", |out| out.write_all(&json))?;
    Ok(check)
}

/// The job of the evidence directory `dir` as it keeps it; `None` where an earlier bitrock kept
/// none.
pub fn job(dir: &Path) -> Result<Option<Job>> {
    let path = dir.join(JOB_JSON);
    read_job_file(&path)?
        .map(|job| {
            serde_json::from_value(job).map_err(|e| Error::Data {
                path: path.clone(),
                message: format!("its job does not read: {e}"),
            })
        })
        .transpose()
}

/// The document of the evidence directory `dir`, its law files' laws registered in this
/// process (read from its job, where it keeps one).
pub fn read(dir: &Path) -> Result<serde_json::Value> {
    read_job_file(&dir.join(JOB_JSON))?;
    read_json_file(&dir.join(EVIDENCE_JSON), "an evidence document", MAX_DOCUMENT_BYTES)
}

/// The most an evidence directory's document may hold, bytes (the document holds the
/// posterior sets; it is read whole as a JSON tree).
const MAX_DOCUMENT_BYTES: u64 = 1 << 30;
/// The most its record may hold, bytes (every sample, 40 bytes a row or so: a day at 1 kHz is
/// 3.5 GB; read straight into the record's columns).
const MAX_RECORD_BYTES: u64 = 1 << 33;

/// The posterior particles of the evidence directory `dir` (SI) and the weight on bit its
/// torque parameters are for, N, where the evidence scaled each torque by WOB / W_ref.
pub fn posterior(dir: &Path) -> Result<(Vec<Particle>, Option<f64>)> {
    let document = read(dir)?;
    let w_ref_n = document["w_ref_kn"].as_f64().map(|kn| kn * 1000.0);
    let particles = crate::documents::read_particles_csv(&dir.join(POSTERIOR_CSV))?;
    Ok((particles, w_ref_n))
}

/// The samples an evidence directory's evidence was computed on, as `data.csv` keeps them: bit
/// speed (rad/s) and torque (in `unit`, the record's) of the calibration and validation rows.
#[derive(Clone, Debug, PartialEq)]
pub struct StoredSamples {
    pub unit: TorqueUnit,
    pub calibration: Vec<(f64, f64)>,
    pub validation: Vec<(f64, f64)>,
}

/// The samples of the evidence directory `dir` ([`StoredSamples`]); refusals name the file,
/// line and column.
pub fn samples(dir: &Path) -> Result<StoredSamples> {
    let path = dir.join(DATA_CSV);
    let (mut reader, header) = crate::files::csv_with_header(&path)?;
    let unit = match header.as_slice() {
        [set, speed, torque] if set == "set" && speed == "speed_rad_s" && torque.starts_with("torque_") => {
            TorqueUnit::from_suffix(torque)
        }
        _ => None,
    }
    .ok_or_else(|| Error::Format {
        path: path.clone(),
        line: Some(1),
        message: format!(
            "not the header of an evidence's data.csv (set,speed_rad_s,torque_knm or torque_nm): {}",
            header.join(",")
        ),
    })?;
    let mut stored = StoredSamples {
        unit,
        calibration: Vec::new(),
        validation: Vec::new(),
    };
    for row in crate::files::csv_rows(&mut reader, &path, &header) {
        let row = row?;
        let sample = (row.number(1)?, row.number(2)?);
        match row.cell(0) {
            "calibration" => stored.calibration.push(sample),
            "validation" => stored.validation.push(sample),
            other => return Err(row.bad_cell(0, format!("`{other}` is neither calibration nor validation"))),
        }
    }
    Ok(stored)
}
