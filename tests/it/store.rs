//! The run store: what goes in comes back bit for bit, a continued run equals an
//! uninterrupted one (also after a SIGKILL part-way), and a directory that is not a run is
//! refused by name.

use crate::support::bin;
use bitrock::abc::rejection::RejectionConfig;
use bitrock::abc::schedule::Schedule;
use bitrock::abc::{Population, Silent, StopReason};
use bitrock::data::{DataOptions, demo_field_data};
use bitrock::eval::Backend;
use bitrock::fit::FitOptions;
use bitrock::run::{self, abc::Continuation, abc::Outcome, abc::SamplerConfig};
use bitrock::{Error, Law};
use std::path::Path;

fn config(particles: usize, max_populations: usize, eps_min: f64) -> run::abc::Config {
    run::abc::Config {
        laws: Law::ALL.to_vec(),
        fit: FitOptions::default(),
        delta: 0.4,
        prior_rule: Default::default(),
        prior_file: None,
        seed: 11,
        backend: Backend::Cpu,
        devices: Default::default(),
        gpu_shape: None,
        sampler: SamplerConfig::Rejection(RejectionConfig::from(Schedule {
            particles,
            max_populations,
            eps_min,
            ..Schedule::default()
        })),
        eps_min_from_record: false,
        string: None,
    }
}

fn start(dir: &Path, config: run::abc::Config) -> Outcome {
    let data = demo_field_data(&DataOptions::default()).unwrap();
    let dir = run::Dir {
        path: dir.to_path_buf(),
        replace: false,
    };
    released(
        run::abc::start(
            data,
            config,
            run::abc::Start {
                dir: Some(&dir),
                ..Default::default()
            },
            &mut Silent,
        )
        .unwrap(),
    )
}

/// `outcome` without its run directory's lock, which it holds while it lives (one writer per
/// run directory): these tests continue the run in the same process.
fn released(mut outcome: Outcome) -> Outcome {
    outcome.lock = None;
    outcome
}

/// Populations equal in everything a population is: ε, counts, particles (bit for bit).
/// Timings and the candidates an uninterrupted run scored ahead may differ.
fn assert_same_populations(a: &[Population], b: &[Population]) {
    assert_eq!(a.len(), b.len(), "population counts");
    for (p, q) in a.iter().zip(b) {
        let (r, s) = (&p.record, &q.record);
        assert_eq!(
            (
                r.index,
                r.epsilon.map(f64::to_bits),
                r.draws,
                r.accepted,
                r.near_threshold,
                r.stream
            ),
            (
                s.index,
                s.epsilon.map(f64::to_bits),
                s.draws,
                s.accepted,
                s.near_threshold,
                s.stream
            ),
            "population {}",
            r.index
        );
        assert_eq!(r.per_law, s.per_law, "population {}", r.index);
        assert_eq!(p.particles, q.particles, "particles of population {}", r.index);
    }
}

/// The populations of the store in `dir`, with all their particles.
fn stored(dir: &Path) -> Vec<Population> {
    run::abc::Store::open(dir).unwrap().load_populations().unwrap()
}

/// The run of `config` in memory only: every population keeps its particles.
fn in_memory(config: run::abc::Config) -> Outcome {
    let data = demo_field_data(&DataOptions::default()).unwrap();
    run::abc::start(data, config, run::abc::Start::default(), &mut Silent).unwrap()
}

