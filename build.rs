//! Build steps: the GPU kernels composed and validated, and the GPU tests' switch.
//!
//! Each kernel is its shared files (`shaders/shared/`) followed by its own file, joined by
//! newlines, in the order of [`KERNELS`]; the composed source is written to `OUT_DIR/shaders/`
//! (the library includes it from there) and validated by naga here, as the library runs it
//! without law files, so that a kernel that does not compile fails the build, not a run. Law
//! files' cases are spliced in at run time (and validated when a law file is read).
//!
//! `BITROCK_SKIP_GPU_TESTS=1` compiles the tests that need a GPU adapter as ignored, so that the
//! test harness counts them as ignored, not as passed.

use std::path::Path;

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
    compose_kernels();
}

/// The kernel as the library runs it without law files: the built-in laws' ids declared, the
/// law files' markers empty (`src/eval/gpu/file_laws.rs`, `splice`; a library test checks
/// that both give the same text).
fn without_law_files(source: &str) -> String {
    let mut out = [
        "// FILE_LAW_BLOCKS",
        "// FILE_LAW_PASSES",
        "// FILE_LAW_STRIDED",
        "// FILE_LAW_SLOPES",
    ]
    .iter()
    .fold(source.to_string(), |text, marker| text.replace(marker, ""));
    if source.contains("law_ids[") {
        out = format!(
            "const LAW_COUNT: u32 = 4u;\nvar<private> law_ids: array<u32, 4> = array<u32, 4>(0u, 1u, 2u, 3u);\n{out}"
        );
    }
    out.push('\n');
    out
}

fn compose_kernels() {
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
        let source = parts.join("\n");
        let built_in = without_law_files(&source);
        let module = naga::front::wgsl::parse_str(&built_in)
            .unwrap_or_else(|e| panic!("kernel {name} does not parse:\n{}", e.emit_to_string(&built_in)));
        naga::valid::Validator::new(naga::valid::ValidationFlags::all(), naga::valid::Capabilities::empty())
            .validate(&module)
            .unwrap_or_else(|e| panic!("kernel {name} does not validate:\n{}", e.emit_to_string(&built_in)));
        std::fs::write(out.join(format!("{name}.wgsl")), source).expect("OUT_DIR is writable");
        std::fs::write(out.join(format!("{name}.built-in.wgsl")), built_in).expect("OUT_DIR is writable");
    }
}
