//! Field data: a record of bit speed and torque on bit (optionally time and weight on bit), a
//! CSV file or a WITSML time log ([`witsml`]), read into SI, filtered, and split into a
//! calibration and a validation part.
//!
//! Columns are chosen by name (flags, or a column map file) or found by what their names contain
//! (`speed`, `torque`, `time`, `wob`), else by rig mnemonics ([`mnemonics`]); units come from
//! flags or from the names (suffixes such as `_rpm`, `_knm`, `_klbf`, or a unit in brackets);
//! time in seconds, milliseconds or a wall clock ([`clock`]). Every refusal names the file, and
//! where it applies the line and the column.

pub mod clock;
pub mod drilling;
pub mod mnemonics;
pub mod surface;
pub mod witsml;

use crate::error::{Error, Result};
use crate::units::{ForceUnit, RAD_S_PER_RPM, SpeedUnit, TorqueUnit};
use serde::{Deserialize, Serialize};
use std::io::Read;
use std::path::{Path, PathBuf};

/// How the record is divided into calibration and validation samples.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "lowercase")]
pub enum SplitRule {
    /// The first fraction of the record (in time order) calibrates, the rest validates.
    Block,
    /// Rows are dealt out evenly through the record in the given proportion.
    Interleaved,
}

/// Which columns to read, in which units, and which rows to keep.
#[derive(Clone, Debug)]
pub struct DataOptions {
    /// Bit-speed column; `None` finds the one column whose name contains "speed".
    pub speed_column: Option<String>,
    /// Torque-on-bit column; `None` finds the one column whose name contains "torque".
    pub torque_column: Option<String>,
    /// Weight-on-bit column; `None` uses the one column whose name contains "wob", if any.
    pub wob_column: Option<String>,
    /// Time column (seconds); `None` uses the one column whose name contains "time", if any.
    pub time_column: Option<String>,
    /// Speed unit; `None` reads it from the column suffix.
    pub speed_unit: Option<SpeedUnit>,
    /// Torque unit; `None` reads it from the column suffix.
    pub torque_unit: Option<TorqueUnit>,
    /// Weight-on-bit unit; `None` reads it from the column suffix.
    pub wob_unit: Option<ForceUnit>,
    /// Rows with bit speed below this (rpm) are dropped: the laws hold for w > 0 and
    /// stick-phase samples say nothing about them.
    pub min_speed_rpm: f64,
    /// Keep rows with time ≥ this (s); needs a time column.
    pub t_start_s: Option<f64>,
    /// Keep rows with time ≤ this (s); needs a time column.
    pub t_end_s: Option<f64>,
    /// Keep every k-th row of the time window (1 keeps all), before the speed filter.
    pub thin: usize,
    /// Fraction of the kept rows used for calibration, in (0, 1].
    pub calibration_fraction: f64,
    /// How calibration rows are chosen.
    pub split: SplitRule,
    /// A column map file naming the rig's columns and units by role
    /// ([`mnemonics::ColumnMap`]); the column and unit options above win over it.
    pub column_map: Option<PathBuf>,
}

impl Default for DataOptions {
    fn default() -> Self {
        Self {
            speed_column: None,
            torque_column: None,
            wob_column: None,
            time_column: None,
            speed_unit: None,
            torque_unit: None,
            wob_unit: None,
            min_speed_rpm: 5.0,
            t_start_s: None,
            t_end_s: None,
            thin: 1,
            calibration_fraction: 0.5,
            split: SplitRule::Block,
            column_map: None,
        }
    }
}

impl DataOptions {
    /// Refuses option values that cannot mean anything, naming the flag.
    pub fn validate(&self) -> Result<()> {
        if !self.min_speed_rpm.is_finite() || self.min_speed_rpm < 0.0 {
            return Err(Error::setting(
                "min_speed_rpm",
                format!("must be a finite number ≥ 0, got {}", self.min_speed_rpm),
            ));
        }
        if self.thin == 0 {
            return Err(Error::setting("thin", "must be at least 1 (1 keeps every row)"));
        }
        if !(self.calibration_fraction > 0.0 && self.calibration_fraction <= 1.0) {
            return Err(Error::setting(
                "calibration_fraction",
                format!("must lie in (0, 1], got {}", self.calibration_fraction),
            ));
        }
        for (field, v) in [("t_start_s", self.t_start_s), ("t_end_s", self.t_end_s)] {
            if let Some(v) = v
                && !v.is_finite()
            {
                return Err(Error::setting(field, format!("must be finite, got {v}")));
            }
        }
        if let (Some(a), Some(b)) = (self.t_start_s, self.t_end_s)
            && a >= b
        {
            return Err(Error::setting(
                "t_end_s",
                format!("must exceed `t_start_s` ({a} s), got {b} s"),
            ));
        }
        Ok(())
    }
}

/// Samples of a law's input and output, in SI.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Samples {
    /// Bit speed, rad/s.
    pub speed_rad_s: Vec<f64>,
    /// Torque on bit, N·m.
    pub torque_nm: Vec<f64>,
    /// Weight on bit, N, when the record has it.
    pub wob_n: Option<Vec<f64>>,
    /// Time, s, when the record has it.
    pub time_s: Option<Vec<f64>>,
}

impl Samples {
    /// Bit speed (rad/s) and torque on bit (N·m) alone: no weight on bit, no clock.
    pub fn new(speed_rad_s: Vec<f64>, torque_nm: Vec<f64>) -> Self {
        Self {
            speed_rad_s,
            torque_nm,
            wob_n: None,
            time_s: None,
        }
    }

    /// The mean weight on bit (N) of the samples, where they carry a positive one.
    pub fn mean_wob_n(&self) -> Option<f64> {
        let wob = self.wob_n.as_ref().filter(|w| !w.is_empty())?;
        let mean = crate::numerics::compensated_sum(wob.iter().copied()) / wob.len() as f64;
        (mean.is_finite() && mean > 0.0).then_some(mean)
    }

    /// True where the samples' weight on bit changes beyond rounding: one that never changes
    /// scales nothing.
    pub fn wob_varies(&self) -> bool {
        let Some(mean) = self.mean_wob_n() else {
            return false;
        };
        let (low, high) = self
            .wob_n
            .iter()
            .flatten()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &w| (l.min(w), h.max(w)));
        high - low > 1e-9 * mean
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.speed_rad_s.len()
    }
    /// True when there is no sample.
    pub fn is_empty(&self) -> bool {
        self.speed_rad_s.is_empty()
    }
    /// Σ y² (N·m)², the denominator of the paper's ρ, summed in f64 with compensation.
    pub fn sum_sq_torque(&self) -> f64 {
        crate::numerics::compensated_sum(self.torque_nm.iter().map(|y| y * y))
    }
    /// Weight-on-bit ratio r = W / W_ref per sample, or all ones when WOB is not recorded
    /// or `w_ref_n` is `None` (the paper's assumption: data taken at W = W_ref).
    pub fn wob_ratio(&self, w_ref_n: Option<f64>) -> Vec<f64> {
        match (&self.wob_n, w_ref_n) {
            (Some(w), Some(w_ref)) => w.iter().map(|w| w / w_ref).collect(),
            _ => vec![1.0; self.len()],
        }
    }

    fn pick(&self, keep: impl Fn(usize) -> bool) -> Samples {
        let sel = |v: &Vec<f64>| {
            v.iter()
                .enumerate()
                .filter(|(i, _)| keep(*i))
                .map(|(_, x)| *x)
                .collect::<Vec<_>>()
        };
        Samples {
            speed_rad_s: sel(&self.speed_rad_s),
            torque_nm: sel(&self.torque_nm),
            wob_n: self.wob_n.as_ref().map(sel),
            time_s: self.time_s.as_ref().map(sel),
        }
    }
}

/// A field record after reading, filtering and splitting (serialisable whole, so that a
/// Python `Record` pickles and travels to workers as it is).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct FieldData {
    /// Where it came from (a path, or `<embedded demo data>`).
    pub source: PathBuf,
    /// The unit the record gave torques in; results are printed in it.
    pub torque_unit: TorqueUnit,
    /// The unit the record gave speeds in.
    pub speed_unit: SpeedUnit,
    /// Columns used, in the order speed, torque, wob, time.
    pub columns: ColumnsUsed,
    /// Data rows in the file.
    pub rows_read: usize,
    /// Rows kept by the filters (calibration + validation).
    pub rows_used: usize,
    /// Samples the laws are calibrated on.
    pub calibration: Samples,
    /// Samples held back to judge the calibration.
    pub validation: Samples,
    /// What the record looks wrong in without being unusable (a time column that runs
    /// backwards, torques mostly of the wrong sign): said once by every command that reads it
    /// and kept in the run's record.
    pub warnings: Vec<String>,
    /// What the bit did over the record's time window, every row counted (those below the
    /// minimum speed too): whether it stick-slipped, and where the rig drilled. `None` in
    /// records stored without it.
    #[serde(default)]
    pub bit: Option<BitSeen>,
    /// How the time column read (elapsed seconds, or a wall clock counted from a midnight
    /// UTC), where the record has one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub clock: Option<clock::Clock>,
}

