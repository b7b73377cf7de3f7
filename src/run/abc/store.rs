//! The run store: one SQLite database per run directory (`DIR/run.sqlite`) holding everything
//! a run needs to be read later or continued: the configuration, the calibration and
//! validation samples, the least-squares fits, the prior, and every population with every
//! particle.
//!
//! The set-up is written in one transaction when the run starts and each population in one
//! transaction when it completes, so a killed run loses at most the population in flight and
//! `bitrock abc --resume DIR` continues from what is stored. Everything is SI (rad/s, N·m, N,
//! s); parameters carry their SI unit in the `parameters` table.
//!
//! Particles (schema 3) are stored once each in `particle_rows`, however many populations they
//! belong to: in nested mode population g+1 keeps the particles of population g below its ε,
//! and storing them again made the store 5 × N rows of about 106 bytes at N = 10⁶. A
//! population's particles are its own new rows plus the rows it carries: those of the
//! populations since `population_rows.carried_from_row` whose ρ is below
//! `population_rows.carried_below` (see [`append_population`](Store::append_population)
//! for when a population may carry). The view `particles` shows them as schema 2's table did,
//! one row per particle and population with one column per parameter name (parameter names
//! are unique across the laws: `b0..b3`, `tsb, tcb, g`, `a0..a5`, `c0..c3`; a particle's
//! columns of the other laws are NULL). Schemas 1 and 2 stored `particles` as that table; they
//! are read, and continued in their own layout. The schema is in docs/run-store.md.

use crate::abc::{Particle, Population, PopulationRecord};
use crate::data::{ColumnsUsed, FieldData, Samples};
use crate::error::{Error, Result};
use crate::fit::{LawFit, RecordScales};
use crate::laws::Law;
use crate::prior::{BoxRule, LawBox, Prior};
use crate::run::sqlite::{self, json_error, sql_error};
use crate::units::{SpeedUnit, TorqueUnit};
use rusqlite::{Connection, OptionalExtension, params};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The run store's file in a run directory (SQLite): everything that defines a run and every
/// population.
pub const STORE_FILE: &str = "run.sqlite";

/// SQLite's companions of the store while it is written.
pub const STORE_COMPANIONS: [&str; 3] = ["run.sqlite-journal", "run.sqlite-wal", "run.sqlite-shm"];

/// Version of the schema below. Version 1 (no `prior_bounds.rule`) is still read, its box
/// rules as [`BoxRule::Unrecorded`], and so is version 2 (particles as one table row per
/// particle and population); any other version is refused.
pub const SCHEMA_VERSION: i64 = 3;

/// The first schema that stores each particle once (`particle_rows`, `population_rows` and the
/// view `particles`).
const ROWS_SCHEMA: i64 = 3;

const SCHEMA: &str = r#"
CREATE TABLE meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE invocations (
    id INTEGER PRIMARY KEY,
    kind TEXT NOT NULL CHECK (kind IN ('start', 'resume')),
    started_unix_s REAL NOT NULL,
    finished_unix_s REAL,
    backend TEXT NOT NULL,
    config_json TEXT NOT NULL,
    stop_reason TEXT
);
CREATE TABLE samples (
    split TEXT NOT NULL CHECK (split IN ('calibration', 'validation')),
    position INTEGER NOT NULL,
    time_s REAL,
    speed_rad_s REAL NOT NULL,
    torque_nm REAL NOT NULL,
    wob_n REAL,
    PRIMARY KEY (split, position)
);
CREATE TABLE law_files (name TEXT PRIMARY KEY, source TEXT NOT NULL);
CREATE TABLE parameters (
    law TEXT NOT NULL,
    position INTEGER NOT NULL,
    name TEXT NOT NULL UNIQUE,
    unit_si TEXT NOT NULL,
    PRIMARY KEY (law, position)
);
CREATE TABLE fits (
    law TEXT PRIMARY KEY,
    rho REAL NOT NULL,
    validation_rho REAL,
    condition_number REAL,
    starts INTEGER NOT NULL,
    warnings_json TEXT NOT NULL,
    correlations_json TEXT NOT NULL
);
CREATE TABLE fit_params (
    law TEXT NOT NULL,
    position INTEGER NOT NULL,
    estimate_si REAL NOT NULL,
    std_error_si REAL,
    PRIMARY KEY (law, position)
);
CREATE TABLE prior_laws (
    slot INTEGER PRIMARY KEY,
    law TEXT NOT NULL UNIQUE,
    probability REAL NOT NULL,
    threshold INTEGER NOT NULL
);
CREATE TABLE prior_bounds (
    law TEXT NOT NULL,
    position INTEGER NOT NULL,
    lower_si REAL NOT NULL,
    upper_si REAL NOT NULL,
    rule TEXT NOT NULL,
    PRIMARY KEY (law, position)
);
CREATE TABLE populations (
    population INTEGER PRIMARY KEY,
    epsilon REAL,
    draws INTEGER NOT NULL,
    accepted INTEGER NOT NULL,
    acceptance_rate REAL NOT NULL,
    candidates_scored INTEGER NOT NULL,
    evaluations INTEGER NOT NULL,
    near_threshold INTEGER NOT NULL,
    ess REAL NOT NULL,
    seconds REAL NOT NULL,
    stream INTEGER NOT NULL,
    record_json TEXT NOT NULL
);
CREATE TABLE population_laws (
    population INTEGER NOT NULL,
    law TEXT NOT NULL,
    draws INTEGER NOT NULL,
    accepted INTEGER NOT NULL,
    acceptance_rate REAL NOT NULL,
    probability REAL NOT NULL,
    PRIMARY KEY (population, law)
);
-- Each particle once, in the order of the population that first holds it: p0.. are its law's
-- parameters in the order of `parameters.position`; weight NULL is its first population's
-- `population_rows.row_weight`.
CREATE TABLE particle_rows (
    id INTEGER PRIMARY KEY,
    first_population INTEGER NOT NULL,
    law TEXT NOT NULL,
    candidate INTEGER NOT NULL,
    rho REAL NOT NULL,
    weight REAL,
    p0 REAL, p1 REAL, p2 REAL, p3 REAL, p4 REAL, p5 REAL
);
-- Which rows population g holds, in id order: its new rows [first_row, end_row), and the rows
-- in [carried_from_row, first_row) with rho < carried_below (none when it is NULL).
CREATE TABLE population_rows (
    population INTEGER PRIMARY KEY,
    first_row INTEGER NOT NULL,
    end_row INTEGER NOT NULL,
    carried_from_row INTEGER NOT NULL,
    carried_below REAL,
    row_weight REAL
);
"#;

