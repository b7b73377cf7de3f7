//! Records of what a rig streams from the surface: top-drive speed, surface torque and,
//! where present, weight on bit, on a regular clock. Columns are found by role: a name holding
//! `top_drive` or `rotary` (and not `torque`) is the top drive's speed, one holding `torque`
//! and `surface` (or `top_drive`, `rotary`) the surface torque, one holding `wob` the weight on
//! bit, one holding `time` the clock; else a rig log's mnemonic for the role (`RPMA`, `TQA`,
//! `SWOB`, `DTIM`: [`super::mnemonics::surface_role`]); each can be named instead. Units come
//! from the names' suffixes or bracketed units, or the options, and the clock is read as a bit
//! record's (elapsed, epoch or ISO 8601 stamps). The bit's channels, where a record also holds
//! them, are listed and left alone: surface torque is never read as torque on bit, nor the
//! reverse.

use super::{is_surface_channel, names_milliseconds, resolve_unit};
use crate::error::{Error, Result};
use crate::files::{csv_rows, csv_with_header};
use crate::units::{ForceUnit, SpeedUnit, TorqueUnit};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Which columns of a surface record to read, and in which units.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SurfaceOptions {
    /// Time column (s, or ms by its name); `None` finds the one whose name holds `time`.
    pub time_column: Option<String>,
    /// Top-drive speed column; `None` finds the one whose name holds `top_drive` or `rotary`.
    pub top_drive_column: Option<String>,
    /// Surface torque column; `None` finds the one surface channel whose name holds `torque`.
    pub surface_torque_column: Option<String>,
    /// Weight-on-bit column; `None` uses the one whose name holds `wob`, if any.
    pub wob_column: Option<String>,
    pub top_drive_unit: Option<SpeedUnit>,
    pub torque_unit: Option<TorqueUnit>,
    pub wob_unit: Option<ForceUnit>,
    /// An MWD tool's downhole minimum bit speed column; `None` finds the one downhole speed
    /// whose name says `min` (`downhole_min_rpm`, `DRPM_MIN`), if any.
    pub downhole_min_column: Option<String>,
    /// Its maximum's column; `None` finds the one downhole speed whose name says `max`.
    pub downhole_max_column: Option<String>,
    pub downhole_unit: Option<SpeedUnit>,
    /// The window the tool takes its minimum and maximum over (s); `None`: the record's clock
    /// period (each sample's extremes since the sample before).
    pub downhole_window_s: Option<f64>,
    /// Read no downhole channel, for a reader that does not use them: an MWD tool's columns
    /// are then left alone, as the bit's are. Not stored: it is the reader's, not the record's.
    #[serde(skip)]
    pub ignore_downhole: bool,
}

/// The columns a surface record was read from, by role.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SurfaceColumns {
    pub time: String,
    pub top_drive: String,
    pub surface_torque: String,
    pub wob: Option<String>,
    /// Bit channels the record also holds (bit speed, torque on bit), not read here.
    pub bit: Vec<String>,
    /// An MWD tool's downhole minimum and maximum bit speed, where the record holds them.
    #[serde(default)]
    pub downhole_min: Option<String>,
    #[serde(default)]
    pub downhole_max: Option<String>,
}

/// An MWD tool's downhole stick-slip channels: the bit speed's minimum and maximum over a
/// window ending at each sample (rad/s), either or both.
#[derive(Clone, Debug)]
pub struct DownholeChannels {
    pub least_rad_s: Option<Vec<f64>>,
    pub greatest_rad_s: Option<Vec<f64>>,
    pub unit: SpeedUnit,
    /// The window as the user gave it (s), and in whole samples of the clock.
    pub window_s: f64,
    pub window_samples: usize,
}

/// A surface record in SI on its regular clock.
#[derive(Clone, Debug)]
pub struct SurfaceRecord {
    pub source: PathBuf,
    pub columns: SurfaceColumns,
    pub top_drive_unit: SpeedUnit,
    pub torque_unit: TorqueUnit,
    /// Sample times (s) from the record's first.
    pub time_s: Vec<f64>,
    /// Top-drive speed Ω (rad/s).
    pub top_drive_rad_s: Vec<f64>,
    /// Surface torque (N·m).
    pub surface_torque_nm: Vec<f64>,
    /// Weight on bit (N), where recorded.
    pub wob_n: Option<Vec<f64>>,
    /// The clock's period (s): the median spacing of the stamps.
    pub sample_period_s: f64,
    /// An MWD tool's downhole minimum and maximum bit speed, where the record holds them.
    pub downhole: Option<DownholeChannels>,
}