impl FieldData {
    /// How a wall-clock time column was read (`time 'TIME': ISO 8601 stamps, s since …`), for
    /// the lines that describe the record; `None` for elapsed time or no time column.
    pub fn clock_note(&self) -> Option<String> {
        let clock = self.clock.filter(|c| c.is_wall())?;
        Some(format!(
            "time '{}': {clock}",
            self.columns.time.as_deref().unwrap_or("time")
        ))
    }
}

/// Bit speed below which a sample counts as stuck (rad/s): 1 rpm, as downhole tools count it.
pub const STUCK_SPEED_RAD_S: f64 = RAD_S_PER_RPM;
/// Share of the time stuck from which a bit stick-slips, not turning steadily (a record, a
/// window, a simulated string's verdict window): a bit stuck a hundredth of the time is
/// already in the cycle.
pub const STICK_SLIP_STUCK_SHARE: f64 = 0.01;

/// Stick-slip severity of a bit speed that ranged from `lo` to `hi` about `mean` (any one
/// unit): (max − min) / (2·|mean|); `None` where the mean is zero.
pub fn severity(lo: f64, hi: f64, mean: f64) -> Option<f64> {
    (mean.abs() > f64::MIN_POSITIVE).then(|| (hi - lo) / (2.0 * mean.abs()))
}

/// What a record's bit speed shows: how often the bit stuck, how hard it swung, and the mean
/// speed and weight on bit it drilled at (its operating point: a stick-slip cycle's mean bit
/// speed is the top drive's).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct BitSeen {
    /// Samples looked at.
    pub samples: usize,
    /// Share of them with |bit speed| below [`STUCK_SPEED_RAD_S`].
    pub stuck_share: f64,
    /// Stick-slip severity, (max − min) / (2·mean) of the bit speed; `None` where the mean is 0.
    pub severity: Option<f64>,
    /// Mean bit speed, rpm.
    pub mean_speed_rpm: f64,
    /// Peak bit speed, rpm (`None` in records stored without it).
    #[serde(default)]
    pub peak_speed_rpm: Option<f64>,
    /// Mean weight on bit, kN, where recorded.
    pub mean_wob_kn: Option<f64>,
}

impl BitSeen {
    /// What `speeds_rad_s` (with the weights on bit `wob_n`, N, where recorded) show; `None`
    /// without a sample.
    pub fn of(speeds_rad_s: &[f64], wob_n: Option<&[f64]>) -> Option<Self> {
        if speeds_rad_s.is_empty() {
            return None;
        }
        let n = speeds_rad_s.len() as f64;
        let stuck = speeds_rad_s.iter().filter(|v| v.abs() < STUCK_SPEED_RAD_S).count();
        let mean = crate::numerics::compensated_sum(speeds_rad_s.iter().copied()) / n;
        let (lo, hi) = speeds_rad_s
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
                (lo.min(*v), hi.max(*v))
            });
        Some(Self {
            samples: speeds_rad_s.len(),
            stuck_share: stuck as f64 / n,
            severity: severity(lo, hi, mean),
            mean_speed_rpm: mean / RAD_S_PER_RPM,
            peak_speed_rpm: Some(hi / RAD_S_PER_RPM),
            mean_wob_kn: wob_n
                .filter(|w| !w.is_empty())
                .map(|w| crate::numerics::compensated_sum(w.iter().copied()) / w.len() as f64 / 1000.0),
        })
    }

    /// The bit stick-slipped: stuck at least [`STICK_SLIP_STUCK_SHARE`] of the time.
    pub fn stick_slips(&self) -> bool {
        self.stuck_share >= STICK_SLIP_STUCK_SHARE
    }
}

/// Names of the columns read.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ColumnsUsed {
    pub speed: String,
    pub torque: String,
    pub wob: Option<String>,
    pub time: Option<String>,
}

/// The embedded demo record (synthetic; see data/README.md).
pub const DEMO_CSV: &str = include_str!("../data/demo.csv");
/// Name shown for the embedded record.
pub const DEMO_SOURCE: &str = "<embedded demo data>";

/// The most a record read from a pipe may hold, bytes: a day of a 50 Hz downhole tool's
/// columns is about 0.2 GB, so 4 GB is generous and still bounds an endless stream.
pub const MAX_PIPE_BYTES: u64 = 4_000_000_000;
/// Memory the parse needs per byte of the record: the text, the parsed columns and the
/// filtered copies.
const PARSE_BYTES_PER_BYTE: f64 = 4.0;

/// Reads a field record from a file: a regular file, whose size is checked against the memory
/// available before it is read, or a pipe (`/dev/stdin`, a named pipe), read up to
/// [`MAX_PIPE_BYTES`]. Anything else (a device such as `/dev/zero`, a directory, a socket) is
/// refused naming the path, before a byte is read.
pub fn read_field_data(path: &Path, opts: &DataOptions) -> Result<FieldData> {
    let read_error = |source| Error::Read {
        path: path.to_path_buf(),
        source,
    };
    let refuse = |message: String| Error::Data {
        path: path.to_path_buf(),
        message,
    };
    match crate::files::open_input(path, "a record")? {
        crate::files::Input::Regular { file, size } => {
            crate::limits::check_memory(
                "DATA",
                size as f64 * PARSE_BYTES_PER_BYTE,
                &format!(
                    "reading {} ({})",
                    path.display(),
                    crate::limits::human_bytes(size as f64)
                ),
            )?;
            parse_field_data(file, path, opts)
        }
        crate::files::Input::Pipe(file) => {
            let cap = MAX_PIPE_BYTES.min(
                crate::limits::available_memory_bytes().map_or(u64::MAX, |b| (b as f64 / PARSE_BYTES_PER_BYTE) as u64),
            );
            let mut text = Vec::new();
            std::io::Read::read_to_end(&mut std::io::Read::take(file, cap + 1), &mut text).map_err(read_error)?;
            if text.len() as u64 > cap {
                return Err(refuse(format!(
                    "the pipe holds more than {}, the most a record read from a pipe may hold here; write the record to a file",
                    crate::limits::human_bytes(cap as f64)
                )));
            }
            parse_field_data(text.as_slice(), path, opts)
        }
    }
}

/// Reads the embedded demo record.
pub fn demo_field_data(opts: &DataOptions) -> Result<FieldData> {
    parse_field_data(DEMO_CSV.as_bytes(), Path::new(DEMO_SOURCE), opts)
}

/// True for a column a rig measures at the surface (its name holds `surface`, `top_drive` or
/// `rotary`, or a surface mnemonic: [`mnemonics::is_surface`]): never read as the bit's speed
/// or torque unless named.
pub fn is_surface_channel(name: &str) -> bool {
    mnemonics::is_surface(name)
}

