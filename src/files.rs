//! Files on disk, safely: every output is written whole or not at all (a temporary file beside
//! the target, synced, then renamed over it), bitrock's own temporaries are recognised by their
//! name and removed by the next writer in their directory once no process holds them, and a run
//! directory has one writer at a time (an advisory lock naming the holder's PID).
//!
//! A temporary is live while its writer holds an advisory lock on it (the OS drops the lock
//! when the writer dies, however it dies), so a stale one is one whose lock can be taken.
//!
//! Every file written whole carries a mark (an extended attribute holding the length and CRC-32
//! of what was written), so bitrock can tell later whether a file is its own, unchanged, and may
//! be replaced without asking ([`authorship`]).

use crate::error::{Error, Result};
use std::fs::{File, OpenOptions, TryLockError};
use std::io::{Read, Seek, Write};
use std::path::{Path, PathBuf};

/// Prefix of every temporary file bitrock writes (renamed to its target when complete).
pub const TEMP_PREFIX: &str = ".bitrock-tmp-";
/// Prefix of the directory a new run is staged in beside the run it replaces (`--force`).
pub const STAGING_PREFIX: &str = ".bitrock-new-";
/// The lock file of a run directory: its content is the PID of the process holding the lock.
pub const LOCK_FILE: &str = ".bitrock-lock";
/// Staging directories of bitrock versions that wrote several files at once through one.
const LEGACY_STAGING_PREFIXES: [&str; 2] = [".bitrock-summary-", ".bitrock-report-"];

/// True when `name` is one of bitrock's temporaries, lock file or staging directories.
pub fn is_bitrock_scratch(name: &str) -> bool {
    name == LOCK_FILE
        || [TEMP_PREFIX, STAGING_PREFIX]
            .iter()
            .chain(&LEGACY_STAGING_PREFIXES)
            .any(|prefix| name.starts_with(prefix))
}

/// The directory a file path lies in (`.` for a bare name).
pub fn parent_dir(path: &Path) -> &Path {
    path.parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."))
}

/// A file being written under a temporary name in its target's directory; [`Self::commit`]
/// moves it into place, dropping it removes it. Created with the process umask (mode 0666
/// before the mask), as any file the user asks for.
pub struct TempFile {
    file: tempfile::NamedTempFile,
    /// The flag that named the target, for messages.
    field: String,
}

impl TempFile {
    /// A locked temporary in the directory of `target` (which `flag` named).
    pub fn beside(target: &Path, field: &str) -> Result<Self> {
        let dir = parent_dir(target);
        let mut builder = tempfile::Builder::new();
        builder.prefix(TEMP_PREFIX);
        #[cfg(unix)]
        builder.permissions(std::os::unix::fs::PermissionsExt::from_mode(0o666));
        let file = builder
            .tempfile_in(dir)
            .map_err(|source| Error::output(field, target, source))?;
        // Held until the file is renamed or removed: a later writer's clean-up leaves it alone.
        file.as_file()
            .try_lock()
            .map_err(|e| Error::output(field, target, lock_io_error(e)))?;
        Ok(Self {
            file,
            field: field.to_string(),
        })
    }

    /// Where the temporary is.
    pub fn path(&self) -> &Path {
        self.file.path()
    }

    /// The open temporary file.
    pub fn file_mut(&mut self) -> &mut File {
        self.file.as_file_mut()
    }

    /// Syncs the temporary and renames it over `target`, then syncs the directory, so that
    /// `target` is the old file or the whole new one at every moment, a power cut included.
    pub fn commit(self, target: &Path) -> Result<()> {
        let field = self.field.clone();
        self.file
            .as_file()
            .sync_all()
            .map_err(|source| Error::output(&field, target, source))?;
        self.file
            .persist(target)
            .map_err(|e| Error::output(&field, target, e.error))?;
        sync_dir(parent_dir(target));
        Ok(())
    }
}

/// An input file opened for reading, by what it is: a regular file (its size known before a
/// byte is read) or a pipe (read up to a cap). See [`open_input`].
pub enum Input {
    Regular { file: File, size: u64 },
    Pipe(File),
}

