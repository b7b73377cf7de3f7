//! Units at the edges of the program. The library works in SI (rad/s, N·m, N); these enums name
//! what the user reads and writes, and convert.

use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

/// rad/s per rpm.
pub const RAD_S_PER_RPM: f64 = 2.0 * PI / 60.0;

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
    /// The unit a column name's suffix declares (`bit_speed_rpm`, `w_rad_s`), if any.
    pub fn from_suffix(column: &str) -> Option<Self> {
        let c = column.to_ascii_lowercase();
        if c.ends_with("_rpm") {
            Some(SpeedUnit::Rpm)
        } else if c.ends_with("_rad_s") {
            Some(SpeedUnit::RadS)
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
}

impl TorqueUnit {
    /// N·m per one of this unit.
    pub fn newton_metres(self) -> f64 {
        match self {
            TorqueUnit::Nm => 1.0,
            TorqueUnit::KNm => 1000.0,
        }
    }
    /// Printed name.
    pub fn label(self) -> &'static str {
        match self {
            TorqueUnit::Nm => "N·m",
            TorqueUnit::KNm => "kN·m",
        }
    }
    /// The unit a column name's suffix declares (`torque_knm`, `tob_nm`), if any.
    pub fn from_suffix(column: &str) -> Option<Self> {
        let c = column.to_ascii_lowercase();
        if c.ends_with("_knm") {
            Some(TorqueUnit::KNm)
        } else if c.ends_with("_nm") {
            Some(TorqueUnit::Nm)
        } else {
            None
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
}

impl ForceUnit {
    /// N per one of this unit.
    pub fn newtons(self) -> f64 {
        match self {
            ForceUnit::N => 1.0,
            ForceUnit::KN => 1000.0,
        }
    }
    /// Printed name.
    pub fn label(self) -> &'static str {
        match self {
            ForceUnit::N => "N",
            ForceUnit::KN => "kN",
        }
    }
    /// The unit a column name's suffix declares (`wob_kn`, `wob_n`), if any.
    pub fn from_suffix(column: &str) -> Option<Self> {
        let c = column.to_ascii_lowercase();
        if c.ends_with("_kn") {
            Some(ForceUnit::KN)
        } else if c.ends_with("_n") {
            Some(ForceUnit::N)
        } else {
            None
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
            RateUnit::MH => 1.0 / 3600.0,
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
    /// The unit a column name's suffix declares (`rop_m_h`, `axial_speed_m_s`, `rop_ft_h`).
    pub fn from_suffix(column: &str) -> Option<Self> {
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

/// A unit a record's column may be in: declared by the column name's suffix, or by a setting.
pub trait ColumnUnit: Copy + PartialEq {
    /// The unit the suffix of the column name `column` declares, if any.
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
column_unit!(SpeedUnit, TorqueUnit, ForceUnit, RateUnit);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn suffixes_name_units() {
        assert_eq!(SpeedUnit::from_suffix("bit_speed_rpm"), Some(SpeedUnit::Rpm));
        assert_eq!(SpeedUnit::from_suffix("W_RAD_S"), Some(SpeedUnit::RadS));
        assert_eq!(SpeedUnit::from_suffix("speed"), None);
        assert_eq!(TorqueUnit::from_suffix("torque_knm"), Some(TorqueUnit::KNm));
        assert_eq!(TorqueUnit::from_suffix("torque_nm"), Some(TorqueUnit::Nm));
        assert_eq!(ForceUnit::from_suffix("wob_kn"), Some(ForceUnit::KN));
        assert_eq!(ForceUnit::from_suffix("wob_n"), Some(ForceUnit::N));
    }

    #[test]
    fn sixty_rpm_is_two_pi_rad_s() {
        assert!((SpeedUnit::Rpm.to_rad_s(60.0) - 2.0 * PI).abs() < 1e-12);
    }
}
