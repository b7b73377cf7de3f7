//! One integration-test binary; each module covers one part of the pipeline.

mod abc;
mod advice;
mod batched;
mod cli;
mod evidence;
mod fit;
mod gpu;
mod hostile;
mod law_files;
mod laws;
mod layers;
mod messages;
mod pipeline;
mod records;
mod report;
mod selection;
mod settings;
mod shard;
mod smc;
mod stability;
mod store;
mod strings;
mod support;
mod tune;
mod uniform;
mod watch;
