// The kernels' transcendentals and the laws' dT/dw switch. The laws' own functions (torque
// T(w) at r = 1 and dT/dw, in f32) are written from their definitions: the built-in laws'
// (laws/*.toml) by the build, a law file's by the host.
// Transcendentals are f32 only: naga's f64 exp/tanh are computed wrongly by lavapipe
// (gfx-rs/wgpu#6087). exp goes through exp2 and tanh through one exp2, the cheapest forms with
// absolute errors of a few f32 ulps of 1, which is what the torque sums need.

const LOG2_E: f32 = 1.4426950408889634;

fn exp_f32(x: f32) -> f32 {
    return exp2(x * LOG2_E);
}

// tanh(x) = sign(x) (1 - 2 / (exp(2|x|) + 1)); saturates cleanly to ±1 for large |x|.
fn tanh_f32(x: f32) -> f32 {
    let t = 1.0 - 2.0 / (exp2(abs(x) * (2.0 * LOG2_E)) + 1.0);
    return select(t, -t, x < 0.0);
}

// sin and cos of law files: x reduced by pi/2 in three parts (Cody-Waite), then Cephes' f32
// polynomials on [-pi/4, pi/4]: errors of a few f32 ulps for |x| up to about 1e4, where the
// built-ins' are only bounded in absolute terms (2^-11 on Vulkan).
struct Reduced {
    y: f32,
    quadrant: i32,
}

fn reduce_half_pi(x: f32) -> Reduced {
    let k = round(x * 0.6366197723675814);
    let y = ((x - k * 1.5703125) - k * 4.837512969970703125e-4) - k * 7.549789954891882e-8;
    return Reduced(y, i32(k) & 3);
}

fn sin_poly(y: f32) -> f32 {
    let z = y * y;
    return y + y * z * (-1.6666654611e-1 + z * (8.3321608736e-3 + z * -1.9515295891e-4));
}

fn cos_poly(y: f32) -> f32 {
    let z = y * y;
    return 1.0 - 0.5 * z + z * z * (4.166664568298827e-2 + z * (-1.388731625493765e-3 + z * 2.443315711809948e-5));
}

fn sin_f32(x: f32) -> f32 {
    let a = reduce_half_pi(x);
    let s = select(sin_poly(a.y), cos_poly(a.y), (a.quadrant & 1) == 1);
    return select(s, -s, a.quadrant >= 2);
}

fn cos_f32(x: f32) -> f32 {
    let a = reduce_half_pi(x);
    let c = select(cos_poly(a.y), sin_poly(a.y), (a.quadrant & 1) == 1);
    return select(c, -c, a.quadrant == 1 || a.quadrant == 2);
}

// dT/dw of law `law` (0 = m1 .. 3 = m4, then law files' laws) at speed w, r = 1: the paper's
// analytic derivatives, a law file's symbolic one.
fn dtorque_dw(law: u32, p: array<f32, 6>, w: f32) -> f32 {
    switch law {
        // The build writes a case per built-in law (laws/*.toml), the host one per law file's
        // law, at the next line.
        // LAW_SLOPES
        default: {
            return 0.0;
        }
    }
}

// T(w) of law `law` at r = 1 (the simulated strings).
fn torque_at(law: u32, p: array<f32, 6>, w: f32) -> f32 {
    switch law {
        // The build writes a case per built-in law, the host one per law file's law.
        // LAW_TORQUES
        default: {
            return 0.0;
        }
    }
}
