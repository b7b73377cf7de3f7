//! Units at the edges of the program. The library works in SI (rad/s, N·m, N); these enums name
//! what the user reads and writes, and convert.

use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

/// rad/s per rpm.
pub const RAD_S_PER_RPM: f64 = 2.0 * PI / 60.0;
/// m/s per m/h (a rate of penetration or a feed).
pub const M_S_PER_M_H: f64 = 1.0 / 3600.0;
/// N per pound-force (exact by the international pound and standard gravity).
pub const NEWTONS_PER_POUND_FORCE: f64 = 4.448_221_615_260_5;
/// N·m per foot pound-force (0.3048 m × one pound-force).
pub const NEWTON_METRES_PER_FOOT_POUND_FORCE: f64 = 0.3048 * NEWTONS_PER_POUND_FORCE;

/// A weight on bit in kN, with the digits a reading needs: whole kN from 10 kN (a field
/// string's), tenths from 1 kN, two significant digits below (a laboratory rig's hundreds of
/// newtons, which whole kN would round to 0).
pub fn kn_text(kn: f64) -> String {
    let digits = if kn.abs() >= 10.0 || kn == 0.0 || !kn.is_finite() {
        0
    } else if kn.abs() >= 1.0 {
        1
    } else {
        (1 - kn.abs().log10().floor() as i32) as usize
    };
    format!("{kn:.digits$} kN")
}

/// The unit symbol a column name ends with in brackets (`TQ (kN.m)`, `WOB [klbf]`), as rig
/// logs and WITSML logs name their channels.
pub fn bracketed(column: &str) -> Option<&str> {
    let c = column.trim_end();
    let close = c.chars().last()?;
    let open = match close {
        ')' => '(',
        ']' => '[',
        _ => return None,
    };
    let start = c.rfind(open)?;
    Some(c[start + 1..c.len() - 1].trim())
}

/// A unit symbol as the tables compare it: lower case, without spaces and the separators logs
/// put between a product's factors (`kN.m`, `kN·m`, `kN-m`, `kN*m` are all `knm`).
fn squeezed(symbol: &str) -> String {
    symbol
        .chars()
        .filter(|c| !matches!(c, ' ' | '.' | '·' | '-' | '*' | '_'))
        .flat_map(char::to_lowercase)
        .collect()
}

/// Unit of bit or rotary speed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
pub enum SpeedUnit {
    /// Revolutions per minute.
    #[cfg_attr(feature = "cli", value(name = "rpm"))]
    #[serde(rename = "rpm")]
    Rpm,
    /// Radians per second.
    #[cfg_attr(feature = "cli", value(name = "rad_s"))]
    #[serde(rename = "rad/s")]
    RadS,
}

impl SpeedUnit {
    /// Value in this unit → rad/s.
    pub fn to_rad_s(self, v: f64) -> f64 {
        match self {
            SpeedUnit::Rpm => v * RAD_S_PER_RPM,
            SpeedUnit::RadS => v,
        }
    }
    /// Printed name.
    pub fn label(self) -> &'static str {
        match self {
            SpeedUnit::Rpm => "rpm",
            SpeedUnit::RadS => "rad/s",
        }
    }
    /// The unit a log writes as `symbol` (`rpm`, `c/min`, `rev/min`, `rad/s`), if bitrock reads
    /// it.
    pub fn from_symbol(symbol: &str) -> Option<Self> {
        match squeezed(symbol).as_str() {
            "rpm" | "c/min" | "rev/min" | "1/min" | "r/min" => Some(SpeedUnit::Rpm),
            "rad/s" | "rads" => Some(SpeedUnit::RadS),
            _ => None,
        }
    }
    /// The unit a column name declares (`bit_speed_rpm`, `w_rad_s`, `RPM [c/min]`), if any.
    pub fn from_suffix(column: &str) -> Option<Self> {
        if let Some(symbol) = bracketed(column) {
            return Self::from_symbol(symbol);
        }
        let c = column.to_ascii_lowercase();
        if c.ends_with("_rpm") {
            Some(SpeedUnit::Rpm)
        } else if c.ends_with("_rad_s") {
            Some(SpeedUnit::RadS)
        } else if c
            .split(|ch: char| !ch.is_ascii_alphanumeric())
            .any(|word| word == "rpm")
        {
            // A rig mnemonic (`RPM_DH`, `DH RPM`) names its unit.
            Some(SpeedUnit::Rpm)
        } else {
            None
        }
    }
}