#[test]
fn store_round_trip_is_bit_exact() {
    let dir = tempfile::tempdir().unwrap();
    let run_dir = dir.path().join("run");
    let outcome = start(&run_dir, config(600, 4, 0.014));
    assert_eq!(outcome.run.populations.len(), 4);
    let stored = run::abc::Store::open(&run_dir).unwrap().load().unwrap();
    // Records (timings included) come back exactly; the stored run kept only the last
    // population's particles in memory, and the store has every population's, those of the
    // same run in memory.
    let records = |p: &[Population]| p.iter().map(|p| p.record.clone()).collect::<Vec<_>>();
    assert_eq!(records(&stored.populations), records(&outcome.run.populations));
    assert_eq!(stored.populations.last(), outcome.run.populations.last());
    assert!(outcome.run.populations[..3].iter().all(|p| p.particles.is_empty()));
    assert_same_populations(&stored.populations, &in_memory(config(600, 4, 0.014)).run.populations);
    assert_eq!(stored.setup.prior, outcome.setup.prior);
    assert_eq!(stored.setup.data.calibration, outcome.setup.data.calibration);
    assert_eq!(stored.setup.data.validation, outcome.setup.data.validation);
    assert_eq!(stored.setup.data.torque_unit, outcome.setup.data.torque_unit);
    assert_eq!(stored.setup.data.columns, outcome.setup.data.columns);
    assert_eq!(stored.setup.fits.len(), 4);
    for (a, b) in stored.setup.fits.iter().zip(&outcome.setup.fits) {
        assert_eq!(a.law, b.law);
        assert_eq!(
            a.params_si.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            b.params_si.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
        );
        assert_eq!(a.std_errors_si, b.std_errors_si);
        assert_eq!(a.rho.to_bits(), b.rho.to_bits());
        assert_eq!(a.correlations, b.correlations);
        assert_eq!(a.warnings, b.warnings);
    }
    let config: run::abc::Config = serde_json::from_value(stored.setup.config).unwrap();
    assert_eq!(config, outcome.config);
    // Weights are 1/N and sum to 1 per population.
    for p in &stored.populations {
        let total: f64 = p.particles.iter().map(|q| q.weight).sum();
        assert!((total - 1.0).abs() < 1e-12, "{total}");
    }

    // The particles are plain rows a user can query: one per particle, parameters in columns.
    let conn = rusqlite::Connection::open(run_dir.join("run.sqlite")).unwrap();
    let rows: i64 = conn
        .query_row("SELECT COUNT(*) FROM particles", [], |r| r.get(0))
        .unwrap();
    assert_eq!(rows, 4 * 600);
    let (m2, with_tsb): (i64, i64) = conn
        .query_row(
            "SELECT COUNT(*), COUNT(tsb) FROM particles WHERE law = 'm2' AND population = 3",
            [],
            |r| Ok((r.get(0)?, r.get(1)?)),
        )
        .unwrap();
    assert_eq!(m2, with_tsb, "every m2 particle has its tsb column");
    let stray: i64 = conn
        .query_row(
            "SELECT COUNT(*) FROM particles WHERE law = 'm2' AND b0 IS NOT NULL",
            [],
            |r| r.get(0),
        )
        .unwrap();
    assert_eq!(stray, 0, "an m2 particle has no m1 parameter");
    let probability: f64 = conn
        .query_row(
            "SELECT SUM(probability) FROM population_laws WHERE population = 3",
            [],
            |r| r.get(0),
        )
        .unwrap();
    assert!((probability - 1.0).abs() < 1e-12);
}

/// The same run with the SMC sampler.
fn smc(config: run::abc::Config) -> run::abc::Config {
    let SamplerConfig::Rejection(base) = config.sampler else {
        unreachable!("config() builds rejection runs")
    };
    run::abc::Config {
        sampler: SamplerConfig::Smc(bitrock::abc::smc::SmcConfig {
            schedule: base.schedule,
            ..Default::default()
        }),
        ..config
    }
}

#[test]
fn continuing_a_run_equals_the_uninterrupted_run() {
    continuing_equals_uninterrupted(|c| c);
}

#[test]
fn continuing_an_smc_run_equals_the_uninterrupted_run() {
    continuing_equals_uninterrupted(smc);
}

fn continuing_equals_uninterrupted(sampler: fn(run::abc::Config) -> run::abc::Config) {
    let dir = tempfile::tempdir().unwrap();
    let whole = start(&dir.path().join("whole"), sampler(config(800, 6, 0.0)));
    assert_eq!(whole.run.stop, StopReason::MaxPopulations);
    // Stopped after 3 populations, then continued to 6.
    let part_dir = dir.path().join("part");
    let part = start(&part_dir, sampler(config(800, 3, 0.0)));
    assert_eq!(part.run.populations.len(), 3);
    let more = Continuation {
        max_populations: Some(6),
        ..Continuation::default()
    };
    let continued = released(run::abc::populations::resume(&part_dir, &more, Default::default(), &mut Silent).unwrap());
    assert_eq!(continued.run.stop, StopReason::MaxPopulations);
    assert_same_populations(&continued.run.populations, &whole.run.populations);
    assert_same_populations(&stored(&part_dir), &stored(&dir.path().join("whole")));
    // Continuing a finished run with the same rules adds nothing.
    let again = released(
        run::abc::populations::resume(&part_dir, &Continuation::default(), Default::default(), &mut Silent).unwrap(),
    );
    assert_eq!(again.run.populations.len(), 6);
    assert_eq!(again.run.stop, StopReason::MaxPopulations);
}

