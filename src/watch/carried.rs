//! What a watch carries from window to window, bounded, and stored with each window.

use super::*;

/// The running losses a change is measured against: those of the last this many windows.
pub(super) const LOSS_MEMORY: usize = 120;

/// What a watch carries from window to window: all a watch directory needs to go on after
/// its last stored window as if it had never stopped. Bounded: a few windows' fits, the last
/// 120 losses and one posterior.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Carried {
    /// The last window given (informative or not).
    pub window: Option<usize>,
    /// Carried law probabilities, in `settings.laws` order; `None` before the first
    /// informative window.
    pub(super) probabilities: Option<Vec<f64>>,
    /// The fits (SI parameters by law) of the recent informative windows, by window index:
    /// a window is compared with the latest one it does not overlap.
    pub(super) recent_fits: std::collections::VecDeque<(usize, Fits)>,
    /// The weight on bit (N) each of `recent_fits` holds at, by window index: a fit to the
    /// torque scaled by WOB / W_ref holds at W_ref, one to the torque as the law gives it at its
    /// window's mean WOB. Empty for records without a WOB column and in stores written without
    /// it: their fits are compared as the laws give the torque.
    #[serde(default)]
    pub(super) recent_wob_n: std::collections::VecDeque<(usize, f64)>,
    /// The window that declared the last change: no window overlapping it is a reference.
    pub(super) last_change: Option<usize>,
    /// The last informative window's posterior particles (the mixture, weighted by the
    /// carried probabilities).
    #[serde(with = "posterior_json")]
    pub(super) posterior: Option<Vec<crate::abc::Particle>>,
    /// Whether that posterior's torque parameters are for the torque scaled by WOB / W_ref.
    pub(super) posterior_scaled: bool,
    /// The losses of the windows since the last change (their running level).
    pub(super) losses: std::collections::VecDeque<f64>,
}

/// Posterior particles in JSON: the evidence's carry no ρ (NaN), which JSON has no number for.
mod posterior_json {
    use crate::abc::Particle;
    use crate::laws::Law;
    use serde::{Deserialize, Deserializer, Serialize, Serializer};

    #[derive(Serialize, Deserialize)]
    struct Written {
        law: Law,
        index: u64,
        params: Vec<f64>,
        #[serde(with = "crate::numerics::json_f64")]
        rho: f64,
        weight: f64,
    }

    pub fn serialize<S: Serializer>(value: &Option<Vec<Particle>>, out: S) -> Result<S::Ok, S::Error> {
        value
            .as_ref()
            .map(|ps| {
                ps.iter()
                    .map(|p| Written {
                        law: p.law,
                        index: p.index,
                        params: p.params.clone(),
                        rho: p.rho,
                        weight: p.weight,
                    })
                    .collect::<Vec<_>>()
            })
            .serialize(out)
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(input: D) -> Result<Option<Vec<Particle>>, D::Error> {
        let written = Option::<Vec<Written>>::deserialize(input)?;
        Ok(written.map(|ws| {
            ws.into_iter()
                .map(|w| Particle {
                    law: w.law,
                    index: w.index,
                    params: w.params,
                    rho: w.rho,
                    weight: w.weight,
                })
                .collect()
        }))
    }
}