/// Unit of torque.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
pub enum TorqueUnit {
    /// Newton metres (laboratory rigs).
    #[cfg_attr(feature = "cli", value(name = "nm"))]
    #[serde(rename = "N·m")]
    Nm,
    /// Kilonewton metres (field data; the paper's parameters).
    #[cfg_attr(feature = "cli", value(name = "knm"))]
    #[serde(rename = "kN·m")]
    KNm,
    /// Foot pounds-force (rigs' imperial logs).
    #[cfg_attr(feature = "cli", value(name = "ftlbf"))]
    #[serde(rename = "ft·lbf")]
    FtLbf,
    /// Thousands of foot pounds-force.
    #[cfg_attr(feature = "cli", value(name = "kftlbf"))]
    #[serde(rename = "kft·lbf")]
    KFtLbf,
}

impl TorqueUnit {
    /// N·m per one of this unit.
    pub fn newton_metres(self) -> f64 {
        match self {
            TorqueUnit::Nm => 1.0,
            TorqueUnit::KNm => 1000.0,
            TorqueUnit::FtLbf => NEWTON_METRES_PER_FOOT_POUND_FORCE,
            TorqueUnit::KFtLbf => 1000.0 * NEWTON_METRES_PER_FOOT_POUND_FORCE,
        }
    }
    /// Printed name.
    pub fn label(self) -> &'static str {
        match self {
            TorqueUnit::Nm => "N·m",
            TorqueUnit::KNm => "kN·m",
            TorqueUnit::FtLbf => "ft·lbf",
            TorqueUnit::KFtLbf => "kft·lbf",
        }
    }
    /// The suffix of a column in this unit (`torque_knm`, `tq_ftlbf`).
    pub fn suffix(self) -> &'static str {
        match self {
            TorqueUnit::Nm => "nm",
            TorqueUnit::KNm => "knm",
            TorqueUnit::FtLbf => "ftlbf",
            TorqueUnit::KFtLbf => "kftlbf",
        }
    }
    /// The unit of weight on bit logged beside torque in this unit: N with N·m, kN with kN·m,
    /// lbf with ft·lbf, klbf with kft·lbf.
    pub fn force_unit(self) -> ForceUnit {
        match self {
            TorqueUnit::Nm => ForceUnit::N,
            TorqueUnit::KNm => ForceUnit::KN,
            TorqueUnit::FtLbf => ForceUnit::Lbf,
            TorqueUnit::KFtLbf => ForceUnit::KLbf,
        }
    }
    /// The unit a column name declares (`torque_knm`, `tob_nm`, `TQ_kftlbf`, `TQ (kN.m)`), if
    /// any.
    pub fn from_suffix(column: &str) -> Option<Self> {
        if let Some(symbol) = bracketed(column) {
            return Self::from_symbol(symbol);
        }
        let c = column.to_ascii_lowercase();
        [
            ("_knm", TorqueUnit::KNm),
            ("_nm", TorqueUnit::Nm),
            ("_kftlbf", TorqueUnit::KFtLbf),
            ("_ftlbf", TorqueUnit::FtLbf),
        ]
        .into_iter()
        .find_map(|(suffix, unit)| c.ends_with(suffix).then_some(unit))
    }
    /// The unit a log writes as `symbol` (`kN.m`, `N·m`, `ft.lbf`, `kft-lbf`, `klbf.ft`), if
    /// bitrock reads it.
    pub fn from_symbol(symbol: &str) -> Option<Self> {
        match squeezed(symbol).as_str() {
            "knm" => Some(TorqueUnit::KNm),
            "nm" => Some(TorqueUnit::Nm),
            "ftlbf" | "lbfft" | "ftlb" | "ftlbs" => Some(TorqueUnit::FtLbf),
            "kftlbf" | "klbfft" | "kftlb" | "kftlbs" => Some(TorqueUnit::KFtLbf),
            _ => None,
        }
    }
}

/// Unit of force (weight on bit).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
pub enum ForceUnit {
    /// Newtons.
    #[cfg_attr(feature = "cli", value(name = "n"))]
    #[serde(rename = "N")]
    N,
    /// Kilonewtons.
    #[cfg_attr(feature = "cli", value(name = "kn"))]
    #[serde(rename = "kN")]
    KN,
    /// Pounds-force (rigs' imperial logs).
    #[cfg_attr(feature = "cli", value(name = "lbf"))]
    #[serde(rename = "lbf")]
    Lbf,
    /// Thousands of pounds-force (kips), as rigs log weight on bit.
    #[cfg_attr(feature = "cli", value(name = "klbf"))]
    #[serde(rename = "klbf")]
    KLbf,
}

