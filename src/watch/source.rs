//! Where a watch reads its record: a CSV file (whole, or followed as it grows), a WITSML log
//! or a folder of its chunks (whole, or followed for new chunks: [`super::witsml`]), standard
//! input, a file replayed against its own time column, or a TCP feed (reconnected with
//! back-off when it drops). Each carries CSV lines (a header first) or WITS level-0 blocks
//! ([`super::wits`]), told apart by the first line. Rows come one at a time; a line that
//! cannot be read is skipped and counted, never fatal.

use super::wits::{WitsItems, WitsReader};
use crate::data::surface::{SurfaceOptions, SurfaceRowLayout};
use crate::data::{DataOptions, Row, RowLayout};
use crate::error::{Error, Result};
use crate::units::SpeedUnit;
use std::io::{BufRead, BufReader, ErrorKind, Read};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// How often a followed file is looked at again once its end is reached, and how long a
/// read of a TCP feed waits before the watch may stop.
const FOLLOW_POLL: Duration = Duration::from_millis(200);

/// Longest line a source may send, bytes: a rig export's row of hundreds of channels fits many
/// times over; a stream without newlines (`/dev/zero`, a feed that never ends its line) is
/// refused at it instead of being held whole.
pub const MAX_LINE_BYTES: usize = 1 << 20;

/// `read_line` into `text` (which may hold the start of the line already), refusing a line
/// longer than [`MAX_LINE_BYTES`] as invalid data.
fn read_line_bounded(reader: &mut (dyn BufRead + Send), text: &mut String) -> std::io::Result<usize> {
    let room = (MAX_LINE_BYTES + 1).saturating_sub(text.len()) as u64;
    let read = reader.take(room).read_line(text)?;
    if text.len() > MAX_LINE_BYTES && !text.ends_with('\n') {
        return Err(std::io::Error::new(
            ErrorKind::InvalidData,
            format!(
                "a line of more than {} without a newline: not a line of a record",
                crate::limits::human_bytes(MAX_LINE_BYTES as f64)
            ),
        ));
    }
    Ok(read)
}
/// A followed file or feed that gives no row for this long is said to have stalled (once,
/// until rows come again).
pub const STALL_AFTER: Duration = Duration::from_secs(30);
/// The longest wait between two tries to reconnect a TCP feed (the wait doubles from 1 s).
pub const MAX_BACKOFF: Duration = Duration::from_secs(30);

/// A record's source.
#[derive(Clone, Debug, PartialEq)]
pub enum Source {
    /// A CSV file; with `follow`, read as it grows (like `tail -f`) until the watch is stopped.
    File { path: PathBuf, follow: bool },
    /// Standard input, until it closes.
    Stdin,
    /// A CSV file given at `speed` times its own pace (its time column), as a rig would send
    /// it: 1 is real time.
    Replay { path: PathBuf, speed: f64 },
    /// A TCP feed at `address` (HOST:PORT), read until the watch is stopped; a connection
    /// lost is tried again with back-off.
    Tcp { address: String },
}

impl Source {
    /// The source a command line names: `-` standard input, `tcp://HOST:PORT` a feed, else a
    /// file (followed or replayed as asked).
    pub fn named(name: &Path, follow: bool, replay_speed: Option<f64>) -> Result<Self> {
        let text = name.to_string_lossy();
        if let Some(address) = text.strip_prefix("tcp://") {
            if follow || replay_speed.is_some() {
                return Err(Error::setting(
                    if follow { "follow" } else { "replay_speed" },
                    "applies to a file, not to a TCP feed (which is followed until stopped)",
                ));
            }
            return Ok(Source::Tcp {
                address: address.trim_end_matches('/').to_string(),
            });
        }
        Ok(match (text == "-", replay_speed) {
            (true, _) => Source::Stdin,
            (false, Some(speed)) => Source::Replay {
                path: name.to_path_buf(),
                speed,
            },
            (false, None) => Source::File {
                path: name.to_path_buf(),
                follow,
            },
        })
    }

    /// The name it is known by in messages.
    pub fn name(&self) -> PathBuf {
        match self {
            Source::File { path, .. } | Source::Replay { path, .. } => path.clone(),
            Source::Stdin => PathBuf::from("<stdin>"),
            Source::Tcp { address } => PathBuf::from(format!("tcp://{address}")),
        }
    }
}