#[test]
fn a_finished_run_continues_to_a_lower_eps_min() {
    let dir = tempfile::tempdir().unwrap();
    let run_dir = dir.path().join("run");
    let first = start(&run_dir, config(500, 30, 0.03));
    assert_eq!(first.run.stop, StopReason::EpsMin);
    let n = first.run.populations.len();
    let before = stored(&run_dir);
    let more = Continuation {
        eps_min: Some(0.016),
        ..Continuation::default()
    };
    let continued = released(run::abc::populations::resume(&run_dir, &more, Default::default(), &mut Silent).unwrap());
    assert_eq!(continued.run.stop, StopReason::EpsMin);
    assert!(continued.run.populations.len() > n);
    let populations = stored(&run_dir);
    assert_same_populations(&populations[..n], &before);
    // After the stored populations, the median rule with the new floor.
    for g in n..continued.run.populations.len() {
        let previous = &populations[g - 1];
        let expected = bitrock::abc::schedule::median_rho(&previous.particles).max(0.016);
        let eps = continued.run.populations[g].record.epsilon.unwrap();
        assert_eq!(eps.to_bits(), expected.to_bits(), "population {g}");
    }
}

#[test]
fn a_directory_that_is_not_a_run_is_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    for target in [dir.path().to_path_buf(), dir.path().join("missing")] {
        let err = run::abc::Store::open(&target).err().expect("refused");
        assert!(matches!(err, Error::Data { .. }), "{err}");
        assert!(err.to_string().contains("not a bitrock run directory"), "{err}");
        for args in [
            vec!["export", target.to_str().unwrap()],
            vec!["abc", "--resume", target.to_str().unwrap()],
            vec!["stability", "--run", target.to_str().unwrap()],
            vec!["report", target.to_str().unwrap()],
        ] {
            let out = bin().args(&args).output().unwrap();
            let stderr = String::from_utf8_lossy(&out.stderr);
            assert_eq!(out.status.code(), Some(2), "{args:?}: {stderr}");
            assert!(stderr.contains("not a bitrock run directory"), "{args:?}: {stderr}");
        }
    }
    // A file named run.sqlite that is not a store.
    std::fs::write(dir.path().join("run.sqlite"), "not a database").unwrap();
    let err = run::abc::Store::open(dir.path()).err().expect("refused");
    assert!(err.to_string().contains("not a bitrock"), "{err}");
    // Run-defining flags cannot change on --resume.
    let out = bin()
        .args(["abc", "--resume", dir.path().to_str().unwrap(), "--seed", "4"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--seed"));
}

/// Populations stored so far, read while the writer may hold its lock.
fn stored_populations(dir: &Path) -> usize {
    let Ok(conn) =
        rusqlite::Connection::open_with_flags(dir.join("run.sqlite"), rusqlite::OpenFlags::SQLITE_OPEN_READ_ONLY)
    else {
        return 0;
    };
    conn.query_row("SELECT COUNT(*) FROM populations", [], |r| r.get::<_, i64>(0))
        .map_or(0, |n| n as usize)
}

#[test]
fn a_run_killed_part_way_resumes_to_the_uninterrupted_result() {
    let dir = tempfile::tempdir().unwrap();
    let killed = dir.path().join("killed");
    let whole = dir.path().join("whole");
    let args = |out: &Path| {
        vec![
            "abc".to_string(),
            "--particles".into(),
            "2000".into(),
            "--eps-min".into(),
            "0".into(),
            "--max-populations".into(),
            "9".into(),
            "--backend".into(),
            "cpu".into(),
            "--seed".into(),
            "5".into(),
            "--quiet".into(),
            "--out".into(),
            out.to_str().unwrap().into(),
        ]
    };
    let mut child = bin().args(args(&killed)).spawn().unwrap();
    // Each population costs about twice the one before, so killing once 4 are stored
    // interrupts the run well before its end.
    let t0 = std::time::Instant::now();
    while stored_populations(&killed) < 4 {
        assert!(
            child.try_wait().unwrap().is_none(),
            "the run ended before it could be killed"
        );
        assert!(t0.elapsed().as_secs() < 300, "the run did not reach population 3");
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    child.kill().unwrap(); // SIGKILL
    child.wait().unwrap();
    let at_kill = stored_populations(&killed);
    assert!((4..9).contains(&at_kill), "{at_kill} populations stored when killed");
    assert!(!killed.join("run.json").exists(), "a killed run has no summary yet");

    let out = bin()
        .args(["abc", "--resume", killed.to_str().unwrap(), "--quiet"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let out = bin().args(args(&whole)).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));

    let a = run::abc::Store::open(&killed).unwrap().load_populations().unwrap();
    let b = run::abc::Store::open(&whole).unwrap().load_populations().unwrap();
    assert_eq!(a.len(), 9);
    assert_same_populations(&a, &b);
    // The exports are byte-identical.
    let export = |d: &Path| bin().args(["export", d.to_str().unwrap()]).output().unwrap().stdout;
    assert_eq!(export(&killed), export(&whole));
    assert!(killed.join("run.json").exists());
}

#[test]
fn a_wall_time_stop_is_continued_without_the_old_budget() {
    let dir = tempfile::tempdir().unwrap();
    let run_dir = dir.path().join("run");
    let mut budgeted = config(500, 4, 0.0);
    if let SamplerConfig::Rejection(c) = &mut budgeted.sampler {
        // Spent before the first batch: the run stops with nothing stored.
        c.schedule.max_seconds = Some(1e-9);
    }
    let first = start(&run_dir, budgeted);
    assert_eq!(first.run.stop, StopReason::WallTime);
    assert!(first.run.populations.is_empty());
    let continued = released(
        run::abc::populations::resume(&run_dir, &Continuation::default(), Default::default(), &mut Silent).unwrap(),
    );
    assert_eq!(continued.run.stop, StopReason::MaxPopulations);
    let whole = start(&dir.path().join("whole"), config(500, 4, 0.0));
    assert_same_populations(&continued.run.populations, &whole.run.populations);
    assert_same_populations(&stored(&run_dir), &stored(&dir.path().join("whole")));
}

/// Rewrites the store in `dir` as bitrock 843167d wrote it (schema 2): the particles as a
/// table, one row per particle and population.
fn downgrade_to_schema_2(dir: &Path) {
    let conn = rusqlite::Connection::open(dir.join("run.sqlite")).unwrap();
    conn.execute_batch(
        "CREATE TABLE particles_v2 (
            population INTEGER NOT NULL,
            position INTEGER NOT NULL,
            law TEXT NOT NULL,
            candidate INTEGER NOT NULL,
            rho REAL NOT NULL,
            weight REAL NOT NULL,
            b0 REAL, b1 REAL, b2 REAL, b3 REAL,
            tsb REAL, tcb REAL, g REAL,
            a0 REAL, a1 REAL, a2 REAL, a3 REAL, a4 REAL, a5 REAL,
            c0 REAL, c1 REAL, c2 REAL, c3 REAL,
            PRIMARY KEY (population, position)
        );
        INSERT INTO particles_v2 SELECT * FROM particles;
        DROP VIEW particles;
        DROP TABLE particle_rows;
        DROP TABLE population_rows;
        ALTER TABLE particles_v2 RENAME TO particles;
        UPDATE meta SET value = '2' WHERE key = 'schema_version';",
    )
    .unwrap();
}

#[test]
fn a_store_of_schema_2_is_read_and_continued_in_its_own_layout() {
    let dir = tempfile::tempdir().unwrap();
    let run_dir = dir.path().join("run");
    start(&run_dir, config(500, 2, 0.014));
    let before = stored(&run_dir);
    downgrade_to_schema_2(&run_dir);
    assert_eq!(stored(&run_dir), before);
    let more = Continuation {
        max_populations: Some(4),
        ..Default::default()
    };
    let resumed = run::abc::populations::resume(&run_dir, &more, Default::default(), &mut Silent).unwrap();
    let direct_dir = dir.path().join("direct");
    let direct = start(&direct_dir, config(500, 4, 0.014));
    assert_same_populations(&resumed.run.populations, &direct.run.populations);
    assert_same_populations(&stored(&run_dir), &stored(&direct_dir));
    // Still schema 2: a table with a row per particle and population.
    let conn = rusqlite::Connection::open(run_dir.join("run.sqlite")).unwrap();
    let (version, kind, rows): (String, String, i64) = conn
        .query_row(
            "SELECT (SELECT value FROM meta WHERE key = 'schema_version'),
                    (SELECT type FROM sqlite_master WHERE name = 'particles'),
                    (SELECT COUNT(*) FROM particles)",
            [],
            |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?)),
        )
        .unwrap();
    assert_eq!((version.as_str(), kind.as_str(), rows), ("2", "table", 4 * 500));
}