/// Opens the input `path` without blocking on it: a named pipe no process writes to reads as
/// empty rather than waiting for one. A device (`/dev/zero`), a directory or a socket is
/// refused naming the path, before a byte is read; `what` says what the file should be
/// ("a record", "a law file").
pub fn open_input(path: &Path, what: &str) -> Result<Input> {
    let read_error = |source| Error::Read {
        path: path.to_path_buf(),
        source,
    };
    let mut options = OpenOptions::new();
    options.read(true);
    #[cfg(unix)]
    std::os::unix::fs::OpenOptionsExt::custom_flags(&mut options, libc_nonblock());
    let file = options.open(path).map_err(read_error)?;
    let meta = file.metadata().map_err(read_error)?;
    let kind = meta.file_type();
    if kind.is_file() {
        return Ok(Input::Regular { file, size: meta.len() });
    }
    #[cfg(unix)]
    if std::os::unix::fs::FileTypeExt::is_fifo(&kind) {
        // Opened without waiting for a writer; reads now wait for data as a pipe's should.
        set_blocking(&file).map_err(read_error)?;
        return Ok(Input::Pipe(file));
    }
    let kind = if kind.is_dir() {
        "a directory"
    } else {
        "a device or socket"
    };
    Err(Error::Data {
        path: path.to_path_buf(),
        message: format!("is {kind}, not {what}: give a file (or a pipe such as /dev/stdin)"),
    })
}

/// A CSV file opened for its records, with its header's names (trimmed); a file that cannot be
/// opened, or whose header cannot be read, is refused naming it (and line 1).
pub fn csv_with_header(path: &Path) -> Result<(csv::Reader<File>, Vec<String>)> {
    let file = File::open(path).map_err(|source| Error::Read {
        path: path.to_path_buf(),
        source,
    })?;
    let mut reader = csv::ReaderBuilder::new().from_reader(file);
    let header = reader
        .headers()
        .map_err(|e| Error::Format {
            path: path.to_path_buf(),
            line: Some(1),
            message: e.to_string(),
        })?
        .iter()
        .map(|h| h.trim().to_string())
        .collect();
    Ok((reader, header))
}

/// The data rows of a CSV file opened with [`csv_with_header`], each knowing its line (the
/// header is line 1) so that a refusal names the file, line and column; a row the CSV reader
/// cannot read is refused naming its line.
pub fn csv_rows<'a>(
    reader: &'a mut csv::Reader<File>,
    path: &'a Path,
    header: &'a [String],
) -> impl Iterator<Item = Result<CsvRow<'a>>> + 'a {
    reader.records().enumerate().map(move |(i, record)| {
        let line = i as u64 + 2;
        let record = record.map_err(|e| Error::Format {
            path: path.to_path_buf(),
            line: Some(line),
            message: e.to_string(),
        })?;
        Ok(CsvRow {
            path,
            header,
            line,
            record,
        })
    })
}

/// One data row of a CSV file ([`csv_rows`]).
pub struct CsvRow<'a> {
    path: &'a Path,
    header: &'a [String],
    /// Line in the file (the header is line 1).
    pub line: u64,
    record: csv::StringRecord,
}

impl CsvRow<'_> {
    /// The cell of column `col` (0-based), trimmed; empty where the row is short.
    pub fn cell(&self, col: usize) -> &str {
        self.record.get(col).unwrap_or("").trim()
    }

    /// The refusal of column `col`'s cell, naming the file, line, column and its name.
    pub fn bad_cell(&self, col: usize, message: String) -> Error {
        Error::Cell {
            path: self.path.to_path_buf(),
            line: self.line,
            column: col + 1,
            name: self.header.get(col).cloned().unwrap_or_default(),
            message,
        }
    }

    /// Column `col`'s cell as a finite number, or its refusal.
    pub fn number(&self, col: usize) -> Result<f64> {
        match self.cell(col).parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            _ => Err(self.bad_cell(col, format!("`{}` is not a finite number", self.cell(col)))),
        }
    }
}

