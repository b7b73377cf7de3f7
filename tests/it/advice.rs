//! The advice at a record's own operating point: what the record's bit did, kept with the
//! record; a stick-slipping record never called steady; and the advice applied to the string
//! that made the record, from its settled cycle.

use crate::support::{bin, outcome};
use bitrock::Law;
use bitrock::data::{BitSeen, DataOptions, demo_field_data};
use bitrock::eval::Backend;
use bitrock::run::strings::{OperatingPoint, SimulatedSettings, Simulator};
use bitrock::simulate::strings::Chain;
use bitrock::stability::lumped::Lumped;
use bitrock::stability::map::LawSamples;
use bitrock::units::RAD_S_PER_RPM;

#[test]
fn what_a_bit_speed_record_shows_is_counted_over_every_sample() {
    let rpm = |v: f64| v * RAD_S_PER_RPM;
    // Two of five below 1 rpm (one of them turning backwards); mean 20 rpm; swing 50 rpm.
    let speeds = [rpm(0.0), rpm(-0.5), rpm(10.0), rpm(40.0), rpm(50.5)];
    let wob = [100e3, 110e3, 120e3, 130e3, 140e3];
    let seen = BitSeen::of(&speeds, Some(&wob)).unwrap();
    assert_eq!(seen.samples, 5);
    assert_eq!(seen.stuck_share, 0.4);
    assert!((seen.mean_speed_rpm - 20.0).abs() < 1e-12, "{seen:?}");
    assert!((seen.severity.unwrap() - 51.0 / 40.0).abs() < 1e-12, "{seen:?}");
    assert!((seen.mean_wob_kn.unwrap() - 120.0).abs() < 1e-9, "{seen:?}");
    assert!(seen.stick_slips());
    // A bit turning steadily at 80 rpm ± 5 never sticks; a bit that never turned has no severity.
    let steady: Vec<f64> = (0..100).map(|i| rpm(80.0 + 5.0 * (f64::from(i) * 0.3).sin())).collect();
    let seen = BitSeen::of(&steady, None).unwrap();
    assert_eq!(seen.stuck_share, 0.0);
    assert!(!seen.stick_slips() && seen.mean_wob_kn.is_none());
    assert_eq!(BitSeen::of(&[0.0; 4], None).unwrap().severity, None);
    assert_eq!(BitSeen::of(&[], None), None);
}

#[test]
fn the_demo_record_keeps_its_stick_slip_though_its_stuck_samples_are_not_fitted() {
    let data = demo_field_data(&DataOptions::default()).unwrap();
    let seen = data.bit.expect("a record read keeps what its bit did");
    // Every row counted, those below the fit's minimum speed too.
    assert_eq!(seen.samples, data.rows_read);
    assert!(data.rows_used < data.rows_read);
    // The truth sticks about a third of the time; the tool's 2 rpm noise shows about half of it
    // below 1 rpm.
    assert!(seen.stuck_share > 0.1 && seen.stuck_share < 0.35, "{seen:?}");
    assert!((seen.mean_speed_rpm - 80.0).abs() < 1.0, "{seen:?}");
    assert!((seen.mean_wob_kn.unwrap() - 242.77).abs() < 0.01, "{seen:?}");
}

/// P(stick-slip persists) of the string that made the demo record (m3 at its least-squares
/// estimate, the paper's 1-DOF string, 80 rpm and 244.2 kN) moved from its settled cycle to
/// each of `speeds_rpm` × `weights_kn`, over eight phases of the cycle.
fn truth_persists(speeds_rpm: &[f64], weights_kn: &[f64]) -> Vec<f64> {
    let params = Law::M3.scale_torque(&[2.72, 1.0, 0.09, 9.52, 4.0, 0.08], 1000.0);
    let inputs = vec![LawSamples {
        law: Law::M3,
        probability: 1.0,
        map_si: params.clone(),
        samples_si: vec![params],
        strings: Vec::new(),
    }];
    let settings = SimulatedSettings::new(Chain::one_dof(&Lumped::default()), 244.2e3, Backend::Cpu);
    let mut quiet = |_| {};
    let mut sim = Simulator::new(&settings, &inputs, &mut quiet).unwrap();
    let at = sim
        .at_point(OperatingPoint {
            omega_rpm: 80.0,
            wob_kn: 244.2,
        })
        .unwrap();
    assert_eq!(at.stick_slip_probability, 1.0, "the demo's string stick-slips");
    sim.escape(&at, speeds_rpm, weights_kn).unwrap().probability
}

