//! The scoring shape chosen by measurement: the first GPU run on an adapter times every shape
//! the adapter can run on the run's own prior (its law mix) and record, at three dispatch
//! sizes, and keeps the table in the user's cache directory; later runs on the same adapter
//! (name, vendor, device, backend, driver, PCI bus) and bitrock version read it.
//!
//! The order of choice ([`choose`]): `BITROCK_GPU_SHAPE`; the shape the run recorded; with
//! `BITROCK_GPU_TUNING=off` the adapter type's guess ([`Shape::guess`]); the cached table;
//! a measurement now.

use super::residual::GpuEvaluator;
pub use super::shape::Source;
use super::{GpuContext, GpuError, Shape};
use crate::eval::Problem;
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::Mutex;
use std::time::Instant;

/// Environment variable that turns measuring off (`off`): the adapter type's guess is used
/// and the cache neither read nor written.
pub const TUNING_VAR: &str = "BITROCK_GPU_TUNING";

/// Environment variable naming the directory of bitrock's cache (default: the platform's,
/// such as `~/.cache/bitrock` on Linux).
pub const CACHE_DIR_VAR: &str = "BITROCK_CACHE_DIR";

/// The cache file in the cache directory.
pub const CACHE_FILE: &str = "gpu-shapes.json";

/// Candidates per dispatch the tuner times: the sizes runs meet, from a small SMC round to a
/// paper-scale rejection round.
pub const SIZES: [usize; 3] = [4_096, 65_536, 1_048_576];

/// Samples of the record the tuner scores at most (the shape's speed per evaluation hardly
/// depends on the record's length past this; the time does).
pub const TUNING_SAMPLES: usize = 4_096;

/// A shape whose time at the next size, projected linearly from its last, exceeds this is not
/// timed there, seconds: the cost of the measurement stays bounded on a slow adapter (a CPU
/// driver, where times are linear). A GPU's times grow less than linearly until it is full,
/// so the projection overestimates there, which is why the cap is well above the times of a
/// full GPU at these sizes.
pub const PROJECTION_CAP_S: f64 = 0.25;

/// Timings per shape and size stop before [`REPEATS`] once they took this long together,
/// seconds.
pub const MEASURE_BUDGET_S: f64 = 0.2;

/// Timings per shape and size at most (their median is kept); fewer once they took
/// [`MEASURE_BUDGET_S`].
pub const REPEATS: usize = 3;

/// One shape's time at one size.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Timing {
    pub shape: Shape,
    /// Median seconds of a dispatch and its read-back; `None` when not timed.
    pub seconds: Option<f64>,
    /// Why it was not timed: its time at the smaller size, already more than the fastest
    /// shape's here (more candidates never take less time), seconds.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub at_least_s: Option<f64>,
    /// Why it was not timed: its time projected linearly from the smaller size, over
    /// [`PROJECTION_CAP_S`], seconds.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub projected_s: Option<f64>,
}

/// The timings at one dispatch size and the fastest shape there.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SizeBand {
    /// Candidates per dispatch.
    pub candidates: usize,
    pub timings: Vec<Timing>,
    pub winner: Shape,
}

impl SizeBand {
    /// False when no shape was timed at this size: the winner is the smaller size's.
    pub fn measured(&self) -> bool {
        self.timings.iter().any(|t| t.seconds.is_some())
    }
}

/// A tuning: one adapter's table.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Tuning {
    /// What identifies the adapter and the kernels (see [`adapter_key`]).
    pub key: String,
    /// The adapter as `bitrock devices` describes it.
    pub adapter: String,
    /// Samples per candidate timed.
    pub samples: usize,
    /// When it was measured, Unix seconds.
    pub measured_unix_s: u64,
    /// Seconds the measurement took (pipelines built included).
    pub seconds: f64,
    pub bands: Vec<SizeBand>,
}