/// Index of the column named `wanted`, or of the single column whose name contains `hint`, or
/// else of the single one a rig-log mnemonic gives the role `role` ([`mnemonics::role`]).
fn resolve_column(
    headers: &csv::StringRecord,
    wanted: Option<&str>,
    hint: &str,
    role: mnemonics::Role,
    field: &str,
    required: bool,
    path: &Path,
) -> Result<Option<usize>> {
    let listing = || headers.iter().collect::<Vec<_>>().join(", ");
    if let Some(name) = wanted {
        return match headers.iter().position(|h| h == name) {
            Some(i) => Ok(Some(i)),
            None => Err(Error::Format {
                path: path.to_path_buf(),
                line: Some(1),
                message: format!(
                    "no column named '{name}' (given by `{field}`); the header has: {}",
                    listing()
                ),
            }),
        };
    }
    let candidates = |named: &dyn Fn(&str) -> bool| -> (Vec<usize>, Vec<usize>) {
        // An MWD tool's downhole minimum or maximum is a window's extreme, never the bit's speed.
        headers
            .iter()
            .enumerate()
            .filter(|(_, h)| named(h) && (role != mnemonics::Role::Speed || mnemonics::downhole_extreme(h).is_none()))
            .map(|(i, _)| i)
            .partition(|&i| is_surface_channel(&headers[i]))
    };
    let (surface, mut matches) = candidates(&|h| h.to_ascii_lowercase().contains(hint));
    if matches.is_empty() {
        // Surface channels a mnemonic names are said below as the record's surface channels.
        matches = candidates(&|h| mnemonics::role(h) == Some(role)).1;
    }
    match matches.as_slice() {
        [i] => Ok(Some(*i)),
        [] if !required => Ok(None),
        [] if surface.is_empty() && headers.iter().any(is_surface_channel) => Err(Error::Format {
            path: path.to_path_buf(),
            line: Some(1),
            message: format!(
                "no column of the bit's {hint}: this record holds surface channels ({}), and the bit's \
                 speed and torque are never taken from the surface; infer the law from them with \
                 `bitrock surface`, or name the bit's column with `{field}`",
                headers
                    .iter()
                    .filter(|h| is_surface_channel(h))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        }),
        [] if !surface.is_empty() => Err(Error::Format {
            path: path.to_path_buf(),
            line: Some(1),
            message: format!(
                "column '{}' is a surface channel, and the bit's {hint} is never taken from the surface; \
                 give the bit's column with `{field}`, or infer the law from the surface channels with \
                 `bitrock surface`",
                &headers[surface[0]]
            ),
        }),
        [] => Err(Error::Format {
            path: path.to_path_buf(),
            line: Some(1),
            message: format!(
                "no column name contains '{hint}' or a rig log's mnemonic of it (the table in docs/records.md); name the column with `{field}` (the header has: {})",
                listing()
            ),
        }),
        many => Err(Error::Format {
            path: path.to_path_buf(),
            line: Some(1),
            message: format!(
                "several columns contain '{hint}' ({}); choose one with `{field}`",
                many.iter().map(|&i| &headers[i]).collect::<Vec<_>>().join(", ")
            ),
        }),
    }
}

/// The unit of a column: the flag's when given (and not contradicting the suffix), else the
/// suffix's.
pub(crate) fn resolve_unit<U: crate::units::ColumnUnit>(
    column: &str,
    flag_value: Option<U>,
    field: &str,
    path: &Path,
) -> Result<U> {
    let label = U::symbol;
    match (flag_value, U::declared_by(column)) {
        (Some(f), Some(s)) if f != s => Err(Error::Format {
            path: path.to_path_buf(),
            line: Some(1),
            message: format!(
                "column '{column}' declares {} by its name but `{field}` says {}; rename the column or leave `{field}` out",
                label(s),
                label(f)
            ),
        }),
        (Some(u), _) | (None, Some(u)) => Ok(u),
        (None, None) => Err(Error::Format {
            path: path.to_path_buf(),
            line: Some(1),
            message: format!("cannot tell the unit of column '{column}' from its name; give `{field}`"),
        }),
    }
}

/// The field delimiter of a record, read off its header line (the first line that is neither
/// blank nor a `#` comment): a comma when the header has one, else a semicolon or a tab (as
/// spreadsheets in many locales export). A header with both and no comma is refused, naming
/// them.
pub(crate) fn detect_delimiter(text: &[u8], path: &Path) -> Result<u8> {
    let header = text
        .split(|&b| b == b'\n')
        .find(|line| !line.starts_with(b"#") && !line.trim_ascii().is_empty())
        .unwrap_or_default();
    let has = |b: u8| header.contains(&b);
    match (has(b','), has(b';'), has(b'\t')) {
        (true, _, _) | (false, false, false) => Ok(b','),
        (false, true, false) => Ok(b';'),
        (false, false, true) => Ok(b'\t'),
        (false, true, true) => Err(Error::Format {
            path: path.to_path_buf(),
            line: None,
            message: "the header line has both ';' and tab separators and no comma: use one delimiter (a comma, a semicolon or a tab)".into(),
        }),
    }
}

/// Reads, filters and splits a field record from any reader. `path` is only used in messages.
/// Fields are separated by commas, or by semicolons or tabs when the header line says so
/// (`detect_delimiter`); numbers take a decimal point.
pub fn parse_field_data<R: Read>(mut reader: R, path: &Path, opts: &DataOptions) -> Result<FieldData> {
    opts.validate()?;
    let opts = &mnemonics::ColumnMap::apply(opts)?;
    let mut text = Vec::new();
    reader.read_to_end(&mut text).map_err(|source| Error::Read {
        path: path.to_path_buf(),
        source,
    })?;
    if witsml::is_xml(&text) {
        return parse_witsml(&text, path, opts);
    }
    let delimiter = detect_delimiter(&text, path)?;
    let mut rdr = csv::ReaderBuilder::new()
        .delimiter(delimiter)
        .trim(csv::Trim::All)
        .comment(Some(b'#'))
        .from_reader(text.as_slice());
    let headers = rdr.headers().map_err(|e| csv_error(path, e))?.clone();
    let layout = RowLayout::new(&headers, delimiter, opts, path)?;
    check_time_window(&layout.indices, opts, path)?;

    let records = rdr.records().map(|r| {
        let record = r.map_err(|e| csv_error(path, e))?;
        let line = record.position().map_or(0, |p| p.line());
        Ok((record, line))
    });
    let (all, backwards) = read_rows(records, &layout)?;
    let clock = layout.clock();
    assemble(
        all,
        backwards,
        clock,
        &headers,
        &layout.indices,
        &layout.units,
        opts,
        path,
    )
}

/// A field record from a WITSML time log's text ([`witsml`]): its channels read as a CSV's
/// columns named `MNEMONIC [unit]`, its index as the time column unless `opts` names one; rows
/// with no value in a column read are left out and said.
fn parse_witsml(text: &[u8], path: &Path, opts: &DataOptions) -> Result<FieldData> {
    let text = std::str::from_utf8(text).map_err(|e| Error::Data {
        path: path.to_path_buf(),
        message: format!("the XML is not UTF-8 (at byte {})", e.valid_up_to()),
    })?;
    let log = witsml::read(text, path)?;
    let mut opts = opts.clone();
    if opts.time_column.is_none() {
        opts.time_column = log.time_index.map(|i| log.headers[i].to_string());
    }
    let layout = RowLayout::new(&log.headers, b',', &opts, path)?;
    check_time_window(&layout.indices, &opts, path)?;
    let read = layout.used_columns();
    let rows = log.rows.len();
    let (kept, left_out): (Vec<_>, Vec<_>) = log.rows.into_iter().partition(|(record, _)| {
        !read
            .iter()
            .any(|&i| witsml::is_null(record.get(i).unwrap_or(""), &log.nulls[i]))
    });
    let (all, backwards) = read_rows(kept.into_iter().map(Ok), &layout)?;
    let mut data = assemble(
        all,
        backwards,
        layout.clock(),
        &log.headers,
        &layout.indices,
        &layout.units,
        &opts,
        path,
    )?;
    if let Some((_, line)) = left_out.first() {
        let names: Vec<&str> = read.iter().map(|&i| &log.headers[i]).collect();
        data.warnings.insert(
            0,
            format!(
                "{}: {} of {rows} rows hold no value in a channel read ({}), the first on line {line}: left out",
                path.display(),
                left_out.len(),
                names.join(", ")
            ),
        );
    }
    Ok(data)
}

/// A field record from named columns already in memory (a pandas DataFrame's, in the units
/// their names or `opts` say), read as [`parse_field_data`] reads a CSV: the same choice of
/// columns and units, filters, split and refusals. A column given as `None` holds no numbers
/// (text, say) and is refused only when chosen. `source` names the record in messages; a
/// value that is not finite is refused naming its column and row (0-based).
pub fn field_data_from_columns(
    names: &[String],
    columns: &[Option<&[f64]>],
    source: &Path,
    opts: &DataOptions,
) -> Result<FieldData> {
    let refuse = |message: String| Error::Data {
        path: source.to_path_buf(),
        message,
    };
    if names.len() != columns.len() {
        return Err(refuse(format!(
            "{} column names for {} columns",
            names.len(),
            columns.len()
        )));
    }
    let rows = columns.iter().flatten().next().map_or(0, |c| c.len());
    let lengths = names.iter().zip(columns).filter_map(|(n, c)| c.map(|c| (n, c.len())));
    if let Some((name, length)) = lengths.clone().find(|&(_, length)| length != rows) {
        let first = lengths.clone().next().map_or("", |(n, _)| n.as_str());
        return Err(refuse(format!(
            "column '{name}' has {length} rows, column '{first}' {rows}"
        )));
    }
    // Header refusals say line 1 of a CSV; columns have no lines.
    let headerless = |e: Error| match e {
        Error::Format { path, message, .. } => Error::Format {
            path,
            line: None,
            message,
        },
        e => e,
    };
    opts.validate()?;
    let opts = &mnemonics::ColumnMap::apply(opts)?;
    let headers = csv::StringRecord::from(names.to_vec());
    check_headers(&headers, source).map_err(headerless)?;
    let indices = ColumnIndices::resolve(&headers, opts, source).map_err(headerless)?;
    let units = ColumnUnits::resolve(&headers, &indices, opts, source).map_err(headerless)?;
    check_time_window(&indices, opts, source).map_err(headerless)?;
    let chosen = [Some(indices.speed), Some(indices.torque), indices.wob, indices.time];
    if let Some(i) = chosen.into_iter().flatten().find(|&i| columns[i].is_none()) {
        return Err(refuse(format!("column '{}' does not hold numbers", names[i])));
    }

    let value = |column: usize, row: usize| -> Result<f64> {
        let v = columns[column].expect("checked above")[row];
        if v.is_finite() {
            Ok(v)
        } else {
            Err(refuse(format!(
                "column '{}', row {row}: {v} is not a finite number",
                names[column]
            )))
        }
    };
    let mut all = Samples {
        wob_n: indices.wob.map(|_| Vec::with_capacity(rows)),
        time_s: indices.time.map(|_| Vec::with_capacity(rows)),
        ..Samples::default()
    };
    let mut backwards = None;
    let time = clock::TimeReader::new(units.time_in_ms);
    for row in 0..rows {
        all.speed_rad_s.push(units.speed.to_rad_s(value(indices.speed, row)?));
        all.torque_nm
            .push(value(indices.torque, row)? * units.torque.newton_metres());
        if let (Some(i), Some(u), Some(v)) = (indices.wob, units.wob, all.wob_n.as_mut()) {
            v.push(value(i, row)? * u.newtons());
        }
        if let (Some(i), Some(v)) = (indices.time, all.time_s.as_mut()) {
            let t = time
                .number(value(i, row)?)
                .map_err(|e| refuse(format!("column '{}', row {row}: {e}", names[i])))?;
            if let Some(&previous) = v.last()
                && t < previous
                && backwards.is_none()
            {
                backwards = Some((format!("{} row {row}", source.display()), previous, t));
            }
            v.push(t);
        }
    }
    assemble(all, backwards, time.clock(), &headers, &indices, &units, opts, source)
}

/// Refuses a time window without a time column.
fn check_time_window(indices: &ColumnIndices, opts: &DataOptions, path: &Path) -> Result<()> {
    if indices.time.is_none() && (opts.t_start_s.is_some() || opts.t_end_s.is_some()) {
        return Err(Error::Format {
            path: path.to_path_buf(),
            line: Some(1),
            message: "`t_start_s`/`t_end_s` need a time column (none found; name it with `time_column`)".into(),
        });
    }
    Ok(())
}

/// The record from every row read (`all`, in SI): filtered, split and looked over for
/// warnings. Refuses a record without rows.
#[allow(clippy::too_many_arguments)]
fn assemble(
    all: Samples,
    backwards: Option<Backwards>,
    clock: Option<clock::Clock>,
    headers: &csv::StringRecord,
    indices: &ColumnIndices,
    units: &ColumnUnits,
    opts: &DataOptions,
    path: &Path,
) -> Result<FieldData> {
    if all.is_empty() {
        return Err(Error::Data {
            path: path.to_path_buf(),
            message: "no data rows after the header".into(),
        });
    }

    let name = |i: usize| headers[i].to_string();
    let columns = ColumnsUsed {
        speed: name(indices.speed),
        torque: name(indices.torque),
        wob: indices.wob.map(name),
        time: indices.time.map(name),
    };
    assemble_columns(all, backwards, clock, columns, units, opts, path)
}

/// [`assemble`] of the columns `columns` names.
fn assemble_columns(
    all: Samples,
    backwards: Option<Backwards>,
    clock: Option<clock::Clock>,
    columns: ColumnsUsed,
    units: &ColumnUnits,
    opts: &DataOptions,
    path: &Path,
) -> Result<FieldData> {
    let rows_read = all.len();
    // Judged on every row read: a unit off by a factor moves rows across the filters.
    let wall_clock = clock.is_some_and(clock::Clock::is_wall);
    let implausible = unit_warnings(path, &columns, units, wall_clock, &all);
    let (rows_used, calibration, validation) = filter_and_split(&all, opts, path, &columns)?;
    let bit = seen_in_window(&all, opts);
    let mut warnings = implausible;
    warnings.extend(ambiguous_mnemonics(path, &columns, opts));
    warnings.extend(record_warnings(
        path,
        &columns,
        backwards,
        &calibration,
        &validation,
        rows_used,
    ));
    Ok(FieldData {
        source: path.to_path_buf(),
        torque_unit: units.torque,
        speed_unit: units.speed,
        columns,
        rows_read,
        rows_used,
        calibration,
        validation,
        warnings,
        bit,
        clock,
    })
}

/// A record from samples already in SI (a watch's window) of a source that `declared` its
/// channels' names and units: the options' filters, split and checks, as for a file's rows
/// (the options' columns and units are the source's business, and are not read), the values
/// judged in the units the source declared. A time column that runs backwards is said as in a
/// file, by its row.
pub fn field_data_from_samples(
    all: Samples,
    source: &Path,
    declared: &Declared,
    opts: &DataOptions,
) -> Result<FieldData> {
    opts.validate()?;
    // The columns a map names are named: no note on their names.
    let opts = &mnemonics::ColumnMap::apply(opts)?;
    if all.is_empty() {
        return Err(Error::Data {
            path: source.to_path_buf(),
            message: "no data rows".into(),
        });
    }
    let backwards = all.time_s.as_ref().and_then(|t| {
        let row = t.windows(2).position(|w| w[1] < w[0])? + 1;
        Some((format!("{} row {row}", source.display()), t[row - 1], t[row]))
    });
    let Declared { columns, units, .. } = declared.clone();
    let columns = ColumnsUsed {
        wob: columns.wob.filter(|_| all.wob_n.is_some()),
        time: columns.time.filter(|_| all.time_s.is_some()),
        ..columns
    };
    assemble_columns(all, backwards, None, columns, &units, opts, source)
}

/// Whether row `i` of `all` lies in the options' time window (every row without a time column).
fn in_time_window(all: &Samples, opts: &DataOptions, i: usize) -> bool {
    match &all.time_s {
        Some(t) => opts.t_start_s.is_none_or(|a| t[i] >= a) && opts.t_end_s.is_none_or(|b| t[i] <= b),
        None => true,
    }
}

/// What the bit did in the record's time window, every row counted.
fn seen_in_window(all: &Samples, opts: &DataOptions) -> Option<BitSeen> {
    let window = all.pick(|i| in_time_window(all, opts, i));
    BitSeen::of(&window.speed_rad_s, window.wob_n.as_deref())
}

/// A CSV reader's error as a format error of `path`, at its line where known.
fn csv_error(path: &Path, e: csv::Error) -> Error {
    Error::Format {
        path: path.to_path_buf(),
        line: e.position().map(|p| p.line()),
        message: e.to_string(),
    }
}

/// Refuses a header line that is empty or names a column twice: columns are found by name.
fn check_headers(headers: &csv::StringRecord, path: &Path) -> Result<()> {
    if headers.is_empty() {
        return Err(Error::Format {
            path: path.to_path_buf(),
            line: Some(1),
            message: "empty file: expected a header line".into(),
        });
    }
    if let Some(duplicate) = headers
        .iter()
        .enumerate()
        .find_map(|(i, h)| headers.iter().skip(i + 1).any(|g| g == h).then_some(h))
    {
        return Err(Error::Format {
            path: path.to_path_buf(),
            line: Some(1),
            message: format!("two columns are named '{duplicate}'; rename one"),
        });
    }
    Ok(())
}

/// One row of a record in SI, as a stream reads it (see [`RowLayout`], and
/// [`surface::SurfaceRowLayout`] for a record of surface channels).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Row {
    /// Time, s, where the record has a time column.
    pub time_s: Option<f64>,
    /// The bit's speed and torque; `None` in a record of surface channels, whose surface
    /// torque is never read as the bit's.
    pub bit: Option<BitReading>,
    /// Weight on bit, N, where the record has a column for it.
    pub wob_n: Option<f64>,
    /// Top-drive (surface) speed, rad/s, where the reader of the stream has a column for it
    /// (a watch's operating point; a surface record's drive); `None` from [`RowLayout::row`].
    pub top_drive_rad_s: Option<f64>,
    /// Surface torque, N·m, in a record of surface channels.
    pub surface_torque_nm: Option<f64>,
    /// The bit's depth, m, where the record has a depth column whose name says its unit
    /// ([`depth_column`]): shown beside a window, never inferred from.
    pub depth_m: Option<f64>,
}