/// What a [`Rows`] gives next.
#[derive(Debug)]
pub enum Next {
    /// A row, and when its line arrived.
    Row(Row, Instant),
    /// A followed file or feed has given no row for this long (said once per silence).
    Stalled(Duration),
    /// A line skipped: where and why (counted by the reader too).
    Skipped(String),
    /// What the user should know of the source (a feed lost, reconnected).
    Said(String),
    /// A followed file or feed has no new row yet (given after each look, so that a watch can
    /// be stopped while it waits).
    Waiting,
    /// The source ended (a file read whole, standard input closed).
    End,
}

/// How the lines of a source are read.
enum Format {
    /// CSV: the columns of its header, an optional top-drive column, the parser of its lines,
    /// and the header's text (a feed sends it again on each connection).
    Csv {
        layout: RowLayout,
        top_drive: Option<(usize, SpeedUnit)>,
        lines: Box<LineParser>,
        header: String,
    },
    /// CSV of surface channels alone (top-drive speed, surface torque, weight on bit): rows
    /// without the bit's, each window inferred through simulated strings.
    SurfaceCsv {
        layout: SurfaceRowLayout,
        lines: Box<LineParser>,
        header: String,
    },
    /// WITS level-0 blocks.
    Wits(WitsReader),
}

/// A TCP feed's connection state.
struct Feed {
    address: String,
    /// Down since, and when to try again, with the current back-off.
    down: Option<(Instant, Instant, Duration)>,
}

/// The rows of a source, one at a time.
pub struct Rows {
    reader: Box<dyn BufRead + Send>,
    format: Format,
    name: PathBuf,
    follow: bool,
    feed: Option<Feed>,
    /// Replay speed and the clock it keeps: (speed, started, first row's time).
    replay: Option<(f64, Option<(Instant, f64)>)>,
    line: u64,
    /// A line read up to the source's current end without its newline (a writer mid-line).
    partial: String,
    /// Lines skipped so far.
    pub skipped: u64,
    /// How long a followed file or feed may be silent before [`Next::Stalled`] says so.
    pub stall_after: Duration,
    /// When the last row came, and whether its silence since has been said.
    last_row: Instant,
    stall_said: bool,
    /// Rows before this time are given unpaced ([`Rows::replay_from`]).
    pace_from_s: f64,
    /// Bytes read so far, and the size of a file read to its end (not followed).
    bytes_read: u64,
    size: Option<u64>,
}

impl Rows {
    /// Opens `source` and reads its first line: a CSV header (the columns and units, by the
    /// rules of `fit`) or a WITS block's start (the items of `wits`, in the units of `opts`).
    /// A feed may take its time to send it: `stop` is asked while it waits, and ends the wait
    /// with [`Error::Interrupted`].
    pub fn open(source: &Source, opts: &DataOptions, wits: &WitsItems, stop: &dyn Fn() -> bool) -> Result<Self> {
        let name = source.name();
        let mut opts = opts.clone();
        // A WITSML log or folder of chunks read as the CSV text of its channels, its index the
        // clock unless one is named.
        let mut file = |path: &Path, follow: bool| -> Result<Box<dyn BufRead + Send>> {
            if !super::witsml::is_witsml(path) {
                return Ok(Box::new(BufReader::new(open(path)?)));
            }
            let mut chunks = super::witsml::Chunks::new(path, follow, FOLLOW_POLL)?;
            chunks.first(stop)?;
            if opts.time_column.is_none() {
                opts.time_column = chunks.time_column();
            }
            Ok(Box::new(BufReader::new(chunks)))
        };
        let (reader, follow, replay, feed): (Box<dyn BufRead + Send>, bool, _, _) = match source {
            Source::File { path, follow } => (file(path, *follow)?, *follow, None, None),
            Source::Stdin => (Box::new(BufReader::new(std::io::stdin())), false, None, None),
            Source::Replay { path, speed } => {
                if !(speed.is_finite() && *speed > 0.0) {
                    return Err(Error::setting(
                        "replay_speed",
                        format!("must be a positive number, got {speed}"),
                    ));
                }
                // Bounded before any work: a second of record replayed in at most a day.
                if 1.0 / speed > crate::limits::MAX_WORK_SECONDS {
                    return Err(Error::setting(
                        "replay_speed",
                        format!(
                            "{} replays each second of record in {}: more than a day",
                            crate::limits::readable(*speed),
                            crate::limits::human_seconds(1.0 / speed)
                        ),
                    ));
                }
                (file(path, false)?, false, Some((*speed, None)), None)
            }
            Source::Tcp { address } => {
                let stream = connect(address).map_err(|source| Error::Read {
                    path: name.clone(),
                    source,
                })?;
                let feed = Feed {
                    address: address.clone(),
                    down: None,
                };
                (Box::new(BufReader::new(stream)), false, None, Some(feed))
            }
        };
        let size = match source {
            Source::File { path, follow: false } | Source::Replay { path, .. } => {
                std::fs::metadata(path).ok().filter(|m| m.is_file()).map(|m| m.len())
            }
            _ => None,
        };
        let rows = Self::from_reader(reader, name, &opts, wits, stop)?;
        Ok(Self {
            follow,
            replay,
            feed,
            size,
            ..rows
        })
    }

