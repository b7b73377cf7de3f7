//! `bitrock devices`: the GPU adapters wgpu sees, and the one this environment picks.

use bitrock::eval::gpu::{self, AdapterWish};
use clap::Args;
use std::io::Write;
use std::process::ExitCode;

#[derive(Debug, Args)]
pub struct DevicesCmd {
    /// Print JSON instead of a table.
    #[arg(long)]
    pub json: bool,
}

pub fn run(cmd: &DevicesCmd) -> anyhow::Result<ExitCode> {
    let adapters = gpu::adapters();
    let wish = AdapterWish::from_env(|name| std::env::var(name).ok()).map_err(bitrock::Error::from)?;
    let picked = wish.pick(&adapters);
    let mut out = super::print::stdout();
    if cmd.json {
        let rows: Vec<serde_json::Value> = adapters
            .iter()
            .enumerate()
            .map(|(i, a)| {
                serde_json::json!({
                    "index": i,
                    "name": a.name,
                    "type": format!("{:?}", a.device_type),
                    "backend": format!("{:?}", a.backend),
                    "pci_bus_id": a.device_pci_bus_id,
                    "driver": a.driver,
                    "picked": matches!(picked, Ok(Some(k)) if k == i),
                })
            })
            .collect();
        serde_json::to_writer_pretty(&mut out, &serde_json::json!({ "adapters": rows }))?;
        writeln!(out)?;
        return Ok(ExitCode::SUCCESS);
    }
    writeln!(out, "index  type            backend  PCI bus id      name")?;
    for (i, a) in adapters.iter().enumerate() {
        let mark = if matches!(picked, Ok(Some(k)) if k == i) {
            "*"
        } else {
            " "
        };
        writeln!(
            out,
            "{mark}{i:<5} {:<15} {:<8} {:<15} {} ({})",
            format!("{:?}", a.device_type),
            format!("{:?}", a.backend),
            a.device_pci_bus_id,
            a.name,
            a.driver
        )?;
    }
    match picked {
        Ok(Some(_)) => writeln!(out, "* the adapter {} picks", describe(&wish))?,
        Ok(None) => writeln!(
            out,
            "no adapter named ({} or CUDA_VISIBLE_DEVICES): wgpu picks the high-performance one",
            gpu::ADAPTER_VAR
        )?,
        Err(e) => writeln!(out, "{e}")?,
    }
    Ok(ExitCode::SUCCESS)
}

fn describe(wish: &AdapterWish) -> String {
    match wish {
        AdapterWish::Index(_) | AdapterWish::BusId(_) => gpu::ADAPTER_VAR.to_string(),
        AdapterWish::Name(_) => "WGPU_ADAPTER_NAME".into(),
        AdapterWish::CudaOrdinals(_) | AdapterWish::NoneVisible => "CUDA_VISIBLE_DEVICES".into(),
        AdapterWish::Any => "wgpu".into(),
    }
}
