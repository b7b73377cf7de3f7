//! The WGSL that scores one law in the kernels' loops: its quad function and its case or pass
//! at each place the kernels list the laws (the blocked and tiled loops, the per-law passes,
//! the stability slopes). One writer for both kinds of law: the build writes the built-in
//! laws' at build time (`build.rs`), [`super::file_laws`] a law file's at run time.
//!
//! This file is compiled into the build script too: it uses nothing outside `std`.

use std::fmt::Write;

/// The kernels' text for a set of laws, one part per place the kernels list the laws.
#[derive(Default)]
pub struct LawCases {
    /// Functions: each law's quad function (kernels that score only).
    pub functions: String,
    /// Cases of `block_ssr`'s switch (the blocked loop).
    pub blocks: String,
    /// Lines of `slice_ssr` (one pass per law).
    pub passes: String,
    /// Cases of `strided_ssr`'s switch (the tiled loop).
    pub strided: String,
    /// Cases of `dtorque_dw`'s switch (the stability slopes).
    pub slopes: String,
    /// Cases of `torque_at`'s switch (the simulated strings).
    pub torques: String,
}

impl LawCases {
    /// Adds law `id`: `quad` names its quad function, `torque(p, w)` is the WGSL call of its
    /// torque at r = 1 on parameter array `p` and speed `w`, `slope` the call of its dT/dw on
    /// `p` and `w`. `scores` is false for kernels that only take slopes.
    pub fn add(&mut self, id: usize, quad: &str, torque: &dyn Fn(&str, &str) -> String, slope: &str, scores: bool) {
        writeln!(self.slopes, "        case {id}u: {{ return {slope}; }}").unwrap();
        writeln!(self.torques, "        case {id}u: {{ return {}; }}", torque("p", "w")).unwrap();
        if !scores {
            return;
        }
        let four_at = |w: &str| {
            ["x", "y", "z", "w"]
                .iter()
                .map(|lane| torque("p", &format!("{w}.{lane}")))
                .collect::<Vec<_>>()
                .join(", ")
        };
        writeln!(
            self.functions,
            "fn {quad}(p: array<f32, 6>, d: Quad) -> f32 {{\n    let w = d.w;\n    var t_prev = 0.0;\n    if (LAG) {{\n        t_prev = {};\n    }}\n    return quad_sq(vec4<f32>({}), t_prev, d);\n}}",
            torque("p", "d.w_prev"),
            four_at("w")
        )
        .unwrap();
        let call = |k: usize| format!("{quad}(p[{k}], d)");
        write!(
            self.blocks,
            "        case {id}u: {{\n            for (var q = q0; q < q1; q = q + 1u) {{\n                let d = load_quad(q, end);\n"
        )
        .unwrap();
        for g in 0..4 {
            let four: Vec<String> = (4 * g..4 * g + 4).map(call).collect();
            writeln!(
                self.blocks,
                "                s[{g}] = s[{g}] + vec4<f32>({});",
                four.join(", ")
            )
            .unwrap();
        }
        self.blocks.push_str("            }\n        }\n");
        writeln!(
            self.passes,
            "    out = law_pass({id}u, laws, p, data_start, data_end, out);"
        )
        .unwrap();
        let four: Vec<String> = (0..4).map(call).collect();
        write!(
            self.strided,
            "            case {id}u: {{\n                for (var q = b; q < block_end; q = q + TILE_WORKGROUP) {{\n                    let d = load_quad(q, data_end);\n                    block = block + vec4<f32>({});\n                }}\n            }}\n",
            four.join(", ")
        )
        .unwrap();
    }

    /// `source` with these cases written at the kernels' markers (`// LAW_BLOCKS`, …), each
    /// marker kept after them for the laws written later, and the functions appended.
    pub fn splice(&self, source: &str) -> String {
        let mut out = source.to_string();
        for (marker, text) in [
            ("// LAW_BLOCKS", &self.blocks),
            ("// LAW_PASSES", &self.passes),
            ("// LAW_STRIDED", &self.strided),
            ("// LAW_SLOPES", &self.slopes),
            ("// LAW_TORQUES", &self.torques),
        ] {
            out = out.replace(marker, &format!("{}{marker}", text.trim_start()));
        }
        out.push('\n');
        out.push_str(&self.functions);
        out
    }

    /// `source` without the markers: no more laws to come.
    pub fn close(source: &str) -> String {
        [
            "// LAW_BLOCKS",
            "// LAW_PASSES",
            "// LAW_STRIDED",
            "// LAW_SLOPES",
            "// LAW_TORQUES",
        ]
        .iter()
        .fold(source.to_string(), |text, marker| text.replace(marker, ""))
    }
}