/// The bit's own channels in a row, SI.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BitReading {
    pub speed_rad_s: f64,
    pub torque_nm: f64,
}

/// How the rows of a record are read one at a time (a stream that grows): the columns and
/// their units chosen from its header by the rules that read a whole file.
pub struct RowLayout {
    headers: csv::StringRecord,
    indices: ColumnIndices,
    units: ColumnUnits,
    /// The time column's clock, decided at its first cell.
    time: clock::TimeReader,
    /// The depth column and its unit, where the record has one ([`depth_column`]).
    depth: Option<(usize, crate::units::LengthUnit)>,
    delimiter: u8,
    path: PathBuf,
}

impl RowLayout {
    /// The layout of a record whose header is `headers` (fields separated by `delimiter`);
    /// refuses what [`parse_field_data`] refuses of a header.
    pub fn new(headers: &csv::StringRecord, delimiter: u8, opts: &DataOptions, path: &Path) -> Result<Self> {
        opts.validate()?;
        let opts = &mnemonics::ColumnMap::apply(opts)?;
        check_headers(headers, path)?;
        let indices = ColumnIndices::resolve(headers, opts, path)?;
        let units = ColumnUnits::resolve(headers, &indices, opts, path)?;
        Ok(Self {
            headers: headers.clone(),
            time: clock::TimeReader::new(units.time_in_ms),
            depth: depth_column(headers).filter(|(i, _)| {
                ![Some(indices.speed), Some(indices.torque), indices.wob, indices.time].contains(&Some(*i))
            }),
            indices,
            units,
            delimiter,
            path: path.to_path_buf(),
        })
    }

    /// The header's names.
    pub fn headers(&self) -> &csv::StringRecord {
        &self.headers
    }

    /// The header's indices of the columns read (speed, torque, and weight on bit and time
    /// where the record has them), in the header's order.
    pub fn used_columns(&self) -> Vec<usize> {
        let mut used: Vec<usize> = [
            Some(self.indices.speed),
            Some(self.indices.torque),
            self.indices.wob,
            self.indices.time,
        ]
        .into_iter()
        .flatten()
        .collect();
        used.sort_unstable();
        used
    }

    /// How the time column reads, once a row has been read.
    pub fn clock(&self) -> Option<clock::Clock> {
        self.time.clock()
    }