/// The record's description without its samples (those are rows of `samples`).
#[derive(Clone, Debug, Serialize, Deserialize)]
struct DataMeta {
    source: PathBuf,
    torque_unit: TorqueUnit,
    speed_unit: SpeedUnit,
    columns: ColumnsUsed,
    rows_read: usize,
    rows_used: usize,
    /// The record's warnings (stores written before they were kept read as none).
    #[serde(default)]
    warnings: Vec<String>,
    /// What the bit did over the record (stores written before it was kept read as unknown).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    bit: Option<crate::data::BitSeen>,
}

/// What defines a run besides its populations. Serialisable whole (a run kept in memory by
/// Python pickles with it); the fits' record scales are recomputed from the calibration
/// samples when read, as the store does.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(from = "SetupParts")]
pub struct Setup {
    /// The run's configuration as JSON (see `crate::run::abc::Config`), kept opaque here.
    pub config: serde_json::Value,
    pub data: FieldData,
    pub fits: Vec<LawFit>,
    pub prior: Prior,
}

/// A [`Setup`] as serialised, before its fits' scales are recomputed.
#[derive(Deserialize)]
struct SetupParts {
    config: serde_json::Value,
    data: FieldData,
    fits: Vec<LawFit>,
    prior: Prior,
}

impl From<SetupParts> for Setup {
    fn from(parts: SetupParts) -> Self {
        let scales = RecordScales::of(&parts.data.calibration);
        let mut fits = parts.fits;
        for fit in &mut fits {
            fit.scales = scales;
        }
        Setup {
            config: parts.config,
            data: parts.data,
            fits,
            prior: parts.prior,
        }
    }
}

/// What a derived output (a selection check) records of the run it was made from: how many
/// populations the run had, its last ε and its stored settings. A run that has moved on since
/// (a resume added populations or changed its settings) no longer matches it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct State {
    pub populations: usize,
    pub last_epsilon: Option<f64>,
    pub config: serde_json::Value,
}

impl Stored {
    /// The run's state now.
    pub fn state(&self) -> State {
        State {
            populations: self.populations.len(),
            last_epsilon: self.populations.last().and_then(|p| p.record.epsilon),
            config: self.setup.config.clone(),
        }
    }
}

/// A run read back: its set-up and every completed population.
#[derive(Clone, Debug)]
pub struct Stored {
    pub setup: Setup,
    pub populations: Vec<Population>,
}

/// An open run store.
pub struct Store {
    conn: Connection,
    path: PathBuf,
    /// Schema version of the file (older versions are read, see [`SCHEMA_VERSION`]).
    schema_version: i64,
}

/// How a store lays out particles ([`Store::layout`]).
#[derive(Clone, Copy, Debug)]
pub struct Layout {
    schema_version: i64,
}

impl Layout {
    /// What [`Store::append_population`] writes, taken while the sampler still holds
    /// `previous`, and owned: it can be written on another thread
    /// ([`Store::write_pending`]) while the next population is drawn. It copies only the
    /// particles the store does not hold yet.
    pub fn prepare(self, population: &Population, previous: Option<&Population>) -> PendingPopulation {
        let carried = self.carried(population, previous);
        PendingPopulation {
            record: population.record.clone(),
            carried,
            new: population.particles[carried.unwrap_or(0)..].to_vec(),
        }
    }

    /// How many leading particles of `population` are carried from `previous` (schema 3;
    /// `None`: none, every particle is written).
    fn carried(self, population: &Population, previous: Option<&Population>) -> Option<usize> {
        if self.schema_version >= ROWS_SCHEMA {
            carried_count(population, previous)
        } else {
            None
        }
    }
}

/// A population prepared for the store by [`Layout::prepare`]: its record, how
/// many of its leading particles the store holds already (carried from the population before
/// it), and a copy of the others.
pub struct PendingPopulation {
    record: PopulationRecord,
    carried: Option<usize>,
    new: Vec<Particle>,
}

impl Store {
    /// Creates `dir/run.sqlite` (which must not exist) whole or not at all: the schema and the
    /// set-up are written in one transaction into a temporary beside it (no journal: a failed
    /// temporary is discarded), which is renamed to run.sqlite once complete. A kill at any
    /// moment leaves no store or a complete one, and the temporary is removed by the next run
    /// in `dir` ([`crate::files::remove_stale`]).
    pub fn create(dir: &Path, setup: &Setup) -> Result<Self> {
        let path = dir.join(STORE_FILE);
        if path.exists() {
            return Err(Error::Store {
                path,
                message: "a run store already exists here".into(),
            });
        }
        let err = sql_error(&path);
        sqlite::create_whole(&path, SCHEMA, |tx| {
            // The law files' laws of the run: their sources are stored whole, so that the run
            // never depends on the files again.
            let file_laws = crate::laws::file::among(setup.prior.laws());
            for law in &file_laws {
                let source = law.file().map(|f| f.source.as_str());
                tx.execute(
                    "INSERT INTO law_files (name, source) VALUES (?1, ?2)",
                    params![law.name(), source],
                )
                .map_err(&err)?;
            }
            tx.execute_batch(&particles_view(&file_laws)).map_err(&err)?;
            let meta = [
                ("schema_version", SCHEMA_VERSION.to_string()),
                ("bitrock_version", env!("CARGO_PKG_VERSION").to_string()),
                ("config", setup.config.to_string()),
                (
                    "data",
                    serde_json::to_string(&data_meta(&setup.data)).map_err(json_error(&path))?,
                ),
            ];
            for (key, value) in meta {
                tx.execute("INSERT INTO meta (key, value) VALUES (?1, ?2)", params![key, value])
                    .map_err(&err)?;
            }
            insert_samples(tx, &setup.data, &file_laws, &path)?;
            insert_fits(tx, &setup.fits, &path)?;
            insert_prior(tx, &setup.prior, &path)?;
            Ok(())
        })?;
        let conn = Connection::open(&path).map_err(&err)?;
        drop(err);
        Ok(Self {
            conn,
            path,
            schema_version: SCHEMA_VERSION,
        })
    }