/// Reads the text file `path` (`what` it should be, for messages) whole, refusing before it
/// is read one larger than `max_bytes` (a pipe: as soon as it has sent more), and one that is
/// not UTF-8.
pub fn read_text(path: &Path, what: &str, max_bytes: u64) -> Result<String> {
    let too_big = || Error::Data {
        path: path.to_path_buf(),
        message: format!(
            "is larger than {}, the most {what} may hold",
            crate::limits::human_bytes(max_bytes as f64)
        ),
    };
    let file = match open_input(path, what)? {
        Input::Regular { size, .. } if size > max_bytes => return Err(too_big()),
        Input::Regular { file, .. } | Input::Pipe(file) => file,
    };
    let mut bytes = Vec::new();
    file.take(max_bytes + 1)
        .read_to_end(&mut bytes)
        .map_err(|source| Error::Read {
            path: path.to_path_buf(),
            source,
        })?;
    if bytes.len() as u64 > max_bytes {
        return Err(too_big());
    }
    String::from_utf8(bytes).map_err(|e| Error::Data {
        path: path.to_path_buf(),
        message: format!("is not UTF-8 text (byte {} is not)", e.utf8_error().valid_up_to()),
    })
}

/// A settings file (TOML, at most [`crate::limits::MAX_SETTINGS_FILE_BYTES`]) read as `T`; a
/// syntax error or an unknown key is refused naming the file and its line.
pub fn read_toml<T: serde::de::DeserializeOwned>(path: &Path, what: &str) -> Result<T> {
    let text = read_text(path, what, crate::limits::MAX_SETTINGS_FILE_BYTES)?;
    toml::from_str(&text).map_err(|e| Error::Format {
        path: path.to_path_buf(),
        // Lines are 1-based: count the newlines before the offending byte.
        line: e.span().map(|s| text[..s.start].matches('\n').count() as u64 + 1),
        message: e.message().trim_end().to_string(),
    })
}

#[cfg(target_os = "linux")]
fn libc_nonblock() -> i32 {
    libc::O_NONBLOCK
}
#[cfg(all(unix, not(target_os = "linux")))]
fn libc_nonblock() -> i32 {
    0
}

/// Clears `O_NONBLOCK` on an open pipe.
#[cfg(target_os = "linux")]
fn set_blocking(file: &File) -> std::io::Result<()> {
    use std::os::fd::AsRawFd;
    let fd = file.as_raw_fd();
    // SAFETY: fcntl on a descriptor this process owns.
    let flags = unsafe { libc::fcntl(fd, libc::F_GETFL) };
    if flags < 0 || unsafe { libc::fcntl(fd, libc::F_SETFL, flags & !libc::O_NONBLOCK) } < 0 {
        return Err(std::io::Error::last_os_error());
    }
    Ok(())
}
#[cfg(all(unix, not(target_os = "linux")))]
fn set_blocking(_file: &File) -> std::io::Result<()> {
    Ok(())
}

/// Writes `target`, a file of a directory bitrock manages (a run's summary files, a staged
/// report), whole or not at all: `write` fills a temporary beside it, which replaces `target`
/// only when everything was written. Stale temporaries of bitrock's in that directory are
/// removed first.
pub fn write_own(target: &Path, field: &str, write: impl FnOnce(&mut dyn Write) -> std::io::Result<()>) -> Result<()> {
    remove_stale(parent_dir(target));
    let mut temp = TempFile::beside(target, field)?;
    let mut tally = Tally::new(temp.file_mut());
    let mut out = std::io::BufWriter::new(&mut tally);
    write(&mut out)
        .and_then(|()| out.flush())
        .map_err(|source| Error::output(field, target, source))?;
    drop(out);
    let mark = tally.mark();
    // Best effort: a file system without extended attributes leaves the file unmarked, and
    // bitrock then asks before replacing it, as it asks for any file it did not write.
    let _ = xattr::set_on(temp.file_mut(), &mark);
    temp.commit(target)
}

/// A writer that counts and checksums what passes through it: the mark of a file written whole.
struct Tally<W> {
    inner: W,
    crc: crc32fast::Hasher,
    len: u64,
}

impl<W: Write> Tally<W> {
    fn new(inner: W) -> Self {
        Self {
            inner,
            crc: crc32fast::Hasher::new(),
            len: 0,
        }
    }

    fn mark(&self) -> String {
        mark_of(self.len, self.crc.clone().finalize())
    }
}

