"""A vectorised numpy twin of bitrock's coupled axial-torsional (RGD) string, for `bitrock bench
--coupled`'s comparison: the public bit on the default string, the batch `bench --coupled`
simulates (40-160 rpm by string index mod 97, 100-260 kN by index mod 89, steady drilling
kicked by 1 rpm), the same semi-implicit Euler step with the same contact rules and the same
ring of rock-surface cells per blade sector, every string advanced together (f64).

    python benches/coupled_numpy.py [--strings N] [--seconds S] [--dt-s DT] [--reps R]
    python benches/coupled_numpy.py --against target/release/bitrock [--pairs P] ...

Prints the wall time (median of the repetitions), string-seconds per second and the share of
the strings in each regime (compare with the `regimes` of `bitrock bench --coupled --json`:
steady, stick-slip, bit bounce, both). With `--against BITROCK`, runs `BITROCK bench --coupled
--backend gpu` on the same strings (60 s each, the same repetitions) and the twin one after the
other, `--pairs` times, and prints each pair's rates, how many times the twin's rate the GPU's
is, and the median of those ratios: the machine's load moves both, so the pairs are compared
one by one."""

import argparse
import json
import statistics
import subprocess
import sys
import time

import numpy as np

RPM = np.pi / 30.0
RING_CELLS = 240
REBASE_M = 0.01
STUCK_SPEED_RAD_S = RPM
STICK_SLIP_STUCK_SHARE = 0.01
BOUNCE_SHARE = 0.01
SAMPLE_HZ = 50.0
# `bitrock bench --coupled`'s step (s).
BENCH_DT_S = 1e-4

# The public bit (a 0.108 m, ε 60 MPa, ζ 0.6, σ 60 MPa, l 11 mm, μ 0.6, γ 1, N 4) and the default
# string (the paper's torsional string; 40 t; 1.4e5 N/m; 5e4 N·s/m), in SI.
RADIUS, ENERGY, ZETA, STRESS, FLAT, MU, GAMMA, BLADES = 0.108, 60e6, 0.6, 60e6, 11e-3, 0.6, 1.0, 4
INERTIA, OMEGA_N, XI = 383.33, 0.85, 0.25
MASS, C_A = 40_000.0, 5e4
CUT_W = RADIUS * ZETA * ENERGY
CUT_T = 0.5 * RADIUS * RADIUS * ENERGY
CONTACT_W = RADIUS * FLAT * STRESS
ARM = 0.5 * RADIUS * MU * GAMMA
SECTOR = 2.0 * np.pi / BLADES
CELL = SECTOR / RING_CELLS
K_T = INERTIA * OMEGA_N**2
C_T = 2.0 * XI * INERTIA * OMEGA_N


def batch(n):
    i = np.arange(n)
    omega = (40.0 + 120.0 * ((i % 97) / 96.0)) * RPM
    wob = 1e3 * (100.0 + 160.0 * ((i % 89) / 88.0))
    return omega, wob