    /// Opens the store of run directory `dir`; a directory without one, or with a store of
    /// another schema, is refused with a message naming it.
    pub fn open(dir: &Path) -> Result<Self> {
        if crate::run::surface::dir::is_surface_dir(dir) && !dir.join(STORE_FILE).exists() {
            return Err(Error::Data {
                path: dir.to_path_buf(),
                message: "holds a surface run (`bitrock surface --out`), not an ABC run: its result is surface.json, `bitrock report` and `bitrock stability --run` read it, and `bitrock surface --resume` continues it".into(),
            });
        }
        let kind = sqlite::Kind {
            file: STORE_FILE,
            what: "run",
            made_by: "a directory written by `bitrock abc --out` or by `bitrock.abc(..., out=...)` in Python",
            versions: 1..=SCHEMA_VERSION,
        };
        let (conn, schema_version) = sqlite::open(dir, &kind, rusqlite::OpenFlags::SQLITE_OPEN_READ_WRITE)?;
        let store = Self {
            conn,
            path: dir.join(STORE_FILE),
            schema_version,
        };
        store.register_law_files()?;
        Ok(store)
    }

    /// Registers the law files' laws the run was made with, from their stored sources, so
    /// that its configuration, particles and report read without the files.
    fn register_law_files(&self) -> Result<()> {
        let err = sql_error(&self.path);
        let has_table: bool = self
            .conn
            .query_row(
                "SELECT COUNT(*) FROM sqlite_master WHERE type = 'table' AND name = 'law_files'",
                [],
                |r| r.get::<_, i64>(0),
            )
            .map_err(&err)?
            > 0;
        if !has_table {
            return Ok(());
        }
        let mut stmt = self
            .conn
            .prepare("SELECT name, source FROM law_files ORDER BY name")
            .map_err(&err)?;
        let rows: Vec<(String, String)> = stmt
            .query_map([], |r| Ok((r.get(0)?, r.get(1)?)))
            .map_err(&err)?
            .collect::<std::result::Result<_, _>>()
            .map_err(&err)?;
        for (name, source) in rows {
            let origin = self.path.join(format!("law_files/{name}"));
            crate::laws::file::register(crate::laws::file::LawFile::parse(&source, &origin)?)?;
        }
        Ok(())
    }

    /// Path of the database file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Schema version of the file.
    pub fn schema_version(&self) -> i64 {
        self.schema_version
    }

    /// Writes one completed population (record and particles) in one transaction.
    /// `previous` is the population before it (`None` for population 0), as stored.
    ///
    /// A particle is written once: when `population` begins with exactly the particles of
    /// `previous` whose ρ is below its ε (bit for bit, in their order, as nested rejection
    /// sampling makes it), those are recorded as carried (`population_rows.carried_below`) and
    /// only the rest are written. Carrying needs ε no higher than the ε `previous` carried
    /// with, so that "ρ below the last ε" selects exactly the rows of every population in the
    /// chain; otherwise (paper mode, SMC) every particle is written.
    pub fn append_population(&mut self, population: &Population, previous: Option<&Population>) -> Result<()> {
        let carried = self.carried(population, previous);
        let new = &population.particles[carried.unwrap_or(0)..];
        self.write_population(&population.record, carried, new)
    }

    /// How this store lays out particles: what prepares populations for it once the store
    /// itself has moved to a writing thread.
    pub fn layout(&self) -> Layout {
        Layout {
            schema_version: self.schema_version,
        }
    }

    /// Writes a population prepared by [`Layout::prepare`], in the order they were
    /// prepared.
    pub fn write_pending(&mut self, pending: PendingPopulation) -> Result<()> {
        self.write_population(&pending.record, pending.carried, &pending.new)
    }

    fn carried(&self, population: &Population, previous: Option<&Population>) -> Option<usize> {
        self.layout().carried(population, previous)
    }