    /// The torque unit of the record's torque column.
    pub fn torque_unit(&self) -> TorqueUnit {
        self.units.torque
    }

    /// The columns read and their units.
    pub fn declared(&self) -> Declared {
        let name = |i: usize| self.headers[i].trim().to_string();
        Declared {
            columns: ColumnsUsed {
                speed: name(self.indices.speed),
                torque: name(self.indices.torque),
                wob: self.indices.wob.map(name),
                time: self.indices.time.map(name),
            },
            units: self.units,
            top_drive: None,
            surface: None,
        }
    }

    /// Record `record` (on `line`) in SI; a cell that is not a finite number is refused
    /// naming its line and column, as in a whole file.
    pub fn row(&self, record: &csv::StringRecord, line: u64) -> Result<Row> {
        let cell = |i: usize| parse_cell(record, i, line, &self.headers, self.delimiter, &self.path);
        Ok(Row {
            bit: Some(BitReading {
                speed_rad_s: self.units.speed.to_rad_s(cell(self.indices.speed)?),
                torque_nm: cell(self.indices.torque)? * self.units.torque.newton_metres(),
            }),
            surface_torque_nm: None,
            wob_n: match (self.indices.wob, self.units.wob) {
                (Some(i), Some(u)) => Some(cell(i)? * u.newtons()),
                _ => None,
            },
            time_s: self.indices.time.map(|i| self.time_cell(record, i, line)).transpose()?,
            top_drive_rad_s: None,
            // A depth cell that is no number leaves the row without a depth, never refused.
            depth_m: self.depth.and_then(|(i, unit)| {
                let value: f64 = record.get(i)?.trim().parse().ok()?;
                value.is_finite().then(|| value * unit.metres())
            }),
        })
    }
}

impl RowLayout {
    /// The time in column `i` of `record` (on `line`), s; refused naming its line and column.
    fn time_cell(&self, record: &csv::StringRecord, i: usize, line: u64) -> Result<f64> {
        self.time
            .text(record.get(i).unwrap_or(""))
            .map_err(|message| Error::Cell {
                path: self.path.clone(),
                line,
                column: i + 1,
                name: self.headers[i].to_string(),
                message,
            })
    }
}

/// The bit's depth column of a record whose header is `headers`, and its unit: the one column
/// a depth's name or mnemonic names ([`mnemonics::depth_rank`]), the bit's before the hole's,
/// whose name says its unit (`bit_depth_m`, `DBTM [ft]`). `None` where there is none, or where
/// that is ambiguous: a depth is shown beside a window, never inferred from, so that a record
/// is never refused for it.
pub fn depth_column(headers: &csv::StringRecord) -> Option<(usize, crate::units::LengthUnit)> {
    use crate::units::ColumnUnit;
    let ranked: Vec<(usize, usize)> = headers
        .iter()
        .enumerate()
        .filter_map(|(i, h)| mnemonics::depth_rank(h).map(|rank| (rank, i)))
        .collect();
    let best = ranked.iter().map(|(rank, _)| *rank).min()?;
    match ranked.iter().filter(|(rank, _)| *rank == best).collect::<Vec<_>>()[..] {
        [(_, i)] => crate::units::LengthUnit::declared_by(&headers[*i]).map(|unit| (*i, unit)),
        _ => None,
    }
}

/// Where the columns read sit in the header (0-based).
struct ColumnIndices {
    speed: usize,
    torque: usize,
    wob: Option<usize>,
    time: Option<usize>,
}

impl ColumnIndices {
    /// Each column by its option or its name's hint ([`resolve_column`]): speed and torque
    /// required, weight on bit and time when present. Refuses one column chosen for two roles.
    fn resolve(headers: &csv::StringRecord, opts: &DataOptions, path: &Path) -> Result<Self> {
        let speed = resolve_column(
            headers,
            opts.speed_column.as_deref(),
            "speed",
            mnemonics::Role::Speed,
            "speed_column",
            true,
            path,
        )?
        .expect("required");
        let torque = resolve_column(
            headers,
            opts.torque_column.as_deref(),
            "torque",
            mnemonics::Role::Torque,
            "torque_column",
            true,
            path,
        )?
        .expect("required");
        let wob = resolve_column(
            headers,
            opts.wob_column.as_deref(),
            "wob",
            mnemonics::Role::Wob,
            "wob_column",
            false,
            path,
        )?;
        let time = resolve_column(
            headers,
            opts.time_column.as_deref(),
            "time",
            mnemonics::Role::Time,
            "time_column",
            false,
            path,
        )?;
        let roles = [
            ("speed_column", Some(speed)),
            ("torque_column", Some(torque)),
            ("wob_column", wob),
            ("time_column", time),
        ];
        for (a, (field_a, i)) in roles.iter().enumerate() {
            if let Some((field_b, _)) = i.and_then(|i| roles[a + 1..].iter().find(|(_, j)| *j == Some(i))) {
                return Err(Error::Format {
                    path: path.to_path_buf(),
                    line: Some(1),
                    message: format!(
                        "column '{}' is chosen for both `{field_a}` and `{field_b}`; a column is one quantity",
                        &headers[i.expect("found")]
                    ),
                });
            }
        }
        Ok(Self {
            speed,
            torque,
            wob,
            time,
        })
    }
}

/// Units of the columns read.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ColumnUnits {
    pub speed: SpeedUnit,
    pub torque: TorqueUnit,
    pub wob: Option<ForceUnit>,
    /// Whether the time column's name says milliseconds (else seconds).
    pub time_in_ms: bool,
}

/// What a record's source declares of its channels: their names and their units. The record
/// checks judge its values in these units ([`field_data_from_samples`]), so that a channel whose
/// values do not fit its declared unit is said whether the record is read whole or watched.
#[derive(Clone, Debug, PartialEq)]
pub struct Declared {
    pub columns: ColumnsUsed,
    pub units: ColumnUnits,
    /// A top-drive speed column and its unit, where the source has one (a watch's operating
    /// point; `fit` reads none).
    pub top_drive: Option<(String, SpeedUnit)>,
    /// The columns of a source of surface channels, where it is one: then `columns` and
    /// `units` name its top-drive speed and surface torque, which no bit law is fitted to.
    pub surface: Option<surface::SurfaceColumns>,
}

impl ColumnUnits {
    /// The unit of each column read ([`resolve_unit`]), in the order speed, torque, weight on
    /// bit.
    fn resolve(headers: &csv::StringRecord, indices: &ColumnIndices, opts: &DataOptions, path: &Path) -> Result<Self> {
        let speed = resolve_unit(&headers[indices.speed], opts.speed_unit, "speed_unit", path)?;
        let torque = resolve_unit(&headers[indices.torque], opts.torque_unit, "torque_unit", path)?;
        let wob = match indices.wob {
            Some(i) => Some(resolve_unit(&headers[i], opts.wob_unit, "wob_unit", path)?),
            None => None,
        };
        Ok(Self {
            speed,
            torque,
            wob,
            time_in_ms: indices.time.is_some_and(|i| names_milliseconds(&headers[i])),
        })
    }
}

/// Whether a time column's name says milliseconds (as many loggers stamp): it ends in `_ms`,
/// `[ms]` or `(ms)`.
pub(crate) fn names_milliseconds(name: &str) -> bool {
    let name = name.trim().to_ascii_lowercase();
    ["_ms", "[ms]", "(ms)", " ms"]
        .iter()
        .any(|suffix| name.ends_with(suffix))
}

/// The first place the time column runs backwards: (where, previous time, time), s.
type Backwards = (String, f64, f64);

/// Every data row in SI, in file order, and the first place the time column runs backwards.
/// Refuses the first cell that is not a finite number, naming its line and column.
fn read_rows(
    records: impl Iterator<Item = Result<(csv::StringRecord, u64)>>,
    layout: &RowLayout,
) -> Result<(Samples, Option<Backwards>)> {
    let path = layout.path.as_path();
    let mut all = Samples {
        wob_n: layout.indices.wob.map(|_| Vec::new()),
        time_s: layout.indices.time.map(|_| Vec::new()),
        ..Samples::default()
    };
    let mut backwards: Option<Backwards> = None;
    for record in records {
        let (record, line) = record?;
        let row = layout.row(&record, line)?;
        let bit = row.bit.expect("a bit record's layout reads the bit's channels");
        all.speed_rad_s.push(bit.speed_rad_s);
        all.torque_nm.push(bit.torque_nm);
        if let (Some(w), Some(v)) = (row.wob_n, all.wob_n.as_mut()) {
            v.push(w);
        }
        if let (Some(t), Some(v)) = (row.time_s, all.time_s.as_mut()) {
            if let Some(&previous) = v.last()
                && t < previous
                && backwards.is_none()
            {
                backwards = Some((format!("{}:{line}", path.display()), previous, t));
            }
            v.push(t);
        }
    }
    Ok((all, backwards))
}

