//! WITS level 0, the rig floor's ASCII format: blocks that open with a line `&&` and close
//! with `!!`, each line between them an item code of four digits (the record's two, the
//! item's two) followed by its value (`0120 60.5` or `012060.5`). A block gives one row: the
//! items named by [`WitsItems`] (defaults from WITS record 01, "General Time-Based": 0120
//! rotary speed, 0118 rotary torque, 0116 weight on bit, all surface averages; 0105 date
//! YYMMDD and 0106 time HHMMSS). A block that holds none of them (another record) is passed
//! over; one that holds some but not the speed, torque and time is skipped, saying which.
//!
//! WITS carries no units: the torque's unit (and the weight on bit's, where one is read) must
//! be named; the speed is in rpm unless named.

use crate::data::surface::SurfaceColumns;
use crate::data::{DataOptions, Row};
use crate::error::{Error, Result};
use crate::units::{ForceUnit, SpeedUnit, TorqueUnit};
use serde::{Deserialize, Serialize};

/// How a row's time is read from a block.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum WitsTime {
    /// A time of day HHMMSS (fractions allowed) and, where the block has it, a date YYMMDD:
    /// seconds since the first block's midnight (a time of day that runs back by more than
    /// 12 h without a date is the next day).
    Clock { date: String, time: String },
    /// An item that carries seconds.
    Seconds(String),
}

/// The item codes a watch reads from WITS blocks.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct WitsItems {
    pub speed: String,
    pub torque: String,
    pub wob: Option<String>,
    pub top_drive: Option<String>,
    pub time: WitsTime,
    /// The surface torque's item: a feed of surface channels alone, read as what they are
    /// (the top-drive speed from `top_drive`, record 01's 0120 where none is named; no bit
    /// channel), each window inferred through simulated strings.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub surface_torque: Option<String>,
}

impl Default for WitsItems {
    /// WITS record 01 (General Time-Based): 0120 rotary speed, 0118 rotary torque, 0116
    /// weight on bit (surface averages), 0105 date, 0106 time.
    fn default() -> Self {
        Self {
            speed: "0120".into(),
            torque: "0118".into(),
            wob: Some("0116".into()),
            top_drive: None,
            time: WitsTime::Clock {
                date: "0105".into(),
                time: "0106".into(),
            },
            surface_torque: None,
        }
    }
}

impl WitsItems {
    /// The items read as the bit's speed and torque that WITS record 01 defines as surface
    /// averages (0120 rotary speed, 0118 rotary torque), each with what it is: read as the
    /// bit's, they are said to be surface channels.
    pub fn surface_averages(&self) -> Vec<(&str, &'static str)> {
        if self.surface_torque.is_some() {
            return Vec::new();
        }
        [
            (&self.speed, "0120", "rotary speed"),
            (&self.torque, "0118", "rotary torque"),
        ]
        .into_iter()
        .filter(|(code, surface, _)| code.as_str() == *surface)
        .map(|(code, _, what)| (code.as_str(), what))
        .collect()
    }

