//! `bitrock law FILE`: a law file read and compiled, shown as bitrock understood it: its
//! parameters with units and bounds, the torque, the derivatives it computed, and its WGSL.

use bitrock::laws::file::LawFile;
use clap::Args;
use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Debug, Args)]
pub struct LawCmd {
    /// The law file (TOML; docs/law-files.md).
    #[arg(value_name = "FILE")]
    pub file: PathBuf,
    /// Also print the WGSL the kernels are given.
    #[arg(long)]
    pub wgsl: bool,
}

pub fn run(cmd: &LawCmd) -> anyhow::Result<ExitCode> {
    let law = LawFile::load(&cmd.file)?;
    let names: Vec<&str> = law.params.iter().map(|p| p.name.as_str()).collect();
    let mut out = super::print::stdout();
    writeln!(out, "{}: read, dimensions checked, WGSL validated", cmd.file.display())?;
    writeln!(out, "law {}", law.name)?;
    if let Some(description) = &law.description {
        writeln!(out, "    {description}")?;
    }
    writeln!(
        out,
        "T      = {}   (N·m, w in rad/s, r = W / W_ref)",
        law.formula.trim()
    )?;
    writeln!(out, "dT/dw  = {}", law.dtorque_dw.show(&names))?;
    writeln!(out, "param  unit (SI)           bounds       reference   ∂T/∂param")?;
    for (p, gradient) in law.params.iter().zip(&law.gradient) {
        let reference = p.reference.map_or("—".to_string(), |v| format!("{v}"));
        writeln!(
            out,
            "{:<6} {:<19} {:<12} {:<11} {}",
            p.name,
            p.unit(),
            p.spec("").bounds_text(),
            reference,
            gradient.show(&names)
        )?;
    }
    if cmd.wgsl {
        writeln!(out)?;
        write!(out, "{}", law.wgsl())?;
    }
    Ok(ExitCode::SUCCESS)
}