    /// One transaction: the record, its per-law rows and its `new` particles (those after
    /// the `carried` prefix).
    fn write_population(&mut self, r: &PopulationRecord, carried: Option<usize>, new: &[Particle]) -> Result<()> {
        let path = self.path.clone();
        let err = sql_error(&path);
        let tx = self.conn.transaction().map_err(&err)?;
        tx.execute(
            "INSERT INTO populations (population, epsilon, draws, accepted, acceptance_rate, candidates_scored,
                 evaluations, near_threshold, ess, seconds, stream, record_json)
             VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11, ?12)",
            params![
                r.index as i64,
                r.epsilon,
                r.draws as i64,
                r.accepted as i64,
                r.acceptance_rate,
                r.candidates_scored as i64,
                r.evaluations as i64,
                r.near_threshold as i64,
                r.ess,
                r.seconds,
                i64::from(r.stream),
                serde_json::to_string(r).map_err(json_error(&path))?,
            ],
        )
        .map_err(&err)?;
        for l in &r.per_law {
            tx.execute(
                "INSERT INTO population_laws (population, law, draws, accepted, acceptance_rate, probability)
                 VALUES (?1, ?2, ?3, ?4, ?5, ?6)",
                params![
                    r.index as i64,
                    l.law.name(),
                    l.draws as i64,
                    l.accepted as i64,
                    l.acceptance_rate,
                    l.probability
                ],
            )
            .map_err(&err)?;
        }
        if self.schema_version >= ROWS_SCHEMA {
            insert_particle_rows(&tx, r, carried, new).map_err(&err)?;
        } else {
            insert_particles_table(&tx, r.index, new).map_err(&err)?;
        }
        tx.commit().map_err(&err)
    }

    /// Records an invocation (`start` or `resume`) and returns its id.
    pub fn begin_invocation(&mut self, kind: &str, backend: &str, config: &serde_json::Value) -> Result<i64> {
        let err = sql_error(&self.path);
        self.conn
            .execute(
                "INSERT INTO invocations (kind, started_unix_s, backend, config_json) VALUES (?1, ?2, ?3, ?4)",
                params![kind, unix_seconds(), backend, config.to_string()],
            )
            .map_err(&err)?;
        self.conn
            .execute(
                "UPDATE meta SET value = ?1 WHERE key = 'config'",
                params![config.to_string()],
            )
            .map_err(&err)?;
        Ok(self.conn.last_insert_rowid())
    }

    /// Marks invocation `id` finished with why it stopped, the backend that scored and the
    /// run's configuration (both known for certain only once workers have answered: the GPU
    /// scoring shape is part of the configuration).
    pub fn finish_invocation(
        &mut self,
        id: i64,
        stop_reason: &str,
        backend: &str,
        config: &serde_json::Value,
    ) -> Result<()> {
        let err = sql_error(&self.path);
        let tx = self.conn.transaction().map_err(&err)?;
        tx.execute(
            "UPDATE invocations SET finished_unix_s = ?1, stop_reason = ?2, backend = ?3, config_json = ?4 WHERE id = ?5",
            params![unix_seconds(), stop_reason, backend, config.to_string(), id],
        )
        .map_err(&err)?;
        tx.execute(
            "UPDATE meta SET value = ?1 WHERE key = 'config'",
            params![config.to_string()],
        )
        .map_err(&err)?;
        tx.commit().map_err(&err)
    }

    /// How the run ended, when not by its own stopping rules, in a sentence for everything made
    /// from it: its last invocation was killed before it finished, or it stopped early on a
    /// draw or time budget (its last population was dropped). `None` for a run that ended by
    /// its tolerance, schedule, population count, acceptance or stall rule.
    pub fn early_end(&self) -> Result<Option<String>> {
        use crate::abc::StopReason;
        let last: Option<(String, Option<String>)> = self
            .conn
            .query_row(
                "SELECT kind, stop_reason FROM invocations ORDER BY id DESC LIMIT 1",
                [],
                |r| Ok((r.get(0)?, r.get(1)?)),
            )
            .optional()
            .map_err(sql_error(&self.path))?;
        let Some((kind, stop)) = last else {
            return Ok(None);
        };
        let Some(stop) = stop else {
            // The store lies in its run directory, whose lock a writer holds.
            if let Some(holder) = crate::files::DirLock::holder(crate::files::parent_dir(&self.path)) {
                return Ok(Some(format!(
                    "the run is being written by {holder}: its last invocation ({kind}) has not finished, and what is shown is its state so far"
                )));
            }
            return Ok(Some(format!(
                "the run was interrupted: its last invocation ({kind}) did not finish; its populations are whole: {}",
                super::resume_advice(crate::files::parent_dir(&self.path))
            )));
        };
        let reason: Option<StopReason> = serde_json::from_value(serde_json::Value::String(stop)).ok();
        Ok(match reason {
            Some(r @ (StopReason::MaxDraws | StopReason::WallTime)) => Some(format!(
                "the run stopped early: {}; {}",
                r.describe(),
                super::resume_advice(crate::files::parent_dir(&self.path))
            )),
            _ => None,
        })
    }

    /// The run's configuration as stored (a [`super::Config`]'s JSON), without its record or
    /// populations.
    pub fn config(&self) -> Result<serde_json::Value> {
        let value: String = self
            .conn
            .query_row("SELECT value FROM meta WHERE key = 'config'", [], |r| r.get(0))
            .map_err(sql_error(&self.path))?;
        serde_json::from_str(&value).map_err(json_error(&self.path))
    }

    /// Reads the whole run back, bit for bit as it was written.
    pub fn load(&self) -> Result<Stored> {
        self.load_with(true)
    }

    /// As [`load`](Self::load), with the particles of the last population only (the others'
    /// are empty): what continuing the run and its report need, in memory O(N) however many
    /// populations it has.
    pub fn load_with_last_particles(&self) -> Result<Stored> {
        self.load_with(false)
    }

    fn load_with(&self, every_population: bool) -> Result<Stored> {
        let path = &self.path;
        let err = sql_error(path);
        let jerr = json_error(path);
        let meta = |key: &str| -> Result<String> {
            self.conn
                .query_row("SELECT value FROM meta WHERE key = ?1", [key], |r| r.get(0))
                .map_err(&err)
        };
        let config: serde_json::Value = serde_json::from_str(&meta("config")?).map_err(&jerr)?;
        let data_meta: DataMeta = serde_json::from_str(&meta("data")?).map_err(&jerr)?;
        let data = FieldData {
            source: data_meta.source,
            torque_unit: data_meta.torque_unit,
            speed_unit: data_meta.speed_unit,
            columns: data_meta.columns,
            rows_read: data_meta.rows_read,
            rows_used: data_meta.rows_used,
            calibration: self.load_samples("calibration")?,
            validation: self.load_samples("validation")?,
            warnings: data_meta.warnings,
            bit: data_meta.bit,
            // The run keeps its times, not how the record stamped them.
            clock: None,
        };
        let fits = self.load_fits(RecordScales::of(&data.calibration))?;
        let prior = self.load_prior()?;
        let populations = self.load_populations_with(every_population)?;
        Ok(Stored {
            setup: Setup {
                config,
                data,
                fits,
                prior,
            },
            populations,
        })
    }

    fn load_samples(&self, split: &str) -> Result<Samples> {
        let err = sql_error(&self.path);
        let mut stmt = self
            .conn
            .prepare("SELECT time_s, speed_rad_s, torque_nm, wob_n FROM samples WHERE split = ?1 ORDER BY position")
            .map_err(&err)?;
        type Row = (Option<f64>, f64, f64, Option<f64>);
        let rows: Vec<Row> = stmt
            .query_map([split], |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?, r.get(3)?)))
            .map_err(&err)?
            .collect::<std::result::Result<_, _>>()
            .map_err(&err)?;
        let column = |pick: fn(&Row) -> Option<f64>| -> Option<Vec<f64>> { rows.iter().map(pick).collect() };
        Ok(Samples {
            speed_rad_s: rows.iter().map(|r| r.1).collect(),
            torque_nm: rows.iter().map(|r| r.2).collect(),
            wob_n: if rows.is_empty() { None } else { column(|r| r.3) },
            time_s: if rows.is_empty() { None } else { column(|r| r.0) },
        })
    }

    /// The stored fits; `scales` are those of the stored calibration samples, which the fits
    /// were made on.
    fn load_fits(&self, scales: RecordScales) -> Result<Vec<LawFit>> {
        let err = sql_error(&self.path);
        let jerr = json_error(&self.path);
        let mut stmt = self
            .conn
            .prepare(
                "SELECT law, rho, validation_rho, condition_number, starts, warnings_json, correlations_json
                 FROM fits ORDER BY rowid",
            )
            .map_err(&err)?;
        type Row = (String, f64, Option<f64>, Option<f64>, i64, String, String);
        let rows: Vec<Row> = stmt
            .query_map([], |r| {
                Ok((
                    r.get(0)?,
                    r.get(1)?,
                    r.get(2)?,
                    r.get(3)?,
                    r.get(4)?,
                    r.get(5)?,
                    r.get(6)?,
                ))
            })
            .map_err(&err)?
            .collect::<std::result::Result<_, _>>()
            .map_err(&err)?;
        let mut fits = Vec::new();
        for (law, rho, validation_rho, condition_number, starts, warnings, correlations) in rows {
            let law = self.parse_law(&law)?;
            let mut params = self
                .conn
                .prepare("SELECT estimate_si, std_error_si FROM fit_params WHERE law = ?1 ORDER BY position")
                .map_err(&err)?;
            let values: Vec<(f64, Option<f64>)> = params
                .query_map([law.name()], |r| Ok((r.get(0)?, r.get(1)?)))
                .map_err(&err)?
                .collect::<std::result::Result<_, _>>()
                .map_err(&err)?;
            fits.push(LawFit {
                law,
                params_si: values.iter().map(|v| v.0).collect(),
                std_errors_si: values.iter().map(|v| v.1).collect(),
                rho,
                validation_rho,
                // SQLite stores a NaN as NULL.
                condition_number: condition_number.unwrap_or(f64::NAN),
                correlations: serde_json::from_str(&correlations).map_err(&jerr)?,
                warnings: serde_json::from_str(&warnings).map_err(&jerr)?,
                starts: starts as usize,
                endings: Default::default(),
                scales,
            });
        }
        Ok(fits)
    }

    fn load_prior(&self) -> Result<Prior> {
        let err = sql_error(&self.path);
        let mut stmt = self
            .conn
            .prepare("SELECT law, probability, threshold FROM prior_laws ORDER BY slot")
            .map_err(&err)?;
        let rows: Vec<(String, f64, i64)> = stmt
            .query_map([], |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?)))
            .map_err(&err)?
            .collect::<std::result::Result<_, _>>()
            .map_err(&err)?;
        let mut boxes = Vec::new();
        let mut rules = Vec::new();
        let mut weights = Vec::new();
        let mut thresholds = Vec::new();
        // Schema 1 did not record the rules.
        let rule_column = if self.schema_version >= 2 { "rule" } else { "NULL" };
        for (law, probability, threshold) in rows {
            let law = self.parse_law(&law)?;
            let mut bounds = self
                .conn
                .prepare(&format!(
                    "SELECT lower_si, upper_si, {rule_column} FROM prior_bounds WHERE law = ?1 ORDER BY position"
                ))
                .map_err(&err)?;
            let values: Vec<(f64, f64, Option<String>)> = bounds
                .query_map([law.name()], |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?)))
                .map_err(&err)?
                .collect::<std::result::Result<_, _>>()
                .map_err(&err)?;
            let mut law_rules = Vec::new();
            for (_, _, name) in &values {
                law_rules.push(match name {
                    None => BoxRule::Unrecorded,
                    Some(name) => BoxRule::from_name(name).ok_or_else(|| Error::Store {
                        path: self.path.clone(),
                        message: format!("prior_bounds of {law}: unknown box rule '{name}'"),
                    })?,
                });
            }
            rules.push(law_rules);
            // Written from f32, so the narrowing is exact.
            boxes.push(LawBox::new(
                law,
                values.iter().map(|v| v.0 as f32).collect(),
                values.iter().map(|v| v.1 as f32).collect(),
            ));
            weights.push(probability);
            thresholds.push(threshold as u64);
        }
        Ok(Prior {
            boxes,
            rules,
            weights,
            thresholds,
        })
    }

    /// Every completed population, in order.
    pub fn load_populations(&self) -> Result<Vec<Population>> {
        self.load_populations_with(true)
    }

    /// Every completed population's record, with the particles of every population or of
    /// the last only.
    fn load_populations_with(&self, every_population: bool) -> Result<Vec<Population>> {
        let err = sql_error(&self.path);
        let jerr = json_error(&self.path);
        let mut stmt = self
            .conn
            .prepare("SELECT record_json FROM populations ORDER BY population")
            .map_err(&err)?;
        let records: Vec<String> = stmt
            .query_map([], |r| r.get(0))
            .map_err(&err)?
            .collect::<std::result::Result<_, _>>()
            .map_err(&err)?;
        let mut populations = Vec::with_capacity(records.len());
        let last = records.len().saturating_sub(1);
        for (k, text) in records.into_iter().enumerate() {
            let record: PopulationRecord = serde_json::from_str(&text).map_err(&jerr)?;
            let particles = if every_population || k == last {
                self.load_particles(record.index)?
            } else {
                Vec::new()
            };
            populations.push(Population { record, particles });
        }
        Ok(populations)
    }

    /// The particles of population `g`, in order.
    pub fn load_particles(&self, g: usize) -> Result<Vec<Particle>> {
        if self.schema_version >= ROWS_SCHEMA {
            self.load_particle_rows(g)
        } else {
            self.load_particles_table(g)
        }
    }

    /// Schema 3: population g's carried and new rows, in id order.
    fn load_particle_rows(&self, g: usize) -> Result<Vec<Particle>> {
        let err = sql_error(&self.path);
        let range: Option<(i64, i64, i64, Option<f64>)> = self
            .conn
            .query_row(
                "SELECT first_row, end_row, carried_from_row, carried_below FROM population_rows WHERE population = ?1",
                [g as i64],
                |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?, r.get(3)?)),
            )
            .optional()
            .map_err(&err)?;
        let Some((first_row, end_row, carried_from_row, carried_below)) = range else {
            return Ok(Vec::new());
        };
        let row_weights: std::collections::HashMap<i64, Option<f64>> = self
            .conn
            .prepare("SELECT population, row_weight FROM population_rows")
            .and_then(|mut s| {
                s.query_map([], |r| Ok((r.get(0)?, r.get(1)?)))?
                    .collect::<std::result::Result<_, _>>()
            })
            .map_err(&err)?;
        let mut stmt = self
            .conn
            .prepare(
                "SELECT first_population, law, candidate, rho, weight, p0, p1, p2, p3, p4, p5 FROM particle_rows
                 WHERE id >= ?1 AND id < ?2 AND (id >= ?3 OR rho < ?4) ORDER BY id",
            )
            .map_err(&err)?;
        let mut rows = stmt
            .query(params![carried_from_row, end_row, first_row, carried_below])
            .map_err(&err)?;
        let mut particles = Vec::with_capacity((end_row - first_row).max(0) as usize);
        while let Some(row) = rows.next().map_err(&err)? {
            let first: i64 = row.get(0).map_err(&err)?;
            let law = self.parse_law(&row.get::<_, String>(1).map_err(&err)?)?;
            let weight = match row.get::<_, Option<f64>>(4).map_err(&err)? {
                Some(w) => w,
                None => row_weights.get(&first).copied().flatten().ok_or_else(|| Error::Store {
                    path: self.path.clone(),
                    message: format!("a particle of population {first} has no weight"),
                })?,
            };
            let params = (5..5 + law.n_params())
                .map(|c| row.get::<_, f64>(c))
                .collect::<std::result::Result<Vec<_>, _>>()
                .map_err(&err)?;
            particles.push(Particle {
                law,
                index: row.get::<_, i64>(2).map_err(&err)? as u64,
                params,
                rho: row.get(3).map_err(&err)?,
                weight,
            });
        }
        Ok(particles)
    }

    /// Schemas 1 and 2: population g's rows of the `particles` table.
    fn load_particles_table(&self, g: usize) -> Result<Vec<Particle>> {
        let err = sql_error(&self.path);
        let all_names: Vec<&str> = Law::ALL.iter().flat_map(|l| l.param_names()).collect();
        let mut stmt = self
            .conn
            .prepare(&format!(
                "SELECT law, candidate, rho, weight, {} FROM particles WHERE population = ?1 ORDER BY position",
                all_names.join(", ")
            ))
            .map_err(&err)?;
        let mut rows = stmt.query([g as i64]).map_err(&err)?;
        let mut particles = Vec::new();
        while let Some(row) = rows.next().map_err(&err)? {
            let law_name: String = row.get(0).map_err(&err)?;
            let law = self.parse_law(&law_name)?;
            let first = 4 + Law::ALL[..law.index()].iter().map(|l| l.n_params()).sum::<usize>();
            let params = (first..first + law.n_params())
                .map(|c| row.get::<_, f64>(c))
                .collect::<std::result::Result<Vec<_>, _>>()
                .map_err(&err)?;
            particles.push(Particle {
                law,
                index: row.get::<_, i64>(1).map_err(&err)? as u64,
                params,
                rho: row.get(2).map_err(&err)?,
                weight: row.get(3).map_err(&err)?,
            });
        }
        Ok(particles)
    }

    fn parse_law(&self, name: &str) -> Result<Law> {
        name.parse().map_err(|e: String| Error::Store {
            path: self.path.clone(),
            message: e,
        })
    }
}