/// Most a stamp's spacing may differ from the clock's period, as a share of it: the string is
/// simulated on the record's clock, so a record with gaps or jitter beyond this is refused.
pub const CLOCK_TOLERANCE: f64 = 0.01;

/// Fewest samples a surface record must hold: summaries of fewer say nothing of a cycle.
pub const MIN_SAMPLES: usize = 30;

impl SurfaceRecord {
    /// Reads the surface record at `path` (a CSV with a header).
    pub fn read(path: &Path, opts: &SurfaceOptions) -> Result<Self> {
        let (mut reader, header) = csv_with_header(path)?;
        let roles = Roles::resolve(&header, opts, path)?;
        let mut time_s = Vec::new();
        let mut top_drive_rad_s = Vec::new();
        let mut surface_torque_nm = Vec::new();
        let mut wob_n = roles.wob.map(|_| Vec::new());
        let mut least = roles.downhole_min.map(|_| Vec::new());
        let mut greatest = roles.downhole_max.map(|_| Vec::new());
        let mut lines = Vec::new();
        // Elapsed seconds or milliseconds, epoch seconds or milliseconds, or ISO 8601 stamps.
        let clock = super::clock::TimeReader::new(roles.time_in_ms);
        for row in csv_rows(&mut reader, path, &header) {
            let row = row?;
            time_s.push(
                clock
                    .text(row.cell(roles.time))
                    .map_err(|message| row.bad_cell(roles.time, message))?,
            );
            top_drive_rad_s.push(roles.top_drive_unit.to_rad_s(row.number(roles.top_drive)?));
            surface_torque_nm.push(row.number(roles.surface_torque)? * roles.torque_unit.newton_metres());
            if let (Some((i, unit)), Some(w)) = (roles.wob, wob_n.as_mut()) {
                w.push(row.number(i)? * unit.newtons());
            }
            for (column, values) in [(roles.downhole_min, &mut least), (roles.downhole_max, &mut greatest)] {
                if let (Some(i), Some(values)) = (column, values.as_mut()) {
                    values.push(roles.downhole_unit.to_rad_s(row.number(i)?));
                }
            }
            lines.push(row.line);
        }
        let columns = roles.columns(&|i| header[i].clone());
        let sample_period_s = check_clock(&time_s, path, &|k| format!("line {}", lines[k]))?;
        if least.is_none() && greatest.is_none() {
            let given = [
                ("downhole_unit", opts.downhole_unit.is_some()),
                ("downhole_window_s", opts.downhole_window_s.is_some()),
            ];
            if let Some((field, _)) = given.iter().find(|(_, given)| *given) {
                return Err(Error::setting(
                    *field,
                    "is given, but the record has no downhole minimum or maximum bit speed (a speed named beside `min` or `max`, or one named by `downhole_min_column` or `downhole_max_column`)",
                ));
            }
        }
        let downhole = if least.is_some() || greatest.is_some() {
            let window_s = opts.downhole_window_s.unwrap_or(sample_period_s);
            if !(window_s.is_finite() && window_s >= (1.0 - CLOCK_TOLERANCE) * sample_period_s) {
                return Err(Error::setting(
                    "downhole_window_s",
                    format!("must be at least the record's clock period {sample_period_s} s, got {window_s}"),
                ));
            }
            let window_samples = ((window_s / sample_period_s).round() as usize).max(1);
            if 2 * window_samples > time_s.len() {
                return Err(Error::setting(
                    "downhole_window_s",
                    format!(
                        "must be at most half the record ({} s), got {window_s}: the samples whose window lies inside the record are compared",
                        time_s.len() as f64 * sample_period_s / 2.0
                    ),
                ));
            }
            Some(DownholeChannels {
                window_samples,
                least_rad_s: least,
                greatest_rad_s: greatest,
                unit: roles.downhole_unit,
                window_s,
            })
        } else {
            None
        };
        let t0 = time_s[0];
        time_s.iter_mut().for_each(|t| *t -= t0);
        Ok(Self {
            source: path.to_path_buf(),
            columns,
            top_drive_unit: roles.top_drive_unit,
            torque_unit: roles.torque_unit,
            time_s,
            top_drive_rad_s,
            surface_torque_nm,
            wob_n,
            sample_period_s,
            downhole,
        })
    }