impl ForceUnit {
    /// N per one of this unit.
    pub fn newtons(self) -> f64 {
        match self {
            ForceUnit::N => 1.0,
            ForceUnit::KN => 1000.0,
            ForceUnit::Lbf => NEWTONS_PER_POUND_FORCE,
            ForceUnit::KLbf => 1000.0 * NEWTONS_PER_POUND_FORCE,
        }
    }
    /// Printed name.
    pub fn label(self) -> &'static str {
        match self {
            ForceUnit::N => "N",
            ForceUnit::KN => "kN",
            ForceUnit::Lbf => "lbf",
            ForceUnit::KLbf => "klbf",
        }
    }
    /// The suffix of a column in this unit (`wob_kn`, `wob_klbf`).
    pub fn suffix(self) -> &'static str {
        match self {
            ForceUnit::N => "n",
            ForceUnit::KN => "kn",
            ForceUnit::Lbf => "lbf",
            ForceUnit::KLbf => "klbf",
        }
    }
    /// The unit a column name declares (`wob_kn`, `wob_n`, `WOB_klbf`, `WOB [klbf]`), if any.
    pub fn from_suffix(column: &str) -> Option<Self> {
        if let Some(symbol) = bracketed(column) {
            return Self::from_symbol(symbol);
        }
        let c = column.to_ascii_lowercase();
        [
            ("_kn", ForceUnit::KN),
            ("_n", ForceUnit::N),
            ("_klbf", ForceUnit::KLbf),
            ("_lbf", ForceUnit::Lbf),
        ]
        .into_iter()
        .find_map(|(suffix, unit)| c.ends_with(suffix).then_some(unit))
    }
    /// The unit a log writes as `symbol` (`kN`, `N`, `lbf`, `klbf`, `kip`), if bitrock reads it.
    pub fn from_symbol(symbol: &str) -> Option<Self> {
        match squeezed(symbol).as_str() {
            "kn" => Some(ForceUnit::KN),
            "n" => Some(ForceUnit::N),
            "lbf" | "lb" | "lbs" => Some(ForceUnit::Lbf),
            "klbf" | "klb" | "klbs" | "kip" | "kips" => Some(ForceUnit::KLbf),
            _ => None,
        }
    }
}

/// Unit of an axial speed or rate of penetration.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
pub enum RateUnit {
    /// Metres per hour (drilling's).
    #[cfg_attr(feature = "cli", value(name = "m_h"))]
    #[serde(rename = "m/h")]
    MH,
    /// Metres per second.
    #[cfg_attr(feature = "cli", value(name = "m_s"))]
    #[serde(rename = "m/s")]
    MS,
    /// Feet per hour.
    #[cfg_attr(feature = "cli", value(name = "ft_h"))]
    #[serde(rename = "ft/h")]
    FtH,
}

impl RateUnit {
    /// m/s per one of this unit.
    pub fn metres_per_second(self) -> f64 {
        match self {
            RateUnit::MH => M_S_PER_M_H,
            RateUnit::MS => 1.0,
            RateUnit::FtH => 0.3048 / 3600.0,
        }
    }
    /// Printed name.
    pub fn label(self) -> &'static str {
        match self {
            RateUnit::MH => "m/h",
            RateUnit::MS => "m/s",
            RateUnit::FtH => "ft/h",
        }
    }
    /// The unit a log writes as `symbol` (`m/h`, `m/hr`, `m/s`, `ft/h`, `ft/hr`), if bitrock
    /// reads it.
    pub fn from_symbol(symbol: &str) -> Option<Self> {
        match squeezed(symbol).as_str() {
            "m/h" | "m/hr" => Some(RateUnit::MH),
            "m/s" => Some(RateUnit::MS),
            "ft/h" | "ft/hr" => Some(RateUnit::FtH),
            _ => None,
        }
    }
    /// The unit a column name declares (`rop_m_h`, `axial_speed_m_s`, `rop_ft_h`,
    /// `ROP [ft/h]`).
    pub fn from_suffix(column: &str) -> Option<Self> {
        if let Some(symbol) = bracketed(column) {
            return Self::from_symbol(symbol);
        }
        let c = column.to_ascii_lowercase();
        if c.ends_with("_m_h") {
            Some(RateUnit::MH)
        } else if c.ends_with("_m_s") {
            Some(RateUnit::MS)
        } else if c.ends_with("_ft_h") {
            Some(RateUnit::FtH)
        } else {
            None
        }
    }
}