    /// The rows of `reader` read to its end (not followed, replayed or a feed), its first line
    /// read.
    fn from_reader(
        mut reader: Box<dyn BufRead + Send>,
        name: PathBuf,
        opts: &DataOptions,
        wits: &WitsItems,
        stop: &dyn Fn() -> bool,
    ) -> Result<Self> {
        let mut first = String::new();
        let mut line = 0;
        let mut bytes_read = 0;
        // Comment lines (`#`) before the header, as a whole file allows.
        loop {
            first.clear();
            let read = loop {
                match read_line_bounded(reader.as_mut(), &mut first) {
                    Ok(n) => break n,
                    // A feed's first line may take its time; the watch may stop meanwhile.
                    Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {
                        if stop() {
                            return Err(Error::Interrupted);
                        }
                        continue;
                    }
                    Err(e) if e.kind() == ErrorKind::InvalidData => {
                        return Err(Error::Format {
                            path: name,
                            line: Some(line + 1),
                            message: e.to_string(),
                        });
                    }
                    Err(source) => {
                        return Err(Error::Read {
                            path: name.clone(),
                            source,
                        });
                    }
                }
            };
            line += 1;
            bytes_read += read as u64;
            if read == 0 {
                return Err(Error::Format {
                    path: name,
                    line: Some(line),
                    message: "empty record: expected a header line (or a WITS block's &&)".into(),
                });
            }
            if !first.trim_start().starts_with('#') && !first.trim().is_empty() {
                break;
            }
        }
        let format = if first.trim() == "&&" {
            let mut reader = WitsReader::new(wits.clone(), opts)?;
            reader.line(&first);
            Format::Wits(reader)
        } else {
            let delimiter = crate::data::detect_delimiter(first.as_bytes(), &name)?;
            let header = first.trim_end().to_string();
            let mut lines = Box::new(LineParser::new(delimiter));
            let headers = lines.parse(&header).ok_or_else(|| Error::Format {
                path: name.clone(),
                line: Some(line),
                message: "the header line cannot be read as CSV".into(),
            })?;
            match RowLayout::new(&headers, delimiter, opts, &name) {
                Ok(layout) => Format::Csv {
                    layout,
                    top_drive: top_drive_column(&headers, &name, line)?,
                    lines,
                    header,
                },
                // A record of surface channels alone: its rows carry them, never as the bit's.
                Err(bit) => match surface_layout(&headers, delimiter, opts, &name) {
                    Some(layout) => Format::SurfaceCsv {
                        layout: layout?,
                        lines,
                        header,
                    },
                    None => return Err(bit),
                },
            }
        };
        Ok(Self {
            reader,
            format,
            name,
            follow: false,
            feed: None,
            replay: None,
            line,
            partial: String::new(),
            skipped: 0,
            stall_after: STALL_AFTER,
            last_row: Instant::now(),
            stall_said: false,
            pace_from_s: f64::NEG_INFINITY,
            bytes_read,
            size: None,
        })
    }

    /// The share of a file read to its end (not followed) read so far; `None` for other
    /// sources, whose end is not known.
    pub fn share_read(&self) -> Option<f64> {
        self.size
            .filter(|&size| size > 0)
            .map(|size| (self.bytes_read as f64 / size as f64).min(1.0))
    }

    /// The source's name in messages.
    pub fn name(&self) -> &Path {
        &self.name
    }

