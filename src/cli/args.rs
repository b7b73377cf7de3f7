//! Argument groups shared by several commands (the record, the fit, the drill strings) and
//! their conversion into the library's options.

use bitrock::Law;
use bitrock::data::{self, DataOptions, FieldData, SplitRule};
use bitrock::fit::FitOptions;
use bitrock::run::stability::{DrillStringSpec, StringGiven, Structure};
use bitrock::stability::fe::DrillStringSettings;
use bitrock::stability::lumped::Lumped;
use bitrock::units::{ForceUnit, SpeedUnit, TorqueUnit};
use clap::Args;
use std::path::PathBuf;

/// The flags `--resume` refuses: a run or an evidence resumed takes its record, its fit and its
/// drill string from its directory, and then the kind's own settings, `$own`.
macro_rules! resume_conflicts {
    ($($own:literal),* $(,)?) => {
        [
            "data", "out", "force", "speed_col", "torque_col", "wob_col", "time_col", "speed_unit", "torque_unit",
            "wob_unit", "column_map", "t_start_s", "t_end_s", "thin", "min_speed_rpm", "calibration_fraction", "split", "laws",
            "no_bounds", "starts", "scale_by_wob", "w_ref_kn", "structure", "fe_file", "dp_elements", "bha_elements",
            "alpha", "beta", "inertia_kg_m2", "omega_n_rad_s", "damping_ratio", $($own),*
        ]
    };
}
pub(crate) use resume_conflicts;

/// Which columns of the CSV to read, their units, and the slowest bit speed kept: what a
/// record's rows are read by, whole (`fit`, `abc`…) or as a stream (`watch`).
#[derive(Debug, Args, Clone)]
pub struct ColumnArgs {
    /// Bit-speed column [default: the one column whose name contains "speed"].
    #[arg(long, value_name = "NAME")]
    pub speed_col: Option<String>,
    /// Torque-on-bit column [default: the one column whose name contains "torque"].
    #[arg(long, value_name = "NAME")]
    pub torque_col: Option<String>,
    /// Weight-on-bit column [default: the one column whose name contains "wob", if any].
    #[arg(long, value_name = "NAME")]
    pub wob_col: Option<String>,
    /// Time column, in seconds [default: the one column whose name contains "time", if any].
    #[arg(long, value_name = "NAME")]
    pub time_col: Option<String>,
    /// Unit of the speed column [default: from its suffix, _rpm or _rad_s].
    #[arg(long, value_enum)]
    pub speed_unit: Option<SpeedUnit>,
    /// Unit of the torque column [default: from its suffix, _nm or _knm].
    #[arg(long, value_enum)]
    pub torque_unit: Option<TorqueUnit>,
    /// Unit of the weight-on-bit column [default: from its suffix, _n or _kn].
    #[arg(long, value_enum)]
    pub wob_unit: Option<ForceUnit>,
    /// A column map file (TOML: `speed`, `torque`, `wob`, `time` and `speed_unit`,
    /// `torque_unit`, `wob_unit`) naming a rig's columns and units by role; the flags above
    /// win over it.
    #[arg(long, value_name = "FILE")]
    pub column_map: Option<PathBuf>,
    /// Drop rows whose bit speed is below this, rpm: the laws hold for a turning bit, and
    /// stick-phase samples say nothing about them.
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, default_value_t = DataOptions::default().min_speed_rpm, value_name = "RPM")]
    pub min_speed_rpm: f64,
}

impl ColumnArgs {
    /// The library's options for these flags, the others at their defaults.
    pub fn options(&self) -> DataOptions {
        DataOptions {
            speed_column: self.speed_col.clone(),
            torque_column: self.torque_col.clone(),
            wob_column: self.wob_col.clone(),
            time_column: self.time_col.clone(),
            speed_unit: self.speed_unit,
            torque_unit: self.torque_unit,
            wob_unit: self.wob_unit,
            min_speed_rpm: self.min_speed_rpm,
            column_map: self.column_map.clone(),
            ..DataOptions::default()
        }
    }
}

/// The record: the CSV, which of its columns to read, their units, and which rows to use.
#[derive(Debug, Args, Clone)]
pub struct DataArgs {
    /// Field record (CSV with a header) [default: the embedded demo record].
    pub data: Option<PathBuf>,
    #[command(flatten)]
    pub columns: ColumnArgs,
    /// Use only rows at or after this time, s (needs a time column).
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, value_name = "SECONDS")]
    pub t_start_s: Option<f64>,
    /// Use only rows at or before this time, s (needs a time column).
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, value_name = "SECONDS")]
    pub t_end_s: Option<f64>,
    /// Keep every K-th row of the time window (applied before the speed filter).
    #[arg(long, default_value_t = DataOptions::default().thin, value_name = "K")]
    pub thin: usize,
    /// Fraction of the kept rows used for calibration; the rest validates the fit.
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, default_value_t = DataOptions::default().calibration_fraction, value_name = "F")]
    pub calibration_fraction: f64,
    /// How calibration rows are chosen: block = the first part of the record, interleaved =
    /// spread evenly through it.
    #[arg(long, value_enum, default_value_t = DataOptions::default().split)]
    pub split: SplitRule,
}

