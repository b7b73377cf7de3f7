//! Law files' laws in the kernels: their WGSL (compiled by [`crate::laws::file`]) spliced into
//! the shared sources at the places marked `FILE_LAW_…`, so that a law of the user's own is
//! scored by the same blocked and tiled loops, batched-records kernel and stability slopes as
//! the built-in laws, compiled rather than interpreted.

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
/// each marker, and the list of law ids the tiled shape loops over (m1..m4 alone without
/// laws).
pub(crate) fn splice(source: &str, laws: &[Law]) -> String {
    let (mut blocks, mut passes, mut strided, mut slopes, mut functions) = (
        String::new(),
        String::new(),
        String::new(),
        String::new(),
        String::new(),
    );
    let scores = source.contains("fn quad_sq(");
    for &law in laws {
        let file = law.file().expect("a law file's law");
        let (id, name) = (law.index(), &file.name);
        functions.push_str(&file.wgsl());
        writeln!(slopes, "        case {id}u: {{ return file_slope_{name}(p, w, 1.0); }}").unwrap();
        if !scores {
            continue;
        }
        let quad = |k: usize| format!("file_quad_{name}(p[{k}], d)");
        writeln!(
            functions,
            "fn file_quad_{name}(p: array<f32, 6>, d: Quad) -> f32 {{\n    let w = d.w;\n    var t_prev = 0.0;\n    if (LAG) {{\n        t_prev = file_torque_{name}(p, d.w_prev, 1.0);\n    }}\n    return quad_sq(vec4<f32>(file_torque_{name}(p, w.x, 1.0), file_torque_{name}(p, w.y, 1.0), file_torque_{name}(p, w.z, 1.0), file_torque_{name}(p, w.w, 1.0)), t_prev, d);\n}}"
        )
        .unwrap();
        write!(blocks, "        case {id}u: {{\n            for (var q = q0; q < q1; q = q + 1u) {{\n                let d = load_quad(q, end);\n").unwrap();
        for g in 0..4 {
            let four: Vec<String> = (4 * g..4 * g + 4).map(quad).collect();
            writeln!(
                blocks,
                "                s[{g}] = s[{g}] + vec4<f32>({});",
                four.join(", ")
            )
            .unwrap();
        }
        blocks.push_str("            }\n        }\n");
        writeln!(passes, "    out = law_pass({id}u, laws, p, data_start, data_end, out);").unwrap();
        let four: Vec<String> = (0..4).map(quad).collect();
        write!(
            strided,
            "            case {id}u: {{\n                for (var q = b; q < block_end; q = q + TILE_WORKGROUP) {{\n                    let d = load_quad(q, data_end);\n                    block = block + vec4<f32>({});\n                }}\n            }}\n",
            four.join(", ")
        )
        .unwrap();
    }
    let ids: Vec<String> = Law::ALL.iter().chain(laws).map(|l| format!("{}u", l.index())).collect();
    let mut out = source
        .replace("// FILE_LAW_BLOCKS", &blocks)
        .replace("// FILE_LAW_PASSES", &passes)
        .replace("// FILE_LAW_STRIDED", &strided)
        .replace("// FILE_LAW_SLOPES", &slopes);
    if source.contains("law_ids[") {
        // Declared first: naga processes a pipeline's overrides in declaration order, and the
        // tiled shape's override-sized arrays follow.
        out = format!(
            "const LAW_COUNT: u32 = {n}u;\nvar<private> law_ids: array<u32, {n}> = array<u32, {n}>({});\n{out}",
            ids.join(", "),
            n = ids.len()
        );
    }
    out.push('\n');
    out.push_str(&functions);
    out
}
