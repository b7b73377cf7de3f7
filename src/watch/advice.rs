//! A window's advice: the linear criterion where the bit turns steadily, the simulated
//! strings' escape where it stick-slips, at the window's operating point.

use super::*;
use crate::data::BitSeen;

/// Posterior samples per law simulated for the escape advice of a stick-slipping window.
pub(super) const ESCAPE_SAMPLES: usize = 4;
/// Laws less probable than this are left out of the escape advice's simulations.
pub(super) const ESCAPE_MIN_PROBABILITY: f64 = 0.05;

/// A window's operating point: the mean top-drive speed (the mean bit speed where the
/// record has no top-drive column: the string's twist stays bounded, so the bit turns at the
/// top drive's speed on average, stuck or not), rpm, and the median weight on bit (`w_ref_n`
/// where the record has no column for it), kN, which a glitch of the WOB channel over less than
/// half the window does not move; each at least 1.
pub(super) fn operating_point(rows: &[Row], w_ref_n: f64) -> (f64, f64) {
    let speeds: Vec<f64> = rows
        .iter()
        .filter_map(|r| r.top_drive_rad_s.or(r.bit.map(|b| b.speed_rad_s)))
        .collect();
    let omega_rpm = speeds.iter().sum::<f64>() / speeds.len().max(1) as f64 / RAD_S_PER_RPM;
    let wob: Vec<f64> = rows.iter().map(|r| r.wob_n.unwrap_or(w_ref_n)).collect();
    let wob_kn = crate::numerics::median(&wob).unwrap_or(w_ref_n) / 1000.0;
    (omega_rpm.max(1.0), wob_kn.max(1.0))
}

/// The share of a window's rows whose weight on bit lies beyond three times its median or
/// below a third of it: a glitch of the WOB channel where it is large (said, and left out of
/// the operating point by the median).
pub(super) fn wob_glitch_share(rows: &[Row]) -> f64 {
    let wob: Vec<f64> = rows.iter().filter_map(|r| r.wob_n).collect();
    let Some(median) = crate::numerics::median(&wob).filter(|m| *m > 0.0) else {
        return 0.0;
    };
    let off = wob.iter().filter(|&&w| w > 3.0 * median || w < median / 3.0).count();
    off as f64 / wob.len() as f64
}

impl Watch {
    /// The windows' advice: the watch's criterion and risk; a stick-slipping window's way out
    /// by its string simulated for a few samples of the likely laws, on the CPU (within the
    /// window's latency).
    pub(super) fn adviser(&self) -> Adviser {
        let criterion = self.settings.criterion;
        Adviser {
            criterion,
            risk: self.settings.risk,
            escape: match criterion {
                Criterion::Lumped(lumped) => Some(Chain::one_dof(&lumped)),
                Criterion::Critical(_) => self.settings.fe_chain.clone(),
            }
            .map(|chain| EscapeSettings {
                chain,
                string: None,
                samples: ESCAPE_SAMPLES,
                min_probability: ESCAPE_MIN_PROBABILITY,
                backend: Backend::Cpu,
            }),
        }
    }

    /// Where the window leaves a law's parameter to its prior and the bit stick-slips: the way
    /// out along the carried posterior's spread of it, every string there ended
    /// ([`crate::run::surface::spread_way_out`]), added to `advice` (its words say where the
    /// strings failed).
    pub(super) fn spread_advice(&self, advice: &mut Advice, laws: &[crate::run::surface::LawPosterior]) {
        let (Some(posterior), Some(escape)) = (&self.carried.posterior, self.adviser().escape) else {
            return;
        };
        let inputs = thinned(
            &crate::abc::posterior::map_inputs_of(posterior, crate::run::advice::ADVICE_SAMPLES),
            escape.samples,
            escape.min_probability,
        );
        let point = OperatingPoint {
            omega_rpm: advice.omega_rpm,
            wob_kn: advice.wob_kn,
        };
        // The laws hold at the window's own weight on bit: its W_ref.
        let settings = SimulatedSettings {
            string: escape.string,
            ..SimulatedSettings::new(escape.chain, point.wob_kn * 1000.0, escape.backend)
        };
        match crate::run::surface::spread_way_out(&settings, &inputs, laws, posterior, point, &mut |_| {}) {
            Ok(Some((words, spread))) => {
                advice.words.push_str(&words);
                advice.spread = Some(spread);
            }
            Ok(None) => {}
            Err(e) => advice.words.push_str(&format!(
                "; along the posterior's spread the simulated strings failed ({e})"
            )),
        }
    }

    /// Adds the advice (from the latest posterior), the window's picture and the latency;
    /// `implied`: the bit a window of surface channels implies, taken for the bit seen.
    pub(super) fn completed(&mut self, mut update: Update, window: &Window, implied: Option<BitSeen>) -> Update {
        self.carried.window = Some(window.index);
        let (omega_rpm, wob_kn) = operating_point(&window.rows, self.settings.w_ref_n);
        let inputs = self
            .carried
            .posterior
            .as_ref()
            .map(|posterior| crate::abc::posterior::map_inputs_of(posterior, crate::run::advice::ADVICE_SAMPLES));
        let posterior = inputs.as_deref().map(|inputs| view::Posterior {
            inputs,
            criterion: self.settings.criterion,
            wob_kn,
            risk: self.settings.risk,
        });
        let view = view::view(window.index, &window.rows, self.declared.units.torque, posterior);
        if let Some(inputs) = &inputs {
            // The parameters describe the torque at the window's own weight on bit: that
            // weight is the advice's W_ref. What the bit did is the view's (its speeds seen
            // once).
            update.advice = Some(self.adviser().advise(
                inputs,
                wob_kn * 1000.0,
                OperatingPoint { omega_rpm, wob_kn },
                implied.as_ref().or(view.bit.as_ref()).map(|s| (s, "window")),
            ));
        }
        self.view = Some(view);
        update.latency_s = self.last_arrival.map_or(0.0, |t| t.elapsed().as_secs_f64());
        update
    }
}