impl Tuning {
    /// The table as lines for the user: seconds per dispatch of each shape at each size, and
    /// the fastest.
    pub fn table(&self) -> Vec<String> {
        let mut lines = vec![format!(
            "scoring shapes on {} ({} samples per candidate; seconds per dispatch, median):",
            self.adapter, self.samples
        )];
        let shapes: Vec<Shape> = self
            .bands
            .first()
            .map_or(Vec::new(), |b| b.timings.iter().map(|t| t.shape).collect());
        let mut header = format!("{:>10}", "candidates");
        for shape in &shapes {
            header.push_str(&format!("  {:>10}", shape.name()));
        }
        lines.push(header + "  fastest");
        for band in &self.bands {
            let mut line = format!("{:>10}", band.candidates);
            for t in &band.timings {
                line.push_str(&match (t.seconds, t.at_least_s.or(t.projected_s)) {
                    (Some(s), _) => format!("  {s:>10.3e}"),
                    (None, Some(p)) => format!("  {:>10}", format!(">{p:.1e}")),
                    (None, None) => format!("  {:>10}", "-"),
                });
            }
            let how = if band.measured() {
                ""
            } else {
                " (no shape timed: the smaller size's)"
            };
            lines.push(format!("{line}  {}{how}", band.winner));
        }
        lines
    }

    /// The winner at the measured size nearest `candidates` (in ratio).
    pub fn shape_for(&self, candidates: usize) -> Shape {
        let distance = |band: &SizeBand| (band.candidates.max(1) as f64 / candidates.max(1) as f64).ln().abs();
        self.bands
            .iter()
            .min_by(|a, b| distance(a).total_cmp(&distance(b)))
            .map_or(Shape::Blocked, |band| band.winner)
    }
}

/// What a caller knows about the shape it wants: the run's recorded one, and the candidates
/// per dispatch it expects (the band of a measured table it uses).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ShapeWish {
    pub recorded: Option<Shape>,
    pub candidates: usize,
    /// Whether the run scores explicit candidates (the SMC samplers' perturbed particles, the
    /// evidence's moves) rather than ranges of the prior's streams: what `auto` races on a
    /// software driver ([`crate::eval::auto`]).
    #[serde(default)]
    pub explicit: bool,
    /// Whether those explicit candidates are scored with their lag-1 sums too (the evidence
    /// under the AR(1) noise model: two dispatches on the GPU, one pass on the CPU), which is
    /// then what `auto` races.
    #[serde(default)]
    pub lagged: bool,
}

impl Default for ShapeWish {
    fn default() -> Self {
        Self {
            recorded: None,
            candidates: SIZES[1],
            explicit: false,
            lagged: false,
        }
    }
}

impl ShapeWish {
    /// The wish of a run of `particles` per population, `recorded` its shape if any: a
    /// population is scored in rounds of several N candidates (about 2.2 N for population 0,
    /// N over the acceptance rate later), so the band of 8 N.
    pub fn for_run(recorded: Option<Shape>, particles: usize) -> Self {
        Self {
            recorded,
            candidates: particles.saturating_mul(8).clamp(SIZES[0], SIZES[SIZES.len() - 1]),
            explicit: false,
            lagged: false,
        }
    }
}

/// A shape and where it came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Choice {
    pub shape: Shape,
    pub source: Source,
}

/// The scoring shape for `problem` on `ctx`, in the order of the module documentation.
pub fn choose(ctx: &'static GpuContext, problem: &Problem, wish: ShapeWish) -> Result<Choice, GpuError> {
    let chosen = |shape, source| Choice { shape, source };
    if let Some(shape) = Shape::from_env(ctx)? {
        return Ok(chosen(shape, Source::Named));
    }
    if let Some(shape) = wish.recorded {
        shape.check_fits(ctx)?;
        return Ok(chosen(shape, Source::Recorded));
    }
    if !tuning_on()? {
        return Ok(chosen(Shape::guess(ctx.info.device_type), Source::Guessed));
    }
    let (tuning, source) = tuning(ctx, problem)?;
    Ok(chosen(tuning.shape_for(wish.candidates), source))
}

/// The evaluators whose shape is chosen here: by measurement, the run's record or the
/// environment.
impl GpuEvaluator {
    /// Uploads the data and the prior, on the process's GPU, in the shape measured fastest
    /// there for dispatches of 65,536 candidates (or `BITROCK_GPU_SHAPE`'s; see [`crate::eval::gpu::tune`]).
    pub fn new(problem: Problem) -> std::result::Result<Self, GpuError> {
        Self::wished(problem, ShapeWish::default())
    }