impl<W: Write> Write for Tally<W> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let n = self.inner.write(buf)?;
        self.crc.update(&buf[..n]);
        self.len += n as u64;
        Ok(n)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.inner.flush()
    }
}

/// The mark of a file bitrock wrote: its length and the CRC-32 of its bytes.
fn mark_of(len: u64, crc: u32) -> String {
    format!("bitrock len={len} crc32={crc:08x}")
}

/// Whose an existing file is, as far as bitrock can tell ([`authorship`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Authorship {
    /// Written whole by bitrock and unchanged since: bitrock may replace it.
    Own,
    /// Marked by bitrock but changed since (edited, appended to, truncated): the user's now.
    Changed,
    /// No mark: a file bitrock did not write (or an older bitrock wrote).
    Unmarked,
    /// The file system keeps no extended attributes, so no file on it can carry a mark.
    Unknowable,
}

/// Whose the file at `path` is (a symbolic link is followed): bitrock's own only when it
/// carries the mark written with it and its bytes still match that mark.
pub fn authorship(path: &Path) -> Authorship {
    let Ok(mut file) = File::open(path) else {
        return Authorship::Unmarked;
    };
    let mark = match xattr::get_from(&file) {
        Ok(Some(mark)) => mark,
        Ok(None) => return Authorship::Unmarked,
        Err(_) => return Authorship::Unknowable,
    };
    // A changed length is a changed file: no need to read it.
    let len = file.metadata().map(|m| m.len()).unwrap_or(u64::MAX);
    if !mark.starts_with(&format!("bitrock len={len} ")) {
        return Authorship::Changed;
    }
    let mut tally = Tally::new(std::io::sink());
    if std::io::copy(&mut file, &mut tally).is_err() || tally.mark() != mark {
        return Authorship::Changed;
    }
    Authorship::Own
}

/// The extended attribute that holds a file's mark (`user.bitrock.written`).
mod xattr {
    use std::fs::File;

    /// Where the OS has no extended attributes, nothing is marked.
    #[cfg(not(target_os = "linux"))]
    pub fn set_on(_file: &mut File, _mark: &str) -> std::io::Result<()> {
        Err(std::io::Error::from(std::io::ErrorKind::Unsupported))
    }

    #[cfg(not(target_os = "linux"))]
    pub fn get_from(_file: &File) -> std::io::Result<Option<String>> {
        Err(std::io::Error::from(std::io::ErrorKind::Unsupported))
    }

    #[cfg(target_os = "linux")]
    const NAME: &std::ffi::CStr = c"user.bitrock.written";

    /// Marks the open `file`.
    #[cfg(target_os = "linux")]
    pub fn set_on(file: &mut File, mark: &str) -> std::io::Result<()> {
        use std::os::fd::AsRawFd;
        // SAFETY: a valid descriptor, a NUL-terminated name and a buffer of the length given.
        let rc = unsafe { libc::fsetxattr(file.as_raw_fd(), NAME.as_ptr(), mark.as_ptr().cast(), mark.len(), 0) };
        if rc == 0 {
            Ok(())
        } else {
            Err(std::io::Error::last_os_error())
        }
    }

    /// The mark of the open `file`: `None` when it has none, an error when its file system
    /// keeps no extended attributes.
    #[cfg(target_os = "linux")]
    pub fn get_from(file: &File) -> std::io::Result<Option<String>> {
        use std::os::fd::AsRawFd;
        let mut buf = [0u8; 128];
        // SAFETY: a valid descriptor, a NUL-terminated name and a buffer of the length given.
        let n = unsafe { libc::fgetxattr(file.as_raw_fd(), NAME.as_ptr(), buf.as_mut_ptr().cast(), buf.len()) };
        if n >= 0 {
            return Ok(Some(String::from_utf8_lossy(&buf[..n as usize]).into_owned()));
        }
        let err = std::io::Error::last_os_error();
        match err.raw_os_error() {
            // No such attribute, or one too long to be bitrock's.
            Some(libc::ENODATA | libc::ERANGE) => Ok(None),
            _ => Err(err),
        }
    }
}

/// The file an output path names: the path itself, or where a symbolic link leads (a link is
/// written through, not replaced by a file).
pub fn output_target(target: &Path) -> PathBuf {
    let is_link = std::fs::symlink_metadata(target).is_ok_and(|m| m.file_type().is_symlink());
    if is_link && let Ok(real) = target.canonicalize() {
        return real;
    }
    target.to_path_buf()
}