#[test]
fn a_nested_run_stores_each_particle_once_and_the_particles_view_shows_every_population() {
    let dir = tempfile::tempdir().unwrap();
    let run_dir = dir.path().join("run");
    let config = config(600, 5, 0.0);
    start(&run_dir, config.clone());
    let populations = in_memory(config).run.populations;
    assert_eq!(populations.len(), 5);
    // Population g repeats the particles of g − 1 below ε_g: those are not stored again.
    let carried: usize = populations
        .windows(2)
        .map(|w| {
            let epsilon = w[1].record.epsilon.unwrap();
            w[0].particles.iter().filter(|p| p.rho < epsilon).count()
        })
        .sum();
    assert!(carried > 4 * 600 / 3, "{carried} carried");
    let conn = rusqlite::Connection::open(run_dir.join("run.sqlite")).unwrap();
    let rows: i64 = conn
        .query_row("SELECT COUNT(*) FROM particle_rows", [], |r| r.get(0))
        .unwrap();
    assert_eq!(rows as usize, 5 * 600 - carried);
    // The view gives each population's particles, in order, as schema 2's table did.
    let mut select = conn
        .prepare("SELECT position, law, candidate, rho, weight, tsb, c3 FROM particles WHERE population = ?1")
        .unwrap();
    for p in &populations {
        type Row = (i64, String, i64, f64, f64, Option<f64>, Option<f64>);
        let rows: Vec<Row> = select
            .query_map([p.record.index as i64], |r| {
                Ok((
                    r.get(0)?,
                    r.get(1)?,
                    r.get(2)?,
                    r.get(3)?,
                    r.get(4)?,
                    r.get(5)?,
                    r.get(6)?,
                ))
            })
            .unwrap()
            .collect::<Result<_, _>>()
            .unwrap();
        assert_eq!(rows.len(), p.particles.len(), "population {}", p.record.index);
        for (k, (row, q)) in rows.iter().zip(&p.particles).enumerate() {
            assert_eq!(
                (row.0, row.1.as_str(), row.2, row.3.to_bits(), row.4.to_bits()),
                (
                    k as i64,
                    q.law.name(),
                    q.index as i64,
                    q.rho.to_bits(),
                    q.weight.to_bits()
                )
            );
            let tsb = (q.law == Law::M2).then(|| q.params[0]);
            let c3 = (q.law == Law::M4).then(|| q.params[3]);
            assert_eq!((row.5, row.6), (tsb, c3), "population {} position {k}", p.record.index);
        }
    }
}