    /// Items from `spec`, `key=CODE` pairs separated by commas over the defaults: keys
    /// `speed`, `torque`, `wob`, `top_drive`, `date`, `time` (HHMMSS), `seconds` (an item in
    /// seconds, instead of date and time) and `surface_torque` (a feed of surface channels
    /// alone: [`WitsItems::surface_torque`]); `wob=none` reads no weight on bit.
    pub fn parse(spec: &str) -> Result<Self> {
        let refuse = |message: String| Error::setting("wits_items", message);
        let mut items = Self::default();
        let mut bit_keys = Vec::new();
        for pair in spec.split(',').map(str::trim).filter(|p| !p.is_empty()) {
            let (key, code) = pair
                .split_once('=')
                .ok_or_else(|| refuse(format!("'{pair}' is not key=CODE")))?;
            let code = code.trim();
            if key.trim() == "wob" && code == "none" {
                items.wob = None;
                continue;
            }
            if code.len() != 4 || !code.bytes().all(|b| b.is_ascii_digit()) {
                return Err(refuse(format!(
                    "'{code}' for {key} is not a WITS item code (four digits: record and item)"
                )));
            }
            let code = code.to_string();
            if matches!(key.trim(), "speed" | "torque") {
                bit_keys.push(key.trim().to_string());
            }
            match key.trim() {
                "speed" => items.speed = code,
                "torque" => items.torque = code,
                "wob" => items.wob = Some(code),
                "top_drive" => items.top_drive = Some(code),
                "surface_torque" => items.surface_torque = Some(code),
                "seconds" => items.time = WitsTime::Seconds(code),
                "date" | "time" => {
                    let (mut date, mut time) = match &items.time {
                        WitsTime::Clock { date, time } => (date.clone(), time.clone()),
                        WitsTime::Seconds(_) => ("0105".into(), "0106".into()),
                    };
                    if key.trim() == "date" {
                        date = code;
                    } else {
                        time = code;
                    }
                    items.time = WitsTime::Clock { date, time };
                }
                other => {
                    return Err(refuse(format!(
                        "unknown key '{other}' (speed, torque, wob, top_drive, surface_torque, date, time, seconds)"
                    )));
                }
            }
        }
        bit_keys.sort();
        bit_keys.dedup();
        if items.surface_torque.is_some() && !bit_keys.is_empty() {
            return Err(refuse(format!(
                "{} {} the bit's channels, and surface_torque a feed of surface channels alone: keep one",
                bit_keys.join(" and "),
                if bit_keys.len() == 1 { "names" } else { "name" }
            )));
        }
        Ok(items)
    }

    /// A feed of surface channels alone: its top-drive speed's item and its surface torque's.
    pub fn surface(&self) -> Option<(&str, &str)> {
        let torque = self.surface_torque.as_deref()?;
        Some((self.top_drive.as_deref().unwrap_or(RECORD_01_ROTARY_SPEED), torque))
    }

    fn codes(&self) -> Vec<&str> {
        let mut codes = match self.surface() {
            Some((top_drive, torque)) => vec![top_drive, torque],
            None => {
                let mut codes = vec![self.speed.as_str(), self.torque.as_str()];
                codes.extend(self.top_drive.as_deref());
                codes
            }
        };
        codes.extend(self.wob.as_deref());
        match &self.time {
            WitsTime::Clock { date, time } => codes.extend([date.as_str(), time.as_str()]),
            WitsTime::Seconds(code) => codes.push(code),
        }
        codes
    }
}

/// WITS record 01's rotary speed, a surface average: a surface feed's top-drive speed unless
/// another item is named.
const RECORD_01_ROTARY_SPEED: &str = "0120";

/// Most items a WITS block may hold before its `!!`: a record has some tens; a block never
/// closed is given up at this many instead of growing without end.
pub const MAX_BLOCK_ITEMS: usize = 4096;

/// Reads WITS blocks line by line into rows.
pub struct WitsReader {
    items: WitsItems,
    speed_unit: SpeedUnit,
    torque_unit: TorqueUnit,
    wob_unit: Option<ForceUnit>,
    /// The open block's items, `None` outside a block.
    block: Option<Vec<(String, String)>>,
    /// Day number of the first block's date, and the last clock reading (day, s of day).
    first_day: Option<i64>,
    last_clock: Option<(i64, f64)>,
}

impl WitsReader {
    /// A reader of `items` in the units of `opts` (the torque's required; the weight on bit's
    /// where it is read; rpm for the speed unless named).
    pub fn new(items: WitsItems, opts: &DataOptions) -> Result<Self> {
        let torque_unit = opts.torque_unit.ok_or_else(|| {
            Error::setting(
                "torque_unit",
                format!(
                    "a WITS feed names no units: give the unit of its torque (item {})",
                    items.surface().map_or(items.torque.as_str(), |(_, torque)| torque)
                ),
            )
        })?;
        let wob_unit = match &items.wob {
            Some(code) => Some(opts.wob_unit.ok_or_else(|| {
                Error::setting(
                    "wob_unit",
                    format!("a WITS feed names no units: give the unit of its weight on bit (item {code}), or read none with wob=none"),
                )
            })?),
            None => None,
        };
        Ok(Self {
            items,
            speed_unit: opts.speed_unit.unwrap_or(SpeedUnit::Rpm),
            torque_unit,
            wob_unit,
            block: None,
            first_day: None,
            last_clock: None,
        })
    }