/// The view `particles` over schema 3's rows: what schema 2 stored as a table, one row per
/// particle and population (`position` its place in the population), with one column per
/// The record's samples of a new store, and the parameters' names and units of every law it
/// may hold (the built-in laws and `file_laws`).
fn insert_samples(tx: &rusqlite::Transaction, data: &FieldData, file_laws: &[Law], path: &Path) -> Result<()> {
    let err = sql_error(path);
    let mut insert = tx
        .prepare(
            "INSERT INTO samples (split, position, time_s, speed_rad_s, torque_nm, wob_n)
         VALUES (?1, ?2, ?3, ?4, ?5, ?6)",
        )
        .map_err(&err)?;
    for (split, s) in [("calibration", &data.calibration), ("validation", &data.validation)] {
        for i in 0..s.len() {
            insert
                .execute(params![
                    split,
                    i as i64,
                    s.time_s.as_ref().map(|t| t[i]),
                    s.speed_rad_s[i],
                    s.torque_nm[i],
                    s.wob_n.as_ref().map(|w| w[i]),
                ])
                .map_err(&err)?;
        }
    }
    let mut param = tx
        .prepare("INSERT INTO parameters (law, position, name, unit_si) VALUES (?1, ?2, ?3, ?4)")
        .map_err(&err)?;
    for law in Law::ALL.into_iter().chain(file_laws.iter().copied()) {
        for (j, spec) in law.params().iter().enumerate() {
            param
                .execute(params![
                    law.name(),
                    j as i64,
                    view_column(law, spec.name),
                    spec.unit("N·m")
                ])
                .map_err(&err)?;
        }
    }
    Ok(())
}

