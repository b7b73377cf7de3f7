//! What every sampler shares: the tolerance schedule, the stopping rules and the run's
//! budgets. A sampler keeps only its own population step; the loop from one population to
//! the next asks [`next_epsilon`] for the next tolerance or the reason to stop.
//!
//! Tolerances: ε_0 = ∞ (the first N prior draws) unless a start is given; ε_{g+1} = the
//! median of population g's ρ, or the next value of a user schedule. Stopping rules, checked
//! in this order, so the run always ends: ε reached `eps_min` (that population is the last),
//! the schedule ran out, the median rule stalled (it would lower ε by less than
//! [`STALL_FRACTION`]), `max_populations`, the projected acceptance of the next population is
//! below `min_acceptance`, or `max_draws` candidates were scored or `max_seconds` passed (the
//! population in progress is dropped).

use super::{Particle, Population, StopReason};
use crate::error::{Error, Result};
use crate::numerics::quantile;

/// The tolerances, stopping rules and budgets of a run, whatever its sampler.
#[derive(Clone, Debug, PartialEq)]
pub struct Schedule {
    /// Particles per population, N.
    pub particles: usize,
    /// Smallest tolerance; the population at ε ≤ eps_min is the last.
    pub eps_min: f64,
    /// Most populations (including population 0).
    pub max_populations: usize,
    /// Most candidates scored over the whole run.
    pub max_draws: u64,
    /// Stop when the projected acceptance rate of the next population is below this.
    pub min_acceptance: f64,
    /// ε of population 0 (∞ when `None`).
    pub start_epsilon: Option<f64>,
    /// ε_1, ε_2, ...: a user schedule replacing the median rule.
    pub epsilons: Option<Vec<f64>>,
    /// Candidates per evaluator call at most.
    pub max_batch: usize,
    /// Wall-time budget of one invocation, seconds; the population in progress is dropped.
    pub max_seconds: Option<f64>,
}

impl Default for Schedule {
    fn default() -> Self {
        Self {
            particles: 25_000,
            eps_min: 0.014,
            max_populations: 30,
            max_draws: 2_000_000_000,
            min_acceptance: 1e-5,
            start_epsilon: None,
            epsilons: None,
            max_batch: 1 << 20,
            max_seconds: None,
        }
    }
}

impl Schedule {
    /// Refuses schedules that cannot run, naming the setting, before any work.
    pub fn validate(&self) -> Result<()> {
        if self.particles == 0 {
            return Err(Error::setting("particles", "must be at least 1"));
        }
        if !(self.eps_min.is_finite() && self.eps_min >= 0.0) {
            return Err(Error::setting(
                "eps_min",
                format!("must be finite and ≥ 0, got {}", self.eps_min),
            ));
        }
        if self.max_populations == 0 {
            return Err(Error::setting("max_populations", "must be at least 1"));
        }
        if self.max_draws < self.particles as u64 {
            return Err(Error::setting("max_draws", "must be at least the number of particles"));
        }
        if !(0.0..1.0).contains(&self.min_acceptance) {
            return Err(Error::setting("min_acceptance", "must lie in [0, 1)"));
        }
        if let Some(e) = self.start_epsilon
            && (e.is_nan() || e <= 0.0)
        {
            return Err(Error::setting("start_epsilon", format!("must be positive, got {e}")));
        }
        if let Some(list) = &self.epsilons {
            if list.is_empty() {
                return Err(Error::setting("epsilons", "the list is empty"));
            }
            let mut previous = self.start_epsilon.unwrap_or(f64::INFINITY);
            for &e in list {
                if !(e.is_finite() && e > 0.0 && e < previous) {
                    return Err(Error::setting(
                        "epsilons",
                        format!("must be positive and strictly decreasing (ε_1 > ε_2 > ...), got {e} after {previous}"),
                    ));
                }
                previous = e;
            }
            // A schedule is run as given or refused: never cut at the floor or the count.
            if let Some(&below) = list.iter().find(|&&e| e < self.eps_min) {
                return Err(Error::setting(
                    "epsilons",
                    format!(
                        "{below} lies below `eps_min` {}, where the run would stop: lower `eps_min` or end the schedule above it",
                        self.eps_min
                    ),
                ));
            }
            if list.len() >= self.max_populations {
                return Err(Error::setting(
                    "max_populations",
                    format!(
                        "{} populations cannot hold the schedule's {} tolerances after population 0",
                        self.max_populations,
                        list.len()
                    ),
                ));
            }
        }
        if let Some(t) = self.max_seconds
            && !(t.is_finite() && t > 0.0)
        {
            return Err(Error::setting(
                "max_seconds",
                format!("must be a positive number of seconds, got {t}"),
            ));
        }
        if self.max_batch == 0 {
            // No flag sets it: only a program using the library can get this wrong.
            return Err(Error::setting("Schedule::max_batch", "must be at least 1"));
        }
        Ok(())
    }
}