    /// The WITS items read, where the source sends WITS blocks.
    pub fn wits_items(&self) -> Option<&WitsItems> {
        match &self.format {
            Format::Wits(reader) => Some(reader.items()),
            Format::Csv { .. } | Format::SurfaceCsv { .. } => None,
        }
    }

    /// The channels read and their units.
    pub fn declared(&self) -> crate::data::Declared {
        match &self.format {
            Format::Csv { layout, top_drive, .. } => crate::data::Declared {
                top_drive: top_drive.map(|(i, unit)| (layout.headers()[i].trim().to_string(), unit)),
                ..layout.declared()
            },
            Format::SurfaceCsv { layout, .. } => {
                let columns = layout.columns();
                crate::data::Declared {
                    columns: crate::data::ColumnsUsed {
                        speed: columns.top_drive.clone(),
                        torque: columns.surface_torque.clone(),
                        wob: columns.wob.clone(),
                        time: Some(columns.time.clone()),
                    },
                    units: crate::data::ColumnUnits {
                        speed: layout.top_drive_unit(),
                        torque: layout.torque_unit(),
                        wob: layout.wob_unit(),
                        time_in_ms: false,
                    },
                    top_drive: Some((columns.top_drive.clone(), layout.top_drive_unit())),
                    surface: Some(columns),
                }
            }
            Format::Wits(reader) => reader.declared(),
        }
    }

    /// A silence so far: said once as [`Next::Stalled`], else [`Next::Waiting`].
    fn silent(&mut self) -> Next {
        let silent = self.last_row.elapsed();
        if silent >= self.stall_after && !self.stall_said {
            self.stall_said = true;
            return Next::Stalled(silent);
        }
        Next::Waiting
    }

    /// A feed whose connection is down: waits a little, tries again when its back-off has
    /// passed (doubling it up to [`MAX_BACKOFF`]).
    fn reconnect(&mut self) -> Option<Next> {
        let feed = self.feed.as_mut()?;
        let (since, next_try, backoff) = feed.down?;
        let now = Instant::now();
        if now < next_try {
            std::thread::sleep((next_try - now).min(FOLLOW_POLL));
            return Some(self.silent());
        }
        match connect(&feed.address) {
            Ok(stream) => {
                feed.down = None;
                self.reader = Box::new(BufReader::new(stream));
                self.partial.clear();
                Some(Next::Said(format!(
                    "{}: connected again after {:.0} s",
                    self.name.display(),
                    since.elapsed().as_secs_f64()
                )))
            }
            Err(_) => {
                let backoff = (backoff * 2).min(MAX_BACKOFF);
                feed.down = Some((since, Instant::now() + backoff, backoff));
                Some(self.silent())
            }
        }
    }

    /// A feed's connection lost (`why`): said once, tried again after 1 s.
    fn lost(&mut self, why: &str) -> Next {
        let feed = self.feed.as_mut().expect("a feed");
        let backoff = Duration::from_secs(1);
        feed.down = Some((Instant::now(), Instant::now() + backoff, backoff));
        self.partial.clear();
        if let Format::Wits(reader) = &mut self.format {
            reader.drop_block();
        }
        Next::Said(format!(
            "{}: {why}; connecting again (waits doubling up to {} s)",
            self.name.display(),
            MAX_BACKOFF.as_secs()
        ))
    }

