//! A window's model selection, by the evidence or by the paper's ABC, and its judgement.

use super::*;
use crate::run;

/// A window's least-squares estimates by law (SI).
pub(super) type Fits = Vec<(Law, Vec<f64>)>;

/// A window's model selection, by either procedure.
pub(super) struct Selection {
    /// The window's least-squares fits: what its change was judged by, and what later windows
    /// compare with.
    pub(super) fits: Vec<crate::fit::LawFit>,
    /// Each law compared, in the watch's order.
    pub(super) laws: Vec<Selected>,
    pub(super) candidates: u64,
    /// The ABC's last tolerance; `None` for the evidence.
    pub(super) epsilon: Option<f64>,
    /// The W_ref (N) of the posterior's torque parameters where they are for the torque scaled
    /// by WOB / W_ref; `None` for the torque as the laws give it.
    pub(super) w_ref_n: Option<f64>,
    /// The window's own answer to "which law, how sure", as its evidence or its ABC gives it.
    pub(super) answer: Option<crate::run::answer::Answer>,
}

impl Selection {
    pub(super) fn of(&self, law: Law) -> Option<&Selected> {
        self.laws.iter().find(|l| l.law == law)
    }
}

/// One law of a window's selection.
pub(super) struct Selected {
    pub(super) law: Law,
    /// P(m | window).
    pub(super) probability: f64,
    /// Its posterior particles (SI), weighted within the law.
    pub(super) posterior: Vec<crate::abc::Particle>,
    /// ln Z and its Monte-Carlo error (the evidence's; the paper's ABC has none).
    pub(super) ln_z: Option<(f64, f64)>,
}

impl Selected {
    /// Each of `laws` in a sampler's last `population`: its probability, and its particles
    /// weighted within the law.
    pub(super) fn of_population(laws: &[Law], population: &crate::abc::Population) -> Vec<Self> {
        laws.iter()
            .map(|&law| {
                let probability = population.record.probability_of(law);
                Selected {
                    law,
                    probability,
                    // Weights relative to the law's own: its share of the population's.
                    posterior: population
                        .particles
                        .iter()
                        .filter(|p| p.law == law)
                        .map(|p| crate::abc::Particle {
                            weight: p.weight / probability,
                            ..p.clone()
                        })
                        .collect(),
                    ln_z: None,
                }
            })
            .collect()
    }
}

/// What the fits of the window before say of this one.
pub(super) struct Judged {
    /// Nats of log-likelihood the earlier fits lose here; `None` without an earlier window.
    pub(super) loss: Option<f64>,
    /// The running level of that loss since the last change.
    pub(super) level: Option<f64>,
    pub(super) change: bool,
}

/// A window's run says its notes through the watch's observer, but not the tolerance floor
/// it chose: each window's ε is in its update.
pub(super) struct WindowNotes<'a>(pub(super) &'a mut dyn Observer);

impl Observer for WindowNotes<'_> {
    fn note(&mut self, line: String) {
        if !crate::abc::floor::is_floor_note(&line) {
            self.0.note(line);
        }
    }
}

impl Watch {
    /// The loss of an earlier window's fits here, against this window's own `fits`: the
    /// latest window that does not overlap this one, and none that overlaps the last change's
    /// window (which may hold both formations); a change where it exceeds its running level
    /// by the threshold.
    pub(super) fn judge(&self, window: &Window, fits: &[crate::fit::LawFit], samples: &crate::data::Samples) -> Judged {
        let span = self.windows.span();
        let reference = self
            .carried
            .recent_fits
            .iter()
            .rev()
            .find(|(k, _)| k + span <= window.index)
            .filter(|(k, _)| self.carried.last_change.is_none_or(|c| *k >= c + span));
        let loss = reference.and_then(|(k, before)| {
            let holds_at_n = self.carried.recent_wob_n.iter().find(|(i, _)| i == k).map(|(_, w)| *w);
            loss_nats(before, holds_at_n, fits, samples)
        });
        let level = crate::numerics::median(&self.carried.losses.iter().copied().collect::<Vec<_>>());
        let change = match (loss, level) {
            (Some(loss), Some(level)) => loss - level > self.settings.change_nats,
            (Some(loss), None) => loss > self.settings.change_nats,
            _ => false,
        };
        Judged { loss, level, change }
    }

