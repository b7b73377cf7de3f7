//! A window of surface channels alone (top-drive speed, surface torque, weight on bit): its
//! laws inferred through simulated strings ([`crate::run::surface`]), the model choice with
//! its check by re-simulation, and the bit it implies taken for the bit seen by the advice.
//!
//! A window whose surface torque shows no stick-slip cycle, or fewer than
//! [`crate::run::surface::MIN_CYCLES`], informs nothing: its summaries say T(Ω) at one speed,
//! not the law's shape. The change rule compares fits of the bit's torque and speed, which a
//! surface window has not: none is declared.

use super::*;
use crate::data::BitSeen;
use crate::data::surface::SurfaceRecord;
use crate::run::surface::{Cycle, SurfaceSettings, ValueOrBounds};

/// Particles per population of each surface window's sampler by default.
pub const SURFACE_PARTICLES: usize = 300;

/// The surface run's settings of each window by default: small enough to keep up with a
/// stream at 1 Hz on a workstation's CPU, its model choice still checked.
pub fn default_surface_settings() -> crate::run::surface::Settings {
    crate::run::surface::Settings {
        particles: SURFACE_PARTICLES,
        max_populations: 6,
        pilot: 300,
        check_replicates: 10,
        predictive_draws: 40,
        // The watch advises on every window itself, from the carried posterior.
        advice: false,
        ..Default::default()
    }
}

/// What the surface sampler of a window gives the watch.
pub(super) struct SurfaceSelected {
    pub(super) selection: Selection,
    /// The bit as the window's surface implies it.
    pub(super) bit: BitSeen,
    /// The check by re-simulation of the model choice.
    pub(super) check: WindowCheck,
    /// The window's law posteriors: what a way out rests on that the window does not tell
    /// ([`unidentified_caveat`]).
    pub(super) laws: Vec<crate::run::surface::LawPosterior>,
    /// What the user should know of the window's run (a sampler stopped far above its floor).
    pub(super) warnings: Vec<String>,
    /// What the page's strip chart draws of the window.
    pub(super) strip: super::view::SurfaceStrip,
}

impl Watch {
    /// The surface run every window of surface channels goes through: the watch's laws, its
    /// 1-DOF string and backend; refused by name where the watch's criterion is a
    /// finite-element string, which the surface sampler does not simulate.
    pub(super) fn surface_settings(settings: &WatchSettings) -> Result<SurfaceSettings> {
        let Criterion::Lumped(string) = settings.criterion else {
            return Err(crate::Error::setting(
                "structure",
                "a record of surface channels is inferred through the 1-DOF string simulated per candidate: give its inertia, natural frequency and damping ratio instead of a finite-element string",
            ));
        };
        let given = crate::run::surface::Settings {
            inertia_kg_m2: Some(string.inertia_kg_m2),
            omega_n_rad_s: Some(ValueOrBounds::Value(string.omega_n_rad_s)),
            damping_ratio: Some(ValueOrBounds::Value(string.damping_ratio)),
            backend: settings.backend,
            ..settings.surface.clone()
        };
        given.config(settings.laws.clone())
    }

    /// The window's laws by the surface sampler (seeded seed + k); `Err`: why the window
    /// cannot inform (its clock, too few samples, no cycle).
    pub(super) fn by_surface(
        &self,
        config: &SurfaceSettings,
        window: &Window,
        observer: &mut dyn Observer,
    ) -> Result<std::result::Result<SurfaceSelected, String>> {
        let columns = self
            .declared
            .surface
            .clone()
            .expect("a surface watch declares its columns");
        let source = PathBuf::from(format!("{} (window {})", self.source.display(), window.index));
        let units = &self.declared.units;
        let record = match follow::of_window(SurfaceRecord::of_rows(
            &window.rows,
            &source,
            columns,
            units.speed,
            units.torque,
        ))? {
            Ok(record) => record,
            Err(why) => return Ok(Err(why)),
        };
        if let Some(why) = Cycle::of_record(&record).uninformative("window") {
            return Ok(Err(why));
        }
        let seed = self.settings.evidence.seed.wrapping_add(window.index as u64);
        let mut notes = WindowNotes(observer);
        // From the window before's posterior (the carried mixture), where the watch warm-starts.
        let warm = match (&self.carried.posterior, self.settings.warm_start) {
            (Some(posterior), true) => posterior.as_slice(),
            _ => &[],
        };
        let mut keep = |_: &[crate::abc::Population]| Ok(());
        let sampling = crate::run::surface::Sampling {
            previous: Vec::new(),
            stopped: None,
            keep: &mut keep,
            warm,
            scoring: crate::run::Scoring::Here,
        };
        let result =
            crate::run::surface::infer_continuing(&record, config, seed, sampling, &mut |line| notes.note(line));
        let result = match follow::of_window(result)? {
            Ok(result) => result,
            Err(why) => return Ok(Err(why)),
        };
        let Some(last) = result.run.as_ref().and_then(|run| run.populations.last()) else {
            return Ok(Err(format!("no population of its sampler completed ({})", result.stop)));
        };
        let laws = Selected::of_population(&self.settings.laws, last);
        let bit = result.bit_seen(&record);
        let start_s = window.rows.first().and_then(|r| r.time_s).unwrap_or(0.0);
        let strip = super::view::SurfaceStrip::of(&record, start_s, &result.at_the_bit.speed_rpm);
        Ok(Ok(SurfaceSelected {
            strip,
            bit,
            check: WindowCheck {
                decided: result.check.decided,
                verdict: result.check.verdict,
            },
            selection: Selection {
                fits: Vec::new(),
                laws,
                candidates: result.simulations,
                epsilon: result.final_epsilon,
                // The laws hold at the window's own weight on bit (r = 1 throughout).
                w_ref_n: None,
                answer: None,
            },
            laws: result.laws,
            warnings: result.warnings,
        }))
    }
}