/// The least-squares fits of a new store, with their estimates and standard errors.
fn insert_fits(tx: &rusqlite::Transaction, fits: &[LawFit], path: &Path) -> Result<()> {
    let err = sql_error(path);
    for fit in fits {
        tx.execute(
            "INSERT INTO fits (law, rho, validation_rho, condition_number, starts, warnings_json, correlations_json)
         VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7)",
            params![
                fit.law.name(),
                fit.rho,
                fit.validation_rho,
                fit.condition_number,
                fit.starts as i64,
                serde_json::to_string(&fit.warnings).map_err(json_error(path))?,
                serde_json::to_string(&fit.correlations).map_err(json_error(path))?,
            ],
        )
        .map_err(&err)?;
        for (j, (estimate, std_error)) in fit.params_si.iter().zip(&fit.std_errors_si).enumerate() {
            tx.execute(
                "INSERT INTO fit_params (law, position, estimate_si, std_error_si) VALUES (?1, ?2, ?3, ?4)",
                params![fit.law.name(), j as i64, estimate, std_error],
            )
            .map_err(&err)?;
        }
    }
    Ok(())
}

/// The prior of a new store: each law's slot, probability and threshold, and its bounds.
fn insert_prior(tx: &rusqlite::Transaction, prior: &Prior, path: &Path) -> Result<()> {
    let err = sql_error(path);
    for (slot, ((b, probability), threshold)) in prior
        .boxes
        .iter()
        .zip(&prior.weights)
        .zip(&prior.thresholds)
        .enumerate()
    {
        tx.execute(
            "INSERT INTO prior_laws (slot, law, probability, threshold) VALUES (?1, ?2, ?3, ?4)",
            params![slot as i64, b.law.name(), probability, *threshold as i64],
        )
        .map_err(&err)?;
        for (j, ((lo, hi), rule)) in b.lower.iter().zip(&b.upper).zip(&prior.rules[slot]).enumerate() {
            tx.execute(
                "INSERT INTO prior_bounds (law, position, lower_si, upper_si, rule) VALUES (?1, ?2, ?3, ?4, ?5)",
                params![b.law.name(), j as i64, f64::from(*lo), f64::from(*hi), rule.name()],
            )
            .map_err(&err)?;
        }
    }
    Ok(())
}

