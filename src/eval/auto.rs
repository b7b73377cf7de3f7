//! `auto` where the only GPU is a software driver (lavapipe, SwiftShader: an adapter of the
//! CPU type): its dispatches run on the same cores as the CPU scorer and carry a fixed cost
//! each, so the CPU's own scorer is often the faster, the more so for the small dispatches of
//! the evidence and the watch. There the run's own problem is scored on both at two sizes,
//! each time as a + b·n, and the backend faster at the run's dispatch size kept, said with both
//! projections. A real GPU is kept without a race. A machine races once per adapter, record
//! length, dispatch size and kind of call, and keeps the outcome beside its scoring shapes, so
//! that its runs choose alike.

use super::Evaluator;
use super::Problem;
use super::cpu::CpuEvaluator;
use super::gpu::residual::GpuEvaluator;
use super::gpu::tune::{Choice, ShapeWish};
use super::gpu::{GpuContext, Shape};
use crate::error::Result;
use crate::prior::{Candidate, MAX_DIMS};
use std::collections::HashMap;
use std::sync::Mutex;
use std::time::Instant;

/// The candidates of the two timed sizes: small enough that the race costs a few tenths of a
/// second on a long record, far enough apart to separate a dispatch's fixed cost from its cost
/// per candidate.
const PROBES: [usize; 2] = [256, 4_096];

/// Timings per size (their minimum is kept: the least disturbed by the machine's other work).
const REPEATS: usize = 3;

/// The GPU is kept only where its projection beats the CPU's by this factor: close races
/// would otherwise flip from one run to the next with the machine's noise, and the backend
/// with them.
const GPU_MARGIN: f64 = 1.2;

/// How every line that says which backend `auto` raced to begins (information, as the GPU's
/// own line: [`super::is_information`]).
pub const AUTO_NOTE: &str = "auto: scoring on";

/// A race's outcome: projected seconds per dispatch of `candidates` on each backend.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Race {
    pub candidates: usize,
    pub gpu_s: f64,
    pub cpu_s: f64,
}

impl Race {
    /// Whether the CPU scores the run: the GPU is not 1.2 times faster (`GPU_MARGIN`).
    pub fn cpu_wins(&self) -> bool {
        self.gpu_s * GPU_MARGIN > self.cpu_s
    }

    /// What the user is told of the choice.
    pub fn said(&self, adapter: &str) -> String {
        let ms = |s: f64| format!("{:.1} ms", s * 1e3);
        let (chosen, other) = if self.cpu_wins() {
            ("the CPU".to_string(), adapter.to_string())
        } else {
            (adapter.to_string(), "the CPU".to_string())
        };
        format!(
            "{AUTO_NOTE} {chosen} rather than {other}: a dispatch of {} candidates measured at {} on the CPU and {} on the software GPU (a + b·n from {} and {} candidates; the GPU kept where {GPU_MARGIN}× faster)",
            self.candidates,
            ms(self.cpu_s),
            ms(self.gpu_s),
            PROBES[0],
            PROBES[1]
        )
    }
}

/// A race kept in the cache of scoring shapes ([`super::gpu::tune::Cache`]), by its key: the
/// adapter ([`super::gpu::tune::adapter_key`]), the record's length and the dispatch size
/// (each to the power of two above it: windows of a watch differ by a few samples), and the
/// kind of call.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StoredRace {
    pub key: String,
    pub gpu_s: f64,
    pub cpu_s: f64,
}

/// Races decided in this process, by key.
static RACES: Mutex<Option<HashMap<String, StoredRace>>> = Mutex::new(None);

/// Which backend `auto` keeps for a software GPU, once raced ([`cpu_beats`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kept {
    /// The CPU: faster, or the GPU failed while racing (said either way).
    Cpu,
    /// The GPU; `said` when the race's line already named it with its shape, so that the
    /// caller does not name it again (false only where nothing was raced:
    /// `BITROCK_GPU_TUNING=off`).
    Gpu { said: bool },
}

/// Whether the CPU scores `problem` instead of the software GPU `ctx` (in `choice`'s shape)
/// for the dispatches `wish` describes: the race ([`race`]) said through `note` in one line
/// that names the backend kept, the CPU kept where it wins (or where the GPU fails while
/// racing).
pub fn cpu_beats(
    ctx: &'static GpuContext,
    problem: &Problem,
    choice: Choice,
    wish: ShapeWish,
    note: &mut dyn FnMut(String),
) -> Result<Kept> {
    let race = match race(ctx, problem, choice.shape, wish) {
        // A GPU that fails while racing is one `auto` cannot use.
        Err(crate::Error::Gpu(e)) => {
            note(super::no_usable_gpu(&e));
            return Ok(Kept::Cpu);
        }
        raced => raced?,
    };
    let Some(race) = race else {
        return Ok(Kept::Gpu { said: false });
    };
    note(race.said(&super::gpu_named(&ctx.describe(), choice.shape, choice.source)));
    Ok(if race.cpu_wins() {
        Kept::Cpu
    } else {
        Kept::Gpu { said: true }
    })
}