impl DataArgs {
    /// The library's options for these flags (validated when the record is read).
    pub fn options(&self) -> DataOptions {
        DataOptions {
            t_start_s: self.t_start_s,
            t_end_s: self.t_end_s,
            thin: self.thin,
            calibration_fraction: self.calibration_fraction,
            split: self.split,
            ..self.columns.options()
        }
    }
}

/// How the least-squares fit runs.
#[derive(Debug, Args, Clone)]
pub struct FitArgs {
    #[arg(long, value_name = "LAWS", help = concat!(
        "Laws to fit, comma-separated: the built-in laws (",
        bitrock::built_in_law_list!(),
        ") and the laws of --law-file by their names [default: every built-in law and every --law-file's law]"
    ))]
    pub laws: Option<String>,
    /// Lift the physical bounds (positive static and dynamic torques, positive rates and widths).
    #[arg(long)]
    pub no_bounds: bool,
    /// Starting points polished by Levenberg-Marquardt per law (chosen from a data-driven grid).
    #[arg(long, default_value_t = FitOptions::default().starts, value_name = "N")]
    pub starts: usize,
    /// Scale each sample's predicted torque by r = WOB / W_ref (needs a WOB column). Off: r = 1,
    /// the paper's assumption that the record was taken at W = W_ref.
    #[arg(long)]
    pub scale_by_wob: bool,
    /// Reference weight on bit W_ref, kN, of --scale-by-wob [default: 244.2, the paper's].
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, value_name = "KN")]
    pub w_ref_kn: Option<f64>,
}

impl FitArgs {
    /// The laws of --laws; without it, every built-in law and every --law-file's law.
    pub fn laws(&self) -> anyhow::Result<Vec<Law>> {
        match &self.laws {
            Some(list) => parse_laws(list),
            None => Ok(Law::ALL
                .into_iter()
                .chain(bitrock::laws::file::registered_laws())
                .collect()),
        }
    }

    /// The fit options of the flags (the library validates them).
    pub fn options(&self) -> anyhow::Result<FitOptions> {
        Ok(FitOptions::from_settings(
            !self.no_bounds,
            Some(self.starts),
            self.scale_by_wob,
            self.w_ref_kn,
        )?)
    }
}

/// The laws of a --laws list (built-in laws and --law-file laws by name), refused naming --laws.
pub fn parse_laws(list: &str) -> anyhow::Result<Vec<Law>> {
    Ok(bitrock::laws::parse_law_list(list).map_err(|m| bitrock::Error::setting("laws", m))?)
}

/// The law of a --law flag (a built-in law or a --law-file law by name), refused naming --law.
pub fn parse_law(name: &str) -> anyhow::Result<Law> {
    Ok(name.parse().map_err(|m: String| bitrock::Error::setting("law", m))?)
}

/// The value parser of every floating-point flag: a number, finite. NaN and infinities are
/// refused where they enter, naming the flag (clap's error, exit status 2); ranges and signs
/// are the library's validation, which names the flag too.
pub fn finite_number(text: &str) -> Result<f64, String> {
    let value: f64 = text.trim().parse().map_err(|_| format!("'{text}' is not a number"))?;
    if value.is_finite() {
        Ok(value)
    } else {
        Err(format!("'{text}' is not a finite number"))
    }
}

/// The record the flags name, or the embedded demo record (saying so) when they name none.
pub fn load_data(args: &DataArgs) -> anyhow::Result<FieldData> {
    let opts = args.options();
    let data = match args.data.as_deref() {
        Some(path) => data::read_field_data(path, &opts)?,
        None => {
            super::print::note("note: no DATA given; using the embedded synthetic demo record");
            data::demo_field_data(&opts)?
        }
    };
    for warning in &data.warnings {
        super::print::note(format_args!("warning: {warning}"));
    }
    Ok(data)
}

/// Sizes rayon's global pool (`--threads`, bounded by [`bitrock::limits::max_threads`]);
/// `None` keeps one thread per core.
pub fn set_threads(threads: Option<usize>) -> anyhow::Result<()> {
    if let Some(threads) = threads {
        bitrock::limits::check_threads(threads)?;
        rayon::ThreadPoolBuilder::new().num_threads(threads).build_global()?;
    }
    Ok(())
}

