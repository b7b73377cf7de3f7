//! The library's entry point for the whole job: the same populations in memory as in a run
//! directory, the directory's run.json is the analysis's JSON, and a refused job writes nothing.

use bitrock::abc::Silent;
use bitrock::abc::rejection::RejectionConfig;
use bitrock::abc::schedule::Schedule;
use bitrock::data::{DataOptions, demo_field_data};
use bitrock::eval::Backend;
use bitrock::run::abc::Analysis;
use bitrock::run::{self, abc::SamplerConfig};

fn job(particles: usize) -> run::abc::Job {
    run::abc::Job {
        config: run::abc::Config {
            backend: Backend::Cpu,
            seed: 5,
            sampler: SamplerConfig::Rejection(RejectionConfig::from(Schedule {
                particles,
                eps_min: 0.03,
                ..Schedule::default()
            })),
            ..run::abc::Config::default()
        },
        ..run::abc::Job::default()
    }
}

#[test]
fn a_job_in_memory_equals_the_job_written_to_its_run_directory() {
    let data = || demo_field_data(&DataOptions::default()).unwrap();
    let in_memory = job(300).run(data(), Default::default(), &mut Silent).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run");
    let on_disk = run::abc::Job {
        out: Some(run::Dir {
            path: path.clone(),
            replace: false,
        }),
        ..job(300)
    }
    .run(data(), Default::default(), &mut Silent)
    .unwrap();
    let (a, b) = (&in_memory.outcome.run.populations, &on_disk.outcome.run.populations);
    assert!(a.len() >= 2, "{} populations", a.len());
    assert_eq!(a.len(), b.len());
    // The stored run holds only its last population's particles in memory; the store has
    // them all.
    let stored = run::abc::Store::open(&path).unwrap().load_populations().unwrap();
    for ((p, q), s) in a.iter().zip(b).zip(&stored) {
        assert_eq!(p.particles, s.particles, "population {}", p.record.index);
        assert_eq!(p.record.per_law, q.record.per_law);
        assert_eq!(p.record.per_law, s.record.per_law);
        let last = q.record.index + 1 == b.len();
        assert_eq!(q.particles.is_empty(), !last, "population {}", q.record.index);
    }
    assert_eq!(a.last().unwrap().particles, b.last().unwrap().particles);
    let populations = a.len();
    // A summary of an earlier population reads its particles back from the store.
    let first_in_memory = Analysis::new(in_memory.outcome, Some(0), None).unwrap();
    let first_on_disk = Analysis::new(on_disk.outcome, Some(0), Some(&path)).unwrap();
    assert_eq!(first_on_disk.posterior, first_in_memory.posterior);
    assert_eq!(first_on_disk.envelopes, first_in_memory.envelopes);
    assert_eq!(first_on_disk.posterior.total, 300);
    let (in_memory, on_disk) = (
        Analysis::new(first_in_memory.outcome, None, None).unwrap(),
        Analysis::new(first_on_disk.outcome, None, Some(&path)).unwrap(),
    );
    assert_eq!(in_memory.summary_population, populations - 1);
    assert_eq!(
        in_memory.posterior.model_probabilities,
        on_disk.posterior.model_probabilities
    );
    // The directory holds the store and the summary files; run.json is the analysis's JSON.
    let stored: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(path.join("run.json")).unwrap()).unwrap();
    assert_eq!(stored, on_disk.json());
    for file in ["run.sqlite", "envelopes.csv", "data.csv"] {
        assert!(path.join(file).is_file(), "{file}");
    }
    // One envelope per law with particles, 200 speeds each.
    assert_eq!(in_memory.envelopes.len(), in_memory.posterior.laws.len());
    assert!(in_memory.envelopes.iter().all(|e| e.speed_rad_s.len() == 200));
}

#[test]
fn a_refused_job_names_the_setting_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run");
    let out = Some(run::Dir {
        path: path.clone(),
        replace: false,
    });
    let mut zero_delta = run::abc::Job {
        out: out.clone(),
        ..job(100)
    };
    zero_delta.config.delta = 0.0;
    let mut no_starts = run::abc::Job { out, ..job(100) };
    no_starts.config.fit.starts = 0;
    for (job, flag) in [(zero_delta, "`delta`:"), (no_starts, "`starts`:")] {
        assert!(job.validate().unwrap_err().to_string().starts_with(flag));
        let data = demo_field_data(&DataOptions::default()).unwrap();
        let err = job.run(data, Default::default(), &mut Silent).err().expect("refused");
        assert!(err.is_bad_input() && err.to_string().starts_with(flag), "{err}");
        assert!(!path.exists());
    }
    // A summary population the run does not have.
    let data = demo_field_data(&DataOptions::default()).unwrap();
    let err = run::abc::Job {
        summary_population: Some(99),
        ..job(100)
    }
    .run(data, Default::default(), &mut Silent)
    .err()
    .expect("refused");
    assert!(err.to_string().starts_with("`summary_population`:"), "{err}");
}