    /// Samples.
    pub fn len(&self) -> usize {
        self.time_s.len()
    }

    pub fn is_empty(&self) -> bool {
        self.time_s.is_empty()
    }

    /// Sample rate (Hz).
    pub fn sample_hz(&self) -> f64 {
        1.0 / self.sample_period_s
    }

    /// Recorded length (s): samples times the period.
    pub fn duration_s(&self) -> f64 {
        self.len() as f64 * self.sample_period_s
    }

    /// Mean top-drive speed (rad/s).
    pub fn mean_top_drive_rad_s(&self) -> f64 {
        self.top_drive_rad_s.iter().sum::<f64>() / self.len().max(1) as f64
    }

    /// Weight-on-bit ratio r = W/W_ref per sample: 1 where no weight is recorded or no
    /// reference is given.
    pub fn wob_ratio(&self, w_ref_n: Option<f64>) -> Vec<f64> {
        match (&self.wob_n, w_ref_n) {
            (Some(w), Some(w_ref)) => w.iter().map(|w| w / w_ref).collect(),
            _ => vec![1.0; self.len()],
        }
    }

    /// The roles found, in words: which column is what, in which unit, and what is left alone.
    pub fn roles_text(&self) -> String {
        let c = &self.columns;
        let mut text = format!(
            "top-drive speed from '{}' ({}), surface torque from '{}' ({}), ",
            c.top_drive,
            self.top_drive_unit.label(),
            c.surface_torque,
            self.torque_unit.label()
        );
        match &c.wob {
            Some(w) => text.push_str(&format!("weight on bit from '{w}'")),
            None => text.push_str("no weight on bit (the law's parameters hold at the record's weight)"),
        }
        if let Some(d) = &self.downhole {
            let named: Vec<String> = [("minimum", &c.downhole_min), ("maximum", &c.downhole_max)]
                .into_iter()
                .filter_map(|(what, column)| column.as_ref().map(|n| format!("{what} from '{n}'")))
                .collect();
            text.push_str(&format!(
                "; the MWD's downhole bit speed {} ({}, over {} sample(s), {} s)",
                named.join(" and "),
                d.unit.label(),
                d.window_samples,
                d.window_s
            ));
        }
        text.push_str(&format!(
            "; {} samples every {} s ({} s)",
            self.len(),
            self.sample_period_s,
            self.duration_s()
        ));
        if !c.bit.is_empty() {
            text.push_str(&format!(
                "; the bit's channels ({}) are not read: a record with them is calibrated by `bitrock fit` and `bitrock abc`",
                c.bit.join(", ")
            ));
        }
        text
    }
}

/// How the rows of a surface record are read one at a time (a watch's stream): its roles
/// found in its header by the rules that read a whole file ([`SurfaceRecord::read`]). Its
/// rows carry no bit channels: the bit's, where the header holds them, are left alone.
pub struct SurfaceRowLayout {
    roles: Roles,
    header: csv::StringRecord,
    clock: super::clock::TimeReader,
    delimiter: u8,
    path: PathBuf,
}

impl SurfaceRowLayout {
    /// The layout of a record whose header is `header` (fields separated by `delimiter`).
    pub fn new(header: &[String], delimiter: u8, opts: &SurfaceOptions, path: &Path) -> Result<Self> {
        let roles = Roles::resolve(header, opts, path)?;
        Ok(Self {
            clock: super::clock::TimeReader::new(roles.time_in_ms),
            roles,
            header: csv::StringRecord::from(header.to_vec()),
            delimiter,
            path: path.to_path_buf(),
        })
    }

    /// The bit's channels the header also holds (not read here).
    pub fn bit_channels(&self) -> Vec<&str> {
        self.roles.bit.iter().map(|&i| &self.header[i]).collect()
    }

    /// The columns read, by role.
    pub fn columns(&self) -> SurfaceColumns {
        self.roles.columns(&|i| self.header[i].to_string())
    }

    pub fn top_drive_unit(&self) -> SpeedUnit {
        self.roles.top_drive_unit
    }

    pub fn torque_unit(&self) -> TorqueUnit {
        self.roles.torque_unit
    }

    pub fn wob_unit(&self) -> Option<ForceUnit> {
        self.roles.wob.map(|(_, unit)| unit)
    }

