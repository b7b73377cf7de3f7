//! A watch directory: one SQLite database (`DIR/watch.sqlite`) holding the watch's settings
//! and source, one row per finished window (its update, as the JSON line said it) and what the
//! watch carries after its last window ([`Carried`]: the probabilities, the recent fits and
//! the last posterior), replaced with each window. Each window is stored in one transaction
//! before it is given, so a watch killed at any moment has every window it said, and
//! `bitrock watch --resume` goes on after the last one as if it had never stopped.
//!
//! Bytes per window: its update (about 0.6 kB plus 0.3 kB per law) in `windows`; the carried
//! state and the latest window's picture ([`View`], for the live page) are one row each
//! whatever the record's length (the posterior: 2 × `particles` per law; the picture about
//! 40 kB).

use super::view::View;
use super::{Carried, Update, WatchSettings};
use crate::error::{Error, Result};
use crate::files::DirLock;
use crate::run::sqlite::{self, json_error, sql_error};
use crate::stability::map::Criterion;
use rusqlite::{Connection, OptionalExtension, params};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

pub use crate::run::dir::{WATCH_STORE_COMPANIONS, WATCH_STORE_FILE};

/// Version of the schema below; any other is refused.
pub const WATCH_SCHEMA_VERSION: i64 = 1;

const SCHEMA: &str = r#"
CREATE TABLE meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE windows (
    window INTEGER PRIMARY KEY,
    start_s REAL NOT NULL,
    end_s REAL NOT NULL,
    update_json TEXT NOT NULL
);
CREATE TABLE carried (
    id INTEGER PRIMARY KEY CHECK (id = 1),
    window INTEGER NOT NULL,
    state_json TEXT NOT NULL
);
"#;

/// The latest window's picture ([`View`]), replaced with each window. A store made without it
/// gains it when a watch goes on with it; a reader takes its absence as no picture.
const VIEW_TABLE: &str = r#"
CREATE TABLE IF NOT EXISTS view (
    id INTEGER PRIMARY KEY CHECK (id = 1),
    window INTEGER NOT NULL,
    view_json TEXT NOT NULL
);
"#;

/// What a watch is, stored when it starts: a resumed watch must be the same one.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct WatchMeta {
    /// The source as named when the watch started.
    pub source: String,
    /// The settings that shape the numbers (as [`settings_json`] writes them).
    pub settings: serde_json::Value,
    /// Window length and step, s; the record's rate it measured, Hz.
    pub window_s: f64,
    pub step_s: f64,
    pub rate_hz: f64,
    /// The record's torque unit (parameters are reported in it).
    pub torque_unit: crate::units::TorqueUnit,
    pub bitrock_version: String,
    /// The columns of a record of surface channels alone, each window of which was inferred
    /// through simulated strings; `None` for a record of the bit's channels.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub surface: Option<crate::data::surface::SurfaceColumns>,
}

