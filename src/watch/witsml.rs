//! A watch's WITSML source: one time log file, or a folder a server or a sync tool writes a
//! growing log into as chunk files (`*.xml`, read in the order of their names, each a whole
//! WITSML 1.4.1 or 2.0 log). Each chunk's rows are given as the CSV lines of one record (its
//! header from the first chunk: `MNEMONIC [unit]`), so that the watch reads them by the rules
//! of any record. Followed, the folder is looked at again for new chunks; a chunk that does not
//! parse yet is taken for one still being written while it is the newest, and waited for.

use crate::data::witsml::{self, Log};
use crate::error::{Error, Result};
use std::collections::BTreeSet;
use std::io::{ErrorKind, Read};
use std::path::{Path, PathBuf};
use std::time::Duration;

/// Whether `path` is a folder (of log chunks) or a file whose text begins as XML.
pub fn is_witsml(path: &Path) -> bool {
    if path.is_dir() {
        return true;
    }
    let mut start = [0u8; 256];
    let read = std::fs::File::open(path)
        .and_then(|mut f| f.read(&mut start))
        .unwrap_or(0);
    read > 0 && witsml::is_xml(&start[..read])
}

/// The rows of a WITSML log file or folder of chunks, read as CSV text.
pub struct Chunks {
    path: PathBuf,
    follow: bool,
    poll: Duration,
    /// Chunks given so far.
    done: BTreeSet<PathBuf>,
    /// The first chunk's channels: the record's header.
    headers: Option<csv::StringRecord>,
    time_column: Option<String>,
    /// CSV text not yet read, and how far it has been.
    text: Vec<u8>,
    at: usize,
}

impl Chunks {
    /// The chunks of `path` (a log file or a folder), followed for new chunks with `follow`
    /// (a folder only), looked at every `poll`.
    pub fn new(path: &Path, follow: bool, poll: Duration) -> Result<Self> {
        if follow && !path.is_dir() {
            return Err(Error::setting(
                "follow",
                format!(
                    "{} is one WITSML log, read whole; to follow a growing log, give the folder its chunks are written to",
                    path.display()
                ),
            ));
        }
        Ok(Self {
            path: path.to_path_buf(),
            follow,
            poll,
            done: BTreeSet::new(),
            headers: None,
            time_column: None,
            text: Vec::new(),
            at: 0,
        })
    }

    /// Waits for the first chunk (a followed folder may be empty yet), asking `stop` while it
    /// waits; refuses a folder that holds none when not followed.
    pub fn first(&mut self, stop: &dyn Fn() -> bool) -> Result<()> {
        loop {
            if self.next_chunk()? {
                return Ok(());
            }
            if !self.follow {
                return Err(Error::Data {
                    path: self.path.clone(),
                    message: "holds no WITSML log (*.xml)".into(),
                });
            }
            if stop() {
                return Err(Error::Interrupted);
            }
            std::thread::sleep(self.poll);
        }
    }

    /// The log's index channel as the record's time column, where it is a time.
    pub fn time_column(&self) -> Option<String> {
        self.time_column.clone()
    }

    /// The chunk files not yet read, in name order.
    fn pending(&self) -> Result<Vec<PathBuf>> {
        if !self.path.is_dir() {
            return Ok([self.path.clone()]
                .into_iter()
                .filter(|p| !self.done.contains(p))
                .collect());
        }
        let entries = std::fs::read_dir(&self.path).map_err(|source| Error::Read {
            path: self.path.clone(),
            source,
        })?;
        let mut files: Vec<PathBuf> = entries
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|x| x.eq_ignore_ascii_case("xml")) && p.is_file())
            .filter(|p| !self.done.contains(p))
            .collect();
        files.sort();
        Ok(files)
    }

    /// Reads the next chunk into the CSV text; `false` when there is none (yet).
    fn next_chunk(&mut self) -> Result<bool> {
        let pending = self.pending()?;
        let Some(file) = pending.first() else {
            return Ok(false);
        };
        let text = std::fs::read_to_string(file).map_err(|source| Error::Read {
            path: file.clone(),
            source,
        })?;
        let log = match witsml::read(&text, file) {
            Ok(log) => log,
            // The newest chunk of a followed folder may still be being written.
            Err(_) if self.follow && pending.len() == 1 => return Ok(false),
            Err(e) => return Err(e),
        };
        self.done.insert(file.clone());
        self.append(log, file)?;
        Ok(true)
    }

    /// A chunk's rows as CSV lines, in the first chunk's column order (and its header first).
    fn append(&mut self, log: Log, file: &Path) -> Result<()> {
        let order: Vec<usize> = match &self.headers {
            None => {
                self.time_column = log.time_index.map(|i| log.headers[i].to_string());
                self.headers = Some(log.headers.clone());
                let mut header = csv::Writer::from_writer(Vec::new());
                header.write_record(&log.headers).map_err(|e| self.csv_error(e))?;
                self.push(header)?;
                (0..log.headers.len()).collect()
            }
            Some(headers) => {
                let order: Option<Vec<usize>> = headers
                    .iter()
                    .map(|h| log.headers.iter().position(|g| g.eq_ignore_ascii_case(h)))
                    .collect();
                order.ok_or_else(|| Error::Data {
                    path: file.to_path_buf(),
                    message: format!(
                        "its channels ({}) are not the first chunk's ({}): one record has one set of channels",
                        log.headers.iter().collect::<Vec<_>>().join(", "),
                        headers.iter().collect::<Vec<_>>().join(", ")
                    ),
                })?
            }
        };
        let mut rows = csv::Writer::from_writer(Vec::new());
        for (record, _) in &log.rows {
            // A null stays empty, and the watch skips and counts its row where it reads it.
            let cells = order.iter().map(|&i| {
                let cell = record.get(i).unwrap_or("");
                if witsml::is_null(cell, &log.nulls[i]) { "" } else { cell }
            });
            rows.write_record(cells).map_err(|e| self.csv_error(e))?;
        }
        self.push(rows)
    }

    fn push(&mut self, writer: csv::Writer<Vec<u8>>) -> Result<()> {
        let bytes = writer.into_inner().map_err(|e| Error::Data {
            path: self.path.clone(),
            message: format!("a chunk's rows could not be written as text: {e}"),
        })?;
        self.text.drain(..self.at);
        self.at = 0;
        self.text.extend_from_slice(&bytes);
        Ok(())
    }

    fn csv_error(&self, e: csv::Error) -> Error {
        Error::Data {
            path: self.path.clone(),
            message: format!("a chunk's rows could not be written as text: {e}"),
        }
    }
}

impl Read for Chunks {
    /// The CSV text of the chunks read so far; at its end, the next chunk's; with none, the
    /// end (`Ok(0)`), or for a followed folder a wait of one poll (`WouldBlock`).
    fn read(&mut self, out: &mut [u8]) -> std::io::Result<usize> {
        if self.at == self.text.len() {
            let more = self
                .next_chunk()
                .map_err(|e| std::io::Error::new(ErrorKind::InvalidData, e.to_string()))?;
            if !more {
                if self.follow {
                    std::thread::sleep(self.poll);
                    return Err(std::io::Error::new(ErrorKind::WouldBlock, "no new chunk yet"));
                }
                return Ok(0);
            }
        }
        let n = out.len().min(self.text.len() - self.at);
        out[..n].copy_from_slice(&self.text[self.at..self.at + n]);
        self.at += n;
        Ok(n)
    }
}
