//! How the scoring kernels spread candidates over invocations, and which spreading a process
//! uses: the one a run recorded, the one `BITROCK_GPU_SHAPE` names, or the one measured
//! fastest on this adapter ([`super::tune`]).

use super::{GpuContext, GpuError};

/// How the scoring kernels (residual.wgsl, score_params.wgsl, records.wgsl) spread candidates
/// over invocations. Every shape scores the same candidates by the same law code and blocked
/// sums (shaders/shared/ssr.wgsl); they differ in which invocation evaluates what, so the f32
/// sums of two shapes agree within the parity tolerance, not bit for bit: a run records its
/// shape and keeps it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Shape {
    /// One invocation scores 16 candidates over every sample (register blocking): a SIMD CPU
    /// driver such as lavapipe, where loads cost more than arithmetic. Entry point `main`.
    Blocked,
    /// A workgroup of 64 invocations scores 16 candidates, its invocations striding over the
    /// samples, the partial sums meeting in a fixed-order tree reduction
    /// (shaders/shared/tile.wgsl): GPUs, which need many more invocations than candidates / 16.
    /// Entry point `main_tiled`.
    Tiled,
    /// As [`Shape::Tiled`] with workgroups of 128: fewer samples per invocation.
    Tiled128,
    /// As [`Shape::Tiled`] with workgroups of 256 (needs 17 KB of workgroup memory, more than
    /// the 16 KB WebGPU guarantees: tried only where the adapter has it).
    Tiled256,
}

/// Environment variable that names the scoring shape (`blocked`, `tiled`, `tiled-128`,
/// `tiled-256`) for runs that have none recorded: no measurement then.
pub const SHAPE_VAR: &str = "BITROCK_GPU_SHAPE";

impl Shape {
    pub const ALL: [Shape; 4] = [Shape::Blocked, Shape::Tiled, Shape::Tiled128, Shape::Tiled256];

    pub fn name(self) -> &'static str {
        match self {
            Shape::Blocked => "blocked",
            Shape::Tiled => "tiled",
            Shape::Tiled128 => "tiled-128",
            Shape::Tiled256 => "tiled-256",
        }
    }

    pub(crate) const fn entry_point(self) -> &'static str {
        match self {
            Shape::Blocked => "main",
            _ => "main_tiled",
        }
    }

    /// Whether a workgroup (not an invocation) scores a tile of candidates.
    pub(crate) fn is_tiled(self) -> bool {
        self != Shape::Blocked
    }

    /// Invocations of a tiled workgroup (`TILE_WORKGROUP` in shaders/shared/tile.wgsl).
    fn tile_workgroup(self) -> u32 {
        match self {
            Shape::Blocked | Shape::Tiled => 64,
            Shape::Tiled128 => 128,
            Shape::Tiled256 => 256,
        }
    }

    /// Workgroup memory of the tiled entry point, bytes: the partial sums (16 f32 per
    /// invocation) and the tile's laws, parameters and positions (16 × (4 + 4 + 24 + 4)).
    fn workgroup_bytes(self) -> u32 {
        64 * self.tile_workgroup() + 16 * 36
    }

    /// Whether the adapter of `limits` can run this shape.
    pub fn fits(self, limits: &wgpu::Limits) -> bool {
        !self.is_tiled()
            || (self.tile_workgroup() <= limits.max_compute_invocations_per_workgroup
                && self.tile_workgroup() <= limits.max_compute_workgroup_size_x
                && self.workgroup_bytes() <= limits.max_compute_workgroup_storage_size)
    }

    /// The override constants of a scoring pipeline in this shape; `has_ratio` false skips the
    /// weight-on-bit ratio column (every r = 1).
    pub(crate) fn constants(self, has_ratio: bool) -> Vec<(&'static str, f64)> {
        let mut constants = vec![("HAS_RATIO", if has_ratio { 1.0 } else { 0.0 })];
        if self.is_tiled() {
            constants.push(("TILE_WORKGROUP", f64::from(self.tile_workgroup())));
        }
        constants
    }

    /// The shape an adapter of `device_type` is guessed to want when nothing was measured:
    /// register blocking on a CPU driver, tiles everywhere else.
    pub fn guess(device_type: wgpu::DeviceType) -> Shape {
        match device_type {
            wgpu::DeviceType::Cpu => Shape::Blocked,
            _ => Shape::Tiled,
        }
    }

    /// The shape `BITROCK_GPU_SHAPE` names, if set: a value that is no shape is refused naming
    /// the variable, a shape the adapter of `ctx` cannot run naming its limits.
    pub fn from_env(ctx: &GpuContext) -> Result<Option<Shape>, GpuError> {
        match std::env::var(SHAPE_VAR) {
            Ok(value) => {
                let shape: Shape = value.parse()?;
                shape.check_fits(ctx)?;
                Ok(Some(shape))
            }
            Err(_) => Ok(None),
        }
    }

    /// Refuses a shape the adapter of `ctx` cannot run (a recorded or named one).
    pub fn check_fits(self, ctx: &GpuContext) -> Result<(), GpuError> {
        if self.fits(&ctx.limits) {
            Ok(())
        } else {
            Err(GpuError::TooLarge(format!(
                "the {self} scoring shape needs workgroups of {} invocations and {} bytes of workgroup memory; {} allows {} and {}",
                self.tile_workgroup(),
                self.workgroup_bytes(),
                ctx.info.name,
                ctx.limits.max_compute_invocations_per_workgroup,
                ctx.limits.max_compute_workgroup_storage_size
            )))
        }
    }
}

