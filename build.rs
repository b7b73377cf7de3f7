//! `BITROCK_SKIP_GPU_TESTS=1` compiles the tests that need a GPU adapter as ignored, so that the
//! test harness counts them as ignored, not as passed.
fn main() {
    println!("cargo::rustc-check-cfg=cfg(skip_gpu_tests)");
    println!("cargo::rerun-if-env-changed=BITROCK_SKIP_GPU_TESTS");
    if std::env::var("BITROCK_SKIP_GPU_TESTS").is_ok_and(|v| v == "1") {
        println!("cargo::rustc-cfg=skip_gpu_tests");
    }
}