    /// Record `record` (on `line`) in SI; a cell that is not a finite number is refused
    /// naming its line and column, as in a whole file.
    pub fn row(&self, record: &csv::StringRecord, line: u64) -> Result<super::Row> {
        let cell = |i: usize| super::parse_cell(record, i, line, &self.header, self.delimiter, &self.path);
        let r = &self.roles;
        let time_s = self
            .clock
            .text(record.get(r.time).unwrap_or(""))
            .map_err(|message| Error::Cell {
                path: self.path.clone(),
                line,
                column: r.time + 1,
                name: self.header[r.time].to_string(),
                message,
            })?;
        Ok(super::Row {
            time_s: Some(time_s),
            bit: None,
            wob_n: r.wob.map(|(i, unit)| cell(i).map(|w| w * unit.newtons())).transpose()?,
            top_drive_rad_s: Some(r.top_drive_unit.to_rad_s(cell(r.top_drive)?)),
            surface_torque_nm: Some(cell(r.surface_torque)? * r.torque_unit.newton_metres()),
            depth_m: None,
        })
    }
}

impl SurfaceRecord {
    /// A surface record of rows read one at a time (a watch's window), named `source`: its
    /// clock checked as a whole file's, its times from its first row's. Rows without a time,
    /// top-drive speed or surface torque are refused. Rows carry no MWD downhole channel: the
    /// record has none, whatever `columns` names.
    pub fn of_rows(
        rows: &[super::Row],
        source: &Path,
        columns: SurfaceColumns,
        top_drive_unit: SpeedUnit,
        torque_unit: TorqueUnit,
    ) -> Result<Self> {
        let channels: Option<Vec<(f64, f64, f64)>> = rows
            .iter()
            .map(|r| Some((r.time_s?, r.top_drive_rad_s?, r.surface_torque_nm?)))
            .collect();
        let channels = channels.ok_or_else(|| Error::Data {
            path: source.to_path_buf(),
            message: "a row without a time, a top-drive speed or a surface torque: not a surface record".into(),
        })?;
        let mut time_s: Vec<f64> = channels.iter().map(|c| c.0).collect();
        let sample_period_s = check_clock(&time_s, source, &|k| format!("sample {}", k + 1))?;
        let t0 = time_s.first().copied().unwrap_or(0.0);
        time_s.iter_mut().for_each(|t| *t -= t0);
        let wob_n: Option<Vec<f64>> = columns
            .wob
            .as_ref()
            .and_then(|_| rows.iter().map(|r| r.wob_n).collect());
        Ok(Self {
            source: source.to_path_buf(),
            columns: SurfaceColumns {
                downhole_min: None,
                downhole_max: None,
                ..columns
            },
            top_drive_unit,
            torque_unit,
            time_s,
            top_drive_rad_s: channels.iter().map(|c| c.1).collect(),
            surface_torque_nm: channels.iter().map(|c| c.2).collect(),
            wob_n,
            sample_period_s,
            downhole: None,
        })
    }
}

/// The clock's period (s), refusing a record too short, a clock that does not run forwards, or
/// one whose spacing departs from its median by more than [`CLOCK_TOLERANCE`]; `place(k)` names
/// sample k for the messages.
pub fn check_clock(time_s: &[f64], path: &Path, place: &dyn Fn(usize) -> String) -> Result<f64> {
    let refuse = |message: String| Error::Data {
        path: path.to_path_buf(),
        message,
    };
    if time_s.len() < MIN_SAMPLES {
        return Err(refuse(format!(
            "{} samples: a surface record needs at least {MIN_SAMPLES} to show a stick-slip cycle",
            time_s.len()
        )));
    }
    let steps: Vec<f64> = time_s.windows(2).map(|w| w[1] - w[0]).collect();
    if let Some(k) = steps.iter().position(|&d| d <= 0.0) {
        return Err(refuse(format!(
            "{}: the time {} s does not follow {} s; a surface record's clock runs forwards",
            place(k + 1),
            time_s[k + 1],
            time_s[k]
        )));
    }
    let period = crate::numerics::median(&steps).expect("two samples or more");
    if let Some(k) = steps
        .iter()
        .position(|&d| (d - period).abs() > CLOCK_TOLERANCE * period)
    {
        return Err(refuse(format!(
            "{}: {} s after the previous stamp, on a clock of {period} s: the string is simulated \
             on the record's clock, which must be regular; cut the record at the gap",
            place(k + 1),
            steps[k]
        )));
    }
    Ok(period)
}