/// The race of the GPU `ctx` (in `shape`) against the CPU on `problem` for the dispatches
/// `wish` describes: its size, and ranges of the prior's streams or explicit candidates.
/// Decided once per machine: held by the process, kept in the cache of scoring shapes where
/// it can be written, and read from it (no evaluator built then: a software driver's pipelines
/// take a few tenths of a second to compile); with `BITROCK_GPU_TUNING=off`, not measured
/// (`None`: the GPU is kept).
pub fn race(ctx: &'static GpuContext, problem: &Problem, shape: Shape, wish: ShapeWish) -> Result<Option<Race>> {
    use super::gpu::tune;
    if !tune::tuning_on()? {
        return Ok(None);
    }
    let candidates = wish.candidates.max(1);
    let key = format!(
        "{} | {} samples | {} candidates | {}",
        tune::adapter_key(ctx),
        problem.data_len().next_power_of_two(),
        candidates.next_power_of_two(),
        match (wish.explicit, wish.lagged) {
            (true, true) => "explicit lagged",
            (true, false) => "explicit",
            (false, _) => "streams",
        }
    );
    let found = |stored: &StoredRace| Race {
        candidates,
        gpu_s: stored.gpu_s,
        cpu_s: stored.cpu_s,
    };
    let mut held = RACES.lock().expect("races");
    let held = held.get_or_insert_with(HashMap::new);
    if let Some(stored) = held.get(&key) {
        return Ok(Some(found(stored)));
    }
    let cache = tune::cache_path();
    if let Some(stored) = cache
        .as_deref()
        .and_then(|p| tune::read_cache(p).ok())
        .and_then(|c| c.races.into_iter().find(|r| r.key == key))
    {
        held.insert(key, stored.clone());
        return Ok(Some(found(&stored)));
    }
    let gpu = GpuEvaluator::on(problem.clone(), shape, ctx)?;
    let cpu = CpuEvaluator::new(problem.clone());
    let stored = StoredRace {
        key: key.clone(),
        gpu_s: projected(&gpu, candidates, wish)?,
        cpu_s: projected(&cpu, candidates, wish)?,
    };
    // A cache that cannot be written costs a race in the next process, no more.
    if let Some(path) = &cache {
        let _ = tune::write_race(path, &stored);
    }
    held.insert(key, stored.clone());
    Ok(Some(found(&stored)))
}

/// Seconds of a dispatch of `candidates` on `evaluator`: a + b·n through its times at the two
/// probe sizes (its first call untimed: pipelines built, caches warm). Explicit candidates (the
/// middle of each law's box in turn, with their lag-1 sums where `wish` is lagged) where `wish`
/// asks for them, else the first of the prior's stream 0.
fn projected(evaluator: &dyn Evaluator, candidates: usize, wish: ShapeWish) -> Result<f64> {
    let boxes = &evaluator.problem().prior.boxes;
    let probes: Vec<Candidate> = (0..PROBES[1])
        .map(|i| {
            let slot = i % boxes.len();
            let mut params = [0.0f32; MAX_DIMS];
            for (j, p) in params.iter_mut().enumerate().take(boxes[slot].lower.len()) {
                *p = 0.5 * (boxes[slot].lower[j] + boxes[slot].upper[j]);
            }
            Candidate { slot, params }
        })
        .collect();
    let (mut out, mut lag) = (vec![0.0; PROBES[1]], vec![0.0; PROBES[1]]);
    let mut call = |n: usize| match (wish.explicit, wish.lagged) {
        (true, true) => evaluator.score_params_lagged(&probes[..n], &mut out[..n], &mut lag[..n]),
        (true, false) => evaluator.score_params(&probes[..n], &mut out[..n]),
        (false, _) => evaluator.score(0, 0, &mut out[..n]),
    };
    call(PROBES[0])?;
    let mut times = [0.0; 2];
    for (time, &n) in times.iter_mut().zip(&PROBES) {
        let mut best = f64::INFINITY;
        for _ in 0..REPEATS {
            let started = Instant::now();
            call(n)?;
            best = best.min(started.elapsed().as_secs_f64());
        }
        *time = best;
    }
    Ok(project(PROBES, times, candidates))
}

/// The line through (n₀, t₀) and (n₁, t₁) at `candidates`, its slope and intercept kept
/// non-negative (a timing's noise cannot make more candidates cost less).
fn project(sizes: [usize; 2], times: [f64; 2], candidates: usize) -> f64 {
    let slope = ((times[1] - times[0]) / (sizes[1] - sizes[0]) as f64).max(0.0);
    let fixed = (times[0] - slope * sizes[0] as f64).max(0.0);
    fixed + slope * candidates as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_dispatch_is_its_fixed_cost_and_its_cost_per_candidate() {
        // 1 ms a dispatch and 1 µs a candidate: 1.256 ms and 5.096 ms at the probes.
        let t = |n: usize| 1e-3 + 1e-6 * n as f64;
        let at = project(PROBES, [t(256), t(4096)], 100_000);
        assert!((at - t(100_000)).abs() < 1e-12, "{at}");
        // Noise that makes the larger probe faster projects the smaller one's time.
        assert_eq!(project(PROBES, [2e-3, 1e-3], 100_000).to_bits(), 2e-3f64.to_bits());
    }

    #[test]
    fn the_gpu_is_kept_only_by_a_clear_margin() {
        let race = |gpu_s, cpu_s| Race {
            candidates: 2000,
            gpu_s,
            cpu_s,
        };
        assert!(race(1.0, 1.1).cpu_wins());
        assert!(!race(1.0, 1.3).cpu_wins());
        assert!(
            race(1.0, 0.5)
                .said("llvmpipe")
                .starts_with("auto: scoring on the CPU rather than llvmpipe: a dispatch")
        );
        assert!(
            race(0.5, 1.0)
                .said("llvmpipe")
                .contains("1000.0 ms on the CPU and 500.0 ms on the software GPU")
        );
    }
}
