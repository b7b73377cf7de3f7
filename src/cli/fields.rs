//! The library names its settings as its configuration does (`particles`, `min_speed_rpm`),
//! between backticks; the command line says them as its flags. This table is the one place
//! where a setting becomes a flag.

/// Each setting the library can name, with the flag that sets it.
const FLAGS: &[(&str, &str)] = &[
    // The coupled bit.
    ("radius_m", "--radius-m"),
    ("intrinsic_energy_mpa", "--intrinsic-energy-mpa"),
    ("zeta", "--zeta"),
    ("contact_stress_mpa", "--contact-stress-mpa"),
    ("wear_flat_mm", "--wear-flat-mm"),
    ("friction", "--friction"),
    ("gamma", "--gamma"),
    ("blades", "--blades"),
    ("mass_kg", "--mass-kg"),
    ("axial_stiffness_n_per_m", "--axial-stiffness-kn-m"),
    ("axial_damping_ns_per_m", "--axial-damping-kns-m"),
    ("map_rpm", "--map-rpm"),
    ("map_wob_kn", "--map-wob-kn"),
    ("map_feed_m_h", "--map-feed-m-h"),
    ("feed_m_h", "--feed-m-h"),
    // The record and its columns.
    ("speed_column", "--speed-col"),
    ("torque_column", "--torque-col"),
    ("wob_column", "--wob-col"),
    ("time_column", "--time-col"),
    ("top_drive_column", "--top-drive-col"),
    ("surface_torque_column", "--surface-torque-col"),
    ("downhole_min_column", "--downhole-min-col"),
    ("downhole_max_column", "--downhole-max-col"),
    ("rop_column", "--rop-col"),
    ("axial_speed_column", "--axial-speed-col"),
    ("axial_acceleration_column", "--axial-acceleration-col"),
    ("acceleration_unit", "--acceleration-unit"),
    ("rop_unit", "--rop-unit"),
    ("top_drive_unit", "--top-drive-unit"),
    ("from_surface", "--from-surface"),
    ("downhole_unit", "--downhole-unit"),
    ("downhole_window_s", "--downhole-window-s"),
    ("speed_unit", "--speed-unit"),
    ("torque_unit", "--torque-unit"),
    ("param_torque_unit", "--param-torque-unit"),
    ("wob_unit", "--wob-unit"),
    ("column_map", "--column-map"),
    ("min_speed_rpm", "--min-speed-rpm"),
    ("t_start_s", "--t-start-s"),
    ("t_end_s", "--t-end-s"),
    ("thin", "--thin"),
    ("calibration_fraction", "--calibration-fraction"),
    ("split", "--split"),
    // Least squares.
    ("laws", "--laws"),
    ("law", "--law"),
    ("law_file", "--law-file"),
    ("starts", "--starts"),
    ("w_ref_kn", "--w-ref-kn"),
    ("scale_by_wob", "--scale-by-wob"),
    ("no_bounds", "--no-bounds"),
    // The prior.
    ("prior", "--prior"),
    ("delta", "--delta"),
    ("prior_k", "--prior-k"),
    ("prior_scale", "--prior-scale"),
    // The samplers.
    ("particles", "--particles"),
    ("islands", "--islands"),
    ("max_stages", "--max-stages"),
    ("ess_share", "--ess-share"),
    ("max_sweeps", "--max-sweeps"),
    ("refine_rounds", "--refine-rounds"),
    ("eps_min", "--eps-min"),
    ("epsilons", "--epsilons"),
    ("start_epsilon", "--start-epsilon"),
    ("max_populations", "--max-populations"),
    ("max_draws", "--max-draws"),
    ("max_seconds", "--max-seconds"),
    ("min_acceptance", "--min-acceptance"),
    ("summary_population", "--summary-population"),
    ("sampler", "--sampler"),
    ("prior_rule", "--prior-rule"),
    ("mode", "--mode"),
    ("p_stay", "--p-stay"),
    ("kernel_scale", "--kernel-scale"),
    ("smc_weights", "--smc-weights"),
    ("refill", "--refill"),
    ("law_proposal", "--law-proposal"),
    ("perturbation", "--perturbation"),
    ("backend", "--backend"),
    ("devices", "--devices"),
    ("threads", "--threads"),
    // Outputs.
    ("out", "--out"),
    ("source", "--posterior"),
    ("force", "--force"),
    ("population", "--population"),
    ("run", "--run"),
    // Simulation and the 1-DOF drill string.
    ("params", "--params"),
    ("omega_rpm", "--omega-rpm"),
    ("wob_kn", "--wob-kn"),
    ("omega_rpm/wob_kn", "--omega-rpm/--wob-kn"),
    ("duration_s", "--duration-s"),
    ("settle_s", "--settle-s"),
    ("sample_hz", "--sample-hz"),
    ("dt_s", "--dt-s"),
    ("kick_rpm", "--kick-rpm"),
    ("noise_torque_knm", "--noise-torque-knm"),
    ("noise_speed_rpm", "--noise-speed-rpm"),
    ("wob_fluctuation_kn", "--wob-fluctuation-kn"),
    ("wob_correlation_s", "--wob-correlation-s"),
    ("inertia_kg_m2", "--inertia-kg-m2"),
    ("omega_n_rad_s", "--omega-n-rad-s"),
    ("damping_ratio", "--damping-ratio"),
    // The finite-element drill string.
    ("structure", "--structure"),
    // A stored watch's stability criterion: the structure and its constants.
    ("criterion", "--structure"),
    ("fe_file", "--fe-file"),
    ("dp_elements", "--dp-elements"),
    ("bha_elements", "--bha-elements"),
    ("alpha", "--alpha"),
    ("beta", "--beta"),
    // Stability maps, the selection check, parity and benchmarks.
    ("percentile", "--percentile"),
    ("samples", "--samples"),
    ("sim_samples", "--sim-samples"),
    ("sim_omega_rpm", "--sim-omega-rpm"),
    ("sim_wob_kn", "--sim-wob-kn"),
    ("at_rpm", "--at-rpm"),
    ("at_kn", "--at-kn"),
    ("strings_n", "--strings-n"),
    ("replicates", "--replicates"),
    ("reference", "--reference"),
    ("pilot", "--pilot"),
    ("check_replicates", "--check-replicates"),
    ("predictive_draws", "--predictive-draws"),
    ("noise_sd", "--noise-sd-knm"),
    ("bit_out", "--bit-out"),
    ("check", "--check"),
    ("posterior_out", "--posterior-out"),
    ("batch", "--batch"),
    ("candidates", "--candidates"),
    ("epsilon", "--epsilon"),
    ("reps", "--reps"),
    // The watch and the wells it is tried on.
    ("window_s", "--window-s"),
    ("step_s", "--step-s"),
    ("forgetting", "--forgetting"),
    ("floor", "--floor"),
    ("change_nats", "--change-nats"),
    ("risk", "--risk"),
    ("replay_speed", "--replay-speed"),
    ("resume", "--resume"),
    ("follow", "--follow"),
    ("wits_items", "--wits-items"),
    ("cold_start", "--cold-start"),
    ("abc", "--abc"),
    ("serve", "--serve"),
    ("address", "--address"),
    ("segment", "--well"),
];