/// The number in column `i` (0-based) of `record`, on `line`; refuses text that is not a
/// finite number, hinting at decimal commas in a record not separated by commas.
pub(crate) fn parse_cell(
    record: &csv::StringRecord,
    i: usize,
    line: u64,
    headers: &csv::StringRecord,
    delimiter: u8,
    path: &Path,
) -> Result<f64> {
    let text = record.get(i).unwrap_or("");
    let fail = |message: String| Error::Cell {
        path: path.to_path_buf(),
        line,
        column: i + 1,
        name: headers[i].to_string(),
        message,
    };
    let v: f64 = text.parse().map_err(|_| {
        fail(if delimiter != b',' && text.contains(',') {
            format!("'{text}' is not a number (write decimals with a point, not a comma)")
        } else {
            format!("'{text}' is not a number")
        })
    })?;
    if v.is_finite() {
        Ok(v)
    } else {
        Err(fail(format!("'{text}' is not a finite number")))
    }
}

/// Above this median |torque| a column can hold no drill bit's torque in kN·m (the largest
/// field bits stay below about 60 kN·m): N·m is likelier.
pub const IMPLAUSIBLE_TORQUE_KNM: f64 = 100.0;
/// Below this 95th percentile of |bit speed| in rpm a record can hardly be a drill string's,
/// which turns at some 40–250 rpm (and stick-slip doubles that): rad/s (÷ 9.55) is likelier.
pub const IMPLAUSIBLE_LOW_RPM: f64 = 30.0;
/// Above this 95th percentile of |bit speed| in rad/s (about 955 rpm) rpm is likelier.
pub const IMPLAUSIBLE_HIGH_RAD_S: f64 = 100.0;
/// Above this median weight on bit in kN (200 tonnes) N is likelier.
pub const IMPLAUSIBLE_WOB_KN: f64 = 2000.0;

/// A median step between time stamps this long (s) is no record of stick-slip (cycles of
/// seconds): more likely a time column in milliseconds read as seconds.
const IMPLAUSIBLE_STEP_S: f64 = 5.0;

/// Units and signs that a drill string's record can hardly mean, judged on every row read
/// (`all`, SI) against the unit each column declares: a torque column in kN·m whose median
/// exceeds [`IMPLAUSIBLE_TORQUE_KNM`], a speed column in rpm whose 95th percentile of |speed|
/// is below [`IMPLAUSIBLE_LOW_RPM`] or one in rad/s above [`IMPLAUSIBLE_HIGH_RAD_S`], a weight
/// on bit in kN whose median exceeds [`IMPLAUSIBLE_WOB_KN`], and most non-zero speeds negative.
/// Each warning names the column, its unit and the likelier one.
fn unit_warnings(
    path: &Path,
    columns: &ColumnsUsed,
    units: &ColumnUnits,
    wall_clock: bool,
    all: &Samples,
) -> Vec<String> {
    let quantile = |values: &[f64], q: f64| -> f64 {
        crate::numerics::quantile(&values.iter().map(|x| x.abs()).collect::<Vec<_>>(), q)
    };
    let mut out = Vec::new();
    let source = path.display();
    let torque_knm = quantile(&all.torque_nm, 0.5) / 1000.0;
    if units.torque == TorqueUnit::KNm && torque_knm > IMPLAUSIBLE_TORQUE_KNM {
        out.push(format!(
            "{source}: the torques of column '{}' read in kN·m have a median of {torque_knm:.0} kN·m, beyond any drill bit's (above {IMPLAUSIBLE_TORQUE_KNM} kN·m): if the column holds N·m, say so with `torque_unit` nm (or a name ending in _nm)",
            columns.torque
        ));
    }
    let bit = SpeedChannel {
        what: "bit speeds",
        column: &columns.speed,
        unit: units.speed,
        setting: Some("speed_unit"),
    };
    out.extend(bit.unit_warning(&source.to_string(), &all.speed_rad_s));
    if let (Some(ForceUnit::KN), Some(wob), Some(name)) = (units.wob, &all.wob_n, &columns.wob) {
        let wob_kn = quantile(wob, 0.5) / 1000.0;
        if wob_kn > IMPLAUSIBLE_WOB_KN {
            out.push(format!(
                "{source}: the weights on bit of column '{name}' read in kN have a median of {wob_kn:.0} kN, beyond any drill string's (above {IMPLAUSIBLE_WOB_KN} kN): if the column holds N, say so with `wob_unit` n (or a name ending in _n)"
            ));
        }
    }
    if let (Some(time), Some(name)) = (&all.time_s, &columns.time)
        && !units.time_in_ms
        && !wall_clock
    {
        let steps: Vec<f64> = time.windows(2).map(|w| w[1] - w[0]).filter(|d| *d > 0.0).collect();
        let step = crate::numerics::median(&steps).unwrap_or(0.0);
        if step >= IMPLAUSIBLE_STEP_S {
            out.push(format!(
                "{source}: the time stamps of column '{name}' read in seconds step by {step} s (a median; {:.3} Hz), where a record of stick-slip samples many times a second: if the column holds milliseconds, name it '{name}_ms'",
                1.0 / step
            ));
        }
    }
    let negative = all.speed_rad_s.iter().filter(|&&w| w < 0.0).count();
    let positive = all.speed_rad_s.iter().filter(|&&w| w > 0.0).count();
    if negative > positive {
        out.push(format!(
            "{source}: {negative} of the {} bit speeds of column '{}' are negative: the laws hold for a bit turning forward, and rows below the minimum speed are dropped; check the sign convention of the column",
            all.len(),
            columns.speed
        ));
    }
    out
}

/// A speed channel as a source declares it: what it measures (for messages), its column, its
/// unit and the setting that names the unit (`None`: its name's suffix alone).
pub struct SpeedChannel<'a> {
    pub what: &'a str,
    pub column: &'a str,
    pub unit: SpeedUnit,
    pub setting: Option<&'a str>,
}

impl SpeedChannel<'_> {
    /// What `speeds_rad_s` (read in the declared unit) say of that unit, where a drill string
    /// can hardly mean it (`source` names the record): rpm whose 95th percentile of |speed| is
    /// below 30 rpm (rad/s?), rad/s whose 95th percentile exceeds 100 rad/s (rpm?).
    pub fn unit_warning(&self, source: &str, speeds_rad_s: &[f64]) -> Option<String> {
        let abs: Vec<f64> = speeds_rad_s.iter().map(|x| x.abs()).collect();
        let speed_rad_s = crate::numerics::quantile(&abs, 0.95);
        let speed_rpm = speed_rad_s / RAD_S_PER_RPM;
        let (what, column) = (self.what, self.column);
        let say = |unit: &str, suffix: &str| match self.setting {
            Some(setting) => format!("say so with `{setting}` {unit} (or a name ending in {suffix})"),
            None => format!("name it …{suffix}"),
        };
        match self.unit {
            SpeedUnit::Rpm if speed_rpm < IMPLAUSIBLE_LOW_RPM => Some(format!(
                "{source}: the {what} of column '{column}' read in rpm stay below {speed_rpm:.1} rpm (95 % of them), where a drill string turns at some 40–250 rpm: if the column holds rad/s, {}",
                say("rad_s", "_rad_s")
            )),
            SpeedUnit::RadS if speed_rad_s > IMPLAUSIBLE_HIGH_RAD_S => Some(format!(
                "{source}: the {what} of column '{column}' read in rad/s reach {speed_rad_s:.0} rad/s ({speed_rpm:.0} rpm) in 5 % of the rows: if the column holds rpm, {}",
                say("rpm", "_rpm")
            )),
            _ => None,
        }
    }
}

/// The bit's speed or torque found by a mnemonic that rig logs also give the surface channel
/// (`RPM`, `TQ`) without a downhole mark: said, since surface channels are never to be fitted
/// as the bit's.
fn ambiguous_mnemonics(path: &Path, columns: &ColumnsUsed, opts: &DataOptions) -> Vec<String> {
    [
        (&columns.speed, opts.speed_column.is_some(), "speed", "speed_column"),
        (&columns.torque, opts.torque_column.is_some(), "torque", "torque_column"),
    ]
    .into_iter()
    .filter(|(name, named, _, _)| !named && mnemonics::ambiguous(name))
    .map(|(name, _, what, field)| {
        format!(
            "{}: column '{name}' is read as the bit's {what}, as downhole tools name it; rig logs name the surface channel so too: if it was measured at the surface, infer the law with `bitrock surface`, and to read it as the bit's without this note name it with `{field}`",
            path.display()
        )
    })
    .collect()
}

/// What the record looks wrong in without being unusable: a time column that runs backwards
/// (`backwards`), or more than half the torques used negative.
fn record_warnings(
    path: &Path,
    columns: &ColumnsUsed,
    backwards: Option<Backwards>,
    calibration: &Samples,
    validation: &Samples,
    rows_used: usize,
) -> Vec<String> {
    let mut warnings = Vec::new();
    if let Some((place, previous, t)) = backwards {
        warnings.push(format!(
            "{place}: the time column '{}' runs backwards (t = {t} s after {previous} s): rows are used in file order, and the time window and the block split assume time order",
            columns.time.as_deref().unwrap_or("time")
        ));
    }
    let used = calibration.torque_nm.iter().chain(&validation.torque_nm);
    let negative = used.clone().filter(|&&y| y < 0.0).count();
    if 2 * negative > rows_used {
        warnings.push(format!(
            "{}: {negative} of the {rows_used} torques used are negative: the laws give a positive torque on bit for a turning bit; check the sign convention of column '{}'",
            path.display(),
            columns.torque
        ));
    }
    warnings
}

