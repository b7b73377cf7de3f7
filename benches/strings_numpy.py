"""A vectorised numpy twin of bitrock's string integrator, for `bitrock bench --strings`'
comparison: the 1-DOF string, m2 at the paper's estimate, the batch `bitrock bench --strings`
simulates (speeds 40-160 rpm, weights 0.5-1.5 W_ref, steady rotation kicked by a tenth), the
same fixed RK4 step and the same stick rule (a stop or a release inside a step located by one
secant and the step re-integrated to it), every string advanced together.

    python benches/strings_numpy.py [--strings N] [--seconds S] [--dt-s DT] [--reps R]

Prints the wall time (median of the repetitions), string-seconds per second and the mean stuck
share (compare with the `mean_stuck_share` of `bitrock bench --strings --json`)."""

import argparse
import statistics
import time

import numpy as np

RPM = np.pi / 30.0


def batch(n):
    i = np.arange(n)
    omega = (40.0 + 120.0 * ((i % 97) / 96.0)) * RPM
    ratio = 0.5 + (i % 89) / 88.0
    return omega, ratio


def simulate(n, seconds, dt):
    inertia, omega_n, xi = 383.33, 0.85, 0.25
    k = inertia * omega_n**2
    c = 2.0 * xi * inertia * omega_n
    tsb, tcb, g = 13e3, 6.5e3, 0.3
    omega, r = batch(n)

    def torque(w):
        return r * ((tsb - tcb) * np.exp(-g * w) + tcb)

    static = np.maximum(r * tsb, 0.0)
    u = torque(omega) / k
    w = omega * 1.1
    stuck = np.zeros(n, bool)

    def deriv(u, w, stuck, direction):
        drive = k * u + c * (omega - w)
        dw = np.where(stuck, 0.0, (drive - direction * torque(direction * w)) / inertia)
        return omega - w, dw

    def rk4(u, w, stuck, direction, h):
        a = deriv(u, w, stuck, direction)
        b = deriv(u + 0.5 * h * a[0], w + 0.5 * h * a[1], stuck, direction)
        c_ = deriv(u + 0.5 * h * b[0], w + 0.5 * h * b[1], stuck, direction)
        d = deriv(u + h * c_[0], w + h * c_[1], stuck, direction)
        return (u + h / 6.0 * (a[0] + 2.0 * (b[0] + c_[0]) + d[0]),
                w + h / 6.0 * (a[1] + 2.0 * (b[1] + c_[1]) + d[1]))

    direction = np.ones(n)
    steps_per_sample = int(round(1.0 / 50.0 / dt))
    samples = int(round(seconds * 50.0))
    stuck_count = np.zeros(n)
    for _ in range(samples):
        for _ in range(steps_per_sample):
            remaining = np.full(n, dt)
            for _ in range(4):
                active = remaining > 0.0
                if not active.any():
                    break
                u1, w1 = rk4(u, w, stuck, direction, remaining)
                drive0 = k * u + c * (omega - w)
                drive1 = k * u1 + c * (omega - w1)
                # Stuck: held unless the drive passes the static torque inside the step.
                held = active & stuck & (np.abs(drive1) <= static)
                releasing = active & stuck & ~held
                # Slipping: on unless the speed crosses zero inside the step.
                moving = active & ~stuck & (direction * w1 > 0.0)
                stopping = active & ~stuck & ~moving
                done = held | moving
                u = np.where(done, u1, u)
                w = np.where(done, w1, w)
                remaining = np.where(done, 0.0, remaining)
                bound = np.where(drive1 > 0, static, -static)
                frac_release = np.clip((bound - drive0) / np.where(drive1 != drive0, drive1 - drive0, 1.0), 0.0, 1.0)
                w0d, w1d = direction * w, direction * w1
                frac_stop = np.where(w0d > 0.0, w0d / np.where(w0d != w1d, w0d - w1d, 1.0), 1.0)
                frac = np.where(releasing, frac_release, np.where(stopping, frac_stop, 0.0))
                part = frac * remaining
                u2, w2 = rk4(u, w, stuck, direction, part)
                change = releasing | stopping
                u = np.where(change, u2, u)
                w = np.where(stopping, 0.0, np.where(change, w2, w))
                remaining = np.where(change, remaining - part, remaining)
                drive = k * u + c * (omega - w)
                now_stuck = stopping & (np.abs(drive) <= static)
                direction = np.where(releasing | (stopping & ~now_stuck), np.where(drive > 0, 1.0, -1.0), direction)
                stuck = np.where(releasing, False, np.where(stopping, now_stuck, stuck))
        stuck_count += np.abs(w) < RPM
    return stuck_count.mean() / samples


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--strings", type=int, default=65536)
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--dt-s", type=float, default=0.01)
    parser.add_argument("--reps", type=int, default=3)
    args = parser.parse_args()
    walls, share = [], None
    for _ in range(args.reps):
        t = time.perf_counter()
        share = simulate(args.strings, args.seconds, args.dt_s)
        walls.append(time.perf_counter() - t)
    wall = statistics.median(walls)
    print(f"numpy twin: {args.strings} strings x {args.seconds} s in {wall:.3f} s "
          f"(median of {args.reps}): {args.strings * args.seconds / wall:.3e} string-s/s; "
          f"mean stuck share {share:.4f}")


if __name__ == "__main__":
    main()
