//! Well files: a well drilled through formations, for `bitrock simulate --well FILE`.
//!
//! ```toml
//! sample_hz = 50            # the recorder (default 50 Hz)
//! noise_torque_knm = 0.6    # measurement noise of the whole well (default none)
//! noise_speed_rpm = 0.5
//! seed = 7
//!
//! [[segment]]               # in drilling order
//! name = "shale"            # the record's `segment` column (default: the law's name)
//! duration_s = 120
//! law = "m2"
//! params = [13.0, 6.5, 0.3] # in param_torque_unit (kN·m); default: the paper's estimate
//! omega_rpm = 80            # top-drive speed: a value, or [from, to] for a ramp
//! wob_kn = [180, 240]       # mean weight on bit: a value or a ramp
//! ```
//!
//! Units are in the keys' names; the string is the paper's unless `[string]` gives
//! `inertia_kg_m2`, `omega_n_rad_s`, `damping_ratio`. Every refusal names the file, the line
//! and the column.

use super::{DEFAULT_KICK_RPM, DEFAULT_SEED, Initial, Profile, Recording, Segment, Well};
use crate::error::Result;
use crate::laws::{Law, PAPER_W_REF_N};
use crate::stability::lumped::Lumped;
use crate::units::{RAD_S_PER_RPM, TorqueUnit};
use serde::Deserialize;
use std::path::Path;
use toml::Spanned;

/// Largest well file read (of either bit), bytes: a well of thousands of segments is far smaller.
pub(crate) const MAX_FILE_BYTES: u64 = 1 << 20;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct WellFile {
    #[serde(default = "default_sample_hz")]
    sample_hz: f64,
    #[serde(default = "default_dt_s")]
    dt_s: f64,
    #[serde(default)]
    settle_s: f64,
    #[serde(default = "default_kick_rpm")]
    kick_rpm: f64,
    #[serde(default)]
    noise_torque_knm: f64,
    #[serde(default)]
    noise_speed_rpm: f64,
    #[serde(default)]
    wob_fluctuation_kn: f64,
    #[serde(default = "default_wob_correlation_s")]
    wob_correlation_s: f64,
    #[serde(default = "default_w_ref_kn")]
    w_ref_kn: f64,
    #[serde(default = "default_seed")]
    seed: u64,
    #[serde(default)]
    param_torque_unit: ParamTorqueUnit,
    #[serde(default)]
    string: StringFile,
    segment: Vec<Spanned<SegmentFile>>,
}