/// Every string in a JSON document said with flags, as [`as_flags`] says one text.
pub fn json_as_flags(value: &mut serde_json::Value) {
    match value {
        serde_json::Value::String(text) => *text = as_flags(text),
        serde_json::Value::Array(items) => items.iter_mut().for_each(json_as_flags),
        serde_json::Value::Object(fields) => fields.values_mut().for_each(json_as_flags),
        _ => {}
    }
}

/// `text` with every setting the library names (`` `particles` ``) said as its flag
/// (`--particles`); other backticked text is left as it is.
pub fn as_flags(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    while let Some(open) = rest.find('`') {
        let Some(len) = rest[open + 1..].find('`') else { break };
        let name = &rest[open + 1..open + 1 + len];
        out.push_str(&rest[..open]);
        match flag_of(name) {
            Some(flag) => {
                out.push_str(flag);
                rest = &rest[open + len + 2..];
            }
            None => {
                // Not a setting: keep the opening backtick and look on from the next one.
                out.push('`');
                rest = &rest[open + 1..];
            }
        }
    }
    out.push_str(rest);
    out
}

/// The flag that sets the library's setting `name`.
pub fn flag_of(name: &str) -> Option<&'static str> {
    FLAGS.iter().find(|(field, _)| *field == name).map(|(_, flag)| *flag)
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;

    #[test]
    fn settings_become_flags_and_other_backticks_stay() {
        assert_eq!(
            as_flags("`particles`: must be at least 1"),
            "--particles: must be at least 1"
        );
        assert_eq!(
            as_flags("relax `min_speed_rpm`, `t_start_s`/`t_end_s` or `thin`"),
            "relax --min-speed-rpm, --t-start-s/--t-end-s or --thin"
        );
        assert_eq!(
            as_flags("continue with `bitrock abc --resume R` (`max_draws` ran out)"),
            "continue with `bitrock abc --resume R` (--max-draws ran out)"
        );
        assert_eq!(as_flags("an odd ` backtick"), "an odd ` backtick");
        assert_eq!(as_flags("`out`: R/`x`: cannot write"), "--out: R/`x`: cannot write");
    }

    /// Every conflict names an argument of its command: release builds skip clap's own checks
    /// (`debug_assert`, run too), and there a misspelt name is silently no rule at all.
    #[test]
    fn every_conflict_names_a_real_argument() {
        let mut cli = crate::cli::Cli::command();
        cli.build();
        for command in cli.get_subcommands() {
            for arg in command.get_arguments() {
                // clap panics on a conflict with an argument the command does not have.
                let named = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                    command.get_arg_conflicts_with(arg).len()
                }));
                assert!(
                    named.is_ok(),
                    "{}: a conflict of --{} names no argument",
                    command.get_name(),
                    arg.get_id()
                );
            }
        }
        cli.debug_assert();
    }

    /// Every flag of the table is a flag of some command, and each setting appears once.
    #[test]
    fn the_table_names_real_flags() {
        let mut longs = std::collections::BTreeSet::new();
        let cli = crate::cli::Cli::command();
        // Global flags (--law-file) are the top level's, every command's.
        for command in std::iter::once(&cli).chain(cli.get_subcommands()) {
            for arg in command.get_arguments() {
                if let Some(long) = arg.get_long() {
                    longs.insert(format!("--{long}"));
                }
            }
        }
        for (field, flags) in FLAGS {
            for flag in flags.split('/') {
                assert!(longs.contains(flag), "{field}: {flag} is no command's flag");
            }
            assert_eq!(FLAGS.iter().filter(|(f, _)| f == field).count(), 1, "{field} twice");
        }
    }
}