#[test]
fn a_store_of_schema_1_is_read_with_its_box_rules_unrecorded_but_not_continued() {
    let dir = tempfile::tempdir().unwrap();
    let run_dir = dir.path().join("run");
    let outcome = start(&run_dir, config(500, 2, 0.014));
    let before = stored(&run_dir);
    // What bitrock 3a5ee53 wrote: no rule column, schema version 1.
    downgrade_to_schema_2(&run_dir);
    let conn = rusqlite::Connection::open(run_dir.join("run.sqlite")).unwrap();
    conn.execute_batch(
        "ALTER TABLE prior_bounds DROP COLUMN rule; UPDATE meta SET value = '1' WHERE key = 'schema_version';",
    )
    .unwrap();
    drop(conn);
    let stored = run::abc::Store::open(&run_dir).unwrap().load().unwrap();
    assert_eq!(stored.setup.prior.boxes, outcome.setup.prior.boxes);
    assert_eq!(stored.setup.prior.thresholds, outcome.setup.prior.thresholds);
    for rules in &stored.setup.prior.rules {
        assert!(
            rules.iter().all(|&r| r == bitrock::prior::BoxRule::Unrecorded),
            "{rules:?}"
        );
    }
    assert_eq!(stored.populations, before);
    // Its candidates were rounded by the older float transform: continuing it is refused,
    // naming the reason, and nothing is written.
    let more = Continuation {
        max_populations: Some(3),
        ..Default::default()
    };
    let e = run::abc::populations::resume(&run_dir, &more, Default::default(), &mut Silent)
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("store schema 1") && e.contains("start a new run"), "{e}");
    let again = run::abc::Store::open(&run_dir).unwrap().load().unwrap();
    assert_eq!(again.populations.len(), 2);

    // Another version is refused by name, not misread.
    let conn = rusqlite::Connection::open(run_dir.join("run.sqlite")).unwrap();
    conn.execute("UPDATE meta SET value = '99' WHERE key = 'schema_version'", [])
        .unwrap();
    drop(conn);
    let e = run::abc::Store::open(&run_dir).err().unwrap().to_string();
    assert!(e.contains("schema version 99") && e.contains("versions 1 to 3"), "{e}");
}