#[derive(Deserialize, Default, Clone, Copy)]
#[serde(rename_all = "lowercase")]
enum ParamTorqueUnit {
    #[default]
    Knm,
    Nm,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct StringFile {
    #[serde(default = "default_inertia")]
    inertia_kg_m2: f64,
    #[serde(default = "default_omega_n")]
    omega_n_rad_s: f64,
    #[serde(default = "default_damping_ratio")]
    damping_ratio: f64,
}

impl Default for StringFile {
    fn default() -> Self {
        let paper = Lumped::default();
        Self {
            inertia_kg_m2: paper.inertia_kg_m2,
            omega_n_rad_s: paper.omega_n_rad_s,
            damping_ratio: paper.damping_ratio,
        }
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SegmentFile {
    name: Option<String>,
    duration_s: f64,
    law: Spanned<String>,
    params: Option<Spanned<Vec<f64>>>,
    omega_rpm: Spanned<ProfileFile>,
    wob_kn: Option<Spanned<ProfileFile>>,
}

/// A value, or `[from, to]` for a ramp: a well file's value over a segment (the coupled
/// bit's wells read theirs so too).
#[derive(Clone, Copy, Debug, Deserialize)]
#[serde(untagged)]
pub(crate) enum ProfileFile {
    Constant(f64),
    Ramp([f64; 2]),
}

impl ProfileFile {
    /// The profile in the file's unit times `per_unit`.
    pub(crate) fn profile(&self, per_unit: f64) -> Profile {
        match *self {
            ProfileFile::Constant(v) => Profile::Constant(v),
            ProfileFile::Ramp([from, to]) => Profile::Ramp { from, to },
        }
        .scaled(per_unit)
    }
}

fn default_sample_hz() -> f64 {
    50.0
}
fn default_dt_s() -> f64 {
    1e-3
}
fn default_kick_rpm() -> f64 {
    DEFAULT_KICK_RPM
}
fn default_wob_correlation_s() -> f64 {
    20.0
}
fn default_w_ref_kn() -> f64 {
    PAPER_W_REF_N / 1000.0
}
fn default_seed() -> u64 {
    DEFAULT_SEED
}
fn default_inertia() -> f64 {
    Lumped::default().inertia_kg_m2
}
fn default_omega_n() -> f64 {
    Lumped::default().omega_n_rad_s
}
fn default_damping_ratio() -> f64 {
    Lumped::default().damping_ratio
}

impl Well {
    /// Reads and checks the well file at `path`.
    pub fn load(path: &Path) -> Result<Self> {
        let text = crate::files::read_text(path, "a well file", MAX_FILE_BYTES)?;
        Self::parse(&text, path)
    }

    /// The well the file text `source` describes; `path` names it in refusals.
    pub fn parse(source: &str, path: &Path) -> Result<Self> {
        let text = crate::files::UserFile { source, path };
        let at = |offset: usize, message: String| text.at(offset, message);
        let file: WellFile = text.toml()?;
        if file.segment.is_empty() {
            return Err(at(0, "the well has no [[segment]]".into()));
        }
        let param_unit = match file.param_torque_unit {
            ParamTorqueUnit::Knm => TorqueUnit::KNm,
            ParamTorqueUnit::Nm => TorqueUnit::Nm,
        };
        let mut segments = Vec::with_capacity(file.segment.len());
        for spanned in &file.segment {
            let s = spanned.get_ref();
            let law: Law = s.law.get_ref().parse().map_err(|e: String| at(s.law.span().start, e))?;
            let params = match (&s.params, law.paper_estimate()) {
                (Some(p), _) => law.scale_torque(p.get_ref(), param_unit.newton_metres()),
                (None, Some(p)) => law.scale_torque(p, TorqueUnit::KNm.newton_metres()),
                (None, None) => {
                    return Err(at(
                        s.law.span().start,
                        format!("law {law} has no reference values to default to: give its `params`"),
                    ));
                }
            };
            let where_params = s.params.as_ref().map_or(spanned.span().start, |p| p.span().start);
            law.check_params(&params, "params")
                .map_err(|e| at(where_params, e.to_string()))?;
            if let Some(warning) = law.implausible_torque(&params, "param_torque_unit") {
                return Err(at(where_params, warning));
            }
            let wob_n = s
                .wob_kn
                .as_ref()
                .map_or(Profile::Constant(PAPER_W_REF_N), |w| w.get_ref().profile(1000.0));
            segments.push(Segment {
                name: s.name.clone().unwrap_or_else(|| law.name().to_string()),
                duration_s: s.duration_s,
                law,
                params_nm: params,
                omega_rad_s: s.omega_rpm.get_ref().profile(RAD_S_PER_RPM),
                wob_n,
            });
        }
        let well = Well {
            segments,
            structure: Lumped {
                inertia_kg_m2: file.string.inertia_kg_m2,
                omega_n_rad_s: file.string.omega_n_rad_s,
                damping_ratio: file.string.damping_ratio,
            },
            w_ref_n: file.w_ref_kn * 1000.0,
            recording: Recording {
                settle_s: file.settle_s,
                sample_hz: file.sample_hz,
                dt_s: file.dt_s,
                initial: Initial::Equilibrium {
                    speed_perturbation_rad_s: file.kick_rpm * RAD_S_PER_RPM,
                },
                noise_torque_nm: file.noise_torque_knm * 1000.0,
                noise_speed_rad_s: file.noise_speed_rpm * RAD_S_PER_RPM,
                wob_fluctuation_n: file.wob_fluctuation_kn * 1000.0,
                wob_correlation_s: file.wob_correlation_s,
                seed: file.seed,
            },
        };
        // A segment's settings refused where the segment begins.
        for (i, spanned) in file.segment.iter().enumerate() {
            well.check_segment(i).map_err(|e| {
                let message = e.keyed();
                at(spanned.span().start, format!("segment {}: {message}", i + 1))
            })?;
        }
        Ok(well)
    }
}
