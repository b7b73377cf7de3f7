//! A surface directory (`bitrock surface RECORD --out DIR`, `bitrock.surface(..., out=DIR)`):
//! the inference's document (`surface.json`), its posterior particles (`posterior.csv`, what
//! `bitrock stability --posterior` maps), the bit's predicted speed (`bit.csv`), and what
//! continues it: the record as it was read (`record.csv`, its bytes), the job with the text of
//! the prior file and of every law file it names (`surface-job.json`), and the sampler's
//! populations (`populations.bin`), stored as each completes.
//!
//! `bitrock surface --resume DIR` continues the sampler after the last stored population with
//! new stopping rules (more populations, more time), to the populations an uninterrupted run
//! gives on the same backend; a run killed part-way continues the same way. The check and the bit are then
//! computed again and the directory written anew, whole ([`files::replace_dir`]).

use super::{Sampling, Settings, SurfaceResult, SurfaceSettings, infer_continuing};
use crate::abc::{Particle, Population, StopReason};
use crate::data::BitSeen;
use crate::data::surface::{SurfaceOptions, SurfaceRecord};
use crate::error::{Error, Result};
use crate::eval::Backend;
use crate::eval::surface::InferredString;
use crate::files;
use crate::laws::Law;
use crate::prior::PriorFile;
use crate::run::Scoring;
use crate::run::dir::{
    Owned, POPULATIONS_BIN, POSTERIOR_CSV, RECORD_CSV, SURFACE_BIT_CSV, SURFACE_JOB_JSON, SURFACE_JSON,
    is_evidence_dir, is_run_dir, is_unfinished_evidence_dir, job_file, owns_unchanged, pretty_json, read_job_file,
    read_json_file, refuse_inside_kept_dir,
};
use crate::stability::lumped::Lumped;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// What a surface directory's inference is computed from, besides its record.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Job {
    pub laws: Vec<Law>,
    /// The settings as given (the prior file's path kept only to name it).
    pub settings: Settings,
    /// The prior file's text, read once: what the prior is made from when the run continues.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub prior_text: Option<String>,
    /// How the record's columns were read.
    pub columns: SurfaceOptions,
    /// The record's path when the run started (to name it; the directory keeps its bytes).
    pub source: PathBuf,
    /// Whether the sampler's prior cuts a law's box to its curves within the record's torques
    /// ([`SurfaceSettings::curve_limits`]); absent from a job whose populations were drawn
    /// from the boxes alone, which continues so.
    #[serde(default)]
    pub curve_limits: bool,
    /// The form of the distance its populations were drawn under ([`DISTANCE_FORM`]); absent
    /// from a job of the first form.
    #[serde(default = "first_distance_form")]
    pub distance_form: u32,
}

/// The form of the surface run's distance: which summaries it compares and how it reads the
/// record's noise. A run's particles keep their ρ from population to population, so its
/// populations continue only under the form they were drawn with. Form 2: the wind-up rate
/// among the summaries, the noise read on the wind-ups on a coarse clock, and the check's
/// reference drawn from the laws' posteriors.
pub const DISTANCE_FORM: u32 = 2;

fn first_distance_form() -> u32 {
    1
}

impl Job {
    /// The job of `settings` for `laws` on the record at `source` read with `columns`, the
    /// prior file's text read now.
    pub fn new(laws: Vec<Law>, settings: Settings, columns: SurfaceOptions, source: &Path) -> Result<Self> {
        let prior_text = settings.prior_file.as_deref().map(PriorFile::read_text).transpose()?;
        Ok(Self {
            laws,
            settings,
            prior_text,
            columns,
            source: source.to_path_buf(),
            curve_limits: true,
            distance_form: DISTANCE_FORM,
        })
    }

    /// The run's settings, through the surface run's gate, the prior made from the text kept.
    pub fn config(&self) -> Result<SurfaceSettings> {
        let origin = self
            .settings
            .prior_file
            .clone()
            .unwrap_or_else(|| PathBuf::from("prior"));
        let prior = self
            .prior_text
            .as_deref()
            .map(|text| PriorFile::parse(text, &origin))
            .transpose()?;
        let mut config = self.settings.config_with_prior(self.laws.clone(), prior)?;
        config.curve_limits = self.curve_limits;
        Ok(config)
    }
}

