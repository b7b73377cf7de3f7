//! What a watch says about each window: its laws, its change, its advice.

use super::*;

/// One law in a window's update.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LawUpdate {
    pub law: Law,
    /// The carried probability P_t(m).
    pub probability: f64,
    /// This window's alone, P(m | window).
    pub window_probability: f64,
    /// The law's ln Z on the window and its Monte-Carlo error; none by the paper's ABC.
    pub ln_z: Option<f64>,
    pub ln_z_error: Option<f64>,
    /// Posterior mean, MAP (the mode of a kernel density of the particles, as a run's
    /// summary finds it) and 1 %, 99 % quantiles of each parameter, in the record's torque
    /// unit.
    pub mean: Vec<f64>,
    #[serde(default)]
    pub map: Vec<f64>,
    pub q01: Vec<f64>,
    pub q99: Vec<f64>,
    /// Kish's effective sample size of the law's weighted posterior particles.
    #[serde(default)]
    pub ess: f64,
}

/// The check by re-simulation of a surface window's model choice: records simulated from each
/// law's posterior, classified by their summaries. Summaries that are not sufficient can make
/// ABC model choice inconsistent: a law is called only where its own re-simulations are
/// recognised and the others' are not taken for it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct WindowCheck {
    /// The law called, where the window and the check allow one.
    pub decided: Option<Law>,
    /// Why, in words.
    pub verdict: String,
}

impl WindowCheck {
    /// In a few words: the law called, or none.
    pub fn headline(&self) -> String {
        match self.decided {
            Some(law) => format!("{law}, its check agrees"),
            None => "no law called by its check".into(),
        }
    }
}

/// The advice of a window.
pub use crate::run::advice::Advice;

/// What a watch says of one window: one JSON line.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Update {
    pub window: usize,
    pub start_s: f64,
    pub end_s: f64,
    /// Samples in the window, and those used (above the minimum speed).
    pub samples: usize,
    pub samples_used: usize,
    /// Why the window informs nothing, where it does not.
    pub uninformative: Option<String>,
    /// The most probable law (carried probabilities).
    pub most_probable: Option<Law>,
    /// The window's own answer to "which law, how sure" (its evidence's Bayes factor, or its
    /// ABC's probabilities, in their words); the carried probabilities weigh earlier windows too.
    #[serde(default, serialize_with = "crate::run::answer::Answer::serialize_with_sentence")]
    pub answer: Option<crate::run::answer::Answer>,
    pub laws: Vec<LawUpdate>,
    /// Whether this window starts a new formation, and the log-likelihood (nats) the fits of
    /// the latest window sharing no time with it lose on it, beyond their running level.
    pub change: bool,
    pub change_nats: Option<f64>,
    pub advice: Option<Advice>,
    pub candidates_scored: u64,
    /// The tolerance the window's ABC ended at (the paper's procedure); none for the evidence.
    #[serde(default)]
    pub epsilon: Option<f64>,
    /// A window of surface channels: what the check by re-simulation says of its model choice.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub check: Option<WindowCheck>,
    /// Seconds from the window's last sample arriving to this update.
    pub latency_s: f64,
}
