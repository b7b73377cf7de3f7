//! Records of drilling at the bit for the coupled axial-torsional bit: bit speed, torque on bit,
//! weight on bit and rate of penetration, and the bit's axial speed where the record has it.
//! Columns are found by role: a name holding `speed` (and not `axial`) is the bit's speed, one
//! holding `torque` the torque on bit, `wob` the weight on bit, `rop` or `penetration` the rate
//! of penetration (where the record has one: the calibration needs it, the choice of structure
//! does not), `axial` (and not `acc`) the axial speed, `axial` and `acc` the bit's axial
//! acceleration (a vibration tool's accelerometer), and where the record has that and no axial
//! speed, `time` its clock; each can be named instead. Surface channels are never read as the
//! bit's. Units come from the names' suffixes or the options.

use super::surface::{CLOCK_TOLERANCE, format_error, missing, pick};
use super::{is_surface_channel, resolve_unit};
use crate::error::{Error, Result};
use crate::files::{csv_rows, csv_with_header};
use crate::units::{AccelerationUnit, ForceUnit, RateUnit, SpeedUnit, TorqueUnit};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Which columns of a drilling record to read, and in which units.
#[derive(Clone, Debug, Default)]
pub struct DrillingOptions {
    pub speed_column: Option<String>,
    pub torque_column: Option<String>,
    pub wob_column: Option<String>,
    pub rop_column: Option<String>,
    /// The bit's axial speed; `None` uses the one whose name holds `axial` and not `acc`, if any.
    pub axial_speed_column: Option<String>,
    /// The bit's axial acceleration; `None` uses the one whose name holds `axial` and `acc`, if
    /// any.
    pub axial_acceleration_column: Option<String>,
    /// The clock, read with the axial acceleration; `None` uses the one whose name holds
    /// `time`, if any.
    pub time_column: Option<String>,
    /// Whether to read the bit's axial acceleration and the clock where the record has no axial
    /// speed (the calibration does; the choice of structure does not).
    pub read_axial_acceleration: bool,
    pub speed_unit: Option<SpeedUnit>,
    pub torque_unit: Option<TorqueUnit>,
    pub wob_unit: Option<ForceUnit>,
    /// Unit of the rate of penetration and of the axial speed.
    pub rop_unit: Option<RateUnit>,
    pub acceleration_unit: Option<AccelerationUnit>,
}

/// The columns a drilling record was read from, by role.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DrillingColumns {
    pub speed: String,
    pub torque: String,
    pub wob: String,
    /// The rate of penetration, where the record has one.
    pub rop: Option<String>,
    pub axial_speed: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub axial_acceleration: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub time: Option<String>,
}

/// A drilling record in SI, in file order.
#[derive(Clone, Debug)]
pub struct DrillingRecord {
    pub source: PathBuf,
    pub columns: DrillingColumns,
    pub speed_rad_s: Vec<f64>,
    pub torque_nm: Vec<f64>,
    pub wob_n: Vec<f64>,
    /// The rate of penetration (m/s), where the record has one.
    pub rop_m_s: Option<Vec<f64>>,
    pub axial_speed_m_s: Option<Vec<f64>>,
    /// The bit's axial acceleration (m/s², as its channel reads it: gravity's share and the
    /// sensor's offset included, either sign downward), where the record has it.
    pub axial_acceleration_m_s2: Option<Vec<f64>>,
    /// The clock's period (s, the median spacing of its stamps), where it was read and regular.
    pub sample_period_s: Option<f64>,
    /// Channels the calibration could have used and were not read, and why, as said to the
    /// user (an axial acceleration found by its name whose unit or cells cannot be read, a
    /// clock that is not regular).
    pub unread: Vec<String>,
}