/// The columns of each role and their units.
struct Roles {
    time: usize,
    /// The time column's name says milliseconds.
    time_in_ms: bool,
    top_drive: usize,
    top_drive_unit: SpeedUnit,
    surface_torque: usize,
    torque_unit: TorqueUnit,
    wob: Option<(usize, ForceUnit)>,
    bit: Vec<usize>,
    downhole_min: Option<usize>,
    downhole_max: Option<usize>,
    /// The downhole channels' unit (rpm where the record has none).
    downhole_unit: SpeedUnit,
}

impl Roles {
    /// The columns of each role, named by `name`.
    fn columns(&self, name: &dyn Fn(usize) -> String) -> SurfaceColumns {
        SurfaceColumns {
            time: name(self.time),
            top_drive: name(self.top_drive),
            surface_torque: name(self.surface_torque),
            wob: self.wob.map(|(i, _)| name(i)),
            bit: self.bit.iter().map(|&i| name(i)).collect(),
            downhole_min: self.downhole_min.map(name),
            downhole_max: self.downhole_max.map(name),
        }
    }

    fn resolve(header: &[String], opts: &SurfaceOptions, path: &Path) -> Result<Self> {
        use super::mnemonics::{Extreme, Role, downhole_extreme, role, surface_role};
        let lower = |i: usize| header[i].to_ascii_lowercase();
        // An MWD tool's downhole minimum and maximum bit speed, by name (`min`, `max` beside a
        // downhole speed) or as named.
        let extreme = |wanted: Option<&str>, which: Extreme, what: &str, field: &str| {
            pick(header, wanted, what, field, path, &|i| {
                !is_surface_channel(&header[i]) && downhole_extreme(&header[i]) == Some(which)
            })
        };
        let (downhole_min, downhole_max) = if opts.ignore_downhole {
            (None, None)
        } else {
            (
                extreme(
                    opts.downhole_min_column.as_deref(),
                    Extreme::Least,
                    "downhole minimum bit speed",
                    "downhole_min_column",
                )?,
                extreme(
                    opts.downhole_max_column.as_deref(),
                    Extreme::Greatest,
                    "downhole maximum bit speed",
                    "downhole_max_column",
                )?,
            )
        };
        // Each role by its words first (`top_drive`, `surface` and `torque`, `time`, `wob`),
        // else by a rig log's mnemonic (`RPMA`, `TQA`, `DTIM`, `SWOB`: docs/records.md).
        let pick =
            |wanted: Option<&str>, name: &str, field: &str, words: &dyn Fn(usize) -> bool, mnemonic: Role| match pick(
                header, wanted, name, field, path, words,
            )? {
                Some(i) => Ok(Some(i)),
                None => pick(header, None, name, field, path, &|i| {
                    let by_role = if matches!(mnemonic, Role::Speed | Role::Torque) {
                        surface_role(&header[i])
                    } else {
                        role(&header[i])
                    };
                    by_role == Some(mnemonic)
                }),
            };
        let is_top_drive = |i: usize| {
            let n = lower(i);
            (n.contains("top_drive") || n.contains("rotary")) && !n.contains("torque")
        };
        let is_surface_torque = |i: usize| lower(i).contains("torque") && is_surface_channel(&header[i]);
        let time = pick(
            opts.time_column.as_deref(),
            "time",
            "time_column",
            &|i| lower(i).contains("time"),
            Role::Time,
        )?
        .ok_or_else(|| missing(header, path, "a time", "time", "time_column"))?;
        let top_drive = pick(
            opts.top_drive_column.as_deref(),
            "top_drive",
            "top_drive_column",
            &is_top_drive,
            Role::Speed,
        )?
        .ok_or_else(|| {
            missing(
                header,
                path,
                "a top-drive speed",
                "top_drive' or 'rotary",
                "top_drive_column",
            )
        })?;
        let surface_torque = pick(
            opts.surface_torque_column.as_deref(),
            "surface torque",
            "surface_torque_column",
            &is_surface_torque,
            Role::Torque,
        )?
        .ok_or_else(|| {
            missing(
                header,
                path,
                "a surface torque",
                "torque' and 'surface",
                "surface_torque_column",
            )
        })?;
        let wob = pick(
            opts.wob_column.as_deref(),
            "wob",
            "wob_column",
            &|i| lower(i).contains("wob"),
            Role::Wob,
        )?;
        let chosen = [
            Some(time),
            Some(top_drive),
            Some(surface_torque),
            wob,
            downhole_min,
            downhole_max,
        ];
        let downhole_twice = downhole_min.is_some() && downhole_min == downhole_max;
        if let Some(i) = [downhole_min, downhole_max]
            .into_iter()
            .flatten()
            .find(|&i| downhole_twice || chosen[..4].contains(&Some(i)))
        {
            return Err(format_error(
                path,
                format!(
                    "column '{}' is chosen for a downhole extreme and another role; name the downhole minimum's and maximum's columns with `downhole_min_column` and `downhole_max_column`",
                    header[i]
                ),
            ));
        }
        if let Some(i) = [top_drive, surface_torque].into_iter().find(|&i| i == time) {
            return Err(format_error(
                path,
                format!("column '{}' is chosen for the time and another role", header[i]),
            ));
        }
        if top_drive == surface_torque {
            return Err(format_error(
                path,
                format!(
                    "column '{}' is chosen for both the top-drive speed and the surface torque",
                    header[top_drive]
                ),
            ));
        }
        let bit = (0..header.len())
            .filter(|&i| !chosen.contains(&Some(i)) && !is_surface_channel(&header[i]))
            .filter(|&i| {
                let n = lower(i);
                n.contains("speed") || n.contains("torque")
            })
            .collect();
        Ok(Self {
            time,
            time_in_ms: names_milliseconds(&header[time]),
            top_drive,
            top_drive_unit: resolve_unit(&header[top_drive], opts.top_drive_unit, "top_drive_unit", path)?,
            surface_torque,
            torque_unit: resolve_unit(&header[surface_torque], opts.torque_unit, "torque_unit", path)?,
            wob: match wob {
                Some(i) => Some((i, resolve_unit(&header[i], opts.wob_unit, "wob_unit", path)?)),
                None => None,
            },
            bit,
            downhole_min,
            downhole_max,
            downhole_unit: match downhole_min.or(downhole_max) {
                Some(i) => resolve_unit(&header[i], opts.downhole_unit, "downhole_unit", path)?,
                None => SpeedUnit::Rpm,
            },
        })
    }
}

