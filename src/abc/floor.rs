//! The tolerance floor ε_min a record can reach.
//!
//! No candidate of a law scores below the law's best least-squares ρ on the calibration rows,
//! so a floor below every law's best ρ makes the median rule creep towards it while each
//! population costs about twice the draws of the last, and a floor between two laws' best ρ
//! gives the other law probability 0 by construction. The paper's 0.014 was chosen for its
//! record; on a record with more noise (a laboratory rig, say) it may not be reachable at all.

use crate::error::{Error, Result};
use crate::fit::LawFit;
use crate::laws::Law;

/// The paper's floor ("a reasonable limit for its lower bound would be in the range
/// [0.01, 0.02]"; its runs ended at ≈ 0.014).
pub const PAPER_EPS_MIN: f64 = 0.014;

/// When the paper's floor is not at least this multiple of the best least-squares ρ, the
/// default floor becomes this multiple of it: 10 % above the best fit, where the best law still
/// accepts a fair share of its prior and the median rule has room to move.
pub const FLOOR_MULTIPLE: f64 = 1.1;

/// Where a run's ε_min came from.
#[derive(Clone, Debug, PartialEq)]
pub enum FloorSource {
    /// The paper's 0.014, reachable on this record.
    Paper,
    /// Given by the user.
    Requested,
    /// [`FLOOR_MULTIPLE`] × the best least-squares ρ, because the paper's floor was not reachable.
    BestFit,
}

/// The floor of a run and what the user should be told about it.
#[derive(Clone, Debug, PartialEq)]
pub struct EpsFloor {
    pub eps_min: f64,
    pub source: FloorSource,
    /// The law with the lowest least-squares ρ, and that ρ.
    pub best: (Law, f64),
    /// One line for the user, when the floor is not the paper's or cannot be reached.
    pub note: Option<String>,
}

/// The law with the lowest least-squares ρ among `fits`.
pub fn best_fit(fits: &[LawFit]) -> Option<(Law, f64)> {
    fits.iter()
        .filter(|f| f.rho.is_finite())
        .min_by(|a, b| a.rho.total_cmp(&b.rho))
        .map(|f| (f.law, f.rho))
}

/// The floor for `requested` (`None`: the default) given the laws' fits. A requested floor
/// is kept even when no law can reach it (the run then ends when ε stalls), with a note.
pub fn resolve(fits: &[LawFit], requested: Option<f64>) -> Result<EpsFloor> {
    let best = best_fit(fits).ok_or_else(|| Error::Numerical("no law has a finite least-squares ρ".into()))?;
    let (law, rho) = best;
    Ok(match requested {
        Some(eps_min) => EpsFloor {
            eps_min,
            source: FloorSource::Requested,
            best,
            note: (eps_min <= rho).then(|| {
                format!(
                    "{UNREACHABLE_NOTE} {eps_min} (the best least-squares ρ is {law}'s {rho:.5}); the run will end when ε stalls"
                )
            }),
        },
        None if PAPER_EPS_MIN >= FLOOR_MULTIPLE * rho => EpsFloor {
            eps_min: PAPER_EPS_MIN,
            source: FloorSource::Paper,
            best,
            note: None,
        },
        None => {
            let eps_min = FLOOR_MULTIPLE * rho;
            EpsFloor {
                eps_min,
                source: FloorSource::BestFit,
                best,
                note: Some(format!(
                    "{MOVED_NOTE}{eps_min:.5} = {FLOOR_MULTIPLE} × the best least-squares ρ ({law}: {rho:.5}): the paper's {PAPER_EPS_MIN} is out of this record's reach (`eps_min` sets the floor)"
                )),
            }
        }
    })
}

/// Whether `line` is a note of [`resolve`] (a floor moved to the record's reach, or one no
/// law reaches): a caller that reports each run's floor itself need not say it again.
pub fn is_floor_note(line: &str) -> bool {
    line.starts_with(UNREACHABLE_NOTE) || line.starts_with(MOVED_NOTE)
}

const UNREACHABLE_NOTE: &str = "no law can reach `eps_min`";
const MOVED_NOTE: &str = "ε floor ";

/// Refuses a start tolerance that no law can reach (population 0 could never fill).
pub fn check_start_epsilon(fits: &[LawFit], start: Option<f64>) -> Result<()> {
    if let (Some(start), Some((law, rho))) = (start, best_fit(fits))
        && start <= rho
    {
        return Err(Error::setting(
            "start_epsilon",
            format!(
                "{start} is at or below every law's best least-squares ρ (the lowest is {law}'s {rho:.5}): no candidate could be accepted"
            ),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fit(law: Law, rho: f64) -> LawFit {
        LawFit::for_tests(law, vec![1.0; law.n_params()], rho)
    }

    #[test]
    fn the_paper_floor_is_kept_where_it_is_reachable() {
        // The embedded record: best ρ 0.0066 (m3); 1.1 × 0.0066 < 0.014.
        let fits = [fit(Law::M2, 0.0073), fit(Law::M3, 0.0066)];
        let f = resolve(&fits, None).unwrap();
        assert_eq!(f.source, FloorSource::Paper);
        assert_eq!(f.eps_min.to_bits(), PAPER_EPS_MIN.to_bits());
        assert_eq!(f.best, (Law::M3, 0.0066));
        assert!(f.note.is_none());
    }

    #[test]
    fn an_unreachable_paper_floor_becomes_a_multiple_of_the_best_fit() {
        // A laboratory rig record: best ρ 0.0273 (m3).
        let fits = [fit(Law::M1, 0.0339), fit(Law::M3, 0.0273), fit(Law::M4, 0.0277)];
        let f = resolve(&fits, None).unwrap();
        assert_eq!(f.source, FloorSource::BestFit);
        assert_eq!(f.eps_min.to_bits(), (1.1f64 * 0.0273).to_bits());
        assert!(f.note.unwrap().contains("m3: 0.02730"));
        // Just reachable but not by the margin: also replaced.
        let f = resolve(&[fit(Law::M2, 0.0135)], None).unwrap();
        assert_eq!(f.source, FloorSource::BestFit);
    }

    #[test]
    fn a_requested_floor_is_kept_and_an_unreachable_one_is_said() {
        let fits = [fit(Law::M3, 0.0273)];
        let f = resolve(&fits, Some(0.05)).unwrap();
        assert_eq!(f.eps_min.to_bits(), 0.05f64.to_bits());
        assert_eq!((f.source, f.note), (FloorSource::Requested, None));
        let f = resolve(&fits, Some(0.02)).unwrap();
        assert_eq!(f.eps_min.to_bits(), 0.02f64.to_bits());
        assert!(f.note.unwrap().contains("no law can reach `eps_min` 0.02"));
    }

    #[test]
    fn the_floor_s_notes_are_told_from_others() {
        let fits = [fit(Law::M3, 0.0273)];
        for requested in [None, Some(0.02)] {
            let note = resolve(&fits, requested).unwrap().note.unwrap();
            assert!(is_floor_note(&note), "{note}");
        }
        assert!(!is_floor_note("no usable GPU (no adapter); computing on the CPU"));
    }

    #[test]
    fn a_start_epsilon_below_every_best_fit_is_refused() {
        let fits = [fit(Law::M1, 0.03), fit(Law::M3, 0.0273)];
        assert!(check_start_epsilon(&fits, Some(0.028)).is_ok());
        assert!(check_start_epsilon(&fits, None).is_ok());
        let e = check_start_epsilon(&fits, Some(0.001)).unwrap_err().to_string();
        assert!(e.starts_with("`start_epsilon`:") && e.contains("0.02730"), "{e}");
    }
}