#[test]
fn stability_of_the_demo_run_says_stick_slip_now_and_its_advice_ends_it_in_the_demo_string() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    let (code, _, err) = outcome(
        bin()
            .args(["abc", "--particles", "2000", "--backend", "cpu", "--out"])
            .arg(&run),
    );
    assert_eq!(code, 0, "{err}");
    let (code, out, err) = outcome(
        bin()
            .args(["stability", "--backend", "cpu", "--json", "--run"])
            .arg(&run),
    );
    assert_eq!(code, 0, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let advice = &v["advice"];
    assert_eq!(advice["stick_slip_now"], true, "{advice}");
    let words = advice["words"].as_str().unwrap();
    assert!(words.starts_with("stick-slip now at 80 rpm and 243 kN"), "{words}");
    assert!(!words.contains("steady"), "{words}");
    assert!(v["record"]["stuck_share"].as_f64().unwrap() > 0.1, "{v}");
    // Each way out, applied to the string that made the record from its settled cycle.
    let speed = advice["escape_omega_rpm"][0].as_f64().expect("a speed that ends it");
    let weight = advice["escape_wob_kn"][0].as_f64().expect("a weight that ends it");
    assert!(speed > 80.0 && weight < 243.0, "{advice}");
    assert!(advice["escape_omega_rpm"][1].as_f64().unwrap() >= 0.9, "{advice}");
    assert_eq!(truth_persists(&[speed], &[244.2]), vec![0.0], "{speed} rpm");
    assert_eq!(truth_persists(&[80.0], &[weight]), vec![0.0], "{weight} kN");
    // Fewer than half of this mixture's strings swing the bit as the record does; those that do
    // advise on their own, and their ways out end it too.
    let cycle = &advice["cycle"];
    assert_eq!(cycle["reproduced"], false, "{cycle}");
    let share = cycle["reproducing_share"].as_f64().unwrap();
    assert!(share > 0.2 && share < 0.5, "{cycle}");
    let speed = cycle["escape_omega_rpm"][0]
        .as_f64()
        .expect("the reproducing strings' speed");
    let weight = cycle["escape_wob_kn"][0]
        .as_f64()
        .expect("the reproducing strings' weight");
    assert_eq!(truth_persists(&[speed], &[244.2]), vec![0.0], "{speed} rpm");
    assert_eq!(truth_persists(&[80.0], &[weight]), vec![0.0], "{weight} kN");
    assert!(words.contains("the strings that do reproduce it: raise"), "{words}");
    // The linear criterion's answer is kept beside it, and the table says it in words.
    assert!(advice["p_unstable"].as_f64().is_some(), "{advice}");
    let (code, out, err) = outcome(bin().args(["stability", "--backend", "cpu", "--run"]).arg(&run));
    assert_eq!(code, 0, "{err}");
    let line = out
        .lines()
        .find(|l| l.starts_with("advice at the record's operating point: "))
        .unwrap_or_else(|| panic!("{out}"));
    assert!(
        line.contains(&format!("raise the top-drive speed to {speed:.0} rpm")),
        "{line}"
    );
}

#[test]
fn the_demo_strings_escape_lies_between_110_and_140_rpm() {
    // From every phase of its cycle the string that made the demo record stays in it at 85
    // and 110 rpm and leaves it at 140 rpm: an advice's speed is judged against this.
    assert_eq!(truth_persists(&[85.0, 110.0, 140.0], &[244.2]), vec![1.0, 1.0, 0.0]);
}

/// The advice at the demo record's own operating point from one m3 parameter set (kN·m).
fn demo_advice(params_knm: &[f64]) -> bitrock::run::advice::Advice {
    use bitrock::run::advice::Adviser;
    use bitrock::stability::map::Criterion;
    let seen = demo_field_data(&DataOptions::default()).unwrap().bit.unwrap();
    let params = Law::M3.scale_torque(params_knm, 1000.0);
    let inputs = vec![LawSamples {
        law: Law::M3,
        probability: 1.0,
        map_si: params.clone(),
        samples_si: vec![params],
        strings: Vec::new(),
    }];
    let lumped = Lumped::default();
    let adviser = Adviser::for_record(Criterion::Lumped(lumped), Some(Chain::one_dof(&lumped)), Backend::Cpu);
    adviser.advise_record(&inputs, 244.2e3, &seen)
}

#[test]
fn a_posterior_that_misses_the_records_cycle_is_told_apart_from_the_truth() {
    // The string that made the record reproduces its cycle (peak 220 rpm against the noisy
    // record's 228): no warning, and its way out is the truth's own.
    let truth = demo_advice(&[2.72, 1.0, 0.09, 9.52, 4.0, 0.08]);
    let cycle = truth.cycle.expect("a stick-slipping record is checked");
    assert!(cycle.reproduced && cycle.reproducing_share == 1.0, "{truth:?}");
    assert!(!truth.words.contains("fall short"), "{}", truth.words);
    let speed = truth.escape_omega_rpm.unwrap().0;
    assert!((110.0..=140.0).contains(&speed), "{}", truth.words);
    // The demo evidence's m3 posterior mean (biased by the tool's speed noise at low speeds),
    // whose string swings the bit only to about 196 rpm: its advice says it does not reproduce
    // the cycle.
    let biased = demo_advice(&[1.63, 2.99, 0.68, 9.58, 4.04, 0.082]);
    let cycle = biased.cycle.unwrap();
    assert!(!cycle.reproduced && cycle.simulated_peak_rpm.1 < 205.0, "{biased:?}");
    assert_eq!(cycle.reproducing_share, 0.0, "{biased:?}");
    assert!(
        cycle.escape_omega_rpm.is_none() && cycle.escape_wob_kn.is_none(),
        "no string to advise"
    );
    // The truth reproduces its own cycle: no second advice.
    assert!(truth.cycle.unwrap().escape_omega_rpm.is_none());
    assert!(biased.words.contains("do not reproduce its cycle"), "{}", biased.words);
}