pub(super) fn format_error(path: &Path, message: String) -> Error {
    Error::Format {
        path: path.to_path_buf(),
        line: Some(1),
        message,
    }
}

/// The column named `wanted` (refused where the header lacks it), else the one column that
/// `accept`s (`None` when none does, refused when several do).
pub(super) fn pick(
    header: &[String],
    wanted: Option<&str>,
    role: &str,
    field: &str,
    path: &Path,
    accept: &dyn Fn(usize) -> bool,
) -> Result<Option<usize>> {
    let listing = || header.join(", ");
    if let Some(name) = wanted {
        return match header.iter().position(|h| h == name) {
            Some(i) => Ok(Some(i)),
            None => Err(format_error(
                path,
                format!(
                    "no column named '{name}' (given by `{field}`); the header has: {}",
                    listing()
                ),
            )),
        };
    }
    let matches: Vec<usize> = (0..header.len()).filter(|&i| accept(i)).collect();
    match matches.as_slice() {
        [] => Ok(None),
        [i] => Ok(Some(*i)),
        many => Err(format_error(
            path,
            format!(
                "several columns could be the {role} ({}); choose one with `{field}`",
                many.iter().map(|&i| header[i].as_str()).collect::<Vec<_>>().join(", ")
            ),
        )),
    }
}

