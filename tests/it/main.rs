//! One integration-test binary; each module covers one part of the pipeline.

mod cli;
mod fit;
mod laws;
mod support;