impl DrillingRecord {
    /// Reads the drilling record at `path` (a CSV with a header).
    pub fn read(path: &Path, opts: &DrillingOptions) -> Result<Self> {
        let (mut reader, header) = csv_with_header(path)?;
        let lower = |i: usize| header[i].to_ascii_lowercase();
        let bit = |i: usize| !is_surface_channel(&header[i]);
        let role = |wanted: Option<&str>, what: &str, field: &str, accept: &dyn Fn(usize) -> bool| {
            pick(&header, wanted, what, field, path, accept)
        };
        let speed = role(opts.speed_column.as_deref(), "bit speed", "speed_column", &|i| {
            lower(i).contains("speed")
                && !lower(i).contains("axial")
                && bit(i)
                && super::mnemonics::downhole_extreme(&header[i]).is_none()
        })?
        .ok_or_else(|| missing(&header, path, "a bit speed", "speed", "speed_column"))?;
        let torque = role(opts.torque_column.as_deref(), "torque on bit", "torque_column", &|i| {
            lower(i).contains("torque") && bit(i)
        })?
        .ok_or_else(|| missing(&header, path, "a torque on bit", "torque", "torque_column"))?;
        let wob = role(opts.wob_column.as_deref(), "weight on bit", "wob_column", &|i| {
            lower(i).contains("wob")
        })?
        .ok_or_else(|| missing(&header, path, "a weight on bit", "wob", "wob_column"))?;
        let rop = role(opts.rop_column.as_deref(), "rate of penetration", "rop_column", &|i| {
            lower(i).contains("rop") || lower(i).contains("penetration")
        })?;
        let axial = role(
            opts.axial_speed_column.as_deref(),
            "axial speed",
            "axial_speed_column",
            &|i| lower(i).contains("axial") && !lower(i).contains("acc"),
        )?;
        // The acceleration and its clock are read only where they can tell the calibration
        // something; what was found by name and cannot be read is said, not refused. A column
        // named in the settings must be in the record, read or not: a misspelt name is refused,
        // not passed over.
        for (named, what, field) in [
            (
                opts.axial_acceleration_column.as_deref(),
                "axial acceleration",
                "axial_acceleration_column",
            ),
            (opts.time_column.as_deref(), "time", "time_column"),
        ] {
            if named.is_some() {
                role(named, what, field, &|_| false)?;
            }
        }
        let mut unread = Vec::new();
        let wanted = opts.read_axial_acceleration && axial.is_none();
        let named = opts.axial_acceleration_column.is_some() || opts.acceleration_unit.is_some();
        let acceleration = match wanted {
            true => or_unread(
                role(
                    opts.axial_acceleration_column.as_deref(),
                    "axial acceleration",
                    "axial_acceleration_column",
                    &|i| lower(i).contains("axial") && lower(i).contains("acc"),
                ),
                named,
                &mut unread,
            )?,
            false => None,
        };
        let acceleration_unit = match acceleration {
            Some(i) => or_unread(
                resolve_unit(&header[i], opts.acceleration_unit, "acceleration_unit", path).map(|u| Some((i, u))),
                named,
                &mut unread,
            )?,
            None => None,
        };
        let acceleration = acceleration_unit.map(|(i, _)| i);
        let time = match acceleration {
            Some(_) => or_unread(
                role(opts.time_column.as_deref(), "time", "time_column", &|i| {
                    lower(i).contains("time")
                }),
                opts.time_column.is_some(),
                &mut unread,
            )?,
            None => None,
        };
        let chosen = [Some(speed), Some(torque), Some(wob), rop, axial, acceleration, time];
        for (k, a) in chosen.iter().enumerate() {
            if let Some(a) = a
                && chosen[k + 1..].contains(&Some(*a))
            {
                return Err(format_error(
                    path,
                    format!("column '{}' is chosen for two roles", header[*a]),
                ));
            }
        }
        let speed_unit = resolve_unit(&header[speed], opts.speed_unit, "speed_unit", path)?;
        let torque_unit = resolve_unit(&header[torque], opts.torque_unit, "torque_unit", path)?;
        let wob_unit = resolve_unit(&header[wob], opts.wob_unit, "wob_unit", path)?;
        let rop_unit = match rop {
            Some(i) => Some((i, resolve_unit(&header[i], opts.rop_unit, "rop_unit", path)?)),
            None => None,
        };
        let axial_unit = match axial {
            Some(i) => Some((i, resolve_unit(&header[i], opts.rop_unit, "rop_unit", path)?)),
            None => None,
        };
        let mut out = Self {
            source: path.to_path_buf(),
            columns: DrillingColumns {
                speed: header[speed].clone(),
                torque: header[torque].clone(),
                wob: header[wob].clone(),
                rop: rop.map(|i| header[i].clone()),
                axial_speed: axial.map(|i| header[i].clone()),
                axial_acceleration: acceleration.map(|i| header[i].clone()),
                time: time.map(|i| header[i].clone()),
            },
            speed_rad_s: Vec::new(),
            torque_nm: Vec::new(),
            wob_n: Vec::new(),
            rop_m_s: rop.map(|_| Vec::new()),
            axial_speed_m_s: axial.map(|_| Vec::new()),
            axial_acceleration_m_s2: acceleration.map(|_| Vec::new()),
            sample_period_s: None,
            unread,
        };
        let clock = time.map(|i| (i, super::clock::TimeReader::new(super::names_milliseconds(&header[i]))));
        let mut times = Vec::new();
        for row in csv_rows(&mut reader, path, &header) {
            let row = row?;
            out.speed_rad_s.push(speed_unit.to_rad_s(row.number(speed)?));
            out.torque_nm.push(row.number(torque)? * torque_unit.newton_metres());
            out.wob_n.push(row.number(wob)? * wob_unit.newtons());
            if let (Some((i, unit)), Some(v)) = (rop_unit, out.rop_m_s.as_mut()) {
                v.push(row.number(i)? * unit.metres_per_second());
            }
            if let (Some((i, unit)), Some(v)) = (axial_unit, out.axial_speed_m_s.as_mut()) {
                v.push(row.number(i)? * unit.metres_per_second());
            }
            if let (Some((i, unit)), Some(v)) = (acceleration_unit, out.axial_acceleration_m_s2.as_mut()) {
                match row.number(i) {
                    Ok(a) => v.push(a * unit.metres_per_second_squared()),
                    Err(e) if !named => {
                        out.unread.push(e.to_string());
                        out.axial_acceleration_m_s2 = None;
                        out.columns.axial_acceleration = None;
                    }
                    Err(e) => return Err(e),
                }
            }
            if let Some((i, reader)) = &clock
                && out.columns.time.is_some()
            {
                match reader.text(row.cell(*i)) {
                    Ok(t) => times.push(t),
                    Err(message) if opts.time_column.is_none() => {
                        out.unread.push(row.bad_cell(*i, message).to_string());
                        out.columns.time = None;
                    }
                    Err(message) => return Err(row.bad_cell(*i, message)),
                }
            }
        }
        if out.axial_acceleration_m_s2.is_some()
            && let Some(column) = out.columns.time.clone()
        {
            out.sample_period_s = regular_period(&times);
            if out.sample_period_s.is_none() {
                out.unread.push(format!(
                    "{}: its clock ('{column}') is not regular (a stamp's spacing departs from their \
                     median by more than {:.0} %, or runs backwards): the bit's travel is not \
                     checked against the depth cut",
                    path.display(),
                    100.0 * CLOCK_TOLERANCE
                ));
            }
        }
        if out.speed_rad_s.is_empty() {
            return Err(Error::Format {
                path: path.to_path_buf(),
                line: None,
                message: "the record holds no data rows".into(),
            });
        }
        Ok(out)
    }

