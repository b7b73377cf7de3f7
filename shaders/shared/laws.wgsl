// The four bit-rock laws in f32, twins of src/laws.rs: torque T(w) (r = 1) and dT/dw.
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

// m1: b0 (tanh(b1 w) + b2 w / (1 + b3 w^2)).
fn torque_m1(b0: f32, b1: f32, b2: f32, b3: f32, w: f32) -> f32 {
    return b0 * (tanh_f32(b1 * w) + b2 * w / (1.0 + b3 * w * w));
}

// m2: (tsb - tcb) exp(-g w) + tcb.
fn torque_m2(tsb: f32, tcb: f32, g: f32, w: f32) -> f32 {
    return (tsb - tcb) * exp_f32(-g * w) + tcb;
}

// m3: a0 exp(-a1 (w - a2)^2) + a3 - a4 tanh(a5 w).
fn torque_m3(a0: f32, a1: f32, a2: f32, a3: f32, a4: f32, a5: f32, w: f32) -> f32 {
    let d = w - a2;
    return a0 * exp_f32(-a1 * d * d) + a3 - a4 * tanh_f32(a5 * w);
}

// m4: c0 + c1 w + c2 w^2 + c3 w^3 (Horner).
fn torque_m4(c0: f32, c1: f32, c2: f32, c3: f32, w: f32) -> f32 {
    return c0 + w * (c1 + w * (c2 + w * c3));
}

// dT/dw of law `law` (0 = m1 .. 3 = m4, then law files' laws) at speed w, r = 1: the paper's
// analytic derivatives, a law file's symbolic one.
fn dtorque_dw(law: u32, p: array<f32, 6>, w: f32) -> f32 {
    switch law {
        case 0u: {
            let t = tanh_f32(p[1] * w);
            let q = 1.0 + p[3] * w * w;
            return -p[0] * (p[1] * (t * t - 1.0) - p[2] / q + 2.0 * p[2] * p[3] * w * w / (q * q));
        }
        case 1u: {
            return -(p[0] - p[1]) * p[2] * exp_f32(-p[2] * w);
        }
        case 2u: {
            let t = tanh_f32(p[5] * w);
            let d = w - p[2];
            return p[4] * p[5] * (t * t - 1.0) + (2.0 * p[2] - 2.0 * w) * p[0] * p[1] * exp_f32(-p[1] * d * d);
        }
        case 3u: {
            return p[1] + 2.0 * p[2] * w + 3.0 * p[3] * w * w;
        }
        // The host writes a case per law file's law at the next line.
        // FILE_LAW_SLOPES
        default: {
            return 0.0;
        }
    }
}