/// The settings that decide a watch's numbers, as JSON: what a resumed watch must match; with
/// `surface`, those of a watch of surface channels too.
/// The backend and thread count are not among them (they change no more than the last bits
/// of ρ, within the parity contract).
pub fn settings_json(settings: &WatchSettings, surface: bool) -> serde_json::Value {
    let mut json = serde_json::json!({
        "laws": settings.laws.iter().map(|l| l.name()).collect::<Vec<_>>(),
        // The text of each law file whose law the watch compares: a resumed watch must compare
        // the same laws, not others under their names.
        "law_files": settings
            .laws
            .iter()
            .filter_map(|l| l.file())
            .map(|f| (f.name.clone(), serde_json::Value::from(f.source.clone())))
            .collect::<serde_json::Map<_, _>>(),
        "speed_column": settings.data.speed_column,
        "torque_column": settings.data.torque_column,
        "wob_column": settings.data.wob_column,
        "time_column": settings.data.time_column,
        "speed_unit": settings.data.speed_unit.map(|u| format!("{u:?}")),
        "torque_unit": settings.data.torque_unit.map(|u| format!("{u:?}")),
        "wob_unit": settings.data.wob_unit.map(|u| format!("{u:?}")),
        "min_speed_rpm": settings.data.min_speed_rpm,
        "thin": settings.thin,
        "window_s": settings.window_s,
        "step_s": settings.step_s,
        "particles": settings.evidence.particles,
        "islands": settings.evidence.islands,
        "seed": settings.evidence.seed,
        "noise": format!("{:?}", settings.evidence.noise),
        "prior_scale": settings.evidence.prior_scale,
        "forgetting": settings.forgetting,
        "floor": settings.floor,
        "change_nats": settings.change_nats,
        "risk": settings.risk,
        "w_ref_n": settings.w_ref_n,
        "min_samples": settings.min_samples,
        "min_speed_span_rpm": settings.min_speed_span_rpm,
        "wits_items": settings.wits,
        "warm_start": settings.warm_start,
        // The paper's ABC on each window: what of its run configuration is the watch's own
        // (its laws, seed and backend are the watch's).
        "abc": settings.abc.as_ref().map(|c| serde_json::json!({
            "sampler": c.sampler,
            "delta": c.delta,
            "prior_rule": c.prior_rule,
            "eps_min_from_record": c.eps_min_from_record,
            "fit": c.fit,
        })),
        "criterion": criterion_json(&settings.criterion),
    });
    if surface {
        // A record of surface channels: what of the surface run's settings is the watch's own
        // (its laws, string, seed and backend are the watch's).
        let s = &settings.surface;
        json["surface"] = serde_json::json!({
            "particles": s.particles,
            "max_populations": s.max_populations,
            "pilot": s.pilot,
            "check_replicates": s.check_replicates,
            "predictive_draws": s.predictive_draws,
            "prior_scale": s.prior_scale,
            "dt_s": s.dt_s,
            "settle_s": s.settle_s,
        });
    }
    json
}

/// What decides the advice's stability, as JSON: the 1-DOF model's constants, or the
/// finite-element string's critical bit damping.
fn criterion_json(criterion: &Criterion) -> serde_json::Value {
    match criterion {
        Criterion::Lumped(l) => serde_json::json!({
            "structure": "1dof",
            "inertia_kg_m2": l.inertia_kg_m2,
            "omega_n_rad_s": l.omega_n_rad_s,
            "damping_ratio": l.damping_ratio,
        }),
        Criterion::Critical(c) => serde_json::json!({
            "structure": "fe",
            "critical_bit_damping_nms": c,
        }),
    }
}

/// In words, for captions: "the paper's 1-DOF string" or "the finite-element string (c_b* = …)",
/// from a stored watch's settings (a watch stored without them used the 1-DOF string).
pub fn criterion_words(settings: &serde_json::Value) -> String {
    match settings["criterion"]["critical_bit_damping_nms"].as_f64() {
        Some(c) => format!("the finite-element string, critical bit damping {c:.1} N·m·s/rad"),
        None => "the paper's 1-DOF string".into(),
    }
}

/// A watch store open for writing, its directory locked.
pub struct WatchStore {
    conn: Connection,
    path: PathBuf,
    _lock: DirLock,
}

/// A watch directory read whole.
#[derive(Clone, Debug)]
pub struct StoredWatch {
    pub dir: PathBuf,
    pub meta: WatchMeta,
    /// Every window stored, in order.
    pub updates: Vec<Update>,
    /// What the watch carried after its last window.
    pub carried: Option<Carried>,
    /// The picture of its last window, where the store has one.
    pub view: Option<View>,
}

/// True when `dir` holds a watch store.
pub fn is_watch_dir(dir: &Path) -> bool {
    dir.join(WATCH_STORE_FILE).is_file()
}

impl WatchStore {
    /// Makes `dir` a watch directory (created where missing) for the watch `meta` describes.
    /// A directory that holds a watch already is refused (`resume` goes on with it), and so
    /// is one that holds anything else, before it is created and again under its lock
    /// ([`crate::run::dir::claim`]).
    pub fn create(dir: &Path, meta: &WatchMeta) -> Result<Self> {
        let check = || {
            crate::run::dir::refuse_inside_kept_dir(dir, "out")?;
            if is_watch_dir(dir) {
                return Err(Error::setting(
                    "out",
                    format!(
                        "{} holds a watch already: `resume` goes on with it, or name another directory",
                        dir.display()
                    ),
                ));
            }
            if dir.exists() {
                crate::files::check_output_dir(dir, "out")?;
                crate::files::refuse_foreign(dir, "out", &|rel, is_dir| {
                    crate::run::dir::Owned::Watch.owns(rel, is_dir)
                })?;
            }
            Ok(())
        };
        let (lock, ()) = crate::run::dir::claim(dir, "out", check)?;
        let path = dir.join(WATCH_STORE_FILE);
        // Made whole beside its place, then moved there: a directory holds a watch store
        // with its settings or none.
        sqlite::create_whole(&path, SCHEMA, |tx| {
            for (key, value) in [
                ("schema_version", WATCH_SCHEMA_VERSION.to_string()),
                ("watch", serde_json::to_string(meta).map_err(json_error(&path))?),
            ] {
                tx.execute("INSERT INTO meta (key, value) VALUES (?1, ?2)", params![key, value])
                    .map_err(sql_error(&path))?;
            }
            Ok(())
        })?;
        Self::open_locked(dir, lock)
    }