    pub fn len(&self) -> usize {
        self.speed_rad_s.len()
    }

    pub fn is_empty(&self) -> bool {
        self.speed_rad_s.is_empty()
    }
}

/// `found`; or where finding it failed and the user named none of it, nothing, the reason kept
/// in `unread`.
fn or_unread<T>(found: Result<Option<T>>, named: bool, unread: &mut Vec<String>) -> Result<Option<T>> {
    match found {
        Err(e) if !named => {
            unread.push(e.to_string());
            Ok(None)
        }
        other => other,
    }
}

/// The period (s) of the clock `time_s`: the median spacing of its stamps, where every spacing
/// is positive and within [`CLOCK_TOLERANCE`] of it (a surface record's clock, on which its
/// strings are simulated, is held to the same).
fn regular_period(time_s: &[f64]) -> Option<f64> {
    let steps: Vec<f64> = time_s.windows(2).map(|w| w[1] - w[0]).collect();
    let period = crate::numerics::median(&steps).filter(|p| *p > 0.0)?;
    steps
        .iter()
        .all(|d| (d - period).abs() <= CLOCK_TOLERANCE * period)
        .then_some(period)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(text: &str) -> (tempfile::TempDir, PathBuf) {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bit.csv");
        std::fs::write(&path, text).unwrap();
        (dir, path)
    }

    #[test]
    fn roles_and_units_are_read_from_the_names() {
        let (_d, path) = write(
            "time_s,bit_speed_rpm,torque_on_bit_knm,wob_kn,axial_speed_m_h,rop_m_h,surface_torque_knm\n\
             0,60,10,150,36,36,12\n0.02,30,11,151,0,18,12\n",
        );
        let r = DrillingRecord::read(&path, &DrillingOptions::default()).unwrap();
        assert_eq!(r.columns.speed, "bit_speed_rpm");
        assert_eq!(r.columns.torque, "torque_on_bit_knm");
        assert_eq!(r.columns.axial_speed.as_deref(), Some("axial_speed_m_h"));
        assert!((r.speed_rad_s[0] - 2.0 * std::f64::consts::PI).abs() < 1e-12);
        assert!((r.torque_nm[1] - 11_000.0).abs() < 1e-9);
        assert!((r.wob_n[0] - 150_000.0).abs() < 1e-9);
        assert!((r.rop_m_s.unwrap()[0] - 0.01).abs() < 1e-15);
        assert!(r.axial_speed_m_s.unwrap()[1].abs() < f64::MIN_POSITIVE);
    }

    #[test]
    fn an_acceleration_column_is_never_read_as_the_axial_speed() {
        let header = "bit_speed_rpm,torque_knm,wob_kn,rop_m_h";
        let calibrating = DrillingOptions {
            read_axial_acceleration: true,
            ..DrillingOptions::default()
        };
        let (_d, path) = write(&format!(
            "{header},axial_acceleration_m_s2,axial_speed_m_h\n60,10,150,30,0.5,30\n"
        ));
        let r = DrillingRecord::read(&path, &calibrating).unwrap();
        assert_eq!(r.columns.axial_speed.as_deref(), Some("axial_speed_m_h"));
        // Beside the axial speed, the acceleration tells nothing more: not read.
        assert_eq!(r.axial_acceleration_m_s2, None);
        // Alone, an accelerometer's channel gives no axial speed: it is read as the axial
        // acceleration, in g where its name says so, with the clock where there is one.
        let (_d, path) = write(&format!(
            "time_s,{header},axial_acc_g\n0,60,10,150,30,0.05\n0.02,60,10,150,30,0\n"
        ));
        let r = DrillingRecord::read(&path, &calibrating).unwrap();
        assert_eq!((r.columns.axial_speed, r.axial_speed_m_s), (None, None));
        assert_eq!(r.columns.axial_acceleration.as_deref(), Some("axial_acc_g"));
        assert!((r.axial_acceleration_m_s2.unwrap()[0] - 0.05 * 9.80665).abs() < 1e-12);
        assert!((r.sample_period_s.unwrap() - 0.02).abs() < 1e-12);
        // The choice of structure reads none of it.
        let r = DrillingRecord::read(&path, &DrillingOptions::default()).unwrap();
        assert_eq!((r.axial_acceleration_m_s2, r.sample_period_s), (None, None));
        // A channel found by its name whose unit its name does not give is said and left
        // unread; named by the user, it is refused, naming the setting that gives the unit.
        let (_d, path) = write(&format!("{header},axial_accel\n60,10,150,30,0.05\n"));
        let r = DrillingRecord::read(&path, &calibrating).unwrap();
        assert_eq!(r.axial_acceleration_m_s2, None);
        assert!(
            r.unread.len() == 1 && r.unread[0].contains("`acceleration_unit`"),
            "{:?}",
            r.unread
        );
        let named = DrillingOptions {
            axial_acceleration_column: Some("axial_accel".into()),
            ..calibrating
        };
        let e = DrillingRecord::read(&path, &named).unwrap_err().to_string();
        assert!(e.contains("axial_accel") && e.contains("`acceleration_unit`"), "{e}");
    }

    #[test]
    fn a_rate_of_penetration_is_read_where_the_record_has_one_and_its_unit_is_needed() {
        let (_d, path) = write("bit_speed_rpm,torque_knm,wob_kn\n60,10,150\n");
        let r = DrillingRecord::read(&path, &DrillingOptions::default()).unwrap();
        assert_eq!((r.columns.rop, r.rop_m_s), (None, None));
        let (_d, path) = write("bit_speed_rpm,torque_knm,wob_kn,rop\n60,10,150,30\n");
        let e = DrillingRecord::read(&path, &DrillingOptions::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("'rop'") && e.contains("rop_unit"), "{e}");
    }
}
