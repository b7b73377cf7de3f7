// One explicit candidate uploaded by the host: law id (0 = m1 .. 3 = m4) and its parameters
// (unused ones 0). Keep in sync with `GpuProposal` in src/eval/gpu/mod.rs.
struct Proposal {
    law: u32,
    params: array<f32, 6>,
    _pad: u32,
}