#[test]
fn a_write_that_fails_on_the_store_thread_ends_the_run_with_its_error() {
    // Populations are written by a thread of their own while the next is drawn: a failure
    // there must still end the run, with its error, and leave the populations written before.
    let dir = tempfile::tempdir().unwrap();
    let run_dir = dir.path().join("run");
    start(&run_dir, config(500, 2, 0.0));
    let conn = rusqlite::Connection::open(run_dir.join("run.sqlite")).unwrap();
    conn.execute_batch(
        "CREATE TRIGGER injected BEFORE INSERT ON populations WHEN NEW.population = 3
         BEGIN SELECT RAISE(ABORT, 'injected write failure'); END;",
    )
    .unwrap();
    drop(conn);
    let more = Continuation {
        max_populations: Some(6),
        ..Continuation::default()
    };
    let e = run::abc::populations::resume(&run_dir, &more, Default::default(), &mut Silent)
        .err()
        .expect("the failed write ends the run")
        .to_string();
    assert!(e.contains("injected write failure") && e.contains("run.sqlite"), "{e}");
    assert_eq!(stored_populations(&run_dir), 3);
}

/// Copies a run directory kept in `tests/it/fixtures/runs/` (written by an earlier bitrock,
/// its files without bitrock's marks, as a checkout leaves them) to a scratch directory.
fn earlier_run(name: &str) -> (tempfile::TempDir, std::path::PathBuf) {
    let from = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/it/fixtures/runs")
        .join(name);
    let scratch = tempfile::tempdir().unwrap();
    let dir = scratch.path().join("run");
    std::fs::create_dir(&dir).unwrap();
    for entry in std::fs::read_dir(&from).unwrap() {
        let entry = entry.unwrap();
        std::fs::copy(entry.path(), dir.join(entry.file_name())).unwrap();
    }
    (scratch, dir)
}

/// `bitrock export DIR` as CSV text.
fn exported(dir: &Path) -> String {
    let out = dir.with_extension("export.csv");
    let (code, _, err) = crate::support::outcome(bin().arg("export").arg(dir).arg("-o").arg(&out).arg("--force"));
    assert_eq!(code, 0, "{err}");
    std::fs::read_to_string(out).unwrap()
}

fn expected(name: &str) -> String {
    std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/it/fixtures/runs")
            .join(name),
    )
    .unwrap()
}

/// Run directories written by an earlier bitrock (three populations of 100 particles on the
/// demo record thinned by 10, seed 7, CPU) export to the very bytes that bitrock exported, and
/// resumed to a fourth population they equal the export of the uninterrupted four-population
/// run made by that bitrock.
#[test]
fn run_directories_of_an_earlier_bitrock_open_export_and_resume_bit_for_bit() {
    for name in ["rejection", "smc"] {
        let (_scratch, dir) = earlier_run(name);
        assert_eq!(exported(&dir), expected(&format!("{name}.export.csv")), "{name}");
        let (code, _, err) = crate::support::outcome(
            bin()
                .args(["abc", "--max-populations", "4", "--backend", "cpu", "-q", "--resume"])
                .arg(&dir),
        );
        assert_eq!(code, 0, "{name}: {err}");
        assert_eq!(
            exported(&dir),
            expected(&format!("{name}.resumed-to-4.export.csv")),
            "{name}"
        );
    }
}