/// parameter name.
fn particles_view(file_laws: &[Law]) -> String {
    let parameter_columns: Vec<String> = Law::ALL
        .iter()
        .chain(file_laws)
        .flat_map(|law| {
            law.param_names().into_iter().enumerate().map(move |(j, name)| {
                format!(
                    "CASE r.law WHEN '{}' THEN r.p{j} END AS {}",
                    law.name(),
                    view_column(*law, name)
                )
            })
        })
        .collect();
    format!(
        "CREATE VIEW particles AS
         SELECT m.population AS population,
                ROW_NUMBER() OVER (PARTITION BY m.population ORDER BY r.id) - 1 AS position,
                r.law AS law, r.candidate AS candidate, r.rho AS rho,
                COALESCE(r.weight, f.row_weight) AS weight,
                {}
         FROM population_rows m
         JOIN particle_rows r ON r.id >= m.carried_from_row AND r.id < m.end_row
              AND (r.id >= m.first_row OR r.rho < m.carried_below)
         JOIN population_rows f ON f.population = r.first_population;",
        parameter_columns.join(",\n                ")
    )
}

/// The column of the `particles` view (and the name in the `parameters` table) of parameter
/// `name` of `law`: the name itself for m1..m4, `<law>_<name>` for a law file's law, whose
/// names may repeat another law's.
fn view_column(law: Law, name: &str) -> String {
    match law {
        Law::File(_) => crate::laws::file::store_column(law.name(), name),
        _ => name.to_string(),
    }
}

/// Particles equal to the bit (parameters, ρ and weight compared as bits).
fn same_particle(a: &Particle, b: &Particle) -> bool {
    let bits = |p: &Particle| -> (u64, u64) { (p.rho.to_bits(), p.weight.to_bits()) };
    a.law == b.law
        && a.index == b.index
        && bits(a) == bits(b)
        && a.params.len() == b.params.len()
        && a.params.iter().zip(&b.params).all(|(x, y)| x.to_bits() == y.to_bits())
}

/// Schema 3: how many leading particles of `population` are carried from `previous` (the
/// stored population before it); `None` when it carries nothing (see
/// [`Store::append_population`]). Decided from the particles alone, so that it can be
/// decided while the sampler still holds `previous` and written later: carrying needs ε no
/// higher than `previous`'s, which makes ε no higher than the ε every population of the
/// chain carried with.
fn carried_count(population: &Population, previous: Option<&Population>) -> Option<usize> {
    let (previous, epsilon) = (previous?, population.record.epsilon?);
    if previous.record.index + 1 != population.record.index
        || epsilon.is_nan()
        || previous.record.epsilon.is_some_and(|e| epsilon > e)
    {
        return None;
    }
    let mut carried = previous.particles.iter().filter(|p| p.rho < epsilon);
    let mut count = 0;
    for p in &population.particles {
        match carried.next() {
            Some(q) if same_particle(p, q) => count += 1,
            Some(_) => return None,
            None => break,
        }
    }
    if carried.next().is_some() {
        return None;
    }
    Some(count)
}

/// Schema 3, for a population carrying `carried` particles: the row its carried rows begin
/// at. The population before it was written by the same store, before it: its entry is
/// there, and ε is no higher than the one it carried with ([`carried_count`]).
fn carried_from_row(tx: &rusqlite::Transaction, previous_index: i64, epsilon: f64) -> rusqlite::Result<i64> {
    let (first_row, carried_from_row, carried_below): (i64, i64, Option<f64>) = tx.query_row(
        "SELECT first_row, carried_from_row, carried_below FROM population_rows WHERE population = ?1",
        [previous_index],
        |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?)),
    )?;
    match carried_below {
        None => Ok(first_row),
        Some(below) if epsilon <= below => Ok(carried_from_row),
        // Unreachable through carried_count; a misuse of the store if it ever happens.
        Some(below) => Err(rusqlite::Error::SqliteFailure(
            rusqlite::ffi::Error::new(rusqlite::ffi::SQLITE_MISUSE),
            Some(format!(
                "population {}: ε = {epsilon} above the ε = {below} of the population it carries from",
                previous_index + 1
            )),
        )),
    }
}