    /// As [`GpuEvaluator::new`], in the shape [`choose`] picks for `wish`.
    pub fn wished(problem: Problem, wish: ShapeWish) -> std::result::Result<Self, GpuError> {
        let context = super::context()?;
        let choice = choose(context, &problem, wish)?;
        Ok(Self::on(problem, choice.shape, context)?.chosen_by(choice.source))
    }

    /// One evaluator per GPU of the machine ([`super::every_context`]): `devices` all. All
    /// score in the shape [`choose`] picks on the first, so that the populations do not
    /// depend on which GPU scored which task.
    pub fn on_every_gpu(problem: &Problem, wish: ShapeWish) -> std::result::Result<Vec<Self>, GpuError> {
        let contexts = super::every_context()?;
        let choice = choose(contexts[0], problem, wish)?;
        contexts
            .into_iter()
            .map(|context| Ok(Self::on(problem.clone(), choice.shape, context)?.chosen_by(choice.source)))
            .collect()
    }
}

/// Whether `BITROCK_GPU_TUNING` lets bitrock measure (unset, `on`) or not (`off`).
pub fn tuning_on() -> Result<bool, GpuError> {
    match std::env::var(TUNING_VAR) {
        Err(_) => Ok(true),
        Ok(value) => match value.trim().to_lowercase().as_str() {
            "on" | "" => Ok(true),
            "off" => Ok(false),
            _ => Err(GpuError::Setting {
                name: TUNING_VAR,
                message: format!("must be `on` or `off`, got `{value}`"),
            }),
        },
    }
}

/// Tunings of this process, by adapter key: a process measures an adapter once.
static HELD: Mutex<Option<HashMap<String, Tuning>>> = Mutex::new(None);

/// The adapter's tuning (held, cached or measured now on `problem`) and where it came from. A
/// cache that cannot be read or written is passed over: measuring again is the worst it costs.
pub fn tuning(ctx: &'static GpuContext, problem: &Problem) -> Result<(Tuning, Source), GpuError> {
    let key = adapter_key(ctx);
    let mut held = HELD.lock().expect("held tunings");
    let held = held.get_or_insert_with(HashMap::new);
    if let Some(t) = held.get(&key) {
        return Ok((t.clone(), Source::Cached));
    }
    if let Some(t) = cache_path()
        .and_then(|p| read_cache(&p).ok())
        .and_then(|c| c.tunings.into_iter().find(|t| t.key == key))
    {
        held.insert(key, t.clone());
        return Ok((t, Source::Cached));
    }
    let t = measure(ctx, problem)?;
    let source = keep(held, key, &t);
    Ok((t, source))
}

/// Keeps a table just measured: in the cache where it can be written, and for this process
/// under `key`. [`Source::Measured`], or [`Source::MeasuredNotKept`] where the cache could not
/// be written.
fn keep(held: &mut HashMap<String, Tuning>, key: String, tuning: &Tuning) -> Source {
    let kept = cache_path().is_some_and(|path| write_cache(&path, tuning).is_ok());
    held.insert(key, tuning.clone());
    if kept {
        Source::Measured
    } else {
        Source::MeasuredNotKept
    }
}

/// Measures the adapter of `ctx` on `problem` again, whatever is cached, and keeps the new
/// table (in the cache where it can be written, and for this process): `bitrock bench
/// --retune`. Returns it and [`Source::Measured`] or [`Source::MeasuredNotKept`].
pub fn retune(ctx: &'static GpuContext, problem: &Problem) -> Result<(Tuning, Source), GpuError> {
    let t = measure(ctx, problem)?;
    let mut held = HELD.lock().expect("held tunings");
    let source = keep(held.get_or_insert_with(HashMap::new), adapter_key(ctx), &t);
    Ok((t, source))
}