/// The median rule stops ("stalled") when it would lower ε by less than this fraction: ε is
/// then near the best ρ the laws attain, where each population costs about twice the draws of
/// the last for a change below 1 %.
pub const STALL_FRACTION: f64 = 0.01;

/// The tolerance of the population after the last of `populations`, or why there is none
/// (the stopping rules, checked in the order the module documentation gives).
pub fn next_epsilon(populations: &[Population], schedule: &Schedule) -> std::result::Result<f64, StopReason> {
    let current = populations.last().expect("at least one population");
    let epsilon = current.record.epsilon.unwrap_or(f64::INFINITY);
    if epsilon <= schedule.eps_min {
        return Err(StopReason::EpsMin);
    }
    let next = match &schedule.epsilons {
        Some(list) => match list.get(current.record.index) {
            Some(&e) => e,
            None => return Err(StopReason::ScheduleExhausted),
        },
        None => {
            let median = median_rho(&current.particles);
            // A median step to eps_min or below is the last one and always taken.
            if median > schedule.eps_min && median > epsilon * (1.0 - STALL_FRACTION) {
                return Err(StopReason::Stalled);
            }
            median
        }
    };
    let next = next.max(schedule.eps_min);
    if populations.len() >= schedule.max_populations {
        return Err(StopReason::MaxPopulations);
    }
    let n = current.particles.len();
    let below = current.particles.iter().filter(|p| p.rho < next).count() as f64 / n as f64;
    if below * current.record.acceptance_rate < schedule.min_acceptance {
        return Err(StopReason::AcceptanceFloor);
    }
    Ok(next)
}

/// The median of a population's ρ (the mean of the two middle values for even N), the
/// paper's rule for the next tolerance.
pub fn median_rho(particles: &[Particle]) -> f64 {
    let rho: Vec<f64> = particles.iter().map(|p| p.rho).collect();
    quantile(&rho, 0.5)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::abc::PopulationRecord;
    use crate::laws::Law;

    /// A population at `epsilon` whose particles have the given ρ.
    fn population(epsilon: f64, rhos: &[f64]) -> Population {
        let particles: Vec<Particle> = rhos
            .iter()
            .enumerate()
            .map(|(i, &rho)| Particle {
                law: Law::M2,
                index: i as u64,
                params: vec![1.0, 1.0, 1.0],
                rho,
                weight: 1.0 / rhos.len() as f64,
            })
            .collect();
        Population {
            record: PopulationRecord {
                index: 3,
                epsilon: Some(epsilon),
                draws: 1000,
                accepted: particles.len(),
                acceptance_rate: 0.5,
                per_law: vec![],
                candidates_scored: 1000,
                evaluations: 1000,
                near_threshold: 0,
                ess: particles.len() as f64,
                seconds: 0.0,
                stream: 0,
            },
            particles,
        }
    }

    #[test]
    fn the_median_rule_stalls_near_the_best_attainable_rho_but_always_takes_its_last_step() {
        let config = Schedule {
            eps_min: 0.014,
            ..Schedule::default()
        };
        // Median 0.0299 against ε = 0.03: lowered by 0.33 % < 1 %.
        let stalled = population(0.03, &[0.0298, 0.0299, 0.02995]);
        assert_eq!(next_epsilon(&[stalled], &config), Err(StopReason::Stalled));
        // Median 0.0296: lowered by 1.3 %, taken.
        let moving = population(0.03, &[0.0290, 0.0296, 0.0299]);
        assert_eq!(
            next_epsilon(&[moving], &config).map(f64::to_bits),
            Ok(0.0296f64.to_bits())
        );
        // A median at or below eps_min is the last step and taken however small.
        let last = population(0.0141, &[0.0139, 0.01395, 0.01409]);
        assert_eq!(next_epsilon(&[last], &config).map(f64::to_bits), Ok(0.014f64.to_bits()));
        // A user schedule is never called stalled.
        let schedule = Schedule {
            epsilons: Some(vec![0.05, 0.04, 0.03, 0.0299]),
            ..config
        };
        let p = population(0.03, &[0.0298, 0.0299, 0.02995]);
        assert_eq!(next_epsilon(&[p], &schedule).map(f64::to_bits), Ok(0.0299f64.to_bits()));
    }
}