/// Unit of an acceleration (an accelerometer's channel).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
pub enum AccelerationUnit {
    /// Metres per second squared.
    #[cfg_attr(feature = "cli", value(name = "m_s2"))]
    #[serde(rename = "m/s²")]
    MS2,
    /// Standard gravity, 9.80665 m/s² (vibration tools' unit).
    #[cfg_attr(feature = "cli", value(name = "g"))]
    #[serde(rename = "g")]
    G,
}

impl AccelerationUnit {
    /// m/s² per one of this unit.
    pub fn metres_per_second_squared(self) -> f64 {
        match self {
            AccelerationUnit::MS2 => 1.0,
            AccelerationUnit::G => 9.80665,
        }
    }
    /// Printed name.
    pub fn label(self) -> &'static str {
        match self {
            AccelerationUnit::MS2 => "m/s²",
            AccelerationUnit::G => "g",
        }
    }
    /// The unit a log writes as `symbol` (`m/s2`, `m/s^2`, `m/s²`, `g`), if bitrock reads it.
    pub fn from_symbol(symbol: &str) -> Option<Self> {
        match squeezed(symbol).as_str() {
            "m/s2" | "m/s^2" | "m/s²" | "ms2" => Some(AccelerationUnit::MS2),
            "g" | "gn" => Some(AccelerationUnit::G),
            _ => None,
        }
    }
    /// The unit a column name declares (`axial_acceleration_m_s2`, `axial_acc_g`,
    /// `ACCZ [g]`).
    pub fn from_suffix(column: &str) -> Option<Self> {
        if let Some(symbol) = bracketed(column) {
            return Self::from_symbol(symbol);
        }
        let c = column.to_ascii_lowercase();
        if c.ends_with("_m_s2") {
            Some(AccelerationUnit::MS2)
        } else if c.ends_with("_g") {
            Some(AccelerationUnit::G)
        } else {
            None
        }
    }
}

/// Unit of a depth along the hole (the bit's measured depth).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum LengthUnit {
    /// Metres.
    #[serde(rename = "m")]
    M,
    /// Feet.
    #[serde(rename = "ft")]
    Ft,
}

impl LengthUnit {
    /// m per one of this unit.
    pub fn metres(self) -> f64 {
        match self {
            LengthUnit::M => 1.0,
            LengthUnit::Ft => 0.3048,
        }
    }
    /// Printed name.
    pub fn label(self) -> &'static str {
        match self {
            LengthUnit::M => "m",
            LengthUnit::Ft => "ft",
        }
    }
    /// The unit a log writes as `symbol` (`m`, `ft`, `feet`), if bitrock reads it.
    pub fn from_symbol(symbol: &str) -> Option<Self> {
        match squeezed(symbol).as_str() {
            "m" | "metres" | "meters" => Some(LengthUnit::M),
            "ft" | "feet" | "f" => Some(LengthUnit::Ft),
            _ => None,
        }
    }
    /// The unit a column name declares (`bit_depth_m`, `depth_ft`, `DBTM [m]`), if any.
    pub fn from_suffix(column: &str) -> Option<Self> {
        if let Some(symbol) = bracketed(column) {
            return Self::from_symbol(symbol);
        }
        let c = column.to_ascii_lowercase();
        [("_m", LengthUnit::M), ("_ft", LengthUnit::Ft)]
            .into_iter()
            .find_map(|(suffix, unit)| c.ends_with(suffix).then_some(unit))
    }
}

/// A unit a record's column may be in: declared by the column name (a suffix, a bracketed
/// symbol), or by a setting.
pub trait ColumnUnit: Copy + PartialEq {
    /// The unit the column name `column` declares, if any.
    fn declared_by(column: &str) -> Option<Self>;
    /// The unit's symbol, for messages.
    fn symbol(self) -> &'static str;
}

/// Implements [`ColumnUnit`] by the unit's own `from_suffix` and `label`.
macro_rules! column_unit {
    ($($unit:ty),*) => {$(
        impl ColumnUnit for $unit {
            fn declared_by(column: &str) -> Option<Self> {
                Self::from_suffix(column)
            }
            fn symbol(self) -> &'static str {
                self.label()
            }
        }
    )*};
}
column_unit!(SpeedUnit, TorqueUnit, ForceUnit, RateUnit, LengthUnit, AccelerationUnit);

#[cfg(test)]
mod tests {
    #[test]
    fn a_weight_on_bit_keeps_the_digits_its_scale_needs() {
        assert_eq!(super::kn_text(146.4), "146 kN");
        assert_eq!(super::kn_text(24.6), "25 kN");
        assert_eq!(super::kn_text(2.46), "2.5 kN");
        assert_eq!(super::kn_text(0.39), "0.39 kN");
        assert_eq!(super::kn_text(0.0512), "0.051 kN");
        assert_eq!(super::kn_text(0.0), "0 kN");
    }