/// New stopping rules of a continued surface run, where its strings are simulated and the size
/// of its check; `None` keeps the stored one, a value is kept for the next continuation.
#[derive(Clone, Debug, Default)]
pub struct Continuation {
    /// Most populations, the first and those stored included.
    pub max_populations: Option<usize>,
    /// Wall-time budget of this invocation's sampler, s.
    pub max_seconds: Option<f64>,
    pub backend: Option<Backend>,
    /// Records re-simulated per law for the check.
    pub check_replicates: Option<usize>,
}

/// Refuses, before any work and naming `out`, a directory a surface run cannot be written to:
/// a file, an ABC run or an evidence directory (or one inside a kept directory), one holding
/// anything bitrock did not write there, and a surface run without `force`.
pub fn check_out(dir: &Path, force: bool) -> Result<()> {
    files::check_output_dir(dir, "out")?;
    refuse_inside_kept_dir(dir, "out")?;
    if is_run_dir(dir) || is_evidence_dir(dir) || is_unfinished_evidence_dir(dir) {
        return Err(Error::setting(
            "out",
            format!(
                "{} holds an ABC run or an evidence: write the surface run to a directory of its own",
                dir.display()
            ),
        ));
    }
    files::refuse_foreign(dir, "out", &|rel, is_dir| {
        owns_unchanged(Owned::Surface, dir, rel, is_dir)
    })?;
    if is_surface_dir(dir) && !force {
        return Err(Error::setting(
            "out",
            format!(
                "{0} holds a surface run; continue it with `bitrock surface --resume {0}` (Python: `bitrock.resume_surface`), or pass `force` to start again",
                dir.display()
            ),
        ));
    }
    Ok(())
}

/// True when `dir` holds a surface run (its job).
pub fn is_surface_dir(dir: &Path) -> bool {
    dir.join(SURFACE_JOB_JSON).is_file()
}

/// What a surface directory keeps of its sampler ([`POPULATIONS_BIN`], postcard bytes).
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct Sampled {
    /// Every completed population, in order.
    pub populations: Vec<Population>,
    /// Why the sampler ended, once the run was finished; `None` while it runs (or was killed).
    pub stop: Option<StopReason>,
    /// Where the populations' strings were simulated (`CPU`, `GPU <adapter>`): the pilot's
    /// distance is computed there too, so a run continued elsewhere gives other bits.
    pub backend: String,
}

/// A surface directory being written: locked (one writer at a time), its record and job in
/// place, its populations stored as they complete.
pub struct SurfaceDir {
    dir: PathBuf,
    _lock: files::DirLock,
    /// The record's bytes, written again with the result.
    record_bytes: Vec<u8>,
    job: Job,
}

impl SurfaceDir {
    /// Starts `job`'s run in `dir` (refused as [`check_out`] refuses, before the directory
    /// exists and again under its lock): what an earlier run there wrote is removed, the
    /// record's bytes and the job written. Returns the record as read from the bytes kept (a
    /// file still being written is read once).
    pub fn start(dir: &Path, force: bool, job: Job) -> Result<(Self, SurfaceRecord)> {
        let (lock, ()) = crate::run::dir::claim(dir, "out", || check_out(dir, force))?;
        let record_bytes = std::fs::read(&job.source).map_err(|source| Error::Read {
            path: job.source.clone(),
            source,
        })?;
        let started = Self {
            dir: dir.to_path_buf(),
            _lock: lock,
            record_bytes,
            job,
        };
        // Under the lock, in place (a directory swapped in would not be the one locked): an
        // earlier run's results and populations go first, so that a run killed now continues
        // this job, never the earlier one's populations.
        for name in [
            SURFACE_JSON,
            POSTERIOR_CSV,
            SURFACE_BIT_CSV,
            POPULATIONS_BIN,
            SURFACE_JOB_JSON,
        ] {
            match std::fs::remove_file(dir.join(name)) {
                Err(e) if e.kind() != std::io::ErrorKind::NotFound => return Err(Error::output("out", dir, e)),
                _ => {}
            }
        }
        for (name, bytes) in started.kept() {
            files::write_own(&dir.join(name), "out", |out| out.write_all(&bytes))?;
        }
        let record = SurfaceRecord::read(&dir.join(RECORD_CSV), &started.job.columns)?;
        Ok((started, record))
    }

