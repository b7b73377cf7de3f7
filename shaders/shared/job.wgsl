// One dispatch over a range of candidates (and, for the residual kernel, a range of samples).
// Keep in sync with `Job` in src/eval/gpu/mod.rs.
struct Job {
    // First candidate index of the dispatch (low, high words).
    start: vec2<u32>,
    // Candidate stream (population counter).
    population: u32,
    // Candidates in the dispatch.
    count: u32,
    // Samples data_start..data_end are scored by this dispatch (data_start a multiple of 4).
    data_start: u32,
    data_end: u32,
    // Candidates per row of the (possibly 2-D) dispatch grid.
    row_width: u32,
    // 0: write the dispatch's sum; 1: add it to what earlier dispatches wrote.
    accumulate: u32,
}
