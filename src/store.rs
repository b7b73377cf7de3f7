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
//! Particles are one row each with one column per parameter name (parameter names are unique
//! across the laws: `b0..b3`, `tsb, tcb, g`, `a0..a5`, `c0..c3`); a particle's columns of the
//! other laws are NULL. The schema is in the README ("Run store").

use crate::abc::{Particle, Population, PopulationRecord};
use crate::data::{ColumnsUsed, FieldData, Samples};
use crate::error::{Error, Result};
use crate::files;
use crate::fit::{LawFit, RecordScales};
use crate::laws::Law;
use crate::prior::{BoxRule, LawBox, Prior};
use crate::units::{SpeedUnit, TorqueUnit};
use rusqlite::{Connection, OptionalExtension, params};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// File name of the store inside a run directory.
pub const STORE_FILE: &str = "run.sqlite";

/// Version of the schema below. Version 1 (no `prior_bounds.rule`) is still read, its box
/// rules as [`BoxRule::Unrecorded`]; any other version is refused.
pub const SCHEMA_VERSION: i64 = 2;

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
CREATE TABLE particles (
    population INTEGER NOT NULL,
    position INTEGER NOT NULL,
    law TEXT NOT NULL,
    candidate INTEGER NOT NULL,
    rho REAL NOT NULL,
    weight REAL NOT NULL,
    b0 REAL, b1 REAL, b2 REAL, b3 REAL,
    tsb REAL, tcb REAL, g REAL,
    a0 REAL, a1 REAL, a2 REAL, a3 REAL, a4 REAL, a5 REAL,
    c0 REAL, c1 REAL, c2 REAL, c3 REAL,
    PRIMARY KEY (population, position)
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
}

/// What defines a run besides its populations.
#[derive(Clone, Debug)]
pub struct RunSetup {
    /// The run's configuration as JSON (see `crate::run::RunConfig`), kept opaque here.
    pub config: serde_json::Value,
    pub data: FieldData,
    pub fits: Vec<LawFit>,
    pub prior: Prior,
}

/// A run read back: its set-up and every completed population.
#[derive(Clone, Debug)]
pub struct StoredRun {
    pub setup: RunSetup,
    pub populations: Vec<Population>,
}

/// An open run store.
pub struct RunStore {
    conn: Connection,
    path: PathBuf,
    /// Schema version of the file (older versions are read, see [`SCHEMA_VERSION`]).
    schema_version: i64,
}

fn sql_error(path: &Path) -> impl Fn(rusqlite::Error) -> Error + '_ {
    move |e| Error::Store {
        path: path.to_path_buf(),
        message: e.to_string(),
    }
}

fn json_error(path: &Path) -> impl Fn(serde_json::Error) -> Error + '_ {
    move |e| Error::Store {
        path: path.to_path_buf(),
        message: format!("malformed JSON in the store: {e}"),
    }
}

