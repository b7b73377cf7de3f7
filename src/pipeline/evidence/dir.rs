//! An evidence directory (`bitrock evidence --out DIR`, `bitrock.evidence(..., out=DIR)`): the
//! evidence's document with each law's posterior sets (`evidence.json`, what
//! `bitrock.read_evidence` reads) and the posterior particles (`posterior.csv`, what
//! `bitrock stability --run DIR` maps), written together or not at all.

use crate::abc::Particle;
use crate::error::{Error, Result};
use crate::files;
use crate::run::dir::{EVIDENCE_JSON, Owned, POSTERIOR_CSV, is_run_dir, owns_unchanged, refuse_inside_run};
use std::path::{Path, PathBuf};

/// Refuses, before any work and naming `out`, a directory the evidence cannot be written to:
/// a file, a run directory or one inside it, one holding anything bitrock did not write
/// there, and an evidence directory without `force`.
pub fn check_out(dir: &Path, force: bool) -> Result<()> {
    files::check_output_dir(dir, "out")?;
    refuse_inside_run(dir, "out")?;
    if is_run_dir(dir) {
        return Err(Error::setting(
            "out",
            format!(
                "{} holds an ABC run: write the evidence to a directory of its own",
                dir.display()
            ),
        ));
    }
    files::refuse_foreign(dir, "out", &|rel, is_dir| {
        owns_unchanged(Owned::Evidence, dir, rel, is_dir)
    })?;
    if dir.join(EVIDENCE_JSON).is_file() && !force {
        return Err(Error::setting(
            "out",
            format!("{} holds an evidence; pass `force` to replace it", dir.display()),
        ));
    }
    Ok(())
}

/// Writes the evidence directory `dir` (checked by [`check_out`]): `document` (the evidence's
/// document with each law's posterior sets) and `posterior_csv` (its particle CSV), replacing
/// what an earlier evidence wrote there in one step.
pub fn save(dir: &Path, force: bool, document: &serde_json::Value, posterior_csv: Vec<u8>) -> Result<()> {
    check_out(dir, force)?;
    let mut json = serde_json::to_vec_pretty(document).map_err(|e| Error::Numerical(e.to_string()))?;
    json.push(b'\n');
    let contents = [
        (PathBuf::from(EVIDENCE_JSON), json),
        (PathBuf::from(POSTERIOR_CSV), posterior_csv),
    ];
    files::replace_dir(
        dir,
        "out",
        &|rel, is_dir| owns_unchanged(Owned::Evidence, dir, rel, is_dir),
        &contents,
    )
}

/// The document of the evidence directory `dir`.
pub fn read(dir: &Path) -> Result<serde_json::Value> {
    let path = dir.join(EVIDENCE_JSON);
    let text = files::read_text(&path, "evidence", 1 << 30)?;
    serde_json::from_str(&text).map_err(|e| Error::Data {
        path,
        message: format!("not an evidence document: {e}"),
    })
}

/// The posterior particles of the evidence directory `dir` (SI) and the weight on bit its
/// torque parameters are for, N, where the evidence scaled each torque by WOB / W_ref.
pub fn posterior(dir: &Path) -> Result<(Vec<Particle>, Option<f64>)> {
    let document = read(dir)?;
    let w_ref_n = document["w_ref_kn"].as_f64().map(|kn| kn * 1000.0);
    let particles = crate::documents::read_particles_csv(&dir.join(POSTERIOR_CSV))?;
    Ok((particles, w_ref_n))
}