    /// The surface run in `dir`, locked, to continue: its job (its law files' laws registered
    /// in this process), its record read again from its bytes, and what its sampler stored. A
    /// directory holding anything bitrock did not write is refused before any work (its
    /// results could not be written back).
    pub fn open(dir: &Path) -> Result<(Self, SurfaceRecord, Sampled)> {
        if !is_surface_dir(dir) {
            return Err(Error::setting(
                "resume",
                format!(
                    "{} holds no surface run (`bitrock surface RECORD --out DIR` starts one; Python: `bitrock.surface(..., out=DIR)`)",
                    dir.display()
                ),
            ));
        }
        let lock = files::DirLock::acquire(dir)?;
        files::remove_stale(dir);
        files::refuse_foreign(dir, "resume", &|rel, is_dir| {
            owns_unchanged(Owned::Surface, dir, rel, is_dir)
        })?;
        let job = job(dir)?;
        if job.distance_form != DISTANCE_FORM {
            return Err(Error::setting(
                "resume",
                format!(
                    "{} holds a surface run drawn under another form of the distance (its summaries, or how the record's noise is read) than this bitrock's: its populations cannot be continued or checked again; infer from its record again ({}) into a new directory",
                    dir.display(),
                    dir.join(RECORD_CSV).display()
                ),
            ));
        }
        let record_path = dir.join(RECORD_CSV);
        let record = SurfaceRecord::read(&record_path, &job.columns)?;
        let record_bytes = std::fs::read(&record_path).map_err(|source| Error::Read {
            path: record_path.clone(),
            source,
        })?;
        let sampled_path = dir.join(POPULATIONS_BIN);
        let sampled = match std::fs::read(&sampled_path) {
            Ok(bytes) => postcard::from_bytes(&bytes).map_err(|e| Error::Data {
                path: sampled_path.clone(),
                message: format!("not the populations of a surface run bitrock wrote: {e}"),
            })?,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Sampled::default(),
            Err(source) => {
                return Err(Error::Read {
                    path: sampled_path,
                    source,
                });
            }
        };
        Ok((
            Self {
                dir: dir.to_path_buf(),
                _lock: lock,
                record_bytes,
                job,
            },
            record,
            sampled,
        ))
    }

    /// The run's job.
    pub fn job(&self) -> &Job {
        &self.job
    }

    /// The run's settings continued with `more` after the `stored` populations, kept in its
    /// job when the run is written: the next continuation starts from them. Fewer populations
    /// than those stored are refused.
    pub fn continued(&mut self, more: &Continuation, stored: usize) -> Result<SurfaceSettings> {
        if let Some(n) = more.max_populations {
            if n < stored {
                return Err(Error::setting(
                    "max_populations",
                    format!("the run holds {stored} populations already: give {stored} or more"),
                ));
            }
            self.job.settings.max_populations = n;
        }
        if more.max_seconds.is_some() {
            self.job.settings.max_seconds = more.max_seconds;
        }
        if let Some(backend) = more.backend {
            self.job.settings.backend = backend;
        }
        if let Some(k) = more.check_replicates {
            self.job.settings.check_replicates = k;
        }
        self.job.config()
    }

    /// Infers the laws from `record` with `settings` (the job's, continued), the sampler
    /// continuing after `sampled`'s populations (or, with `again`, not running: the check and
    /// the bit computed again from them), every completed population stored. A run continued
    /// on another backend than its populations' is said: its populations are not bit for bit
    /// those of an uninterrupted run there.
    pub fn run(
        &self,
        record: &SurfaceRecord,
        settings: &SurfaceSettings,
        sampled: Sampled,
        again: bool,
        scoring: Scoring<'_, '_>,
        note: &mut dyn FnMut(String),
    ) -> Result<SurfaceResult> {
        // Where the strings go, decided as `infer` decides it (said there).
        let (_, ran) = crate::eval::strings::resolve(settings.backend, &mut |_| {})?;
        let backend = ran.to_string();
        if !sampled.populations.is_empty() && sampled.backend != backend {
            note(format!(
                "the stored populations' strings were simulated on the {}, these on the {backend}: the distance is measured again there, so the run is not bit for bit one uninterrupted run",
                sampled.backend
            ));
        }
        let path = self.dir.join(POPULATIONS_BIN);
        let mut keep = |populations: &[Population]| {
            let kept = SampledRef {
                populations,
                stop: None,
                backend: &backend,
            };
            let bytes = postcard::to_stdvec(&kept).expect("populations serialise");
            files::write_own(&path, "out", |out| out.write_all(&bytes))
        };
        let sampling = Sampling {
            stopped: if again { sampled.stop } else { None },
            previous: sampled.populations,
            keep: &mut keep,
            warm: &[],
            scoring,
        };
        infer_continuing(record, settings, self.job.settings.seed, sampling, note)
    }

