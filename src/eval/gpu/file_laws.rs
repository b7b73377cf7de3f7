//! Law files' laws in the kernels: their WGSL (compiled by [`crate::laws::file`]) spliced into
//! the shared sources at the places marked `FILE_LAW_…`, so that a law of the user's own is
//! scored by the same blocked and tiled loops, batched-records kernel and stability slopes as
//! the built-in laws, compiled rather than interpreted.

use super::law_cases::LawCases;
use crate::Law;
use std::fmt::Write;

/// The pipeline cache's label of kernel `kernel` with `laws` (law ids are unique in a process,
/// and a registered law never changes).
pub(crate) fn label(kernel: &str, laws: &[Law]) -> String {
    let mut label = kernel.to_string();
    for law in laws {
        write!(label, "+{}:{}", law.index(), law.name()).unwrap();
    }
    label
}

/// `source` with the law files' `laws` spliced in: their functions, one case or pass per law at
/// each marker (after the built-in laws' that the build wrote there), and the list of law ids
/// the tiled shape loops over (the built-in laws alone without laws).
pub(crate) fn splice(source: &str, laws: &[Law]) -> String {
    let mut cases = LawCases::default();
    let scores = source.contains("fn quad_sq(");
    for &law in laws {
        let file = law.file().expect("a law file's law");
        let name = &file.name;
        cases.functions.push_str(&file.wgsl());
        cases.add(
            law.index(),
            &format!("file_quad_{name}"),
            &|p, w| format!("file_torque_{name}({p}, {w}, 1.0)"),
            &format!("file_slope_{name}(p, w, 1.0)"),
            scores,
        );
    }
    let mut out = LawCases::close(&cases.splice(source));
    if source.contains("law_ids[") {
        let ids: Vec<String> = Law::ALL.iter().chain(laws).map(|l| format!("{}u", l.index())).collect();
        // Declared first: naga processes a pipeline's overrides in declaration order, and the
        // tiled shape's override-sized arrays follow.
        out = format!(
            "const LAW_COUNT: u32 = {n}u;\nvar<private> law_ids: array<u32, {n}> = array<u32, {n}>({});\n{out}",
            ids.join(", "),
            n = ids.len()
        );
    }
    out
}