    pub fn torque_unit(&self) -> TorqueUnit {
        self.torque_unit
    }

    /// The items it reads.
    pub fn items(&self) -> &WitsItems {
        &self.items
    }

    /// The items read, named by their codes, and their units (the time in seconds).
    pub fn declared(&self) -> crate::data::Declared {
        let item = |code: &str| format!("item {code}");
        let time = match &self.items.time {
            WitsTime::Clock { date, time } => format!("items {date} and {time}"),
            WitsTime::Seconds(code) => item(code),
        };
        let (speed, torque) = self.items.surface().unwrap_or((&self.items.speed, &self.items.torque));
        let surface = self.items.surface().map(|(top_drive, torque)| SurfaceColumns {
            time: time.clone(),
            top_drive: item(top_drive),
            surface_torque: item(torque),
            wob: self.items.wob.as_deref().map(item),
            bit: Vec::new(),
            downhole_min: None,
            downhole_max: None,
        });
        crate::data::Declared {
            columns: crate::data::ColumnsUsed {
                speed: item(speed),
                torque: item(torque),
                wob: self.items.wob.as_deref().map(item),
                time: Some(time),
            },
            units: crate::data::ColumnUnits {
                speed: self.speed_unit,
                torque: self.torque_unit,
                wob: self.wob_unit,
                time_in_ms: false,
            },
            top_drive: match self.items.surface() {
                Some((code, _)) => Some((item(code), self.speed_unit)),
                None => self.items.top_drive.as_deref().map(|code| (item(code), SpeedUnit::Rpm)),
            },
            surface,
        }
    }

    /// Forgets the open block: one cut by a dropped connection is not a row.
    pub fn drop_block(&mut self) {
        self.block = None;
    }

    /// Takes one line; gives the row of a block it closes (`Err`: why the block is skipped),
    /// or `None`.
    pub fn line(&mut self, line: &str) -> Option<std::result::Result<Row, String>> {
        let line = line.trim();
        if line == "&&" {
            self.block = Some(Vec::new());
            return None;
        }
        if line == "!!" {
            let block = self.block.take()?;
            return self.row(&block);
        }
        let block = self.block.as_mut()?;
        if block.len() >= MAX_BLOCK_ITEMS {
            self.block = None;
            return Some(Err(format!(
                "a WITS block of more than {MAX_BLOCK_ITEMS} items without its closing !!: skipped"
            )));
        }
        if line.len() >= 4 && line.is_char_boundary(4) {
            let (code, value) = line.split_at(4);
            block.push((code.to_string(), value.trim().to_string()));
        }
        None
    }

    fn row(&mut self, block: &[(String, String)]) -> Option<std::result::Result<Row, String>> {
        let codes = self.items.codes();
        if !block.iter().any(|(c, _)| codes.contains(&c.as_str())) {
            return None;
        }
        let value = |code: &str| -> std::result::Result<Option<f64>, String> {
            match block.iter().rev().find(|(c, _)| c == code) {
                None => Ok(None),
                Some((_, text)) => text
                    .parse::<f64>()
                    .ok()
                    .filter(|v| v.is_finite())
                    .map(Some)
                    .ok_or_else(|| format!("item {code}: '{text}' is not a number")),
            }
        };
        let required = |code: &str, what: &str| -> std::result::Result<f64, String> {
            value(code)?.ok_or_else(|| format!("a WITS block without item {code} ({what})"))
        };
        Some((|| {
            // A surface feed's channels as what they are; a bit feed's as the bit's.
            let (bit, top_drive, surface_torque_nm) = match self.items.surface() {
                Some((top_drive, torque)) => (
                    None,
                    Some(self.speed_unit.to_rad_s(required(top_drive, "top-drive speed")?)),
                    Some(required(torque, "surface torque")? * self.torque_unit.newton_metres()),
                ),
                None => (
                    Some(crate::data::BitReading {
                        speed_rad_s: self.speed_unit.to_rad_s(required(&self.items.speed, "speed")?),
                        torque_nm: required(&self.items.torque, "torque")? * self.torque_unit.newton_metres(),
                    }),
                    match &self.items.top_drive {
                        Some(code) => Some(SpeedUnit::Rpm.to_rad_s(required(code, "top-drive speed")?)),
                        None => None,
                    },
                    None,
                ),
            };
            let wob = match (&self.items.wob, self.wob_unit) {
                (Some(code), Some(unit)) => Some(required(code, "weight on bit")? * unit.newtons()),
                _ => None,
            };
            let time_s = match self.items.time.clone() {
                WitsTime::Seconds(code) => required(&code, "time, s")?,
                WitsTime::Clock { date, time } => {
                    let of_day = seconds_of_day(required(&time, "time, HHMMSS")?)
                        .ok_or_else(|| format!("item {time}: not a time HHMMSS"))?;
                    let day = match value(&date)? {
                        Some(d) => day_number(d).ok_or_else(|| format!("item {date}: not a date YYMMDD"))?,
                        // Without a date: the last block's day, the next one where the clock
                        // ran back by more than half a day (midnight passed).
                        None => match self.last_clock {
                            Some((day, last)) if of_day < last - 43_200.0 => day + 1,
                            Some((day, _)) => day,
                            None => 0,
                        },
                    };
                    self.last_clock = Some((day, of_day));
                    let first = *self.first_day.get_or_insert(day);
                    (day - first) as f64 * 86_400.0 + of_day
                }
            };
            Ok(Row {
                time_s: Some(time_s),
                bit,
                wob_n: wob,
                top_drive_rad_s: top_drive,
                surface_torque_nm,
                depth_m: None,
            })
        })())
    }
}