/// The filters (time window, then thinning, then the minimum bit speed) and the calibration /
/// validation split of every row read; the number of rows kept. Refuses a record left empty,
/// or whose kept or calibration torque is zero throughout.
fn filter_and_split(
    all: &Samples,
    opts: &DataOptions,
    path: &Path,
    columns: &ColumnsUsed,
) -> Result<(usize, Samples, Samples)> {
    let torque_column = &columns.torque;
    let rows_read = all.len();
    // Filters: time window, then thinning, then the minimum bit speed.
    let window: Vec<usize> = (0..rows_read).filter(|&i| in_time_window(all, opts, i)).collect();
    let min_speed = SpeedUnit::Rpm.to_rad_s(opts.min_speed_rpm);
    let kept: Vec<usize> = window
        .iter()
        .step_by(opts.thin)
        .copied()
        .filter(|&i| all.speed_rad_s[i] >= min_speed)
        .collect();
    if kept.is_empty() {
        return Err(Error::Data {
            path: path.to_path_buf(),
            message: format!(
                "no row left after filtering ({rows_read} read, {} in the time window, none with bit speed ≥ {} rpm after thinning by {}); relax `min_speed_rpm`, `t_start_s`/`t_end_s` or `thin`",
                window.len(),
                opts.min_speed_rpm,
                opts.thin
            ),
        });
    }
    let mut keep_mask = vec![false; rows_read];
    for &i in &kept {
        keep_mask[i] = true;
    }
    let used = all.pick(|i| keep_mask[i]);
    if used.torque_nm.iter().all(|&y| y == 0.0) {
        return Err(Error::Data {
            path: path.to_path_buf(),
            message: format!(
                "every kept torque value in column '{torque_column}' is zero: the misfit ρ = ‖y − T‖²/‖y‖² is undefined"
            ),
        });
    }

    let n = used.len();
    let f = opts.calibration_fraction;
    let in_calibration = |i: usize| match opts.split {
        SplitRule::Block => (i as f64) < (f * n as f64).ceil(),
        // Bresenham: row i calibrates when the running quota floor((i+1)f) steps up.
        SplitRule::Interleaved => ((i + 1) as f64 * f).floor() > (i as f64 * f).floor(),
    };
    let calibration = used.pick(in_calibration);
    let validation = used.pick(|i| !in_calibration(i));
    if calibration.torque_nm.iter().all(|&y| y == 0.0) {
        return Err(Error::Data {
            path: path.to_path_buf(),
            message:
                "every calibration torque is zero: the misfit ρ is undefined; change `calibration_fraction` or `split`"
                    .into(),
        });
    }
    check_fittable(&calibration, path, columns)?;

    Ok((n, calibration, validation))
}

/// Largest |torque| a record may have, N·m: a hundred times the largest top drive's (about
/// 1e5 N·m), and where f32 sums of squared residuals on the GPU stay finite.
pub const MAX_TORQUE_NM: f64 = 1e9;
/// Smallest largest-|torque| of a record, N·m: far below a bench rig's (about 0.1 N·m); below
/// it the squares the fit and the GPU sum leave f32's normal range.
pub const MIN_TORQUE_NM: f64 = 1e-6;

/// Largest bit speed a record may have, rad/s (about 95,000 rpm): a hundred times a
/// turbodrill's, and where the fit's speed-cubed scales stay finite.
pub const MAX_SPEED_RAD_S: f64 = 1e4;

/// Relative difference below which two bit speeds count as the same: 10⁻⁹ of the largest,
/// far below any tachometer's resolution and far above f64's rounding.
pub const SAME_SPEED_TOLERANCE: f64 = 1e-9;