    /// Writes the finished run's document, posterior particles and predicted bit speed beside
    /// its record, job (with the settings it was continued with) and populations, the
    /// directory replaced whole.
    pub fn finish(self, record: &SurfaceRecord, result: &SurfaceResult) -> Result<()> {
        let document = serde_json::to_value(result).expect("a surface result serialises");
        let mut contents = self.kept();
        contents.push((PathBuf::from(SURFACE_JSON), pretty_json(&document)));
        if let Some(csv) = result.posterior_csv(&self.job.laws, record.torque_unit) {
            contents.push((PathBuf::from(POSTERIOR_CSV), csv));
        }
        let mut bit = Vec::new();
        result.bit_csv(record, &mut bit).expect("a CSV is written to memory");
        contents.push((PathBuf::from(SURFACE_BIT_CSV), bit));
        if let Some(run) = &result.run {
            let sampled = SampledRef {
                populations: &run.populations,
                stop: Some(run.stop),
                backend: &result.backend,
            };
            contents.push((
                PathBuf::from(POPULATIONS_BIN),
                postcard::to_stdvec(&sampled).expect("populations serialise"),
            ));
        }
        files::replace_dir(
            &self.dir,
            "out",
            &|rel, is_dir| owns_unchanged(Owned::Surface, &self.dir, rel, is_dir),
            &contents,
        )
    }

    /// The files that continue the run: its record and job.
    fn kept(&self) -> Vec<(PathBuf, Vec<u8>)> {
        vec![
            (PathBuf::from(RECORD_CSV), self.record_bytes.clone()),
            (PathBuf::from(SURFACE_JOB_JSON), job_file(&self.job, &self.job.laws)),
        ]
    }
}

/// [`Sampled`] borrowed, for writing without a copy.
#[derive(Serialize)]
struct SampledRef<'a> {
    populations: &'a [Population],
    stop: Option<StopReason>,
    backend: &'a str,
}

/// The finished surface run in `dir` checked again by re-simulation with `replicates` records
/// per law (on `backend`, default the run's): the sampler does not run (the stored
/// populations, ended as they ended, are the run's), the check and the bit are computed again
/// and the directory written anew. A run under way is refused with how to finish it.
pub fn check_again(
    dir: &Path,
    replicates: usize,
    backend: Option<Backend>,
    note: &mut dyn FnMut(String),
) -> Result<SurfaceResult> {
    if replicates == 0 {
        return Err(Error::setting("replicates", "must be at least 1"));
    }
    read(dir)?;
    let (mut run, record, sampled) = SurfaceDir::open(dir)?;
    let more = Continuation {
        backend,
        check_replicates: Some(replicates),
        ..Continuation::default()
    };
    let settings = run.continued(&more, sampled.populations.len())?;
    let result = run.run(&record, &settings, sampled, true, Scoring::Here, note)?;
    run.finish(&record, &result)?;
    Ok(result)
}

/// The job of the surface directory `dir`, its law files' laws registered in this process.
pub fn job(dir: &Path) -> Result<Job> {
    let path = dir.join(SURFACE_JOB_JSON);
    let stored = read_job_file(&path)?.ok_or_else(|| Error::Data {
        path: path.clone(),
        message: "no job in it".to_string(),
    })?;
    serde_json::from_value(stored).map_err(|e| Error::Data {
        path,
        message: format!("its job does not read: {e}"),
    })
}