    /// Opens the watch in `dir` to go on with it.
    pub fn resume(dir: &Path) -> Result<(Self, StoredWatch)> {
        let stored = read(dir)?;
        let lock = DirLock::acquire(dir)?;
        let store = Self::open_locked(dir, lock)?;
        Ok((store, stored))
    }

    /// Forgets how the watch ended: going on again (after the resume's checks), it has not.
    pub fn clear_end(&mut self) -> Result<()> {
        self.conn
            .execute("DELETE FROM meta WHERE key = 'ended'", [])
            .map_err(sql_error(&self.path))?;
        Ok(())
    }

    /// Records how the watch ended (`ended`, JSON: [`super::Ended::page_json`]): what a page of
    /// its directory says of it (`bitrock serve`). A watch killed records nothing.
    pub fn record_end(&mut self, ended: &serde_json::Value) -> Result<()> {
        self.conn
            .execute(
                "INSERT OR REPLACE INTO meta (key, value) VALUES ('ended', ?1)",
                params![ended.to_string()],
            )
            .map_err(sql_error(&self.path))?;
        Ok(())
    }

    fn open_locked(dir: &Path, lock: DirLock) -> Result<Self> {
        let path = dir.join(WATCH_STORE_FILE);
        let conn = Connection::open_with_flags(&path, rusqlite::OpenFlags::SQLITE_OPEN_READ_WRITE)
            .map_err(sql_error(&path))?;
        conn.pragma_update(None, "synchronous", "FULL")
            .map_err(sql_error(&path))?;
        // A reader (`bitrock serve`, `read_watch`) holds the store for a moment now and then.
        conn.busy_timeout(std::time::Duration::from_secs(10))
            .map_err(sql_error(&path))?;
        conn.execute_batch(VIEW_TABLE).map_err(sql_error(&path))?;
        Ok(Self {
            conn,
            path,
            _lock: lock,
        })
    }

    /// Stores a finished window, what the watch carries after it and its picture, in one
    /// transaction.
    pub fn append(&mut self, update: &Update, carried: &Carried, view: Option<&View>) -> Result<()> {
        let path = self.path.clone();
        let err = sql_error(&path);
        let update_json = serde_json::to_string(update).map_err(json_error(&path))?;
        let state_json = serde_json::to_string(carried).map_err(json_error(&path))?;
        let tx = self.conn.transaction().map_err(&err)?;
        tx.execute(
            "INSERT INTO windows (window, start_s, end_s, update_json) VALUES (?1, ?2, ?3, ?4)",
            params![update.window as i64, update.start_s, update.end_s, update_json],
        )
        .map_err(&err)?;
        tx.execute(
            "INSERT OR REPLACE INTO carried (id, window, state_json) VALUES (1, ?1, ?2)",
            params![update.window as i64, state_json],
        )
        .map_err(&err)?;
        if let Some(view) = view {
            let view_json = serde_json::to_string(view).map_err(json_error(&path))?;
            tx.execute(
                "INSERT OR REPLACE INTO view (id, window, view_json) VALUES (1, ?1, ?2)",
                params![view.window as i64, view_json],
            )
            .map_err(&err)?;
        }
        tx.commit().map_err(&err)
    }
}

/// Reads the watch in `dir` (read-only: a running watch may be read).
pub fn read(dir: &Path) -> Result<StoredWatch> {
    let reader = Reader::open(dir)?;
    let updates = reader.updates_after(None)?;
    let carried = reader.carried()?;
    if carried.as_ref().and_then(|c| c.window) != updates.last().map(|u: &Update| u.window) {
        return Err(Error::Store {
            path: reader.path.clone(),
            message: "the carried state is not the last window's".into(),
        });
    }
    Ok(StoredWatch {
        dir: dir.to_path_buf(),
        view: reader.view()?,
        meta: reader.meta,
        updates,
        carried,
    })
}