    use super::*;

    #[test]
    fn suffixes_name_units() {
        assert_eq!(SpeedUnit::from_suffix("bit_speed_rpm"), Some(SpeedUnit::Rpm));
        assert_eq!(SpeedUnit::from_suffix("W_RAD_S"), Some(SpeedUnit::RadS));
        assert_eq!(SpeedUnit::from_suffix("speed"), None);
        assert_eq!(SpeedUnit::from_suffix("RPM_DH"), Some(SpeedUnit::Rpm));
        assert_eq!(TorqueUnit::from_suffix("torque_knm"), Some(TorqueUnit::KNm));
        assert_eq!(TorqueUnit::from_suffix("torque_nm"), Some(TorqueUnit::Nm));
        assert_eq!(ForceUnit::from_suffix("wob_kn"), Some(ForceUnit::KN));
        assert_eq!(ForceUnit::from_suffix("wob_n"), Some(ForceUnit::N));
        assert_eq!(TorqueUnit::from_suffix("TQ_kNm"), Some(TorqueUnit::KNm));
        assert_eq!(TorqueUnit::from_suffix("TQ_kftlbf"), Some(TorqueUnit::KFtLbf));
        assert_eq!(TorqueUnit::from_suffix("tq_ftlbf"), Some(TorqueUnit::FtLbf));
        assert_eq!(ForceUnit::from_suffix("WOB_klbf"), Some(ForceUnit::KLbf));
        assert_eq!(ForceUnit::from_suffix("wob_lbf"), Some(ForceUnit::Lbf));
    }

    #[test]
    fn bracketed_symbols_name_units_as_logs_write_them() {
        assert_eq!(TorqueUnit::from_suffix("TQ (kN.m)"), Some(TorqueUnit::KNm));
        assert_eq!(TorqueUnit::from_suffix("Torque [kft.lbf]"), Some(TorqueUnit::KFtLbf));
        assert_eq!(TorqueUnit::from_suffix("TOB [ft-lbf]"), Some(TorqueUnit::FtLbf));
        assert_eq!(TorqueUnit::from_suffix("TOB [daN.m]"), None);
        assert_eq!(ForceUnit::from_suffix("WOB (klbf)"), Some(ForceUnit::KLbf));
        assert_eq!(ForceUnit::from_suffix("WOB [kN]"), Some(ForceUnit::KN));
        assert_eq!(SpeedUnit::from_suffix("RPM [c/min]"), Some(SpeedUnit::Rpm));
        assert_eq!(SpeedUnit::from_suffix("DRPM (rad/s)"), Some(SpeedUnit::RadS));
        assert_eq!(RateUnit::from_suffix("ROP [ft/hr]"), Some(RateUnit::FtH));
        assert_eq!(AccelerationUnit::from_suffix("ACCZ [g]"), Some(AccelerationUnit::G));
        assert_eq!(
            AccelerationUnit::from_suffix("ACCZ (m/s^2)"),
            Some(AccelerationUnit::MS2)
        );
        assert_eq!(AccelerationUnit::from_suffix("axial_acc_g"), Some(AccelerationUnit::G));
        assert_eq!(
            AccelerationUnit::from_suffix("axial_acceleration_m_s2"),
            Some(AccelerationUnit::MS2)
        );
        // A bracket decides: a suffix inside the name before it does not.
        assert_eq!(TorqueUnit::from_suffix("tq_knm [ft.lbf]"), Some(TorqueUnit::FtLbf));
    }

    #[test]
    fn imperial_units_convert_by_their_definitions() {
        // 1 lbf = 0.45359237 kg × 9.80665 m/s²; 1 ft = 0.3048 m.
        assert!((ForceUnit::Lbf.newtons() - 0.453_592_37 * 9.806_65).abs() < 1e-12);
        assert!((ForceUnit::KLbf.newtons() - 4_448.221_615_260_5).abs() < 1e-9);
        assert!((TorqueUnit::FtLbf.newton_metres() - 1.355_817_948_331_400_4).abs() < 1e-12);
        assert!((TorqueUnit::KFtLbf.newton_metres() - 1_355.817_948_331_400_4).abs() < 1e-9);
    }

    #[test]
    fn sixty_rpm_is_two_pi_rad_s() {
        assert!((SpeedUnit::Rpm.to_rad_s(60.0) - 2.0 * PI).abs() < 1e-12);
    }
}