    /// The window's law probabilities by the evidence, warm-started from the window before
    /// where there is one; computed again from the boxes where the window declares a change
    /// or a law's warm samplers missed its posterior. `Err`: why the window cannot inform.
    pub(super) fn by_evidence(
        &self,
        window: &Window,
        data: &FieldData,
        observer: &mut dyn Observer,
    ) -> Result<std::result::Result<(Selection, Judged), String>> {
        let warm = self.warm_start();
        // From the window before's estimates, the fits need only the grid's best starts
        // beside them (which still find a minimum that moved away with a change of rock).
        let fit = match &warm {
            Some(warm) if !warm.fits.is_empty() => FitOptions {
                starts: WARM_FIT_STARTS,
                ..FitOptions::default()
            },
            _ => FitOptions::default(),
        };
        let template = self.evidence.as_ref().expect("a watch by the evidence keeps its job");
        let job = run::evidence::Job {
            fit,
            sampler: EvidenceConfig {
                seed: template.sampler.seed.wrapping_add(window.index as u64),
                ..template.sampler.clone()
            },
            warm,
            ..template.clone()
        };
        let mut analysis = match of_window(job.run(data, crate::run::Scoring::Here, observer))? {
            Ok(analysis) => analysis,
            Err(why) => return Ok(Err(why)),
        };
        let mut candidates = analysis.evidence.candidates_scored;
        let judged = self.judge(window, &analysis.fits, &data.calibration);
        // The fits the change was judged by are the ones the next windows compare with.
        let fits = analysis.fits.clone();
        if (judged.change || missed_mode(&analysis, data.calibration.len())) && job.warm.is_some() {
            // A change of rock: what the window before carried describes another formation
            // (its improbable laws kept few particles, its posterior lies elsewhere), so this
            // window's evidence is found again from the boxes, every law with all its
            // particles, as the paper would. So too where a law's warm samplers missed the
            // posterior that its fit shows (a mode the window before did not have).
            let cold = run::evidence::Job {
                fit: FitOptions::default(),
                sampler: EvidenceConfig {
                    law_particles: Vec::new(),
                    ..job.sampler.clone()
                },
                warm: None,
                ..job.clone()
            };
            match of_window(cold.run(data, crate::run::Scoring::Here, observer))? {
                Ok(fresh) => {
                    candidates += fresh.evidence.candidates_scored;
                    analysis = fresh;
                }
                Err(why) => return Ok(Err(why)),
            }
        }
        let laws = analysis
            .evidence
            .laws
            .iter()
            .map(|e| Selected {
                law: e.law,
                probability: e.probability,
                posterior: e
                    .posterior
                    .iter()
                    .enumerate()
                    .map(|(i, (params, weight))| crate::abc::Particle {
                        law: e.law,
                        index: i as u64,
                        params: params.clone(),
                        rho: f64::NAN,
                        weight: *weight,
                    })
                    .collect(),
                ln_z: Some((e.ln_z, e.ln_z_error)),
            })
            .collect();
        let selection = Selection {
            fits,
            laws,
            candidates,
            epsilon: None,
            w_ref_n: analysis.fit.w_ref_n,
            answer: analysis.answer(None),
        };
        Ok(Ok((selection, judged)))
    }