    /// The next row (waiting for it when following or replaying), a line skipped, or the end.
    pub fn next_row(&mut self) -> Result<Next> {
        if let Some(next) = self.reconnect() {
            return Ok(next);
        }
        loop {
            let mut text = std::mem::take(&mut self.partial);
            let read = match read_line_bounded(self.reader.as_mut(), &mut text) {
                Ok(n) => n,
                // A feed with nothing yet: the watch may stop while it waits.
                Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {
                    self.partial = text;
                    return Ok(self.silent());
                }
                Err(e) if self.feed.is_some() => return Ok(self.lost(&format!("the connection failed ({e})"))),
                Err(e) if e.kind() == ErrorKind::InvalidData => {
                    return Err(Error::Format {
                        path: self.name.clone(),
                        line: Some(self.line + 1),
                        message: e.to_string(),
                    });
                }
                Err(source) => {
                    return Err(Error::Read {
                        path: self.name.clone(),
                        source,
                    });
                }
            };
            self.bytes_read += read as u64;
            if read == 0 && self.feed.is_some() {
                return Ok(self.lost("the feed closed the connection"));
            }
            if read == 0 || !text.ends_with('\n') {
                if self.follow {
                    // At the end for now: wait for the writer (a partial line is kept).
                    self.partial = text;
                    if let Next::Stalled(silent) = self.silent() {
                        return Ok(Next::Stalled(silent));
                    }
                    std::thread::sleep(FOLLOW_POLL.min(self.stall_after));
                    return Ok(Next::Waiting);
                }
                if text.trim().is_empty() {
                    return Ok(Next::End);
                }
            }
            self.line += 1;
            let content = text.trim_end_matches(['\n', '\r']);
            if content.trim().is_empty() || content.trim_start().starts_with('#') {
                continue;
            }
            let arrived = Instant::now();
            let row = match &mut self.format {
                Format::Csv {
                    layout,
                    top_drive,
                    lines,
                    header,
                } => {
                    // A feed sends its header again with each connection.
                    if self.feed.is_some() && content.trim_end() == header {
                        continue;
                    }
                    csv_row(content, layout, *top_drive, lines, self.line)
                }
                Format::SurfaceCsv { layout, lines, header } => {
                    if self.feed.is_some() && content.trim_end() == header {
                        continue;
                    }
                    let record = lines.parse(content).ok_or_else(|| "not a CSV line".to_string());
                    record.and_then(|record| layout.row(&record, self.line).map_err(|e| e.to_string()))
                }
                Format::Wits(reader) => match reader.line(content) {
                    Some(row) => row,
                    None => continue,
                },
            };
            match row {
                Ok(row) => {
                    self.last_row = Instant::now();
                    self.stall_said = false;
                    self.pace(&row);
                    let arrived = if self.replay.is_some() { Instant::now() } else { arrived };
                    return Ok(Next::Row(row, arrived));
                }
                Err(why) => {
                    self.skipped += 1;
                    let at = format!("{}:{}", self.name.display(), self.line);
                    return Ok(Next::Skipped(if why.starts_with(&at) {
                        why
                    } else {
                        format!("{at}: {why}")
                    }));
                }
            }
        }
    }

    /// A replay gives the rows before `t_s` at once and paces from there: a watch going on
    /// after its stored windows.
    pub fn replay_from(&mut self, t_s: f64) {
        self.pace_from_s = t_s;
    }

    /// A replay waits until the row's time, scaled by its speed, has passed since the first
    /// paced one.
    fn pace(&mut self, row: &Row) {
        let (Some((speed, clock)), Some(t)) = (self.replay.as_mut(), row.time_s) else {
            return;
        };
        if t < self.pace_from_s {
            return;
        }
        let (started, t0) = *clock.get_or_insert((Instant::now(), t));
        // A time stamp so far ahead that its wait overflows waits as long as a wait can.
        let due = Duration::try_from_secs_f64(((t - t0) / *speed).max(0.0)).unwrap_or(Duration::MAX);
        if let Some(wait) = due.checked_sub(started.elapsed()) {
            std::thread::sleep(wait);
        }
    }
}

/// One CSV line of a record as a row in SI (its top-drive speed where the record has one).
fn csv_row(
    content: &str,
    layout: &RowLayout,
    top_drive: Option<(usize, SpeedUnit)>,
    lines: &mut LineParser,
    line: u64,
) -> std::result::Result<Row, String> {
    let record = lines.parse(content).ok_or_else(|| "not a CSV line".to_string())?;
    let mut row = layout.row(&record, line).map_err(|e| e.to_string())?;
    if let Some((i, unit)) = top_drive {
        let text = record.get(i).unwrap_or("");
        let value: f64 = text.parse().ok().filter(|v: &f64| v.is_finite()).ok_or_else(|| {
            format!(
                "column {} ('{}'): '{text}' is not a number",
                i + 1,
                &layout.headers()[i]
            )
        })?;
        row.top_drive_rad_s = Some(unit.to_rad_s(value));
    }
    Ok(row)
}