/// Everything under `dir` that bitrock did not write, judged by `owned` (relative path,
/// is-a-directory), in sorted order; bitrock's own temporaries and lock are never foreign.
/// Directories `owned` accepts are searched; symbolic links are judged as files, never followed.
pub fn foreign_entries(dir: &Path, owned: &dyn Fn(&Path, bool) -> bool) -> Vec<PathBuf> {
    fn walk(root: &Path, rel: &Path, owned: &dyn Fn(&Path, bool) -> bool, out: &mut Vec<PathBuf>) {
        let Ok(entries) = std::fs::read_dir(root.join(rel)) else {
            return;
        };
        let mut entries: Vec<_> = entries.flatten().collect();
        entries.sort_by_key(|e| e.file_name());
        for entry in entries {
            let name = entry.file_name();
            if name.to_str().is_some_and(is_bitrock_scratch) {
                continue;
            }
            let child = rel.join(&name);
            let is_dir = entry.file_type().is_ok_and(|t| t.is_dir());
            if !owned(&child, is_dir) {
                out.push(child);
            } else if is_dir {
                walk(root, &child, owned, out);
            }
        }
    }
    let mut out = Vec::new();
    walk(dir, Path::new(""), owned, &mut out);
    out
}

/// Refuses, naming `flag`, a directory to be replaced or written into that holds anything
/// bitrock did not write ([`foreign_entries`]), listing the first few. The one rule of every
/// command that replaces a directory: `abc --force`, `demo`, `report`, `check-selection`.
pub fn refuse_foreign(dir: &Path, field: &str, owned: &dyn Fn(&Path, bool) -> bool) -> Result<()> {
    let foreign = foreign_entries(dir, owned);
    if foreign.is_empty() {
        return Ok(());
    }
    const SHOWN: usize = 5;
    let shown: Vec<String> = foreign.iter().take(SHOWN).map(|p| p.display().to_string()).collect();
    let more = if foreign.len() > SHOWN {
        format!(" and {} more", foreign.len() - SHOWN)
    } else {
        String::new()
    };
    Err(Error::setting(
        field,
        format!(
            "{}: holds files bitrock did not write, or changed since it wrote them ({}{more}); it is not replaced, even with `force`: give another directory",
            dir.display(),
            shown.join(", ")
        ),
    ))
}

/// Replaces directory `target` (named by `flag`) by one holding exactly `contents` (relative
/// paths and bytes), in one step: the new directory is staged beside it and swapped in
/// ([`exchange_dirs`]), so `target` holds the old files or all the new ones at every moment,
/// and nothing an earlier version wrote there outlives it. A `target` holding anything
/// `owned` does not accept is refused first ([`refuse_foreign`]).
pub fn replace_dir(
    target: &Path,
    field: &str,
    owned: &dyn Fn(&Path, bool) -> bool,
    contents: &[(PathBuf, Vec<u8>)],
) -> Result<()> {
    check_output_dir(target, field)?;
    refuse_foreign(target, field, owned)?;
    let parent = parent_dir(target);
    std::fs::create_dir_all(parent).map_err(|source| Error::output(field, target, source))?;
    remove_stale(parent);
    let staging = tempfile::Builder::new()
        .prefix(STAGING_PREFIX)
        .tempdir_in(parent)
        .map_err(|source| Error::output(field, target, source))?;
    // Live while locked: a concurrent writer's clean-up leaves it alone.
    let lock = DirLock::acquire(staging.path())?;
    for (rel, bytes) in contents {
        let path = staging.path().join(rel);
        std::fs::create_dir_all(parent_dir(&path)).map_err(|source| Error::output(field, target, source))?;
        write_own(&path, field, |out| out.write_all(bytes))?;
    }
    // The lock file goes before the swap (the lock itself is held on its open file until the
    // end): the directory holds exactly `contents`.
    let _ = std::fs::remove_file(staging.path().join(LOCK_FILE));
    if target.exists() {
        exchange_dirs(target, staging.path()).map_err(|source| Error::output(field, target, source))?;
        // The staging name now holds the old directory: dropping it removes it.
    } else {
        let staged = staging.keep();
        std::fs::rename(&staged, target).map_err(|source| Error::output(field, target, source))?;
    }
    sync_dir(parent);
    drop(lock);
    Ok(())
}