/// Schema 3: the rows of `population` that `previous` does not carry, and its entry in
/// `population_rows`. One prepared statement, parameters bound in place.
fn insert_particle_rows(
    tx: &rusqlite::Transaction,
    record: &PopulationRecord,
    carried: Option<usize>,
    new: &[Particle],
) -> rusqlite::Result<()> {
    let g = record.index as i64;
    let first_row: i64 = tx.query_row("SELECT COALESCE(MAX(end_row), 0) FROM population_rows", [], |r| {
        r.get(0)
    })?;
    let (carried_from_row, carried_below) = match (carried, record.epsilon) {
        (Some(_), Some(epsilon)) => (carried_from_row(tx, g - 1, epsilon)?, Some(epsilon)),
        _ => (first_row, None),
    };
    // Rejection gives every particle the same weight: stored once, not per row.
    let row_weight = new
        .first()
        .map(|p| p.weight)
        .filter(|w| new.iter().all(|p| p.weight.to_bits() == w.to_bits()));
    // Rows go in ROWS_PER_INSERT at a time: one statement step per row was most of the
    // cost of writing a population.
    let statement = |rows: usize| {
        let values = vec!["(?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)"; rows].join(", ");
        tx.prepare(&format!(
            "INSERT INTO particle_rows (id, first_population, law, candidate, rho, weight, p0, p1, p2, p3, p4, p5)
             VALUES {values}"
        ))
    };
    let weight_of = |p: &Particle| if row_weight.is_some() { None } else { Some(p.weight) };
    let (chunked, tail) = new.split_at(new.len() / ROWS_PER_INSERT * ROWS_PER_INSERT);
    let mut insert = statement(ROWS_PER_INSERT)?;
    for (c, chunk) in chunked.chunks_exact(ROWS_PER_INSERT).enumerate() {
        for (k, p) in chunk.iter().enumerate() {
            let id = first_row + (c * ROWS_PER_INSERT + k) as i64;
            bind_particle_row(&mut insert, k, id, g, p, weight_of(p))?;
        }
        insert.raw_execute()?;
    }
    let mut insert = statement(1)?;
    for (k, p) in tail.iter().enumerate() {
        let id = first_row + (chunked.len() + k) as i64;
        bind_particle_row(&mut insert, 0, id, g, p, weight_of(p))?;
        insert.raw_execute()?;
    }
    tx.execute(
        "INSERT INTO population_rows (population, first_row, end_row, carried_from_row, carried_below, row_weight)
         VALUES (?1, ?2, ?3, ?4, ?5, ?6)",
        params![
            g,
            first_row,
            first_row + new.len() as i64,
            carried_from_row,
            carried_below,
            row_weight
        ],
    )?;
    Ok(())
}

/// Rows of `particle_rows` per INSERT statement (12 parameters each, far below SQLite's
/// limit of 32,766).
const ROWS_PER_INSERT: usize = 64;

/// Binds the values of `particle_rows` row number `row` of a multi-row INSERT: id, first
/// population, law, candidate, ρ, weight (NULL: the population's row weight), p0..p5.
fn bind_particle_row(
    insert: &mut rusqlite::Statement,
    row: usize,
    id: i64,
    population: i64,
    p: &Particle,
    weight: Option<f64>,
) -> rusqlite::Result<()> {
    let at = 12 * row;
    insert.raw_bind_parameter(at + 1, id)?;
    insert.raw_bind_parameter(at + 2, population)?;
    insert.raw_bind_parameter(at + 3, p.law.name())?;
    insert.raw_bind_parameter(at + 4, p.index as i64)?;
    insert.raw_bind_parameter(at + 5, p.rho)?;
    insert.raw_bind_parameter(at + 6, weight)?;
    for j in 0..crate::laws::MAX_PARAMS {
        insert.raw_bind_parameter(at + 7 + j, p.params.get(j).copied())?;
    }
    Ok(())
}

/// Schemas 1 and 2: one row of the `particles` table per particle, so that a run stored by
/// an older bitrock continues in its own layout.
fn insert_particles_table(tx: &rusqlite::Transaction, index: usize, particles: &[Particle]) -> rusqlite::Result<()> {
    let g = index as i64;
    let mut statements: Vec<rusqlite::Statement> = Law::ALL
        .iter()
        .map(|law| {
            let names: Vec<&str> = law.param_names();
            let marks: Vec<String> = (0..names.len()).map(|j| format!("?{}", j + 7)).collect();
            tx.prepare(&format!(
                "INSERT INTO particles (population, position, law, candidate, rho, weight, {})
                 VALUES (?1, ?2, ?3, ?4, ?5, ?6, {})",
                names.join(", "),
                marks.join(", ")
            ))
        })
        .collect::<std::result::Result<_, _>>()?;
    for (position, p) in particles.iter().enumerate() {
        let statement = &mut statements[p.law.index()];
        statement.raw_bind_parameter(1, g)?;
        statement.raw_bind_parameter(2, position as i64)?;
        statement.raw_bind_parameter(3, p.law.name())?;
        statement.raw_bind_parameter(4, p.index as i64)?;
        statement.raw_bind_parameter(5, p.rho)?;
        statement.raw_bind_parameter(6, p.weight)?;
        for (j, &v) in p.params.iter().enumerate() {
            statement.raw_bind_parameter(7 + j, v)?;
        }
        statement.raw_execute()?;
    }
    Ok(())
}

fn data_meta(data: &FieldData) -> DataMeta {
    DataMeta {
        source: data.source.clone(),
        torque_unit: data.torque_unit,
        speed_unit: data.speed_unit,
        columns: data.columns.clone(),
        rows_read: data.rows_read,
        rows_used: data.rows_used,
        warnings: data.warnings.clone(),
        bit: data.bit,
    }
}

fn unix_seconds() -> f64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64())
}