def simulate(n, seconds, dt):
    omega, wob0 = batch(n)
    rows = np.arange(n)
    # Steady drilling under the weight, part of it spent on the axial damping.
    turns = omega / (2.0 * np.pi)
    dn0 = np.maximum((wob0 - CONTACT_W) / (BLADES * (CUT_W + C_A * turns)), 0.0)
    rate0 = BLADES * dn0 * turns
    wob_s = wob0 - C_A * rate0
    torque_s = CUT_T * BLADES * dn0 + ARM * (wob_s - CUT_W * BLADES * dn0)
    lag = torque_s / K_T
    w = omega + RPM
    v = rate0.copy()
    depth = np.zeros(n)
    phase = np.zeros(n)
    ahead = (np.arange(RING_CELLS) + 0.5) * CELL
    ring = -dn0[:, None] * (1.0 - ahead[None, :] / SECTOR)
    behind_old = -dn0 * (1.0 + 0.5 * CELL / SECTOR)
    runaway = 1e3 * np.maximum(omega, 1.0)

    def transport(turn, start_depth, end_depth):
        nonlocal behind_old
        start = phase
        end = start + turn
        fwd = turn > 0.0
        k = np.floor(start / CELL - 0.5) + 1.0
        crossed = 0
        while crossed < RING_CELLS:
            m = fwd & ((k + 0.5) * CELL <= end)
            if not m.any():
                break
            r = rows[m]
            at = (k[m] + 0.5) * CELL
            cut = start_depth[m] + (end_depth[m] - start_depth[m]) * (at - start[m]) / turn[m]
            c = np.mod(k[m], RING_CELLS).astype(np.int64)
            behind_old[m] = ring[r, c]
            ring[r, c] = np.maximum(ring[r, c], cut)
            k = np.where(m, k + 1.0, k)
            crossed += 1
        back = turn < 0.0
        if back.any():
            k = np.floor(start / CELL - 0.5)
            crossed = 0
            while crossed < RING_CELLS:
                m = back & ((k + 0.5) * CELL > end)
                if not m.any():
                    break
                r = rows[m]
                c = np.mod(k[m], RING_CELLS).astype(np.int64)
                ring[r, c] = behind_old[m]
                behind_old[m] = ring[r, np.mod(k[m] - 1.0, RING_CELLS).astype(np.int64)]
                k = np.where(m, k - 1.0, k)
                crossed += 1
        return np.mod(end, SECTOR)

    steps_per_sample = int(np.ceil(1.0 / SAMPLE_HZ / dt))
    dt = 1.0 / SAMPLE_HZ / steps_per_sample
    samples = int(round(seconds * SAMPLE_HZ))
    stuck_count = np.zeros(n)
    off_count = np.zeros(n)
    diverged = np.zeros(n, bool)
    for _ in range(samples):
        for _ in range(steps_per_sample):
            x = phase / CELL - 0.5
            below = np.floor(x)
            ahead_cell = np.mod(below + 1.0, RING_CELLS).astype(np.int64)
            surface = behind_old + (x - below) * (ring[rows, ahead_cell] - behind_old)
            dn = depth - surface
            on = dn >= 0.0
            d = np.where(on, BLADES * dn, 0.0)
            wc, tc = CUT_W * d, CUT_T * d
            wf = np.where(on, CONTACT_W, 0.0)
            fa = wob0 - C_A * v
            # Axial: moving down (all the contact), lifting (none), or held.
            down = (v > 0.0) | ((v == 0.0) & (~on | (fa > wc + wf)))
            lift = ~down & ((v < 0.0) | (fa < wc))
            held = ~down & ~lift
            wob = np.where(down, wc + wf, np.where(lift, wc, fa))
            v_new = np.where(held, 0.0, v + (fa - wob) / MASS * dt)
            v_new = np.where(on & (v != 0.0) & (v_new * v <= 0.0), 0.0, v_new)
            # Torsion: the friction the wear flats give is what they carry axially, the weight
            # beyond the cutting's.
            tf = ARM * (wob - wc)
            tau = K_T * lag + C_T * (omega - w)
            forward = (w > 0.0) | ((w == 0.0) & (tau > tc + tf))
            backward = ~forward & ((w < 0.0) | (tau < -tf))
            stuck = ~forward & ~backward
            torque = np.where(forward, tc + tf, np.where(backward, -tf, tau))
            w_new = np.where(stuck, 0.0, w + (tau - torque) / INERTIA * dt)
            w_new = np.where(on & (w != 0.0) & (w_new * w <= 0.0), 0.0, w_new)
            depth_new = depth + v_new * dt
            lag = lag + (omega - w_new) * dt
            phase = transport(w_new * dt, depth, depth_new)
            depth, v, w = depth_new, v_new, w_new
            far = np.abs(depth) > REBASE_M
            if far.any():
                ring[far] -= depth[far, None]
                behind_old = np.where(far, behind_old - depth, behind_old)
                depth = np.where(far, 0.0, depth)
        diverged |= ~((np.abs(w) <= runaway) & (np.abs(v) < 1e3) & (np.abs(lag) < 1e30))
        stuck_count += np.abs(w) < STUCK_SPEED_RAD_S
        off_count += dn < 0.0
    sticks = stuck_count / samples >= STICK_SLIP_STUCK_SHARE
    bounces = off_count / samples >= BOUNCE_SHARE
    regimes = [
        np.mean(~diverged & ~sticks & ~bounces),
        np.mean(~diverged & sticks & ~bounces),
        np.mean(~diverged & ~sticks & bounces),
        np.mean(diverged | (sticks & bounces)),
    ]
    return samples * steps_per_sample * dt, regimes


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--strings", type=int, default=256)
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--dt-s", type=float, default=BENCH_DT_S)
    parser.add_argument("--reps", type=int, default=1)
    parser.add_argument("--against", metavar="BITROCK",
                        help="a bitrock binary whose `bench --coupled --backend gpu` to compare with")
    parser.add_argument("--pairs", type=int, default=3,
                        help="with --against: GPU and twin runs, one after the other, this many times")
    args = parser.parse_args()
    if args.reps < 1 or args.pairs < 1 or args.strings < 1:
        parser.error("--strings, --reps and --pairs must be at least 1")
    if not (args.dt_s > 0.0 and args.seconds >= 1.0 / SAMPLE_HZ):
        parser.error(f"--dt-s must be above 0 and --seconds at least a sample, {1.0 / SAMPLE_HZ:g} s")
    if args.against is None and args.pairs != parser.get_default("pairs"):
        parser.error("--pairs needs --against")
    if args.against is not None and args.dt_s != BENCH_DT_S:
        parser.error(f"--against compares at bitrock bench's step, --dt-s {BENCH_DT_S:g}")
    if args.against is None:
        twin(args)
        return
    ratios = []
    for pair in range(1, args.pairs + 1):
        gpu = bitrock_rate(args)
        numpy_rate = twin(args)
        ratios.append(gpu / numpy_rate)
        print(f"pair {pair}: gpu {gpu:.3e} string-s/s, numpy {numpy_rate:.3e}: "
              f"{ratios[-1]:.1f} times")
    print(f"gpu against the numpy twin, {args.strings} strings: {statistics.median(ratios):.1f} "
          f"times (the median of {args.pairs} pairs: {', '.join(f'{r:.1f}' for r in ratios)})")


