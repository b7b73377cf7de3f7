// One dispatch over a range of candidates. Keep in sync with `Job` in src/eval/gpu/mod.rs.
struct Job {
    // First candidate index of the dispatch (low, high words).
    start: vec2<u32>,
    // Candidate stream (population counter).
    population: u32,
    // Candidates in the dispatch.
    count: u32,
    // Data samples D (residual kernel).
    data_len: u32,
    // Candidates per row of the (possibly 2-D) dispatch grid.
    row_width: u32,
    _pad: vec2<u32>,
}
