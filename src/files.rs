//! Files on disk, safely: every output is written whole or not at all (a temporary file beside
//! the target, synced, then renamed over it), bitrock's own temporaries are recognised by their
//! name and removed by the next writer in their directory once no process holds them, and a run
//! directory has one writer at a time (an advisory lock naming the holder's PID).
//!
//! A temporary is live while its writer holds an advisory lock on it (the OS drops the lock
//! when the writer dies, however it dies), so a stale one is one whose lock can be taken.

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
    flag: String,
}

impl TempFile {
    /// A locked temporary in the directory of `target` (which `flag` named).
    pub fn beside(target: &Path, flag: &str) -> Result<Self> {
        let dir = parent_dir(target);
        let mut builder = tempfile::Builder::new();
        builder.prefix(TEMP_PREFIX);
        #[cfg(unix)]
        builder.permissions(std::os::unix::fs::PermissionsExt::from_mode(0o666));
        let file = builder
            .tempfile_in(dir)
            .map_err(|source| Error::output(flag, target, source))?;
        // Held until the file is renamed or removed: a later writer's clean-up leaves it alone.
        file.as_file()
            .try_lock()
            .map_err(|e| Error::output(flag, target, lock_io_error(e)))?;
        Ok(Self {
            file,
            flag: flag.to_string(),
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
        let flag = self.flag.clone();
        self.file
            .as_file()
            .sync_all()
            .map_err(|source| Error::output(&flag, target, source))?;
        self.file
            .persist(target)
            .map_err(|e| Error::output(&flag, target, e.error))?;
        sync_dir(parent_dir(target));
        Ok(())
    }
}

/// Writes `target` (named by `flag`) whole or not at all: `write` fills a temporary beside it,
/// which replaces `target` only when everything was written. Stale temporaries of bitrock's in
/// that directory are removed first. A run's store is never a target.
pub fn write_whole(target: &Path, flag: &str, write: impl FnOnce(&mut dyn Write) -> std::io::Result<()>) -> Result<()> {
    check_output_file(target, flag)?;
    remove_stale(parent_dir(target));
    let mut temp = TempFile::beside(target, flag)?;
    let mut out = std::io::BufWriter::new(temp.file_mut());
    write(&mut out)
        .and_then(|()| out.flush())
        .map_err(|source| Error::output(flag, target, source))?;
    drop(out);
    temp.commit(target)
}

/// Refuses, naming `flag`, an output file that cannot be written: a directory, a dangling
/// symbolic link, a path in a directory that does not exist, or a run's store.
pub fn check_output_file(target: &Path, flag: &str) -> Result<()> {
    check_not_dangling(target, flag)?;
    if target.is_dir() {
        return Err(Error::arg(
            flag,
            format!("{} is a directory; give a file name", target.display()),
        ));
    }
    let dir = parent_dir(target);
    if !dir.is_dir() {
        return Err(Error::arg(
            flag,
            format!("{}: the directory {} does not exist", target.display(), dir.display()),
        ));
    }
    if is_run_store(target) {
        return Err(Error::arg(
            flag,
            format!(
                "{} is a run's store ({}); it is never overwritten: give another file",
                target.display(),
                crate::store::STORE_FILE
            ),
        ));
    }
    Ok(())
}

/// Refuses, naming `flag`, an output directory that is a dangling symbolic link or a file.
pub fn check_output_dir(dir: &Path, flag: &str) -> Result<()> {
    check_not_dangling(dir, flag)?;
    if dir.exists() && !dir.is_dir() {
        return Err(Error::arg(
            flag,
            format!("{} exists and is not a directory", dir.display()),
        ));
    }
    Ok(())
}

fn check_not_dangling(path: &Path, flag: &str) -> Result<()> {
    let is_link = std::fs::symlink_metadata(path).is_ok_and(|m| m.file_type().is_symlink());
    if is_link && !path.exists() {
        let to = std::fs::read_link(path).unwrap_or_default();
        return Err(Error::arg(
            flag,
            format!(
                "{} is a symbolic link to {}, which does not exist",
                path.display(),
                to.display()
            ),
        ));
    }
    Ok(())
}

/// True when `path` is an existing run store: named like one and holding an SQLite database.
fn is_run_store(path: &Path) -> bool {
    let Ok(real) = path.canonicalize() else {
        return false;
    };
    let mut magic = [0u8; 16];
    real.file_name().is_some_and(|n| n == crate::store::STORE_FILE)
        && File::open(&real)
            .and_then(|mut f| f.read_exact(&mut magic))
            .is_ok_and(|()| &magic == b"SQLite format 3\0")
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
                let mut pid = String::new();
                let _ = file.read_to_string(&mut pid);
                let holder = match pid.trim() {
                    "" => "another process".to_string(),
                    pid => format!("another process (PID {pid})"),
                };
                return Err(Error::Busy {
                    path: dir.to_path_buf(),
                    holder,
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

    /// The directory locked (where it was when locked).
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The lock file, kept open while the lock is held.
    pub fn file(&self) -> &File {
        &self.file
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