impl std::str::FromStr for Shape {
    type Err = GpuError;

    fn from_str(value: &str) -> Result<Shape, GpuError> {
        Shape::ALL
            .into_iter()
            .find(|s| s.name() == value.trim().to_lowercase())
            .ok_or_else(|| GpuError::Setting {
                name: SHAPE_VAR,
                message: format!(
                    "must be one of {}, got `{value}`",
                    Shape::ALL.map(Shape::name).join(", ")
                ),
            })
    }
}

impl std::fmt::Display for Shape {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl serde::Serialize for Shape {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.name())
    }
}

impl<'de> serde::Deserialize<'de> for Shape {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Shape, D::Error> {
        let name = String::deserialize(d)?;
        name.parse().map_err(serde::de::Error::custom)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_parse_back_and_serialise_as_names() {
        for shape in Shape::ALL {
            assert_eq!(shape.name().parse::<Shape>().unwrap(), shape);
            let json = serde_json::to_string(&shape).unwrap();
            assert_eq!(json, format!("\"{}\"", shape.name()));
            assert_eq!(serde_json::from_str::<Shape>(&json).unwrap(), shape);
        }
        assert!(" Tiled-128 ".parse::<Shape>().is_ok());
        let e = "tiled-512".parse::<Shape>().unwrap_err().to_string();
        assert!(
            e.contains(SHAPE_VAR) && e.contains("tiled-512") && e.contains("tiled-256"),
            "{e}"
        );
    }

    #[test]
    fn a_shape_fits_where_its_workgroup_and_memory_do() {
        // WebGPU's defaults: 256 invocations, 16 KB of workgroup memory.
        let limits = wgpu::Limits::default();
        assert!(Shape::Blocked.fits(&limits) && Shape::Tiled.fits(&limits) && Shape::Tiled128.fits(&limits));
        assert!(!Shape::Tiled256.fits(&limits));
        let large = wgpu::Limits {
            max_compute_workgroup_storage_size: 48 * 1024,
            ..limits.clone()
        };
        assert!(Shape::Tiled256.fits(&large));
        let narrow = wgpu::Limits {
            max_compute_invocations_per_workgroup: 64,
            ..large
        };
        assert!(Shape::Tiled.fits(&narrow) && !Shape::Tiled128.fits(&narrow));
    }

    #[test]
    fn tiled_pipelines_name_their_workgroup_and_blocked_ones_do_not() {
        assert_eq!(Shape::Blocked.constants(true), vec![("HAS_RATIO", 1.0)]);
        assert_eq!(
            Shape::Tiled128.constants(false),
            vec![("HAS_RATIO", 0.0), ("TILE_WORKGROUP", 128.0)]
        );
    }
}

/// Where a process's scoring shape came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Source {
    /// `BITROCK_GPU_SHAPE`.
    Named,
    /// The run's record (a resumed run, its selection check).
    Recorded,
    /// The adapter type's guess (`BITROCK_GPU_TUNING=off`).
    Guessed,
    /// The cached measurement of this adapter.
    Cached,
    /// Measured now (and cached).
    Measured,
    /// Measured now, and the cache could not be written.
    MeasuredNotKept,
    /// Given by the caller (tests, benchmarks of one shape).
    Given,
}

impl std::fmt::Display for Source {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Source::Named => "named by BITROCK_GPU_SHAPE",
            Source::Recorded => "recorded by the run",
            Source::Guessed => "guessed from the adapter type, measuring off",
            Source::Cached => "measured fastest on this adapter",
            Source::Measured => "measured fastest on this adapter just now",
            Source::MeasuredNotKept => {
                "measured fastest on this adapter just now, not kept: the cache directory (BITROCK_CACHE_DIR) cannot be written, so the next process measures again"
            }
            Source::Given => "as asked",
        })
    }
}
