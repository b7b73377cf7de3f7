// Whether the driver ended this invocation's loops early: lavapipe ends every loop at its next
// pass once an invocation has run 65,535 iterations together, and a step cut that way still
// ends its sample period as if whole. A loop of two passes whose bound the compiler cannot know
// runs one then. `zero` is 0 read from the job in a way no compiler can fold (a field's top
// bit that the host never sets). Call it after the kernel's last loop that writes.
fn loops_were_cut(zero: u32) -> bool {
    var passes = 0u;
    for (var t = 0u; t < 2u + zero; t = t + 1u) {
        passes = passes + 1u;
    }
    return passes < 2u;
}
