// A law file's torque and dT/dw at arbitrary points, through the law's generated WGSL (the host
// appends `fn file_torque_LAW` and `fn file_slope_LAW` and defines `law_torque` and `law_slope`
// calling them). Tests compare it with the f64 CPU twin.

struct Point {
    p: array<f32, 6>,
    w: f32,
    r: f32,
}

@group(0) @binding(0) var<storage, read> points: array<Point>;
@group(0) @binding(1) var<storage, read_write> out: array<vec2<f32>>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let k = gid.x + gid.y * groups.x * 64u;
    if (k >= arrayLength(&points)) {
        return;
    }
    let q = points[k];
    out[k] = vec2<f32>(law_torque(q.p, q.w, q.r), law_slope(q.p, q.w, q.r));
}