/// Measures every shape `ctx` can run on `problem` (its first [`TUNING_SAMPLES`] samples).
pub fn measure(ctx: &'static GpuContext, problem: &Problem) -> Result<Tuning, GpuError> {
    let started = Instant::now();
    let mut sample = problem.clone();
    let d = problem.data_len().min(TUNING_SAMPLES);
    sample.speed_rad_s.truncate(d);
    sample.torque_nm.truncate(d);
    sample.wob_ratio.truncate(d);
    let shapes = worth_trying(ctx.info.device_type, &ctx.limits);
    let evaluators = shapes
        .iter()
        .map(|&shape| GpuEvaluator::on(sample.clone(), shape, ctx))
        .collect::<Result<Vec<_>, _>>()?;
    let mut out = vec![0.0f32; SIZES[SIZES.len() - 1]];
    let bands = measure_with(&shapes, &SIZES, &mut |shape, candidates| {
        let evaluator = &evaluators[shapes.iter().position(|&s| s == shape).expect("a measured shape")];
        let timed = Instant::now();
        evaluator.sum_sq_residuals(0, 0, &mut out[..candidates])?;
        Ok(timed.elapsed().as_secs_f64())
    })?;
    Ok(Tuning {
        key: adapter_key(ctx),
        adapter: ctx.describe(),
        samples: d,
        measured_unix_s: std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |t| t.as_secs()),
        seconds: started.elapsed().as_secs_f64(),
        bands,
    })
}

/// The shapes worth timing on an adapter: every one it can run, except wider tiles on a CPU
/// driver (its invocations run one after another: more of them only add work).
pub fn worth_trying(device_type: wgpu::DeviceType, limits: &wgpu::Limits) -> Vec<Shape> {
    Shape::ALL
        .into_iter()
        .filter(|s| s.fits(limits))
        .filter(|&s| device_type != wgpu::DeviceType::Cpu || matches!(s, Shape::Blocked | Shape::Tiled))
        .collect()
}

/// The tuning's logic with any clock: `time(shape, candidates)` scores `candidates` in `shape`
/// and returns the seconds. Every shape is run once untimed at the first size (pipelines
/// built, caches warm). At each size the shapes are timed fastest first (by their last time),
/// up to [`REPEATS`] times each (median); a shape is passed over when its last time already
/// exceeds the fastest time here, or when its linear projection exceeds [`PROJECTION_CAP_S`].
/// The fastest timed shape wins.
pub fn measure_with(
    shapes: &[Shape],
    sizes: &[usize],
    time: &mut dyn FnMut(Shape, usize) -> Result<f64, GpuError>,
) -> Result<Vec<SizeBand>, GpuError> {
    for &shape in shapes {
        time(shape, sizes[0])?;
    }
    // The last timed (size, seconds) of each shape.
    let mut last: Vec<Option<(usize, f64)>> = vec![None; shapes.len()];
    let mut bands: Vec<SizeBand> = Vec::new();
    for &candidates in sizes {
        let mut order: Vec<usize> = (0..shapes.len()).collect();
        order.sort_by(|&a, &b| {
            let t = |k: usize| last[k].map_or(0.0, |(_, s)| s);
            t(a).total_cmp(&t(b))
        });
        let mut timings: Vec<Option<Timing>> = vec![None; shapes.len()];
        let mut fastest: Option<(Shape, f64)> = None;
        for k in order {
            let shape = shapes[k];
            let skipped = |at_least_s, projected_s| Timing {
                shape,
                seconds: None,
                at_least_s,
                projected_s,
            };
            let timing = match last[k] {
                Some((_, s)) if fastest.is_some_and(|(_, best)| s > best) => skipped(Some(s), None),
                Some((n, s)) if s * candidates as f64 / n as f64 > PROJECTION_CAP_S => {
                    skipped(None, Some(s * candidates as f64 / n as f64))
                }
                _ => {
                    let mut seconds = Vec::new();
                    while seconds.len() < REPEATS && seconds.iter().sum::<f64>() < MEASURE_BUDGET_S {
                        seconds.push(time(shape, candidates)?);
                    }
                    seconds.sort_by(f64::total_cmp);
                    let median = seconds[seconds.len() / 2];
                    last[k] = Some((candidates, median));
                    if fastest.is_none_or(|(_, best)| median < best) {
                        fastest = Some((shape, median));
                    }
                    Timing {
                        shape,
                        seconds: Some(median),
                        at_least_s: None,
                        projected_s: None,
                    }
                }
            };
            timings[k] = Some(timing);
        }
        let winner = match (fastest, bands.last()) {
            (Some((shape, _)), _) => shape,
            (None, Some(previous)) => previous.winner,
            (None, None) => unreachable!("the first size times every shape"),
        };
        bands.push(SizeBand {
            candidates,
            timings: timings.into_iter().map(|t| t.expect("every shape decided")).collect(),
            winner,
        });
    }
    Ok(bands)
}

