// Test kernel: uniform_between of shared/philox.wgsl on (lo bits, hi bits, word) triples, so
// tests can compare the WGSL twin's bits with src/rng.rs on hard cases (subnormals, ties, far
// terms). Needs shared/philox.wgsl.
// One triple per element: lo and hi as f32 bits, the word, and an unused word.
@group(0) @binding(0) var<storage, read> triples: array<vec4<u32>>;
// The result of triple k as f32 bits.
@group(0) @binding(1) var<storage, read_write> out: array<u32>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let k = gid.x + gid.y * groups.x * 64u;
    if (k >= arrayLength(&triples)) {
        return;
    }
    let t = triples[k];
    out[k] = bitcast<u32>(uniform_between(bitcast<f32>(t.x), bitcast<f32>(t.y), t.z));
}