/// Refuses calibration samples that no law can be fitted to, saying why: bit speed constant
/// (identical rows among them: the laws are told apart only by how torque changes with speed),
/// or speeds above [`MAX_SPEED_RAD_S`] or torques outside [`MIN_TORQUE_NM`]..[`MAX_TORQUE_NM`]
/// (a unit or scaling error).
fn check_fittable(calibration: &Samples, path: &Path, columns: &ColumnsUsed) -> Result<()> {
    let (speed_column, torque_column) = (&columns.speed, &columns.torque);
    let fail = |message: String| {
        Err(Error::Data {
            path: path.to_path_buf(),
            message,
        })
    };
    let (lo, hi) = calibration
        .speed_rad_s
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &w| (a.min(w), b.max(w)));
    if hi - lo <= SAME_SPEED_TOLERANCE * hi.abs() {
        return fail(format!(
            "every calibration row has bit speed {lo} rad/s: the laws are fitted to how torque changes with speed, and a constant speed cannot tell them apart (or fix their parameters)"
        ));
    }
    let fastest = lo.abs().max(hi.abs());
    if fastest > MAX_SPEED_RAD_S {
        return fail(format!(
            "the largest |bit speed| in column '{speed_column}' is {fastest:.3e} rad/s ({:.3e} rpm), above {MAX_SPEED_RAD_S:e} rad/s (about 95,000 rpm), far beyond any drill bit; check the column's unit (`speed_unit`)",
            fastest / RAD_S_PER_RPM
        ));
    }
    let largest = calibration.torque_nm.iter().fold(0.0f64, |m, y| m.max(y.abs()));
    if !(MIN_TORQUE_NM..=MAX_TORQUE_NM).contains(&largest) {
        return fail(format!(
            "the largest |torque| in column '{torque_column}' is {largest:e} N·m, outside {MIN_TORQUE_NM:e}..{MAX_TORQUE_NM:e} N·m where a drill string's lies and the fit's arithmetic holds; check the column's unit (`torque_unit`)"
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str, opts: &DataOptions) -> Result<FieldData> {
        parse_field_data(text.as_bytes(), Path::new("x.csv"), opts)
    }

    const GOOD: &str =
        "time_s,bit_speed_rpm,torque_knm,wob_kn\n0,60,10,240\n0.02,2,11,241\n0.04,90,9,242\n0.06,120,8,243\n";

    #[test]
    fn the_bit_s_depth_is_read_where_its_name_says_its_unit_and_never_refuses_a_row() {
        let layout = |header: &str| {
            let headers = csv::StringRecord::from(header.split(',').collect::<Vec<_>>());
            RowLayout::new(&headers, b',', &DataOptions::default(), Path::new("x.csv")).unwrap()
        };
        let row = |layout: &RowLayout, line: &str| {
            layout
                .row(&csv::StringRecord::from(line.split(',').collect::<Vec<_>>()), 2)
                .unwrap()
        };
        // The bit's depth before the hole's; feet converted at the edge.
        let both = layout("time_s,bit_speed_rpm,torque_knm,hole_depth_m,DBTM [ft]");
        assert_eq!(row(&both, "0,60,10,1525.0,5000").depth_m, Some(5000.0 * 0.3048));
        // A cell that is no number leaves the row without a depth.
        assert_eq!(row(&both, "0,60,10,1525.0,-999.25x").depth_m, None);
        assert_eq!(row(&both, "0,60,10,1525.0,").depth_m, None);
        assert_eq!(
            row(&layout("bit_speed_rpm,torque_knm,depth_m"), "60,10,1525.5").depth_m,
            Some(1525.5)
        );
        // No unit in its name, or two depths alike: no depth, and the record reads.
        assert_eq!(
            row(&layout("bit_speed_rpm,torque_knm,depth"), "60,10,1525.5").depth_m,
            None
        );
        assert_eq!(
            row(&layout("bit_speed_rpm,torque_knm,md_depth_m,tvd_depth_m"), "60,10,1,2").depth_m,
            None
        );
    }

    #[test]
    fn an_mwd_tool_s_downhole_extremes_beside_the_bit_s_speed_are_not_its_speed() {
        let text = "time_s,bit_speed_rpm,bit_speed_max_rpm,torque_knm\n0,60,90,10\n0.02,30,60,11\n0.04,90,95,9\n0.06,120,125,8\n";
        let all = DataOptions {
            calibration_fraction: 1.0,
            ..Default::default()
        };
        let d = parse(text, &all).unwrap();
        assert_eq!(d.columns.speed, "bit_speed_rpm");
        // Alone, an extreme is no speed of the bit's: the record is refused naming the setting.
        let e = parse(
            "time_s,DRPM_MAX,torque_knm\n0,60,10\n0.02,2,11\n",
            &DataOptions::default(),
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("speed_column"), "{e}");
    }

    #[test]
    fn reads_si_and_filters_slow_rows() {
        let d = parse(
            GOOD,
            &DataOptions {
                calibration_fraction: 1.0,
                ..Default::default()
            },
        )
        .unwrap();
        assert_eq!(d.rows_read, 4);
        assert_eq!(d.rows_used, 3);
        let w = &d.calibration.speed_rad_s;
        assert!((w[0] - 2.0 * std::f64::consts::PI).abs() < 1e-12);
        assert_eq!(d.calibration.torque_nm, vec![10_000.0, 9_000.0, 8_000.0]);
        assert_eq!(
            d.calibration.wob_n.as_ref().unwrap(),
            &vec![240_000.0, 242_000.0, 243_000.0]
        );
        assert_eq!(d.torque_unit, TorqueUnit::KNm);
    }

    #[test]
    fn block_and_interleaved_splits() {
        let text: String = std::iter::once("speed_rad_s,torque_nm".to_string())
            .chain((0..10).map(|i| format!("{},{}", 1 + i, 100 + i)))
            .collect::<Vec<_>>()
            .join("\n");
        let block = parse(
            &text,
            &DataOptions {
                calibration_fraction: 0.3,
                ..Default::default()
            },
        )
        .unwrap();
        assert_eq!(block.calibration.torque_nm, vec![100.0, 101.0, 102.0]);
        assert_eq!(block.validation.len(), 7);
        let inter = parse(
            &text,
            &DataOptions {
                calibration_fraction: 0.5,
                split: SplitRule::Interleaved,
                ..Default::default()
            },
        )
        .unwrap();
        assert_eq!(inter.calibration.torque_nm, vec![101.0, 103.0, 105.0, 107.0, 109.0]);
        assert_eq!(inter.validation.torque_nm, vec![100.0, 102.0, 104.0, 106.0, 108.0]);
    }

    #[test]
    fn window_and_thinning() {
        let opts = DataOptions {
            t_start_s: Some(0.01),
            t_end_s: Some(0.07),
            thin: 2,
            calibration_fraction: 1.0,
            min_speed_rpm: 0.0,
            ..Default::default()
        };
        let d = parse(GOOD, &opts).unwrap();
        // window keeps rows 2..4, thinning keeps rows 2 and 4.
        assert_eq!(d.calibration.torque_nm, vec![11_000.0, 8_000.0]);
    }

    #[test]
    fn semicolon_and_tab_records_read_as_comma_ones() {
        let opts = DataOptions {
            calibration_fraction: 1.0,
            ..Default::default()
        };
        let comma = parse(GOOD, &opts).unwrap();
        for delimiter in [";", "\t", "; "] {
            let text = format!("# a comment, with a comma\n{}", GOOD.replace(',', delimiter));
            let d = parse(&text, &opts).unwrap_or_else(|e| panic!("{delimiter:?}: {e}"));
            assert_eq!(d.columns, comma.columns, "{delimiter:?}");
            assert_eq!(d.calibration, comma.calibration, "{delimiter:?}");
        }
        // A decimal comma in a semicolon record is named as such, at its line and column.
        let e = parse("speed_rpm;torque_knm\n60;1,5\n", &opts).unwrap_err().to_string();
        assert_eq!(
            e,
            "x.csv:2:2: column 'torque_knm': '1,5' is not a number (write decimals with a point, not a comma)"
        );
        // Both separators and no comma: refused, naming both.
        let e = parse("time_s;speed_rpm\ttorque_knm\n0;60\t1\n", &opts).unwrap_err();
        assert!(e.is_bad_input());
        assert!(e.to_string().contains("both ';' and tab"), "{e}");
    }

    #[test]
    fn errors_name_line_and_column() {
        let bad = "time_s,bit_speed_rpm,torque_knm\n0,60,10\n0.02,abc,11\n";
        let e = parse(bad, &DataOptions::default()).unwrap_err().to_string();
        assert_eq!(e, "x.csv:3:2: column 'bit_speed_rpm': 'abc' is not a number");
        let nan = "time_s,bit_speed_rpm,torque_knm\n0,60,10\n0.02,60,inf\n";
        let e = parse(nan, &DataOptions::default()).unwrap_err().to_string();
        assert_eq!(e, "x.csv:3:3: column 'torque_knm': 'inf' is not a finite number");
        let e = parse(
            "a_rpm,torque_nm\n1,2\n",
            &DataOptions {
                speed_column: Some("w".into()),
                ..Default::default()
            },
        )
        .unwrap_err();
        assert!(e.to_string().contains("no column named 'w'"), "{e}");
        let e = parse("speed,torque_nm\n60,2\n", &DataOptions::default()).unwrap_err();
        assert!(e.to_string().contains("speed_unit"), "{e}");
        let e = parse("speed_rpm,torque_nm\n60,0\n70,0\n", &DataOptions::default()).unwrap_err();
        assert!(e.to_string().contains("zero"), "{e}");
        let e = parse("speed_rpm,torque_nm\n1,3\n", &DataOptions::default()).unwrap_err();
        assert!(e.to_string().contains("no row left"), "{e}");
        let e = parse("speed_rpm,torque_nm\n60,3,4\n", &DataOptions::default()).unwrap_err();
        assert!(e.to_string().starts_with("x.csv:2:"), "{e}");
        let e = parse(
            "speed_rpm,torque_knm\n60,3\n",
            &DataOptions {
                torque_unit: Some(TorqueUnit::Nm),
                ..Default::default()
            },
        )
        .unwrap_err();
        assert!(e.to_string().contains("declares kN·m"), "{e}");
        assert!(e.is_bad_input());
    }

    /// The columns of a CSV, as a DataFrame would hand them over.
    fn columns_of(text: &str) -> (Vec<String>, Vec<Vec<f64>>) {
        let mut lines = text.lines();
        let names: Vec<String> = lines.next().unwrap().split(',').map(String::from).collect();
        let mut columns = vec![Vec::new(); names.len()];
        for line in lines {
            for (column, cell) in columns.iter_mut().zip(line.split(',')) {
                column.push(cell.parse().unwrap());
            }
        }
        (names, columns)
    }

    fn from_columns(names: &[String], columns: &[Vec<f64>], opts: &DataOptions) -> Result<FieldData> {
        let slices: Vec<Option<&[f64]>> = columns.iter().map(|c| Some(c.as_slice())).collect();
        field_data_from_columns(names, &slices, Path::new("<DataFrame>"), opts)
    }

    #[test]
    fn columns_in_memory_read_as_the_same_csv_does() {
        let text = "time_s,bit_speed_rpm,torque_knm,wob_kn\n0,60,10,240\n0.02,2,11,241\n0.04,90,9,242\n0.01,120,8,243\n0.08,100,8.5,244\n";
        let (names, columns) = columns_of(text);
        for opts in [
            DataOptions::default(),
            DataOptions {
                split: SplitRule::Interleaved,
                calibration_fraction: 0.6,
                ..Default::default()
            },
        ] {
            let csv = parse(text, &opts).unwrap();
            let mem = from_columns(&names, &columns, &opts).unwrap();
            assert_eq!(mem.calibration, csv.calibration);
            assert_eq!(mem.validation, csv.validation);
            assert_eq!((mem.rows_read, mem.rows_used), (csv.rows_read, csv.rows_used));
            assert_eq!(mem.columns, csv.columns);
            assert_eq!(mem.torque_unit, TorqueUnit::KNm);
            // The same warning (time runs backwards at 0.01 s), placed by row, not line.
            assert_eq!(mem.warnings.len(), 1);
            assert!(
                mem.warnings[0].starts_with("<DataFrame> row 3: the time column"),
                "{:?}",
                mem.warnings
            );
            assert!(
                csv.warnings[0].starts_with("x.csv:5: the time column"),
                "{:?}",
                csv.warnings
            );
        }
    }

    #[test]
    fn columns_in_memory_are_refused_naming_column_and_row() {
        let (names, mut columns) = columns_of(GOOD);
        columns[2][1] = f64::NAN;
        let e = from_columns(&names, &columns, &DataOptions::default()).unwrap_err();
        assert_eq!(
            e.to_string(),
            "<DataFrame>: column 'torque_knm', row 1: NaN is not a finite number"
        );
        assert!(e.is_bad_input());

        let (names, mut columns) = columns_of(GOOD);
        columns[0].pop();
        let e = from_columns(&names, &columns, &DataOptions::default()).unwrap_err();
        assert_eq!(
            e.to_string(),
            "<DataFrame>: column 'bit_speed_rpm' has 4 rows, column 'time_s' 3"
        );

        // A column without numbers is refused when chosen, and only then.
        let (names, columns) = columns_of(GOOD);
        let mut slices: Vec<Option<&[f64]>> = columns.iter().map(|c| Some(c.as_slice())).collect();
        slices[3] = None;
        let source = Path::new("<DataFrame>");
        let e = field_data_from_columns(&names, &slices, source, &DataOptions::default()).unwrap_err();
        assert_eq!(e.to_string(), "<DataFrame>: column 'wob_kn' does not hold numbers");
        slices[3] = Some(&columns[3]);
        slices[0] = None;
        let opts = DataOptions {
            time_column: Some("time_s".into()),
            ..Default::default()
        };
        assert!(field_data_from_columns(&names, &slices, source, &opts).is_err());
        let renamed: Vec<String> = ["comment", "bit_speed_rpm", "torque_knm", "wob_kn"]
            .map(String::from)
            .to_vec();
        let d = field_data_from_columns(&renamed, &slices, source, &DataOptions::default()).unwrap();
        assert_eq!(d.rows_read, 4);

        let (mut names, columns) = columns_of(GOOD);
        names[2] = "torque".into();
        let e = from_columns(&names, &columns, &DataOptions::default()).unwrap_err();
        assert_eq!(
            e.to_string(),
            "<DataFrame>: cannot tell the unit of column 'torque' from its name; give `torque_unit`"
        );
    }
}
