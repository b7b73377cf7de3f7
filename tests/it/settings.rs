//! Every kind of run's settings pass one gate in the library (`run::settings`): each field of a
//! kind's `Settings` is a flag of its command here, and a keyword of its Python function in the
//! Python package's tests, so that no setting exists on one surface alone.

use crate::support::{bin, outcome};

/// The fields of `S` that `bitrock <command> --help` does not offer as flags. A field's flag is
/// its name in dashes, except where `renamed` gives it.
fn missing_flags<S: serde::Serialize + Default>(command: &str, renamed: &[(&str, &str)]) -> Vec<String> {
    let (code, help, _) = outcome(bin().args([command, "--help"]));
    assert_eq!(code, 0);
    bitrock::run::settings::fields::<S>()
        .into_iter()
        .filter(|field| {
            let flag = renamed.iter().find(|(f, _)| f == field).map_or_else(
                || format!("--{}", field.replace('_', "-")),
                |(_, flag)| (*flag).to_string(),
            );
            // A flag with a value is followed by it; a switch ends its line.
            !help.contains(&format!("{flag} ")) && !help.contains(&format!("{flag}\n"))
        })
        .collect()
}

#[test]
fn every_setting_of_every_kind_is_a_flag_of_its_command() {
    let abc = bitrock::run::settings::fields::<bitrock::run::abc::Settings>();
    assert!(abc.len() >= 20 && abc.contains(&"perturbation".to_string()), "{abc:?}");
    // The run's prior file is `--prior` on the command line, as every command names it.
    let missing = missing_flags::<bitrock::run::abc::Settings>("abc", &[("prior_file", "--prior")]);
    assert!(missing.is_empty(), "abc settings without a flag: {missing:?}");
    let evidence = bitrock::run::settings::fields::<bitrock::run::evidence::Settings>();
    assert!(
        evidence.len() >= 13 && evidence.contains(&"ess_share".to_string()),
        "{evidence:?}"
    );
    let missing = missing_flags::<bitrock::run::evidence::Settings>("evidence", &[]);
    assert!(missing.is_empty(), "evidence settings without a flag: {missing:?}");
    let coupled = bitrock::run::settings::fields::<bitrock::run::coupled::Settings>();
    assert!(
        coupled.len() >= 25 && coupled.contains(&"intrinsic_energy_mpa".to_string()),
        "{coupled:?}"
    );
    let missing = missing_flags::<bitrock::run::coupled::Settings>("coupled", &[]);
    assert!(missing.is_empty(), "coupled settings without a flag: {missing:?}");
    let surface = bitrock::run::settings::fields::<bitrock::run::surface::Settings>();
    assert!(
        surface.len() >= 17 && surface.contains(&"check_replicates".to_string()),
        "{surface:?}"
    );
    let missing = missing_flags::<bitrock::run::surface::Settings>(
        "surface",
        &[("prior_file", "--prior"), ("advice", "--no-advice")],
    );
    assert!(missing.is_empty(), "surface settings without a flag: {missing:?}");
}

/// The drill string is a setting of every command that maps or advises, by the same flags:
/// `abc` and `evidence` keep it with what they write, `stability`, `report` and `watch` map
/// and advise on it.
#[test]
fn the_drill_string_is_a_flag_of_every_command_that_maps_or_advises() {
    let string = [
        "--inertia-kg-m2",
        "--omega-n-rad-s",
        "--damping-ratio",
        "--fe-file",
        "--dp-elements",
        "--bha-elements",
        "--alpha",
        "--beta",
    ];
    for command in ["abc", "evidence", "stability", "watch", "report"] {
        let (code, help, _) = outcome(bin().args([command, "--help"]));
        assert_eq!(code, 0);
        let missing: Vec<&str> = string
            .iter()
            .copied()
            .filter(|flag| !help.contains(&format!("{flag} ")))
            .collect();
        assert!(missing.is_empty(), "{command} lacks {missing:?}");
        // The report maps on the 1-DOF string and compares a finite-element one: no choice.
        assert_eq!(help.contains("--structure "), command != "report", "{command}");
    }
}