/// The finite-element drill string: a TOML file (the paper's table built in) and overrides.
#[derive(Debug, Args, Clone)]
pub struct FeArgs {
    /// TOML file with any of: shear_modulus_pa, density_kg_m3, dp_length_m, bha_length_m,
    /// dp_outer_m, dp_inner_m, bha_outer_m, bha_inner_m, dp_elements, bha_elements, alpha, beta.
    #[arg(long, value_name = "FILE")]
    pub fe_file: Option<PathBuf>,
    /// Elements in the drill pipe.
    #[arg(long, value_name = "N")]
    pub dp_elements: Option<usize>,
    /// Elements in the BHA.
    #[arg(long, value_name = "N")]
    pub bha_elements: Option<usize>,
    /// Mass-proportional Rayleigh damping α, 1/s.
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, value_name = "ALPHA")]
    pub alpha: Option<f64>,
    /// Stiffness-proportional Rayleigh damping β, s.
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, value_name = "BETA")]
    pub beta: Option<f64>,
}

/// What a run and an evidence start from, and what `--resume` takes from their directory
/// instead: the record, the laws and their fits, and the drill string of their maps and advice
/// (kept with them: `stability --run` and `report` map on it).
#[derive(Debug, Args)]
pub struct InferenceArgs {
    #[command(flatten)]
    pub record: DataArgs,
    #[command(flatten)]
    pub fit: FitArgs,
    #[command(flatten)]
    pub string: StructureArgs,
}

/// The drill string stability is judged on: the 1-DOF model or the finite-element string,
/// with the settings of each; what is not given comes from the string it is laid over (a run's
/// or an evidence's own, else the paper's).
#[derive(Debug, Args)]
pub struct StructureArgs {
    /// Structure: 1dof (the 1-DOF string) or fe (the finite-element string, its critical bit
    /// damping found by bisection before any map) [default: a run's own, else 1dof].
    #[arg(long, value_enum)]
    pub structure: Option<Structure>,
    #[command(flatten)]
    pub fe: FeArgs,
    #[command(flatten)]
    pub lumped: LumpedArgs,
}

impl StructureArgs {
    /// The string as these flags give it.
    pub fn given(&self) -> StringGiven {
        self.lumped.given(self.structure, &self.fe)
    }

    /// The string these flags give, laid over `base` (a run's own; `None`: the paper's).
    pub fn over(&self, base: Option<&DrillStringSpec>) -> (Structure, Lumped, DrillStringSettings) {
        self.given().over(base)
    }
}

/// The equivalent 1-DOF string [default: a run's own, else the paper's 5 km field string].
#[derive(Debug, Args, Clone)]
pub struct LumpedArgs {
    /// Equivalent moment of inertia I_eq, kg·m² [default: the paper's 383.33].
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, value_name = "KG_M2")]
    pub inertia_kg_m2: Option<f64>,
    /// Natural frequency omega_n, rad/s [default: the paper's 0.85].
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, value_name = "RAD_S")]
    pub omega_n_rad_s: Option<f64>,
    /// Damping ratio xi [default: the paper's 0.25].
    #[arg(long, value_parser = finite_number, allow_hyphen_values = true, value_name = "XI")]
    pub damping_ratio: Option<f64>,
}

impl LumpedArgs {
    /// The string these flags, `structure` and the finite-element flags `fe` give, field by
    /// field.
    pub fn given(&self, structure: Option<Structure>, fe: &FeArgs) -> StringGiven {
        StringGiven {
            structure,
            inertia_kg_m2: self.inertia_kg_m2,
            omega_n_rad_s: self.omega_n_rad_s,
            damping_ratio: self.damping_ratio,
            fe: fe.settings(),
        }
    }

    /// The 1-DOF model these flags describe, the paper's where they are silent (validate
    /// before use).
    pub fn lumped(&self) -> Lumped {
        let paper = Lumped::default();
        Lumped {
            inertia_kg_m2: self.inertia_kg_m2.unwrap_or(paper.inertia_kg_m2),
            omega_n_rad_s: self.omega_n_rad_s.unwrap_or(paper.omega_n_rad_s),
            damping_ratio: self.damping_ratio.unwrap_or(paper.damping_ratio),
        }
    }

    /// [`Self::lumped`], validated.
    pub fn validated(&self) -> anyhow::Result<Lumped> {
        let lumped = self.lumped();
        lumped.validate()?;
        Ok(lumped)
    }
}

impl FeArgs {
    /// The drill string these flags describe.
    pub fn settings(&self) -> DrillStringSettings {
        DrillStringSettings {
            fe_file: self.fe_file.clone(),
            dp_elements: self.dp_elements,
            bha_elements: self.bha_elements,
            alpha: self.alpha,
            beta: self.beta,
            base: None,
        }
    }
}