/// Seconds since midnight of a time HHMMSS (fractions of a second allowed).
fn seconds_of_day(hhmmss: f64) -> Option<f64> {
    let whole = hhmmss.trunc() as i64;
    let (h, m, s) = (whole / 10_000, whole / 100 % 100, whole % 100);
    let fraction = hhmmss - hhmmss.trunc();
    (hhmmss >= 0.0 && h < 24 && m < 60 && s < 60).then(|| (h * 3600 + m * 60 + s) as f64 + fraction)
}

/// Days since 1970-01-01 of a date YYMMDD (years 70–99 are the 1900s).
fn day_number(yymmdd: f64) -> Option<i64> {
    let whole = yymmdd as i64;
    if yymmdd < 0.0 || yymmdd.fract() != 0.0 {
        return None;
    }
    let (yy, m, d) = (whole / 10_000, whole / 100 % 100, whole % 100);
    let y = if yy >= 70 { 1900 + yy } else { 2000 + yy };
    if !(1..=12).contains(&m) || !(1..=31).contains(&d) {
        return None;
    }
    // Days from civil (proleptic Gregorian), the era-based algorithm.
    let y = if m <= 2 { y - 1 } else { y };
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let mp = (m + 9) % 12;
    let doy = (153 * mp + 2) / 5 + d - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    Some(era * 146_097 + doe - 719_468)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn reader(items: WitsItems) -> WitsReader {
        let opts = DataOptions {
            torque_unit: Some(TorqueUnit::KNm),
            wob_unit: Some(ForceUnit::KN),
            ..DataOptions::default()
        };
        WitsReader::new(items, &opts).unwrap()
    }

    fn rows(reader: &mut WitsReader, text: &str) -> Vec<std::result::Result<Row, String>> {
        text.lines().filter_map(|l| reader.line(l)).collect()
    }

    #[test]
    fn record_01_s_surface_averages_are_told_apart_from_downhole_items() {
        let defaults = WitsItems::default();
        assert_eq!(
            defaults.surface_averages(),
            [("0120", "rotary speed"), ("0118", "rotary torque")]
        );
        let downhole = WitsItems::parse("speed=0902,torque=0903,top_drive=0120").unwrap();
        assert!(downhole.surface_averages().is_empty());
        let torque_only = WitsItems::parse("speed=0902").unwrap();
        assert_eq!(torque_only.surface_averages(), [("0118", "rotary torque")]);
    }

    #[test]
    fn a_feed_of_surface_channels_is_read_as_what_it_is() {
        let items = WitsItems::parse("surface_torque=0118").unwrap();
        assert!(items.surface_averages().is_empty(), "nothing read as the bit's");
        let mut r = reader(items);
        let got = rows(&mut r, "&&\n0105261127\n0106120000\n012060\n011810.5\n0116 120\n!!\n");
        let row = got[0].as_ref().unwrap();
        assert_eq!(row.bit, None);
        assert!((row.top_drive_rad_s.unwrap() - 2.0 * std::f64::consts::PI).abs() < 1e-12);
        assert!((row.surface_torque_nm.unwrap() - 10_500.0).abs() < 1e-9);
        assert_eq!(row.wob_n, Some(120_000.0));
        let declared = r.declared();
        let surface = declared.surface.unwrap();
        assert_eq!(
            (surface.top_drive.as_str(), surface.surface_torque.as_str()),
            ("item 0120", "item 0118")
        );
        // A block without the surface torque is skipped, naming it.
        let got = rows(&mut r, "&&\n0105261127\n0106120001\n012060\n0116 120\n!!\n");
        assert!(
            got[0].as_ref().unwrap_err().contains("0118 (surface torque)"),
            "{got:?}"
        );
        // The bit's channels and a surface feed at once: refused.
        let both = WitsItems::parse("speed=0902,surface_torque=0118")
            .unwrap_err()
            .to_string();
        assert!(both.contains("speed") && both.contains("surface_torque"), "{both}");
    }

    #[test]
    fn blocks_give_rows_in_si_and_the_clock_runs_over_midnight() {
        let mut r = reader(WitsItems::default());
        let got = rows(
            &mut r,
            "&&\n0105261127\n0106235959\n012060\n011810.5\n0116 120\n!!\n\
             &&\n0201999\n!!\n\
             &&\n0105261128\n0106000001.5\n012061\n011811\n0116121\n!!\n\
             &&\n0106000002\n012062\n!!\n\
             &&\n0105261128\n0106000003\n0120x\n011811\n0116121\n!!\n",
        );
        assert_eq!(got.len(), 4, "another record's block is passed over: {got:?}");
        let first = got[0].as_ref().unwrap();
        assert_eq!(first.time_s, Some(86_399.0));
        assert!((first.bit.unwrap().speed_rad_s - 2.0 * std::f64::consts::PI).abs() < 1e-12);
        assert!((first.bit.unwrap().torque_nm - 10_500.0).abs() < 1e-9);
        assert_eq!(first.wob_n, Some(120_000.0));
        assert_eq!(got[1].as_ref().unwrap().time_s, Some(86_401.5), "the next day");
        assert!(
            got[2].as_ref().unwrap_err().contains("without item 0118"),
            "{:?}",
            got[2]
        );
        assert!(
            got[3].as_ref().unwrap_err().contains("'x' is not a number"),
            "{:?}",
            got[3]
        );
        // Without dates, the clock passing midnight is the next day.
        let mut r = reader(WitsItems::parse("wob=none").unwrap());
        let got = rows(
            &mut r,
            "&&\n0106235958\n01201\n01181\n!!\n&&\n0106000003\n01201\n01181\n!!\n",
        );
        let times: Vec<f64> = got.iter().map(|r| r.as_ref().unwrap().time_s.unwrap()).collect();
        assert_eq!(times, [86_398.0, 86_403.0]);
        assert_eq!(day_number(700101.0), Some(0));
        assert_eq!(day_number(240229.0), Some(19_782));
        assert_eq!(day_number(241301.0), None);
    }

    #[test]
    fn items_are_named_by_key_and_refused_naming_what_is_wrong() {
        let items = WitsItems::parse("speed=0913, torque=0915, seconds=0999, top_drive=0120").unwrap();
        assert_eq!(items.speed, "0913");
        assert_eq!(items.time, WitsTime::Seconds("0999".into()));
        assert_eq!(items.top_drive.as_deref(), Some("0120"));
        for (spec, says) in [
            ("speed=913", "four digits"),
            ("rpm=0120", "unknown key 'rpm'"),
            ("speed", "key=CODE"),
        ] {
            let e = WitsItems::parse(spec).unwrap_err().to_string();
            assert!(e.contains(says) && e.contains("wits_items"), "{e}");
        }
        let e = WitsReader::new(WitsItems::default(), &DataOptions::default())
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("torque_unit"), "{e}");
    }
}