/// The refusal of a record without a column of a required role.
pub(super) fn missing(header: &[String], path: &Path, what: &str, hint: &str, field: &str) -> Error {
    format_error(
        path,
        format!(
            "no column is {what} (a name holding '{hint}'); name it with `{field}` (the header has: {})",
            header.join(", ")
        ),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(text: &str) -> (tempfile::TempDir, PathBuf) {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("rig.csv");
        std::fs::write(&path, text).unwrap();
        (dir, path)
    }

    fn rows(header: &str, row: impl Fn(usize) -> String, n: usize) -> String {
        let mut text = format!("{header}\n");
        for k in 0..n {
            text.push_str(&row(k));
            text.push('\n');
        }
        text
    }

    #[test]
    fn roles_are_found_by_name_and_the_bit_channels_left_alone() {
        let text = rows(
            "time_s,bit_speed_rpm,torque_knm,wob_kn,top_drive_rpm,surface_torque_knm",
            |k| format!("{k},50,8,200,60,{}", 9.0 + (k % 7) as f64),
            40,
        );
        let (_dir, path) = write(&text);
        let r = SurfaceRecord::read(&path, &SurfaceOptions::default()).unwrap();
        assert_eq!(r.columns.top_drive, "top_drive_rpm");
        assert_eq!(r.columns.surface_torque, "surface_torque_knm");
        assert_eq!(r.columns.wob.as_deref(), Some("wob_kn"));
        assert_eq!(r.columns.bit, ["bit_speed_rpm", "torque_knm"]);
        assert!((r.top_drive_rad_s[0] - 60.0 * crate::units::RAD_S_PER_RPM).abs() < 1e-12);
        assert!((r.surface_torque_nm[3] - 12_000.0).abs() < 1e-9);
        assert!((r.wob_ratio(Some(100_000.0))[0] - 2.0).abs() < 1e-15);
        assert!((r.sample_period_s - 1.0).abs() < 1e-15);
        assert!(r.roles_text().contains("not read"), "{}", r.roles_text());
    }

    #[test]
    fn a_rig_export_s_mnemonics_imperial_units_and_iso_clock_read_as_the_plain_record() {
        let plain = rows(
            "time_s,top_drive_rpm,surface_torque_knm,wob_kn",
            |k| format!("{k},60,{},200", 9.0 + (k % 7) as f64),
            40,
        );
        // The same channels as a rig logs them: WITS mnemonics, kft·lbf and klbf, ISO 8601
        // stamps with a zone, one a second.
        let kft_lbf_per_knm = 1000.0 / crate::units::TorqueUnit::FtLbf.newton_metres() / 1000.0;
        let klbf_per_kn = 1000.0 / crate::units::ForceUnit::KLbf.newtons();
        let rig = rows(
            "DTIM,RPMA [rpm],TQA (kft.lbf),SWOB [klbf]",
            |k| {
                format!(
                    "2026-11-30T10:00:{k:02}+01:00,60,{},{}",
                    (9.0 + (k % 7) as f64) * kft_lbf_per_knm,
                    200.0 * klbf_per_kn
                )
            },
            40,
        );
        let ((_a, plain), (_b, rig)) = (write(&plain), write(&rig));
        let (plain, rig) = (
            SurfaceRecord::read(&plain, &SurfaceOptions::default()).unwrap(),
            SurfaceRecord::read(&rig, &SurfaceOptions::default()).unwrap(),
        );
        assert_eq!(
            (
                rig.columns.time.as_str(),
                rig.columns.top_drive.as_str(),
                rig.columns.surface_torque.as_str()
            ),
            ("DTIM", "RPMA [rpm]", "TQA (kft.lbf)")
        );
        assert_eq!(rig.columns.wob.as_deref(), Some("SWOB [klbf]"));
        assert_eq!(rig.time_s, plain.time_s);
        assert_eq!(rig.top_drive_rad_s, plain.top_drive_rad_s);
        for (a, b) in rig.surface_torque_nm.iter().zip(&plain.surface_torque_nm) {
            assert!((a - b).abs() < 1e-9 * b, "{a} vs {b}");
        }
        for (a, b) in rig.wob_n.unwrap().iter().zip(plain.wob_n.as_ref().unwrap()) {
            assert!((a - b).abs() < 1e-9 * b, "{a} vs {b}");
        }
    }

    #[test]
    fn a_bit_record_is_refused_naming_the_missing_role() {
        let text = rows("time_s,bit_speed_rpm,torque_knm", |k| format!("{k},50,8"), 40);
        let (_dir, path) = write(&text);
        let e = SurfaceRecord::read(&path, &SurfaceOptions::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("top-drive speed") && e.contains("top_drive_column"), "{e}");
    }

    #[test]
    fn a_gap_in_the_clock_is_refused_naming_its_line() {
        let text = rows(
            "time_ms,top_drive_rpm,surface_torque_nm",
            |k| format!("{},60,{}", if k < 20 { k * 500 } else { k * 500 + 2000 }, 9000 + k),
            40,
        );
        let (_dir, path) = write(&text);
        let e = SurfaceRecord::read(&path, &SurfaceOptions::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("line 22") && e.contains("2.5 s after"), "{e}");
    }

    #[test]
    fn an_mwd_tool_s_downhole_extremes_are_read_by_name_or_mnemonic_and_their_window_checked() {
        // By name, in rpm, over the clock's period by default.
        let text = rows(
            "time_s,top_drive_rpm,surface_torque_knm,downhole_min_rpm,downhole_max_rpm",
            |k| format!("{k},60,{},{},{}", 9.0 + (k % 7) as f64, k % 3, 100 + k),
            40,
        );
        let (_dir, path) = write(&text);
        let r = SurfaceRecord::read(&path, &SurfaceOptions::default()).unwrap();
        assert_eq!(r.columns.downhole_min.as_deref(), Some("downhole_min_rpm"));
        assert_eq!(r.columns.downhole_max.as_deref(), Some("downhole_max_rpm"));
        assert!(r.columns.bit.is_empty(), "{:?}", r.columns.bit);
        let d = r.downhole.as_ref().unwrap();
        assert_eq!(d.window_samples, 1);
        assert!((d.least_rad_s.as_ref().unwrap()[2] - 2.0 * crate::units::RAD_S_PER_RPM).abs() < 1e-15);
        assert!((d.greatest_rad_s.as_ref().unwrap()[39] - 139.0 * crate::units::RAD_S_PER_RPM).abs() < 1e-12);
        assert!(
            r.roles_text().contains("minimum from 'downhole_min_rpm'"),
            "{}",
            r.roles_text()
        );
        // A rig's mnemonics, the maximum alone, its unit named and a 5 s window on a 1 s clock.
        let text = rows(
            "DTIM,RPMA [rpm],TQA (kN.m),DRPM_MAX",
            |k| format!("{k},60,{},{}", 9.0 + (k % 7) as f64, 12.0 + k as f64),
            40,
        );
        let (_dir, path) = write(&text);
        let opts = SurfaceOptions {
            downhole_unit: Some(SpeedUnit::RadS),
            downhole_window_s: Some(5.0),
            ..SurfaceOptions::default()
        };
        let r = SurfaceRecord::read(&path, &opts).unwrap();
        assert_eq!(r.columns.downhole_min, None);
        assert_eq!(r.columns.downhole_max.as_deref(), Some("DRPM_MAX"));
        let d = r.downhole.as_ref().unwrap();
        assert_eq!(d.window_samples, 5);
        assert!(d.least_rad_s.is_none());
        assert_eq!(d.greatest_rad_s.as_ref().unwrap()[0].to_bits(), 12.0f64.to_bits());
        // Without its unit, a name that does not say it is refused naming the setting.
        let e = SurfaceRecord::read(&path, &SurfaceOptions::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("DRPM_MAX") && e.contains("downhole_unit"), "{e}");
        // A window shorter than the clock's period cannot be: refused by name.
        let opts = SurfaceOptions {
            downhole_unit: Some(SpeedUnit::Rpm),
            downhole_window_s: Some(0.5),
            ..SurfaceOptions::default()
        };
        let e = SurfaceRecord::read(&path, &opts).unwrap_err().to_string();
        assert!(e.contains("downhole_window_s") && e.contains("clock period 1 s"), "{e}");
        // Nor one past half the record: too few samples would have a window inside it.
        let opts = SurfaceOptions {
            downhole_unit: Some(SpeedUnit::Rpm),
            downhole_window_s: Some(25.0),
            ..SurfaceOptions::default()
        };
        let e = SurfaceRecord::read(&path, &opts).unwrap_err().to_string();
        assert!(
            e.contains("downhole_window_s") && e.contains("half the record (20 s)"),
            "{e}"
        );
        // The tool's window or unit given for a record without its channels is refused by name.
        let text = rows(
            "time_s,top_drive_rpm,surface_torque_knm",
            |k| format!("{k},60,{}", 9 + k % 7),
            40,
        );
        let (_dir, path) = write(&text);
        let opts = SurfaceOptions {
            downhole_window_s: Some(5.0),
            ..SurfaceOptions::default()
        };
        let e = SurfaceRecord::read(&path, &opts).unwrap_err().to_string();
        assert!(
            e.contains("downhole_window_s") && e.contains("no downhole minimum"),
            "{e}"
        );
        // A bit record's reader never takes an extreme for the bit's speed.
        assert_eq!(super::super::mnemonics::role("DRPM_MAX"), None);
        assert_eq!(
            super::super::mnemonics::role("DRPM"),
            Some(super::super::mnemonics::Role::Speed)
        );
    }
}