def twin(args):
    """Runs the twin `--reps` times and prints its line; returns its string-seconds per second."""
    walls, regimes, seconds = [], None, None
    with np.errstate(all="ignore"):
        for _ in range(args.reps):
            t = time.perf_counter()
            seconds, regimes = simulate(args.strings, args.seconds, args.dt_s)
            walls.append(time.perf_counter() - t)
    wall = statistics.median(walls)
    steady, stick_slip, bounce, both = regimes
    rate = args.strings * seconds / wall
    print(f"numpy twin: {args.strings} strings x {seconds:g} s in {wall:.3f} s "
          f"(median of {args.reps}): {rate:.3e} string-s/s; "
          f"steady {steady:.2f}, stick-slip {stick_slip:.2f}, bounce {bounce:.2f}, both {both:.2f}",
          flush=True)
    return rate


def fail(message, status=2):
    """Says what is wrong and exits with `status` (2, as bitrock does on bad input)."""
    print(f"coupled_numpy.py: error: {message}", file=sys.stderr)
    sys.exit(status)


def bitrock_rate(args):
    """Runs `bitrock bench --coupled --backend gpu` on the twin's strings and step; prints its
    line and returns its string-seconds per second."""
    command = [args.against, "bench", "--coupled", "--backend", "gpu", "--strings-n",
               str(args.strings), "--reps", str(args.reps), "--json"]
    try:
        run = subprocess.run(command, capture_output=True, text=True)
    except OSError as error:
        fail(f"--against {args.against}: {error.strerror}")
    if run.returncode != 0:
        fail(f"{' '.join(command)} failed ({run.returncode}): {run.stderr.strip()}", run.returncode)
    try:
        row = json.loads(run.stdout)[0]
        backend, strings, rate = row["backend"], row["strings"], row["string_seconds_per_s"]
        wall, seconds = row["wall_s"]["median"], row["seconds_per_string"]
    except (ValueError, LookupError, TypeError):
        fail(f"--against {args.against}: `bench --coupled --json` printed no coupled bench row")
    print(f"{backend}: {strings} strings x {seconds:g} s in {wall:.3f} s (median of {args.reps}): "
          f"{rate:.3e} string-s/s", flush=True)
    if not backend.startswith("gpu"):
        fail(f"--against {args.against} ran no GPU: {backend}")
    return rate


if __name__ == "__main__":
    main()