/// The string's coordinates of a run that inferred it, its natural frequency and damping
/// ratio, read from the particle file `path` and put after each particle's law's parameters,
/// as the sampler had them.
fn append_string_columns(path: &Path, particles: &mut [Particle]) -> Result<()> {
    let malformed = |line: Option<u64>, message: String| Error::Format {
        path: path.to_path_buf(),
        line,
        message,
    };
    let mut reader = csv::Reader::from_path(path).map_err(|e| malformed(None, e.to_string()))?;
    let header = reader.headers().map_err(|e| malformed(Some(1), e.to_string()))?.clone();
    let names = ["string.omega_n [rad/s]", "string.damping_ratio [1]"];
    let columns = names.map(|name| header.iter().position(|h| h.trim() == name));
    let [Some(omega), Some(xi)] = columns else {
        return Err(malformed(
            Some(1),
            format!(
                "the run inferred its string, but its particles lack the columns {}",
                names.join(" and ")
            ),
        ));
    };
    let mut rows = reader.records();
    let n = particles.len();
    for (i, particle) in particles.iter_mut().enumerate() {
        let line = Some(i as u64 + 2);
        let row = rows
            .next()
            .ok_or_else(|| malformed(line, format!("{n} particles but only {i} rows")))?
            .map_err(|e| malformed(line, e.to_string()))?;
        for column in [omega, xi] {
            let value = row
                .get(column)
                .and_then(|v| v.trim().parse::<f64>().ok())
                .ok_or_else(|| {
                    malformed(
                        line,
                        format!("'{}' is not a number", header.get(column).unwrap_or("").trim()),
                    )
                })?;
            particle.params.push(value);
        }
    }
    Ok(())
}

/// The finished document of the surface directory `dir` (its law files' laws registered).
pub fn read(dir: &Path) -> Result<serde_json::Value> {
    job(dir)?;
    let path = dir.join(SURFACE_JSON);
    if !path.is_file() {
        return Err(Error::Data {
            path: dir.to_path_buf(),
            message: format!(
                "holds a surface run under way, not finished; continue it with `bitrock surface --resume {}` (Python: `bitrock.resume_surface`)",
                dir.display()
            ),
        });
    }
    read_json_file(&path, "a surface run's document", MAX_DOCUMENT_BYTES)
}

/// The most a surface run's document may hold, bytes (it holds the bit's band per sample).
const MAX_DOCUMENT_BYTES: u64 = 1 << 30;

/// A finished surface directory, read once: its job (its law files' laws registered in this
/// process), its document and its record.
pub struct Finished {
    pub dir: PathBuf,
    pub job: Job,
    pub document: serde_json::Value,
    pub record: SurfaceRecord,
}

impl Finished {
    /// The finished surface run in `dir`; one under way is refused with how to finish it.
    pub fn read(dir: &Path) -> Result<Self> {
        let document = read(dir)?;
        let job = job(dir)?;
        let record = SurfaceRecord::read(&dir.join(RECORD_CSV), &job.columns)?;
        Ok(Self {
            dir: dir.to_path_buf(),
            job,
            document,
            record,
        })
    }

    /// The final population's particles (SI), the weight on bit their torque parameters are
    /// for (N): the run's W_ref, or without one the record's mean weight on bit (the laws
    /// inferred at r = 1 hold there), and why, in words.
    pub fn posterior(&self) -> Result<(Vec<Particle>, f64, &'static str)> {
        let particles = crate::documents::read_particles_csv(&self.dir.join(POSTERIOR_CSV))?;
        let mean_wob_n = super::mean_wob_n(&self.record, None);
        let (w_ref_n, why) = match (self.job.settings.w_ref_kn, &self.record.wob_n) {
            (Some(kn), _) => (kn * 1000.0, "the surface run's own"),
            (None, Some(_)) => (
                mean_wob_n,
                "the surface run inferred the laws at its record's mean weight on bit",
            ),
            (None, None) => (
                mean_wob_n,
                "the surface run's record holds no weight on bit: the laws hold at the paper's W_ref",
            ),
        };
        Ok((particles, w_ref_n, why))
    }

    /// The final population's particles as the sampler had them: where the run inferred its
    /// string, its two coordinates after each particle's law's parameters.
    pub fn particles(&self) -> Result<Vec<Particle>> {
        let path = self.dir.join(POSTERIOR_CSV);
        let mut particles = crate::documents::read_particles_csv(&path)?;
        if self.sample_strings()?.is_some() {
            append_string_columns(&path, &mut particles)?;
        }
        Ok(particles)
    }

    /// The bit as the surface implies it: the posterior medians of its stuck share and
    /// severity, at the top drive's mean speed and the record's mean weight on bit (where
    /// recorded).
    pub fn bit(&self) -> Result<BitSeen> {
        let record = &self.record;
        let median = |name: &str| {
            self.document["at_the_bit"][name][1]
                .as_f64()
                .ok_or_else(|| self.malformed(format!("at_the_bit.{name} has no median")))
        };
        Ok(super::implied_bit(record, median("stuck_share")?, median("severity")?))
    }