/// The layout of a header of surface channels alone (a top-drive speed and a surface torque
/// found by the rules of `bitrock surface`, in `speed_unit` where given, and no bit channel),
/// or what is wrong with it; `None` for a header that names a bit channel, which the bit's
/// layout then refuses in its own words.
fn surface_layout(
    headers: &csv::StringRecord,
    delimiter: u8,
    opts: &DataOptions,
    name: &Path,
) -> Option<Result<SurfaceRowLayout>> {
    // The bit's columns named: the bit's layout says what is wrong with them.
    if opts.speed_column.is_some() || opts.torque_column.is_some() {
        return None;
    }
    let header: Vec<String> = headers.iter().map(|h| h.trim().to_string()).collect();
    let names_the_bit = |h: &String| {
        let lower = h.to_ascii_lowercase();
        !crate::data::is_surface_channel(h) && (lower.contains("speed") || lower.contains("torque"))
    };
    if !header.iter().any(|h| crate::data::is_surface_channel(h)) || header.iter().any(names_the_bit) {
        return None;
    }
    let surface = SurfaceOptions {
        time_column: opts.time_column.clone(),
        wob_column: opts.wob_column.clone(),
        top_drive_unit: opts.speed_unit,
        torque_unit: opts.torque_unit,
        wob_unit: opts.wob_unit,
        ..SurfaceOptions::default()
    };
    match SurfaceRowLayout::new(&header, delimiter, &surface, name) {
        Ok(layout) if !layout.bit_channels().is_empty() => None,
        made => Some(made),
    }
}

/// A connection to a feed at `address`, its reads waiting at most [`FOLLOW_POLL`].
fn connect(address: &str) -> std::io::Result<TcpStream> {
    use std::net::ToSocketAddrs;
    let mut last = std::io::Error::new(ErrorKind::NotFound, format!("{address} resolves to no address"));
    for addr in address.to_socket_addrs()? {
        match TcpStream::connect_timeout(&addr, Duration::from_secs(5)) {
            Ok(stream) => {
                stream.set_read_timeout(Some(FOLLOW_POLL))?;
                return Ok(stream);
            }
            Err(e) => last = e,
        }
    }
    Err(last)
}

/// The one column whose name contains "top_drive" (its unit from its suffix, `_rpm` or
/// `_rad_s`), if any: the operating point's speed. Several, or one without a unit, are refused.
fn top_drive_column(headers: &csv::StringRecord, name: &Path, line: u64) -> Result<Option<(usize, SpeedUnit)>> {
    let found: Vec<usize> = headers
        .iter()
        .enumerate()
        .filter(|(_, h)| h.to_ascii_lowercase().contains("top_drive"))
        .map(|(i, _)| i)
        .collect();
    let refuse = |message: String| Error::Format {
        path: name.to_path_buf(),
        line: Some(line),
        message,
    };
    match found.as_slice() {
        [] => Ok(None),
        [i] => SpeedUnit::from_suffix(&headers[*i])
            .map(|u| Some((*i, u)))
            .ok_or_else(|| {
                refuse(format!(
                    "the top-drive speed column '{}' has no unit suffix: name it …_rpm or …_rad_s",
                    &headers[*i]
                ))
            }),
        many => Err(refuse(format!(
            "several columns name a top-drive speed ({}); keep one",
            many.iter().map(|&i| &headers[i]).collect::<Vec<_>>().join(", ")
        ))),
    }
}

fn open(path: &Path) -> Result<impl Read + Send + use<>> {
    std::fs::File::open(path).map_err(|source| Error::Read {
        path: path.to_path_buf(),
        source,
    })
}

/// The lines of a CSV source read one at a time, each on its own (a quote left open on one
/// never runs into the next). The parser is built once per source and reset per line:
/// building one is most of the cost of reading a short line.
struct LineParser {
    core: csv_core::Reader,
    /// The line's fields, unquoted, one after another.
    fields: Vec<u8>,
    /// Where each field ends in `fields`.
    ends: Vec<usize>,
}

impl LineParser {
    fn new(delimiter: u8) -> Self {
        Self {
            core: csv_core::ReaderBuilder::new().delimiter(delimiter).build(),
            fields: vec![0; 256],
            ends: vec![0; 16],
        }
    }

