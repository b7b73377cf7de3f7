//! The SQLite stores of every kind of run (`run.sqlite`, `watch.sqlite`): made whole or not at
//! all, opened behind one schema gate that names the directory and what it is not, and their
//! errors named by file.

use crate::error::{Error, Result};
use crate::files;
use rusqlite::{Connection, OpenFlags, OptionalExtension};
use std::ops::RangeInclusive;
use std::path::Path;

/// A SQLite error of the store at `path`.
pub(crate) fn sql_error(path: &Path) -> impl Fn(rusqlite::Error) -> Error + '_ {
    move |e| Error::Store {
        path: path.to_path_buf(),
        message: e.to_string(),
    }
}

/// A JSON document of the store at `path` that cannot be read.
pub(crate) fn json_error(path: &Path) -> impl Fn(serde_json::Error) -> Error + '_ {
    move |e| Error::Store {
        path: path.to_path_buf(),
        message: format!("malformed JSON in the store: {e}"),
    }
}

/// Makes the store `path` (which must not exist) whole or not at all: `schema` and what `fill`
/// writes go in one transaction into a temporary beside it (no journal: a failed temporary is
/// discarded), renamed to `path` once complete. A kill at any moment leaves no store or a
/// complete one; the temporary is removed by the next writer ([`files::remove_stale`]).
pub(crate) fn create_whole(
    path: &Path,
    schema: &str,
    fill: impl FnOnce(&rusqlite::Transaction) -> Result<()>,
) -> Result<()> {
    let temp = files::TempFile::beside(path, "out")?;
    let err = sql_error(path);
    let mut conn = Connection::open(temp.path()).map_err(&err)?;
    conn.pragma_update(None, "journal_mode", "OFF").map_err(&err)?;
    let tx = conn.transaction().map_err(&err)?;
    tx.execute_batch(schema).map_err(&err)?;
    fill(&tx)?;
    tx.commit().map_err(&err)?;
    conn.close().map_err(|(_, e)| err(e))?;
    temp.commit(path)
}

/// What a store is, for the gate's refusals.
pub(crate) struct Kind<'a> {
    /// The store's file name in its directory (`run.sqlite`).
    pub file: &'a str,
    /// What its directory is called in words (`run`, `watch`).
    pub what: &'a str,
    /// Where such a directory comes from, in words (the command and the Python call).
    pub made_by: &'a str,
    /// The schema versions this bitrock reads.
    pub versions: RangeInclusive<i64>,
}

/// Opens the store of `kind` in directory `dir` behind the schema gate: a directory that is
/// missing, has no such store, has a file that is not one, or has a store of a schema this
/// bitrock does not read is refused with a message naming the directory. Gives the connection
/// and the store's schema version. A reader waits a moment for a writer that holds the store.
pub(crate) fn open(dir: &Path, kind: &Kind, flags: OpenFlags) -> Result<(Connection, i64)> {
    let path = dir.join(kind.file);
    let file = kind.file;
    let refuse = |why: String| Error::Data {
        path: dir.to_path_buf(),
        message: format!("not a bitrock {} directory ({why}); give {}", kind.what, kind.made_by),
    };
    if !dir.is_dir() {
        let why = if dir.exists() {
            "a file, not a directory"
        } else {
            "no such directory"
        };
        return Err(refuse(why.into()));
    }
    if !path.is_file() {
        return Err(refuse(format!("it has no {file}")));
    }
    let conn = Connection::open_with_flags(&path, flags).map_err(|e| refuse(format!("{file}: {e}")))?;
    conn.busy_timeout(std::time::Duration::from_secs(10))
        .map_err(sql_error(&path))?;
    let version: Option<String> = conn
        .query_row("SELECT value FROM meta WHERE key = 'schema_version'", [], |r| r.get(0))
        .optional()
        .map_err(|e| refuse(format!("{file} is not a bitrock {} store: {e}", kind.what)))?;
    let (low, high) = (*kind.versions.start(), *kind.versions.end());
    let readable = if low == high {
        format!("version {high}")
    } else {
        format!("versions {low} to {high}")
    };
    match version.as_deref().map(str::parse::<i64>) {
        Some(Ok(v)) if kind.versions.contains(&v) => Ok((conn, v)),
        Some(Ok(v)) => Err(refuse(format!(
            "{file} has schema version {v}; this bitrock reads {readable}"
        ))),
        _ => Err(refuse(format!("{file} has no schema version"))),
    }
}