/// What identifies an adapter and the kernels it ran: a new driver, another bus slot or
/// another bitrock version is measured again.
pub fn adapter_key(ctx: &GpuContext) -> String {
    let i = &ctx.info;
    format!(
        "{} | vendor {:#06x} device {:#06x} | {:?} {:?} | driver {} {} | bus {} | bitrock {}",
        i.name,
        i.vendor,
        i.device,
        i.backend,
        i.device_type,
        i.driver,
        i.driver_info,
        i.device_pci_bus_id,
        env!("CARGO_PKG_VERSION")
    )
}

/// The cache file of the tunings: in `BITROCK_CACHE_DIR`, else the platform's cache
/// directory; `None` where there is none.
pub fn cache_path() -> Option<PathBuf> {
    let dir = match std::env::var_os(CACHE_DIR_VAR) {
        Some(dir) if !dir.is_empty() => PathBuf::from(dir),
        _ => dirs::cache_dir()?.join("bitrock"),
    };
    Some(dir.join(CACHE_FILE))
}

/// The cache file's contents.
#[derive(Debug, Default, Serialize, Deserialize)]
pub struct Cache {
    pub tunings: Vec<Tuning>,
    /// `auto`'s races of a software driver against the CPU ([`crate::eval::auto`]), so that a
    /// machine keeps its choice from run to run.
    #[serde(default)]
    pub races: Vec<crate::eval::auto::StoredRace>,
}

/// The most the cache of scoring shapes may hold, bytes: a tuning is about 1 kB, one per
/// adapter, law set and record size measured.
const MAX_CACHE_BYTES: u64 = 4_000_000;

/// The tunings the cache file at `path` holds (none where there is no file). A cache that is
/// not a regular file of bitrock's (a pipe, a device) is refused, never waited on.
pub fn read_cache(path: &std::path::Path) -> crate::Result<Cache> {
    if std::fs::metadata(path).is_ok_and(|m| !m.is_file()) {
        return Err(crate::Error::Data {
            path: path.to_path_buf(),
            message: "is not a regular file, so not a cache bitrock wrote".into(),
        });
    }
    match crate::files::read_text(path, "a cache of scoring shapes", MAX_CACHE_BYTES) {
        Ok(text) => serde_json::from_str(&text).map_err(|e| crate::Error::Data {
            path: path.to_path_buf(),
            message: format!("not a bitrock cache of scoring shapes: {e}"),
        }),
        Err(crate::Error::Read { source, .. }) if source.kind() == std::io::ErrorKind::NotFound => Ok(Cache::default()),
        Err(e) => Err(e),
    }
}

/// Adds `tuning` to the cache file at `path` (replacing one of the same key; an unreadable
/// file is replaced), written whole or not at all.
pub fn write_cache(path: &std::path::Path, tuning: &Tuning) -> crate::Result<()> {
    let mut cache = read_cache(path).unwrap_or_default();
    cache.tunings.retain(|t| t.key != tuning.key);
    cache.tunings.push(tuning.clone());
    replace_cache(path, &cache)
}

/// Adds `race` to the cache file at `path` (replacing one of the same key), as
/// [`write_cache`].
pub fn write_race(path: &std::path::Path, race: &crate::eval::auto::StoredRace) -> crate::Result<()> {
    let mut cache = read_cache(path).unwrap_or_default();
    cache.races.retain(|r| r.key != race.key);
    cache.races.push(race.clone());
    replace_cache(path, &cache)
}