    /// One CSV line as a record (fields trimmed), or `None` when it holds none.
    fn parse(&mut self, line: &str) -> Option<csv::StringRecord> {
        use csv_core::ReadRecordResult as Read;
        self.core.reset();
        let mut input = line.as_bytes();
        let (mut written, mut ended) = (0, 0);
        loop {
            let (result, read, out, end) =
                self.core
                    .read_record(input, &mut self.fields[written..], &mut self.ends[ended..]);
            input = &input[read..];
            written += out;
            ended += end;
            match result {
                Read::InputEmpty => {}
                Read::OutputFull => self.fields.resize(2 * self.fields.len(), 0),
                Read::OutputEndsFull => self.ends.resize(2 * self.ends.len(), 0),
                Read::Record => break,
                Read::End => return None,
            }
        }
        let mut record = csv::StringRecord::with_capacity(written, ended);
        let mut start = 0;
        for &end in &self.ends[..ended] {
            record.push_field(std::str::from_utf8(&self.fields[start..end]).ok()?.trim());
            start = end;
        }
        Some(record)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn read(text: &'static str) -> Result<Rows> {
        let reader: Box<dyn BufRead + Send> = Box::new(BufReader::new(text.as_bytes()));
        Rows::from_reader(
            reader,
            PathBuf::from("feed.csv"),
            &DataOptions::default(),
            &WitsItems::default(),
            &|| false,
        )
    }

    fn rows_of(text: &'static str) -> Rows {
        read(text).unwrap()
    }

    #[test]
    fn rows_are_read_one_at_a_time_and_bad_lines_skipped() {
        let mut rows =
            rows_of("# a rig\ntime_s,bit_speed_rpm,torque_knm\n0.0,60,10\n0.02,x,10\n\n0.04,62,11\n0.06,63\n");
        let Next::Row(row, _) = rows.next_row().unwrap() else {
            panic!()
        };
        assert_eq!(row.time_s, Some(0.0));
        assert!((row.bit.unwrap().speed_rad_s - 60.0 * std::f64::consts::PI / 30.0).abs() < 1e-12);
        assert!((row.bit.unwrap().torque_nm - 10_000.0).abs() < 1e-9);
        let Next::Skipped(why) = rows.next_row().unwrap() else {
            panic!()
        };
        assert!(
            why.starts_with("feed.csv:4") && why.contains("'x' is not a number"),
            "{why}"
        );
        let Next::Row(row, _) = rows.next_row().unwrap() else {
            panic!()
        };
        assert_eq!(row.time_s, Some(0.04));
        let Next::Skipped(why) = rows.next_row().unwrap() else {
            panic!()
        };
        assert!(why.starts_with("feed.csv:7"), "{why}");
        assert!(matches!(rows.next_row().unwrap(), Next::End));
        assert_eq!(rows.skipped, 2);
    }

    /// The next row, stall, skip or end of a followed source, past its waits.
    fn next_event(rows: &mut Rows) -> Next {
        loop {
            match rows.next_row().unwrap() {
                Next::Waiting => continue,
                next => return next,
            }
        }
    }

    #[test]
    fn a_followed_file_that_falls_silent_is_said_to_have_stalled_once() {
        use std::io::Write;
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("feed.csv");
        std::fs::write(&path, "time_s,bit_speed_rpm,torque_knm\n0.0,60,7\n").unwrap();
        let mut rows = Rows::open(
            &Source::File {
                path: path.clone(),
                follow: true,
            },
            &DataOptions::default(),
            &WitsItems::default(),
            &|| false,
        )
        .unwrap();
        rows.stall_after = Duration::from_millis(300);
        assert!(matches!(next_event(&mut rows), Next::Row(..)));
        let Next::Stalled(silent) = next_event(&mut rows) else {
            panic!("a stall")
        };
        assert!(silent >= Duration::from_millis(300));
        // Rows again: read, and the next silence is said again; a line written in two parts
        // is one row.
        let mut file = std::fs::OpenOptions::new().append(true).open(&path).unwrap();
        write!(file, "0.1,6").unwrap();
        file.flush().unwrap();
        let writer = std::thread::spawn(move || {
            std::thread::sleep(Duration::from_millis(100));
            writeln!(file, "1,8").unwrap();
        });
        let Next::Row(row, _) = next_event(&mut rows) else {
            panic!("the row")
        };
        writer.join().unwrap();
        assert_eq!(row.time_s, Some(0.1));
        assert!((row.bit.unwrap().speed_rad_s - 61.0 * std::f64::consts::PI / 30.0).abs() < 1e-12);
        assert!(matches!(next_event(&mut rows), Next::Stalled(_)));
    }

    #[test]
    fn a_header_without_the_columns_is_refused_naming_them() {
        let e = read("time_s,depth_m\n").err().unwrap().to_string();
        assert!(e.contains("speed"), "{e}");
    }
}