/// A watch store opened read-only: what `bitrock serve` follows while a watch writes it.
pub struct Reader {
    conn: Connection,
    path: PathBuf,
    pub meta: WatchMeta,
}

impl Reader {
    /// Opens the store of the watch directory `dir`, refusing what is not one.
    pub fn open(dir: &Path) -> Result<Self> {
        let path = dir.join(WATCH_STORE_FILE);
        let kind = sqlite::Kind {
            file: WATCH_STORE_FILE,
            what: "watch",
            made_by: "a directory written by `bitrock watch --out` or by `bitrock.watch(..., out=...)` in Python",
            versions: WATCH_SCHEMA_VERSION..=WATCH_SCHEMA_VERSION,
        };
        let (conn, _) = sqlite::open(dir, &kind, rusqlite::OpenFlags::SQLITE_OPEN_READ_ONLY)?;
        let missing = || Error::Data {
            path: dir.to_path_buf(),
            message: format!("not a bitrock watch directory ({WATCH_STORE_FILE} does not say what it watched)"),
        };
        let text: Option<String> = conn
            .query_row("SELECT value FROM meta WHERE key = 'watch'", [], |r| r.get(0))
            .optional()
            .map_err(sql_error(&path))?;
        let meta: WatchMeta = serde_json::from_str(&text.ok_or_else(missing)?).map_err(json_error(&path))?;
        Ok(Self { conn, path, meta })
    }

    /// How the watch ended, where it recorded it ([`WatchStore::record_end`]).
    pub fn ended(&self) -> Result<Option<serde_json::Value>> {
        let text: Option<String> = self
            .conn
            .query_row("SELECT value FROM meta WHERE key = 'ended'", [], |r| r.get(0))
            .optional()
            .map_err(sql_error(&self.path))?;
        text.map(|t| serde_json::from_str(&t).map_err(json_error(&self.path)))
            .transpose()
    }

    /// Whether a watch writes the directory now (holds its lock).
    pub fn is_written(&self) -> bool {
        let dir = self.path.parent().unwrap_or(Path::new("."));
        crate::files::DirLock::is_held(dir)
    }

    /// The stored windows after window `after` (all of them with `None`), in order.
    pub fn updates_after(&self, after: Option<usize>) -> Result<Vec<Update>> {
        let err = sql_error(&self.path);
        let mut select = self
            .conn
            .prepare("SELECT update_json FROM windows WHERE window > ?1 ORDER BY window")
            .map_err(&err)?;
        let rows = select
            .query_map([after.map_or(-1, |k| k as i64)], |r| r.get::<_, String>(0))
            .map_err(&err)?;
        let mut updates = Vec::new();
        for text in rows {
            updates.push(serde_json::from_str(&text.map_err(&err)?).map_err(json_error(&self.path))?);
        }
        Ok(updates)
    }

    /// What the watch carried after its last stored window.
    pub fn carried(&self) -> Result<Option<Carried>> {
        self.single("SELECT state_json FROM carried WHERE id = 1")
    }

    /// The picture of the last stored window; `None` where the store has none.
    pub fn view(&self) -> Result<Option<View>> {
        let has_table: bool = self
            .conn
            .query_row(
                "SELECT count(*) FROM sqlite_master WHERE type = 'table' AND name = 'view'",
                [],
                |r| r.get::<_, i64>(0),
            )
            .map_err(sql_error(&self.path))?
            > 0;
        if !has_table {
            return Ok(None);
        }
        self.single("SELECT view_json FROM view WHERE id = 1")
    }

    /// The one JSON row `sql` selects, parsed; `None` where there is none.
    fn single<T: serde::de::DeserializeOwned>(&self, sql: &str) -> Result<Option<T>> {
        let text: Option<String> = self
            .conn
            .query_row(sql, [], |r| r.get(0))
            .optional()
            .map_err(sql_error(&self.path))?;
        text.map(|t| serde_json::from_str(&t))
            .transpose()
            .map_err(json_error(&self.path))
    }
}
