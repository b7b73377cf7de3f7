//! Times the host-side stages of a large run on its stored populations, one at a time, so that
//! "everything else" of `bitrock abc` at large N can be broken down (the README's "Large N"):
//!
//! ```sh
//! bitrock abc data/demo.csv --particles 1000000 --quiet --json --out /tmp/big --backend cpu
//! cargo run --release --example large_stages -- /tmp/big [--no-store]
//! ```
//!
//! Stages: reading the populations back, the next ε (median of ρ), the posterior summary
//! (probabilities, moments, exact quantiles, correlations, MAP), the predictive envelopes,
//! the run.json document, and writing every population into a fresh store (one transaction
//! each). Wall-clock seconds of one pass each, on all cores.

use bitrock::abc::posterior::{ENVELOPE_LEVEL, predictive_envelope, speed_grid, summarize};
use bitrock::abc::schedule::median_rho;
use bitrock::run;
use std::time::Instant;

fn main() -> anyhow::Result<()> {
    let dir = std::env::args()
        .nth(1)
        .ok_or_else(|| anyhow::anyhow!("usage: large_stages RUN_DIR"))?;
    let dir = std::path::Path::new(&dir);
    // Wall-clock seconds, and CPU seconds of all threads (less sensitive to other load on a
    // shared machine).
    let cpu_at_start = std::cell::Cell::new(cpu_seconds());
    let time = |label: &str, t: Instant| {
        let cpu = cpu_seconds();
        println!(
            "{label:<40} {:>7.3} s wall {:>7.2} s CPU",
            t.elapsed().as_secs_f64(),
            cpu - cpu_at_start.replace(cpu)
        );
    };

    let t = Instant::now();
    cpu_at_start.set(cpu_seconds());
    let store = run::abc::Store::open(dir)?;
    let stored = store.load_with_last_particles()?;
    time("read the last population back", t);
    let last = stored
        .populations
        .last()
        .ok_or_else(|| anyhow::anyhow!("no population"))?;
    println!("{} populations, N = {}", stored.populations.len(), last.particles.len());

    let t = Instant::now();
    cpu_at_start.set(cpu_seconds());
    std::hint::black_box(median_rho(&last.particles));
    time("ε median (last population)", t);

    let laws: Vec<bitrock::Law> = last.record.per_law.iter().map(|l| l.law).collect();
    let t = Instant::now();
    cpu_at_start.set(cpu_seconds());
    let posterior = summarize(&last.particles, &laws);
    time("posterior summary (last population)", t);

    let data = &stored.setup.data;
    let speeds = data.calibration.speed_rad_s.iter().chain(&data.validation.speed_rad_s);
    let (lo, hi) = speeds.fold((f64::INFINITY, 0.0f64), |(a, b), &w| (a.min(w), b.max(w)));
    let grid = speed_grid(lo, hi, 200);
    let t = Instant::now();
    cpu_at_start.set(cpu_seconds());
    let envelopes: Vec<_> = laws
        .iter()
        .filter_map(|&law| predictive_envelope(&last.particles, law, &grid, ENVELOPE_LEVEL, 1.0))
        .collect();
    time("predictive envelopes (200 speeds)", t);

    let t = Instant::now();
    cpu_at_start.set(cpu_seconds());
    let json = serde_json::to_string_pretty(&serde_json::json!({
        "posterior": posterior,
        "envelopes": envelopes,
        "populations": stored.populations.iter().map(|p| &p.record).collect::<Vec<_>>(),
    }))?;
    std::hint::black_box(json.len());
    time("JSON of the summary and records", t);

    if std::env::args().any(|a| a == "--no-store") {
        return Ok(());
    }
    let t = Instant::now();
    cpu_at_start.set(cpu_seconds());
    let stored = store.load()?;
    time("read every population back", t);
    let scratch = tempfile::tempdir_in(dir.parent().unwrap_or(dir))?;
    let mut copy = run::abc::Store::create(scratch.path(), &stored.setup)?;
    let mut previous = None;
    for p in &stored.populations {
        let t = Instant::now();
        cpu_at_start.set(cpu_seconds());
        copy.append_population(p, previous)?;
        time(&format!("store population {}", p.record.index), t);
        previous = Some(p);
    }
    let bytes = std::fs::metadata(copy.path())?.len();
    let particles: usize = stored.populations.iter().map(|p| p.particles.len()).sum();
    println!(
        "store: {bytes} bytes, {:.1} bytes per particle per population",
        bytes as f64 / particles as f64
    );
    Ok(())
}

/// User and system CPU seconds of this process, all threads (Linux: /proc/self/stat, in
/// clock ticks of 1/100 s); 0 where it cannot be read.
fn cpu_seconds() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    // Fields after the command name (which ends with ')'), from the state: utime and stime
    // are the 12th and 13th of them.
    let rest = stat.rsplit_once(')').map_or("", |r| r.1);
    let fields: Vec<&str> = rest.split_whitespace().collect();
    let ticks = |i: usize| fields.get(i).and_then(|f| f.parse::<f64>().ok()).unwrap_or(0.0);
    (ticks(11) + ticks(12)) / 100.0
}