    /// The 1-DOF string the run simulated its candidates on: as given, or where it inferred
    /// the natural frequency or damping ratio, their posterior medians.
    pub fn string(&self) -> Result<Lumped> {
        let string = &self.document["string"];
        let number = |value: &serde_json::Value, name: &str| {
            value
                .as_f64()
                .ok_or_else(|| self.malformed(format!("string.{name} is not a number")))
        };
        Ok(Lumped {
            inertia_kg_m2: number(&string["inertia_kg_m2"], "inertia_kg_m2")?,
            omega_n_rad_s: number(&string["omega_n_rad_s"]["median"], "omega_n_rad_s.median")?,
            damping_ratio: number(&string["damping_ratio"]["median"], "damping_ratio.median")?,
        })
    }

    /// Where the run inferred its string: the string its particles carry after their laws'
    /// parameters ([`crate::eval::surface::InferredString`]), what it held given exactly.
    pub fn sample_strings(&self) -> Result<Option<InferredString>> {
        let inferred = self.document["string"]["inferred"].as_bool().unwrap_or(false);
        if !inferred {
            return Ok(None);
        }
        let lumped = self.string()?;
        let given = |name: &str, value: f64| {
            self.document["string"][name]["given"]
                .as_bool()
                .unwrap_or(false)
                .then_some(value)
        };
        Ok(Some(InferredString {
            inertia_kg_m2: lumped.inertia_kg_m2,
            omega_n_rad_s: given("omega_n_rad_s", lumped.omega_n_rad_s),
            damping_ratio: given("damping_ratio", lumped.damping_ratio),
        }))
    }

    /// The document as Python reads it: with the record's clock.
    pub fn with_clock(mut self) -> serde_json::Value {
        self.document["time_s"] = serde_json::to_value(&self.record.time_s).expect("numbers serialise");
        self.document
    }

    fn malformed(&self, message: String) -> Error {
        Error::Data {
            path: self.dir.join(SURFACE_JSON),
            message,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A job that does not say its prior is cut (its populations drawn from the boxes alone)
    /// continues from the boxes alone; a new job cuts.
    #[test]
    fn a_job_that_does_not_say_its_prior_is_cut_continues_from_the_boxes_alone() {
        let job = Job::new(
            vec![Law::M2, Law::M4],
            Settings::default(),
            SurfaceOptions::default(),
            Path::new("record.csv"),
        )
        .unwrap();
        assert!(job.config().unwrap().curve_limits);
        let mut stored = serde_json::to_value(&job).unwrap();
        assert_eq!(
            stored.as_object_mut().unwrap().remove("curve_limits"),
            Some(true.into())
        );
        let older: Job = serde_json::from_value(stored).unwrap();
        assert!(!older.config().unwrap().curve_limits);
    }

    /// A job that does not say its distance's form is of the first, which this bitrock does
    /// not continue; a new job is of this one's.
    #[test]
    fn a_job_of_another_distance_form_is_not_continued() {
        let job = Job::new(
            vec![Law::M2],
            Settings::default(),
            SurfaceOptions::default(),
            Path::new("record.csv"),
        )
        .unwrap();
        assert_eq!(job.distance_form, DISTANCE_FORM);
        let mut stored = serde_json::to_value(&job).unwrap();
        assert_eq!(
            stored.as_object_mut().unwrap().remove("distance_form"),
            Some(DISTANCE_FORM.into())
        );
        let older: Job = serde_json::from_value(stored).unwrap();
        assert_eq!(older.distance_form, 1);
        // Written as a directory and opened to continue: refused, naming the setting.
        let dir = tempfile::tempdir().unwrap();
        files::write_own(&dir.path().join(RECORD_CSV), "out", |out| {
            out.write_all(b"time_s,top_drive_rpm,surface_torque_knm\n")
        })
        .unwrap();
        files::write_own(&dir.path().join(SURFACE_JOB_JSON), "out", |out| {
            out.write_all(&job_file(&older, &older.laws))
        })
        .unwrap();
        let refused = SurfaceDir::open(dir.path()).err().expect("refused");
        assert!(
            refused.to_string().contains("another form of the distance"),
            "{refused}"
        );
    }
}