/// Writes `cache` to `path`, whole or not at all.
fn replace_cache(path: &std::path::Path, cache: &Cache) -> crate::Result<()> {
    let dir = crate::files::parent_dir(path);
    std::fs::create_dir_all(dir).map_err(|source| crate::Error::Write {
        path: dir.to_path_buf(),
        source,
    })?;
    let text = serde_json::to_string_pretty(cache).expect("tunings serialise");
    crate::files::write_own(path, CACHE_DIR_VAR, |out| out.write_all(text.as_bytes()))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A clock of two made-up shapes: `tiled` fills a GPU at once (a fixed cost), `blocked`
    /// needs many candidates to fill it and then runs at twice tiled's rate.
    fn gpu_like(shape: Shape, candidates: usize) -> f64 {
        let n = candidates as f64;
        match shape {
            Shape::Blocked => 2e-3 + n * 1e-9,
            _ => 1e-4 + n * 2e-9,
        }
    }

    #[test]
    fn the_faster_shape_wins_at_each_size_and_the_nearest_size_decides() {
        let shapes = [Shape::Blocked, Shape::Tiled];
        let mut calls = Vec::new();
        let sizes = [65_536, 1_048_576, 16_777_216];
        let bands = measure_with(&shapes, &sizes, &mut |s, n| {
            calls.push((s, n));
            Ok(gpu_like(s, n))
        })
        .unwrap();
        // 65,536: tiled 2.3e-4 s against blocked 2.1e-3 s; 1,048,576: 2.2e-3 against 3.0e-3;
        // 16,777,216: 3.4e-2 against 1.9e-2 (blocked wins from about 1.9 M on).
        let winners: Vec<Shape> = bands.iter().map(|b| b.winner).collect();
        assert_eq!(winners, [Shape::Tiled, Shape::Tiled, Shape::Blocked]);
        assert!(bands.iter().all(|b| b.measured()));
        let seconds = |b: usize, k: usize| bands[b].timings[k].seconds.unwrap();
        assert!((seconds(2, 0) - gpu_like(Shape::Blocked, sizes[2])).abs() < 1e-12);
        assert!((seconds(2, 1) - gpu_like(Shape::Tiled, sizes[2])).abs() < 1e-12);
        // One warm-up per shape, then three timings per shape and size.
        assert_eq!(calls.len(), 2 + 3 * 2 * 3);
        let tuning = Tuning {
            key: String::new(),
            adapter: String::new(),
            samples: 1,
            measured_unix_s: 0,
            seconds: 0.0,
            bands,
        };
        assert_eq!(tuning.shape_for(1), Shape::Tiled);
        assert_eq!(tuning.shape_for(1_048_576), Shape::Tiled);
        assert_eq!(tuning.shape_for(5_000_000), Shape::Blocked);
        assert_eq!(tuning.shape_for(usize::MAX), Shape::Blocked);
        assert!(
            tuning.table().last().unwrap().ends_with("blocked"),
            "{:?}",
            tuning.table()
        );
    }

    #[test]
    fn a_shape_already_slower_than_the_fastest_is_not_timed_again() {
        // A CPU driver at small sizes: tiled six times slower, both linear.
        let mut timed = Vec::new();
        let bands = measure_with(&[Shape::Tiled, Shape::Blocked], &[256, 4_096], &mut |s, n| {
            timed.push((s, n));
            let rate = if s == Shape::Blocked { 2e9 } else { 2e9 / 6.0 };
            Ok(n as f64 * 4096.0 / rate)
        })
        .unwrap();
        assert!(bands.iter().all(|b| b.winner == Shape::Blocked && b.measured()));
        // At 4,096 blocked (faster at 256) goes first, 8.4 ms; tiled's 3.1 ms at 256 is less,
        // so it is timed too: more candidates may cost it little more on a GPU.
        assert!(bands[1].timings.iter().all(|t| t.seconds.is_some()));
        // Make tiled's time at the smaller size exceed blocked's time at the larger one.
        let bands = measure_with(&[Shape::Tiled, Shape::Blocked], &[256, 4_096], &mut |s, n| {
            Ok(if s == Shape::Blocked {
                1e-3 * n as f64 / 256.0
            } else {
                0.02
            })
        })
        .unwrap();
        let tiled = &bands[1].timings[0];
        assert_eq!((tiled.seconds, tiled.at_least_s), (None, Some(0.02)));
        assert_eq!(bands[1].winner, Shape::Blocked);
    }

    #[test]
    fn a_projection_over_the_cap_is_not_timed_and_a_size_nobody_reaches_keeps_the_last_winner() {
        // lavapipe: every shape linear in the candidates, tiled six times slower.
        let mut timed = Vec::new();
        let bands = measure_with(&[Shape::Blocked, Shape::Tiled], &SIZES, &mut |s, n| {
            timed.push((s, n));
            let rate = if s == Shape::Blocked { 2e8 } else { 2e8 / 6.0 };
            Ok(n as f64 * 4096.0 / rate)
        })
        .unwrap();
        // 4,096 × 4,096: blocked 84 ms (warm-up and three timings), tiled 503 ms (warm-up and
        // one timing: it spent the budget).
        assert_eq!(bands[0].winner, Shape::Blocked);
        let count = |shape| timed.iter().filter(|&&(s, n)| s == shape && n == 4_096).count();
        assert_eq!((count(Shape::Blocked), count(Shape::Tiled)), (4, 2));
        // 65,536: blocked projects to 1.3 s, over the cap; tiled is at least 503 ms.
        assert!(!bands[1].measured() && bands[1].timings.iter().all(|t| t.seconds.is_none()));
        assert!((bands[1].timings[0].projected_s.unwrap() - 1.342).abs() < 1e-3);
        assert_eq!(bands[1].winner, Shape::Blocked);
        assert!(!bands[2].measured() && bands[2].winner == Shape::Blocked);
        assert!(timed.iter().all(|&(_, n)| n == 4_096));
    }

    #[test]
    fn a_cpu_driver_tries_one_tile_width_and_a_gpu_every_one_that_fits() {
        let big = wgpu::Limits {
            max_compute_workgroup_storage_size: 48 * 1024,
            ..wgpu::Limits::default()
        };
        assert_eq!(
            worth_trying(wgpu::DeviceType::Cpu, &big),
            [Shape::Blocked, Shape::Tiled]
        );
        assert_eq!(worth_trying(wgpu::DeviceType::DiscreteGpu, &big), Shape::ALL);
        assert_eq!(
            worth_trying(wgpu::DeviceType::IntegratedGpu, &wgpu::Limits::default()),
            [Shape::Blocked, Shape::Tiled, Shape::Tiled128]
        );
    }

    #[test]
    fn the_median_of_the_repeats_is_kept() {
        let mut clock = [5e-4, 1e-4, 3e-4, 9e-4].into_iter().cycle();
        let bands = measure_with(&[Shape::Tiled], &[10], &mut |_, _| Ok(clock.next().unwrap())).unwrap();
        // Warm-up 5e-4 (untimed), then 1e-4, 3e-4, 9e-4: median 3e-4.
        assert_eq!(bands[0].timings[0].seconds, Some(3e-4));
    }

    #[test]
    fn the_cache_keeps_one_tuning_per_adapter_and_survives_a_damaged_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("nested").join(CACHE_FILE);
        let tuning = |key: &str, winner| Tuning {
            key: key.into(),
            adapter: "an adapter".into(),
            samples: 4096,
            measured_unix_s: 1,
            seconds: 0.2,
            bands: vec![SizeBand {
                candidates: 4096,
                timings: vec![Timing {
                    shape: winner,
                    seconds: Some(1e-3),
                    at_least_s: None,
                    projected_s: None,
                }],
                winner,
            }],
        };
        write_cache(&path, &tuning("a", Shape::Tiled)).unwrap();
        write_cache(&path, &tuning("b", Shape::Blocked)).unwrap();
        write_cache(&path, &tuning("a", Shape::Tiled128)).unwrap();
        let cache = read_cache(&path).unwrap();
        assert_eq!(cache.tunings.len(), 2);
        assert_eq!(
            cache.tunings.iter().find(|t| t.key == "a").unwrap().bands[0].winner,
            Shape::Tiled128
        );
        std::fs::write(&path, "{ not json").unwrap();
        let e = read_cache(&path).unwrap_err().to_string();
        assert!(e.contains(CACHE_FILE) && e.contains("not a bitrock cache"), "{e}");
        write_cache(&path, &tuning("c", Shape::Blocked)).unwrap();
        assert_eq!(read_cache(&path).unwrap().tunings.len(), 1);
        assert!(read_cache(&dir.path().join("none.json")).unwrap().tunings.is_empty());
    }
}
