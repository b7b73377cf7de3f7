//! Build steps: the built-in laws compiled from their files, the GPU kernels composed and
//! validated, and the GPU tests' switch.
//!
//! The built-in laws (`laws/*.toml`) become the library's Rust code (`OUT_DIR/laws.rs`) and
//! their WGSL functions and cases (`build/laws.rs`), compiled by the law-file language's own
//! compiler (`src/laws/file/expr.rs`, included here as a module).
//!
//! Each kernel is its shared files (`shaders/shared/`) followed by its own file, joined by
//! newlines, in the order of [`KERNELS`], with the built-in laws' cases written at the kernels'
//! markers (which stay, for law files); the composed source is written to `OUT_DIR/shaders/`
//! (the library includes it from there) and validated by naga here, as the library runs it
//! without law files, so that a kernel that does not compile fails the build, not a run. Law
//! files' cases are spliced in at run time (and validated when a law file is read).
//!
//! `BITROCK_SKIP_GPU_TESTS=1` compiles the tests that need a GPU adapter as ignored, so that the
//! test harness counts them as ignored, not as passed.

use std::path::Path;

// The law-file language (parser, dimensions, derivatives, WGSL and Rust text) and the writer
// of a law's kernel cases: the library's own modules, which use nothing outside std and the
// crates listed as build-dependencies.
#[allow(dead_code)]
#[path = "src/laws/file/expr.rs"]
mod expr;
#[allow(dead_code)]
#[path = "src/eval/gpu/law_cases.rs"]
mod law_cases;
#[path = "build/laws.rs"]
mod laws;
#[path = "src/eval/gpu/validator.rs"]
mod validator;

/// Every kernel: its name and its files under `shaders/`, shared ones first.
const KERNELS: &[(&str, &[&str])] = &[
    (
        "residual",
        &[
            "shared/philox.wgsl",
            "shared/job.wgsl",
            "shared/candidate.wgsl",
            "shared/laws.wgsl",
            "shared/ssr.wgsl",
            "shared/tile.wgsl",
            "residual.wgsl",
        ],
    ),
    (
        "score_params",
        &[
            "shared/job.wgsl",
            "shared/proposal.wgsl",
            "shared/laws.wgsl",
            "shared/ssr.wgsl",
            "shared/tile.wgsl",
            "score_params.wgsl",
        ],
    ),
    (
        "records",
        &[
            "shared/philox.wgsl",
            "shared/job.wgsl",
            "shared/candidate.wgsl",
            "shared/proposal.wgsl",
            "shared/laws.wgsl",
            "shared/ssr.wgsl",
            "shared/tile.wgsl",
            "records.wgsl",
        ],
    ),
    ("kernel_sums", &["shared/laws.wgsl", "kernel_sums.wgsl"]),
    ("slopes", &["shared/laws.wgsl", "slopes.wgsl"]),
    ("stability", &["stability.wgsl"]),
    (
        "coupled",
        &["shared/any_lane.wgsl", "shared/loop_limit.wgsl", "coupled.wgsl"],
    ),
    (
        "coupled_without_subgroups",
        &["shared/each_lane.wgsl", "shared/loop_limit.wgsl", "coupled.wgsl"],
    ),
    (
        "strings",
        &["shared/laws.wgsl", "shared/loop_limit.wgsl", "strings.wgsl"],
    ),
    (
        "candidates",
        &[
            "shared/philox.wgsl",
            "shared/job.wgsl",
            "shared/candidate.wgsl",
            "candidates.wgsl",
        ],
    ),
    (
        "test_uniform_between",
        &["shared/philox.wgsl", "test_uniform_between.wgsl"],
    ),
];

fn main() {
    println!("cargo::rustc-check-cfg=cfg(skip_gpu_tests)");
    println!("cargo::rerun-if-env-changed=BITROCK_SKIP_GPU_TESTS");
    if std::env::var("BITROCK_SKIP_GPU_TESTS").is_ok_and(|v| v == "1") {
        println!("cargo::rustc-cfg=skip_gpu_tests");
    }
    let manifest = std::env::var("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR");
    let out = std::env::var("OUT_DIR").expect("cargo sets OUT_DIR");
    let built_in = laws::read(&Path::new(&manifest).join("laws"));
    std::fs::write(Path::new(&out).join("laws.rs"), laws::rust(&built_in)).expect("OUT_DIR is writable");
    compose_kernels(&built_in);
}

/// The kernel as the library runs it without law files: the markers gone, the law ids those of
/// the built-in laws (`src/eval/gpu/file_laws.rs`, `splice`, does the same with law files; a
/// library test checks that both give the same text without any).
fn without_law_files(source: &str, built_in: usize) -> String {
    let mut out = law_cases::LawCases::close(&law_cases::LawCases::default().splice(source));
    if source.contains("law_ids[") {
        let ids: Vec<String> = (0..built_in).map(|k| format!("{k}u")).collect();
        out = format!(
            "const LAW_COUNT: u32 = {built_in}u;\nvar<private> law_ids: array<u32, {built_in}> = array<u32, {built_in}>({});\n{out}",
            ids.join(", ")
        );
    }
    out
}

fn compose_kernels(built_in: &[laws::BuiltIn]) {
    // Read when the script runs, not when it was compiled: one compiled script may serve
    // another checkout of the same sources (a shared target directory).
    let manifest = std::env::var("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR");
    let shaders = Path::new(&manifest).join("shaders");
    println!("cargo::rerun-if-changed=shaders");
    let out = Path::new(&std::env::var("OUT_DIR").expect("cargo sets OUT_DIR")).join("shaders");
    std::fs::create_dir_all(&out).expect("OUT_DIR is writable");
    for (name, files) in KERNELS {
        let parts: Vec<String> = files
            .iter()
            .map(|f| {
                let path = shaders.join(f);
                println!("cargo::rerun-if-changed={}", path.display());
                std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
            })
            .collect();
        let mut source = parts.join("\n");
        // Kernels that hold the laws' functions (shaders/shared/laws.wgsl) get the built-in ones.
        if source.contains("fn dtorque_dw(") {
            source = laws::wgsl_cases(built_in, source.contains("fn quad_sq(")).splice(&source);
        }
        let built_in = without_law_files(&source, built_in.len());
        let module = naga::front::wgsl::parse_str(&built_in)
            .unwrap_or_else(|e| panic!("kernel {name} does not parse:\n{}", e.emit_to_string(&built_in)));
        validator::validator(name)
            .validate(&module)
            .unwrap_or_else(|e| panic!("kernel {name} does not validate:\n{}", e.emit_to_string(&built_in)));
        std::fs::write(out.join(format!("{name}.wgsl")), source).expect("OUT_DIR is writable");
        std::fs::write(out.join(format!("{name}.built-in.wgsl")), built_in).expect("OUT_DIR is writable");
    }
}