/// Refuses, naming `flag`, an output directory that is a dangling symbolic link or a file.
pub fn check_output_dir(dir: &Path, field: &str) -> Result<()> {
    check_not_dangling(dir, field)?;
    if dir.exists() && !dir.is_dir() {
        return Err(Error::setting(
            field,
            format!("{} exists and is not a directory", dir.display()),
        ));
    }
    Ok(())
}

pub fn check_not_dangling(path: &Path, field: &str) -> Result<()> {
    let is_link = std::fs::symlink_metadata(path).is_ok_and(|m| m.file_type().is_symlink());
    if is_link && !path.exists() {
        let to = std::fs::read_link(path).unwrap_or_default();
        return Err(Error::setting(
            field,
            format!(
                "{} is a symbolic link to {}, which does not exist",
                path.display(),
                to.display()
            ),
        ));
    }
    Ok(())
}

/// Removes bitrock's stale temporaries and staging directories in `dir`: those no process
/// holds (a writer killed before its rename). Best effort: what cannot be removed stays.
pub fn remove_stale(dir: &Path) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        let name = entry.file_name();
        let Some(name) = name.to_str() else { continue };
        let path = entry.path();
        if name.starts_with(TEMP_PREFIX) {
            if File::open(&path).is_ok_and(|f| f.try_lock().is_ok()) {
                let _ = std::fs::remove_file(&path);
            }
        } else if name.starts_with(STAGING_PREFIX) {
            // A staging directory is live while its writer holds its lock file.
            if DirLock::is_free(&path) {
                let _ = std::fs::remove_dir_all(&path);
            }
        } else if LEGACY_STAGING_PREFIXES.iter().any(|p| name.starts_with(p)) {
            let _ = std::fs::remove_dir_all(&path);
        }
    }
}

/// Syncs a directory's entries (a rename into it) to disk; best effort (not every file
/// system can sync a directory).
pub fn sync_dir(dir: &Path) {
    if let Ok(d) = File::open(dir) {
        let _ = d.sync_all();
    }
}

/// The one-writer lock of a run directory, held until dropped: an advisory lock on
/// `DIR/.bitrock-lock`, which holds the PID of the process that has it.
#[derive(Debug)]
pub struct DirLock {
    file: File,
    dir: PathBuf,
}

impl DirLock {
    /// Whether a process holds the lock of `dir` now (read without taking it from anyone: a
    /// shared lock taken and let go at once).
    pub fn is_held(dir: &Path) -> bool {
        let Ok(file) = File::open(dir.join(LOCK_FILE)) else {
            return false;
        };
        match file.try_lock_shared() {
            Ok(()) => {
                let _ = file.unlock();
                false
            }
            Err(_) => true,
        }
    }

    /// Takes the lock of `dir` (which must exist), or refuses naming the process holding it.
    pub fn acquire(dir: &Path) -> Result<Self> {
        let path = dir.join(LOCK_FILE);
        let mut file = OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(&path)
            .map_err(|source| Error::Write {
                path: path.clone(),
                source,
            })?;
        match file.try_lock() {
            Ok(()) => {}
            Err(TryLockError::WouldBlock) => {
                return Err(Error::Busy {
                    path: dir.to_path_buf(),
                    holder: holder_named_in(&mut file),
                });
            }
            Err(TryLockError::Error(source)) => return Err(Error::Write { path, source }),
        }
        let write_pid = |f: &mut File| -> std::io::Result<()> {
            f.set_len(0)?;
            f.rewind()?;
            write!(f, "{}", std::process::id())?;
            f.flush()
        };
        write_pid(&mut file).map_err(|source| Error::Write { path, source })?;
        Ok(Self {
            file,
            dir: dir.to_path_buf(),
        })
    }

    /// True when no process holds the lock of `dir` (or `dir` has no lock file).
    pub fn is_free(dir: &Path) -> bool {
        match File::open(dir.join(LOCK_FILE)) {
            Ok(f) => f.try_lock().is_ok(),
            Err(_) => true,
        }
    }