    /// The window's law probabilities by the paper's ABC: `config`'s sampler on δ boxes around
    /// the window's fits (started from the window before's estimates beside the grid's best),
    /// down to the floor the window reaches; seeded by the watch's seed + the window's index.
    /// `Err`: why the window cannot inform.
    pub(super) fn by_abc(
        &self,
        config: &crate::run::abc::Config,
        window: &Window,
        data: &FieldData,
        observer: &mut dyn Observer,
    ) -> Result<std::result::Result<(Selection, Judged), String>> {
        let known: Fits = match self.settings.warm_start {
            true => self
                .carried
                .recent_fits
                .back()
                .map(|(_, f)| f.clone())
                .unwrap_or_default(),
            false => Vec::new(),
        };
        let fit = match known.is_empty() {
            true => config.fit,
            false => FitOptions {
                starts: WARM_FIT_STARTS,
                ..config.fit
            },
        };
        let fits = match of_window(crate::fit::fit_record_from(&self.settings.laws, data, &fit, &known))? {
            Ok(fits) => fits,
            Err(why) => return Ok(Err(why)),
        };
        let judged = self.judge(window, &fits, &data.calibration);
        let config = crate::run::abc::Config {
            laws: self.settings.laws.clone(),
            seed: self.settings.evidence.seed.wrapping_add(window.index as u64),
            backend: self.settings.backend,
            ..config.clone()
        };
        let backend = config.backend;
        let w_ref_n = config.fit.w_ref_n;
        let mut evaluator =
            |problem, note: &mut dyn FnMut(String)| crate::eval::evaluator(problem, backend, Default::default(), note);
        let how = crate::run::abc::Start {
            fits: Some(fits.clone()),
            scoring: crate::run::Scoring::Evaluator(&mut evaluator),
            ..Default::default()
        };
        let outcome = crate::run::abc::start(data.clone(), config, how, &mut WindowNotes(observer));
        let outcome = match of_window(outcome)? {
            Ok(outcome) => outcome,
            Err(why) => return Ok(Err(why)),
        };
        let (setup, fit, run) = (outcome.setup, outcome.config.fit, outcome.run);
        let candidates = run.populations.iter().map(|p| p.record.candidates_scored).sum();
        let Some(last) = run.populations.into_iter().last() else {
            return Ok(Err(format!(
                "no population of its ABC completed ({})",
                run.stop.describe()
            )));
        };
        let laws = Selected::of_population(&self.settings.laws, &last);
        let probabilities: Vec<(Law, f64)> = self
            .settings
            .laws
            .iter()
            .map(|&law| (law, last.record.probability_of(law)))
            .collect();
        let answer = match of_window(crate::run::abc::answer(&setup, &fit, &last.record, &probabilities))? {
            Ok((_, answer)) => answer,
            Err(why) => return Ok(Err(why)),
        };
        let selection = Selection {
            fits,
            laws,
            candidates,
            epsilon: last.record.epsilon,
            w_ref_n,
            answer,
        };
        Ok(Ok((selection, judged)))
    }

    /// Each law's reference from the last informative window's posterior (a kernel density
    /// of its particles, mixed with its box): its evidence samplers start there instead of
    /// from the box, its fit from that window's estimate as well as from the grid, and its
    /// particles go by its carried probability. `None` with `warm_start` off or before the
    /// first informative window.
    pub(super) fn warm_start(&self) -> Option<WarmStart> {
        let posterior = self.carried.posterior.as_ref().filter(|_| self.settings.warm_start)?;
        let references = self
            .settings
            .laws
            .iter()
            .filter_map(|&law| {
                let own: Vec<(&[f64], f64)> = posterior
                    .iter()
                    .filter(|p| p.law == law)
                    .map(|p| (p.params.as_slice(), p.weight))
                    .collect();
                Reference::from_posterior(law, &own)
            })
            .collect();
        Some(WarmStart {
            references,
            fits: self
                .carried
                .recent_fits
                .back()
                .map(|(_, fits)| fits.clone())
                .unwrap_or_default(),
            scaled: self.carried.posterior_scaled,
            worth: self
                .settings
                .laws
                .iter()
                .copied()
                .zip(self.carried.probabilities.iter().flatten().copied())
                .collect(),
        })
    }
}