impl RunStore {
    /// Creates `dir/run.sqlite` (which must not exist) whole or not at all: the schema and the
    /// set-up are written in one transaction into a temporary beside it (no journal: a failed
    /// temporary is discarded), which is renamed to run.sqlite once complete. A kill at any
    /// moment leaves no store or a complete one, and the temporary is removed by the next run
    /// in `dir` ([`files::remove_stale`]).
    pub fn create(dir: &Path, setup: &RunSetup) -> Result<Self> {
        let path = dir.join(STORE_FILE);
        if path.exists() {
            return Err(Error::Store {
                path,
                message: "a run store already exists here".into(),
            });
        }
        let temp = files::TempFile::beside(&path, "--out")?;
        let err = sql_error(&path);
        let mut conn = Connection::open(temp.path()).map_err(&err)?;
        conn.pragma_update(None, "journal_mode", "OFF").map_err(&err)?;
        let tx = conn.transaction().map_err(&err)?;
        tx.execute_batch(SCHEMA).map_err(&err)?;
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
        {
            let mut insert = tx
                .prepare(
                    "INSERT INTO samples (split, position, time_s, speed_rad_s, torque_nm, wob_n)
                     VALUES (?1, ?2, ?3, ?4, ?5, ?6)",
                )
                .map_err(&err)?;
            for (split, s) in [
                ("calibration", &setup.data.calibration),
                ("validation", &setup.data.validation),
            ] {
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
            for law in Law::ALL {
                for (j, spec) in law.params().iter().enumerate() {
                    param
                        .execute(params![law.name(), j as i64, spec.name, spec.unit("N·m")])
                        .map_err(&err)?;
                }
            }
        }
        for fit in &setup.fits {
            tx.execute(
                "INSERT INTO fits (law, rho, validation_rho, condition_number, starts, warnings_json, correlations_json)
                 VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7)",
                params![
                    fit.law.name(),
                    fit.rho,
                    fit.validation_rho,
                    fit.condition_number,
                    fit.starts as i64,
                    serde_json::to_string(&fit.warnings).map_err(json_error(&path))?,
                    serde_json::to_string(&fit.correlations).map_err(json_error(&path))?,
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
        let prior = &setup.prior;
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
        tx.commit().map_err(&err)?;
        conn.close().map_err(|(_, e)| err(e))?;
        temp.commit(&path)?;
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
        let path = dir.join(STORE_FILE);
        let not_a_run = |why: String| Error::Data {
            path: dir.to_path_buf(),
            message: format!("not a bitrock run directory ({why}); give a directory written by `bitrock abc --out`"),
        };
        if !dir.is_dir() {
            return Err(not_a_run("no such directory".into()));
        }
        if !path.is_file() {
            return Err(not_a_run(format!("it has no {STORE_FILE}")));
        }
        let conn = Connection::open_with_flags(&path, rusqlite::OpenFlags::SQLITE_OPEN_READ_WRITE)
            .map_err(|e| not_a_run(format!("{STORE_FILE}: {e}")))?;
        let version: Option<String> = conn
            .query_row("SELECT value FROM meta WHERE key = 'schema_version'", [], |r| r.get(0))
            .optional()
            .map_err(|e| not_a_run(format!("{STORE_FILE} is not a bitrock store: {e}")))?;
        match version.as_deref().map(str::parse::<i64>) {
            Some(Ok(v @ (1 | SCHEMA_VERSION))) => Ok(Self {
                conn,
                path,
                schema_version: v,
            }),
            Some(Ok(v)) => Err(not_a_run(format!(
                "{STORE_FILE} has schema version {v}; this bitrock reads versions 1 to {SCHEMA_VERSION}"
            ))),
            _ => Err(not_a_run(format!("{STORE_FILE} has no schema version"))),
        }
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
    pub fn append_population(&mut self, population: &Population) -> Result<()> {
        let path = self.path.clone();
        let err = sql_error(&path);
        let r = &population.record;
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
        {
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
                .collect::<std::result::Result<_, _>>()
                .map_err(&err)?;
            for (position, p) in population.particles.iter().enumerate() {
                let statement = &mut statements[p.law.index()];
                let mut values: Vec<rusqlite::types::Value> = vec![
                    (r.index as i64).into(),
                    (position as i64).into(),
                    p.law.name().to_string().into(),
                    (p.index as i64).into(),
                    p.rho.into(),
                    p.weight.into(),
                ];
                values.extend(p.params.iter().map(|&v| rusqlite::types::Value::Real(v)));
                statement.execute(rusqlite::params_from_iter(values)).map_err(&err)?;
            }
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

    /// Marks invocation `id` finished with why it stopped.
    pub fn finish_invocation(&mut self, id: i64, stop_reason: &str) -> Result<()> {
        self.conn
            .execute(
                "UPDATE invocations SET finished_unix_s = ?1, stop_reason = ?2 WHERE id = ?3",
                params![unix_seconds(), stop_reason, id],
            )
            .map_err(sql_error(&self.path))?;
        Ok(())
    }

    /// Reads the whole run back, bit for bit as it was written.
    pub fn load(&self) -> Result<StoredRun> {
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
        };
        let fits = self.load_fits(RecordScales::of(&data.calibration))?;
        let prior = self.load_prior()?;
        let populations = self.load_populations()?;
        Ok(StoredRun {
            setup: RunSetup {
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
            boxes.push(LawBox {
                law,
                lower: values.iter().map(|v| v.0 as f32).collect(),
                upper: values.iter().map(|v| v.1 as f32).collect(),
            });
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
        for text in records {
            let record: PopulationRecord = serde_json::from_str(&text).map_err(&jerr)?;
            let particles = self.load_particles(record.index)?;
            populations.push(Population { record, particles });
        }
        Ok(populations)
    }

    /// The particles of population `g`, in order.
    pub fn load_particles(&self, g: usize) -> Result<Vec<Particle>> {
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

fn data_meta(data: &FieldData) -> DataMeta {
    DataMeta {
        source: data.source.clone(),
        torque_unit: data.torque_unit,
        speed_unit: data.speed_unit,
        columns: data.columns.clone(),
        rows_read: data.rows_read,
        rows_used: data.rows_used,
    }
}

fn unix_seconds() -> f64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64())
}