    /// Who holds the lock of `dir` now: `Some("another process (PID n)")` while another
    /// process does, `None` when none does, this process does, or `dir` has no lock file.
    pub fn holder(dir: &Path) -> Option<String> {
        let mut file = File::open(dir.join(LOCK_FILE)).ok()?;
        if file.try_lock_shared().is_ok() {
            return None;
        }
        let holder = holder_named_in(&mut file);
        // This process holds it (a check reading the run it locked): no other writer.
        (holder != holder_of_pid(&std::process::id().to_string())).then_some(holder)
    }

    /// The directory locked (where it was when locked).
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The lock file, kept open while the lock is held.
    pub fn file(&self) -> &File {
        &self.file
    }
}

/// The process a lock file names: "another process (PID n)", or "another process" when the
/// file holds no PID.
fn holder_named_in(file: &mut File) -> String {
    let mut pid = String::new();
    let _ = file.read_to_string(&mut pid);
    holder_of_pid(pid.trim())
}

fn holder_of_pid(pid: &str) -> String {
    if pid.is_empty() {
        "another process".to_string()
    } else {
        format!("another process (PID {pid})")
    }
}

fn lock_io_error(e: TryLockError) -> std::io::Error {
    match e {
        TryLockError::Error(e) => e,
        TryLockError::WouldBlock => std::io::Error::other("a fresh temporary is locked by another process"),
    }
}

/// Swaps two directories in one step where the OS can (Linux's `RENAME_EXCHANGE`): afterwards
/// `a` holds what `b` held and `b` what `a` held, and no moment exists where either name is
/// missing. Elsewhere, two renames through a third name beside them.
pub fn exchange_dirs(a: &Path, b: &Path) -> std::io::Result<()> {
    #[cfg(target_os = "linux")]
    {
        use std::ffi::CString;
        use std::os::unix::ffi::OsStrExt;
        let ca = CString::new(a.as_os_str().as_bytes())?;
        let cb = CString::new(b.as_os_str().as_bytes())?;
        // SAFETY: two valid NUL-terminated paths, relative to the working directory.
        let rc = unsafe {
            libc::renameat2(
                libc::AT_FDCWD,
                ca.as_ptr(),
                libc::AT_FDCWD,
                cb.as_ptr(),
                libc::RENAME_EXCHANGE,
            )
        };
        if rc == 0 {
            return Ok(());
        }
        let err = std::io::Error::last_os_error();
        // File systems without RENAME_EXCHANGE fall through to the two renames.
        if !matches!(err.raw_os_error(), Some(libc::EINVAL | libc::ENOSYS)) {
            return Err(err);
        }
    }
    // Not a staging name: a kill between the renames leaves the old run here, kept.
    let aside = parent_dir(a).join(format!(".bitrock-old-{}", std::process::id()));
    std::fs::rename(a, &aside)?;
    std::fs::rename(b, a)?;
    std::fs::rename(&aside, b)
}

/// A file the user wrote (a law file, a well file): its text, and its path to name in refusals.
pub(crate) struct UserFile<'a> {
    pub source: &'a str,
    pub path: &'a Path,
}

impl UserFile<'_> {
    /// A refusal at byte `offset` of the file, by its line and column.
    pub fn at(&self, offset: usize, message: String) -> Error {
        let (line, column) = line_column(self.source, offset);
        Error::Syntax {
            path: self.path.to_path_buf(),
            line,
            column,
            message,
        }
    }

    /// The file's TOML read as `T`: a syntax error, an unknown key or a value of the wrong type
    /// refused where it stands.
    pub fn toml<T: serde::de::DeserializeOwned>(&self) -> Result<T> {
        toml::from_str(self.source).map_err(|e| {
            let offset = e.span().map_or(0, |s| s.start);
            self.at(offset, e.message().trim().to_string())
        })
    }
}

/// Line and column (1-based, in characters) of byte `offset` of `text`: where a refusal of a
/// file the user wrote (a law file, a well file) points.
fn line_column(text: &str, offset: usize) -> (u64, usize) {
    let before = &text[..offset.min(text.len())];
    let line = before.matches('\n').count() as u64 + 1;
    let column = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    (line, column)
}
