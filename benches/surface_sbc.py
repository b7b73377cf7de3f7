"""Simulation-based calibration of ``bitrock surface``: does what it infers from the surface
cover what the bit did?

For each replicate, m2's torques and decay rate are drawn from uniform ranges (tsb 10-16
kN·m, tcb 4-8 kN·m, g 0.2-0.5 s/rad), a record is made by ``bitrock simulate --channels all
--initial rest`` (the surface channels the inference reads, the bit's kept as the truth; the
string started from rest as the inference starts its strings, so that a steady record carries
no transient the model cannot know), and ``bitrock surface
--laws m2`` infers from its surface channels alone. Per replicate it scores:

* each parameter the run calls identified: whether its central 90 % interval (q05-q95) holds
  the drawn value (the unidentified ones are counted apart: their interval is the box's);
* the bit's speed: the share of samples at which the 90 % band of the posterior predictive
  (``--bit-out``) holds the record's true bit speed;
* the stuck share: the record's own (samples whose bit speed is below 1 rpm, the library's
  threshold) against the posterior's median, within ``--stuck-tolerance`` (0.05), and inside
  its 90 % range, counted over the records that stick-slip (stuck at least 1 % of the time,
  the library's rule); steady ones are counted apart.

It prints the rates over the replicates and, with ``--out``, writes every replicate's figures as
JSON (after each replicate, so that a long run stopped part-way keeps what it did). Only the standard library and the ``bitrock`` binary are needed:

    python3 benches/surface_sbc.py --bitrock target/release/bitrock [--replicates 50] \\
        [--sample-hz 1] [--particles 300] [--max-populations 6] [--pilot 300] [--out sbc.json]

With ``--string`` each replicate's string is drawn too (natural frequency 0.6-1.4 rad/s,
damping ratio 0.1-0.4, the paper's inertia) and inferred with the law within wider bounds
(``--omega-n-rad-s 0.5:1.5 --damping-ratio 0.05:0.5``): the string's two are scored as the
law's parameters are.

With ``--twin`` the records come from an independent integrator instead of bitrock's: scipy's
LSODA with its own stick handling (an event at zero bit speed, the stuck bit held until the
string's torque reaches the static torque), the twin of the Python package's tests, on the same
string from rest, with white noise from numpy. It needs the package's test extras (numpy, scipy,
pandas, pytest), so run it with the tests' environment's Python:

    target/python-venv/bin/python benches/surface_sbc.py --twin [--replicates 50]
"""

import argparse
import csv
import json
import os
import random
import statistics
import subprocess
import sys
import tempfile

RANGES = {"tsb": (10.0, 16.0), "tcb": (4.0, 8.0), "g": (0.2, 0.5)}
# With --string: the string's natural frequency (rad/s) and damping ratio drawn, and the
# bounds the inference is given.
STRING_RANGES = {"omega_n_rad_s": (0.6, 1.4), "damping_ratio": (0.1, 0.4)}
STRING_BOUNDS = {"omega_n_rad_s": "0.5:1.5", "damping_ratio": "0.05:0.5"}
TORQUES = {"tsb", "tcb"}
STUCK_RPM = 1.0
# Drive held before recording starts, s.
SETTLE_S = 60.0
STICK_SLIP_SHARE = 0.01
# The surface run warns of a final ε this many times its noise floor or more.
UNCONVERGED = 4.0


def run(cmd):
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode != 0:
        sys.exit(f"{' '.join(cmd)} failed ({done.returncode}):\n{done.stderr}")
    return done.stdout


def twin_record(args, truth, index, path):
    """m2 with `truth` on the paper's 1-DOF string from rest (no lag, the bit stuck), settled
    SETTLE_S then recorded, by the tests' LSODA twin: the columns `bitrock simulate --channels
    all` writes that the scoring reads (the surface channels and the bit's speed)."""
    tests = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "bindings", "python", "tests")
    if tests not in sys.path:
        sys.path.insert(0, tests)
    import numpy as np
    from test_strings import RPM, integrate, one_dof

    chain = one_dof()
    omega = args.omega_rpm * RPM
    p_nm = [1000.0 * truth["tsb"], 1000.0 * truth["tcb"], truth["g"]]
    rest = (np.zeros(2), True, 1.0)
    surface = []
    done = integrate(chain, "m2", p_nm, omega, 1.0, rest, SETTLE_S, args.duration_s,
                     sample_hz=args.sample_hz, surface=surface)
    if done is None:
        sys.exit(f"replicate {index}: the twin's bit ran away with {truth}")
    speeds, _ = done
    noise = np.random.default_rng(index).normal(0.0, 1000.0 * args.noise_knm, len(surface))
    with open(path, "w", newline="") as f:
        out = csv.writer(f)
        out.writerow(["time_s", "top_drive_rpm", "surface_torque_knm", "wob_kn", "bit_speed_rpm"])
        for i, (torque, speed) in enumerate(zip(np.array(surface) + noise, speeds)):
            out.writerow([i / args.sample_hz, args.omega_rpm, torque / 1000.0, 244.2, speed / RPM])


def flag(name):
    return "--" + name.replace("_", "-")


def replicate(args, index, scratch):
    rng = random.Random(index)
    truth = {name: rng.uniform(*bounds) for name, bounds in RANGES.items()}
    string = {name: rng.uniform(*bounds) for name, bounds in STRING_RANGES.items()} if args.string else {}
    if string and args.twin:
        sys.exit("--string draws bitrock's strings; the twin's string is the paper's")
    record = os.path.join(scratch, f"r{index}.csv")
    bit_out = os.path.join(scratch, f"r{index}-bit.csv")
    if args.twin:
        twin_record(args, truth, index, record)
    else:
        params = ",".join(f"{truth[n]:.6g}" for n in ("tsb", "tcb", "g"))
        run([args.bitrock, "simulate", "--law", "m2", "--params", params,
             "--omega-rpm", str(args.omega_rpm), "--duration-s", str(args.duration_s),
             "--settle-s", str(SETTLE_S), "--initial", "rest", "--sample-hz", str(args.sample_hz),
             "--noise-torque-knm", str(args.noise_knm), "--channels", "all",
             "--seed", str(index), "--out", record]
            + [a for name, value in string.items() for a in (flag(name), f"{value:.6g}")])
    bounds = [a for name in string for a in (flag(name), STRING_BOUNDS[name])]
    result = json.loads(run([args.bitrock, "surface", record, "--laws", "m2",
                             "--particles", str(args.particles),
                             "--max-populations", str(args.max_populations),
                             "--pilot", str(args.pilot), "--seed", str(index),
                             "--no-advice", "--json", "--bit-out", bit_out] + bounds
                            + (["--semi-automatic"] if args.semi_automatic else [])))
    with open(record, newline="") as f:
        true_rpm = [float(row["bit_speed_rpm"]) for row in csv.DictReader(f)]
    with open(bit_out, newline="") as f:
        band = [(float(r["bit_speed_rpm_p05"]), float(r["bit_speed_rpm_p95"])) for r in csv.DictReader(f)]
    if len(band) != len(true_rpm):
        sys.exit(f"replicate {index}: {len(band)} predicted samples for {len(true_rpm)} recorded")
    law = next(l for l in result["laws"] if l["law"] == "m2")
    covered = {}
    for p in law["params"]:
        value = truth[p["name"]] * (1000.0 if p["name"] in TORQUES else 1.0)
        covered[p["name"]] = {
            "identified": p["identified"],
            "covered": p["q05"] <= value <= p["q95"],
            "width": (p["q95"] - p["q05"]) / value,
        }
    for name, value in string.items():
        p = result["string"][name]
        covered[name] = {"identified": p["identified"], "covered": p["q05"] <= value <= p["q95"],
                         "width": (p["q95"] - p["q05"]) / value}
    truth.update(string)
    stuck_true = sum(abs(w) < STUCK_RPM for w in true_rpm) / len(true_rpm)
    low, median, high = result["at_the_bit"]["stuck_share"]
    return {
        "index": index,
        "truth": truth,
        "params": covered,
        "band_coverage": sum(lo <= w <= hi for (lo, hi), w in zip(band, true_rpm)) / len(band),
        "stuck_true": stuck_true,
        "stuck_predicted": [low, median, high],
        "stuck_within_tolerance": abs(median - stuck_true) <= args.stuck_tolerance,
        "stuck_inside_90": low <= stuck_true <= high,
        "epsilon_over_floor": (result["final_epsilon"] / result["noise_floor"]
                               if result["final_epsilon"] is not None and result["noise_floor"] > 0 else None),
        "seconds": result["seconds"],
    }


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--bitrock", default="target/release/bitrock")
    parser.add_argument("--replicates", type=int, default=50)
    parser.add_argument("--sample-hz", type=float, default=1.0)
    parser.add_argument("--duration-s", type=float, default=300.0)
    parser.add_argument("--omega-rpm", type=float, default=60.0)
    parser.add_argument("--noise-knm", type=float, default=0.2)
    parser.add_argument("--particles", type=int, default=300)
    parser.add_argument("--max-populations", type=int, default=6)
    parser.add_argument("--pilot", type=int, default=300)
    parser.add_argument("--stuck-tolerance", type=float, default=0.05)
    parser.add_argument("--string", action="store_true",
                        help="draw each record's string too and infer it with the law")
    parser.add_argument("--twin", action="store_true",
                        help="records from the tests' LSODA twin instead of bitrock simulate")
    parser.add_argument("--semi-automatic", action="store_true",
                        help="run the inference with --semi-automatic (regression-projected summaries)")
    parser.add_argument("--out")
    args = parser.parse_args()
    if args.replicates < 1:
        parser.error("--replicates must be at least 1")
    rows = []
    with tempfile.TemporaryDirectory() as scratch:
        for index in range(1, args.replicates + 1):
            rows.append(replicate(args, index, scratch))
            if args.out:
                with open(args.out, "w") as f:
                    json.dump({"settings": vars(args), "replicates": rows}, f, indent=1)
            r = rows[-1]
            print(f"replicate {index}: stuck {r['stuck_true']:.3f} -> {r['stuck_predicted'][1]:.3f}, "
                  f"band {r['band_coverage']:.3f}, "
                  + ", ".join(f"{n} {'in' if c['covered'] else 'OUT'}{'' if c['identified'] else ' (box)'}"
                              for n, c in r["params"].items()), file=sys.stderr)
    n = len(rows)
    print(f"{n} replicates ({'scipy LSODA twin' if args.twin else 'bitrock simulate'}) of m2 at {args.omega_rpm:g} rpm, {args.duration_s:g} s at {args.sample_hz:g} Hz, "
          + ("the string drawn and inferred, " if args.string else "")
          + f"{args.noise_knm:g} kN·m of noise; surface --laws m2 --particles {args.particles} "
          f"--max-populations {args.max_populations} --pilot {args.pilot}"
          + (" --semi-automatic" if args.semi_automatic else ""))
    for name in list(RANGES) + (list(STRING_RANGES) if args.string else []):
        identified = [r["params"][name]["covered"] for r in rows if r["params"][name]["identified"]]
        boxed = [r["params"][name]["covered"] for r in rows if not r["params"][name]["identified"]]
        line = f"  {name}: identified in {len(identified)} of {n}"
        if identified:
            line += f", its 90 % interval holds the truth in {sum(identified)} ({sum(identified) / len(identified):.0%})"
        if boxed:
            line += f"; unidentified in {len(boxed)} (the box's interval holds it in {sum(boxed)})"
        line += f"; interval width over the truth, median {statistics.median(r['params'][name]['width'] for r in rows):.2f}"
        print(line)
    bands = [r["band_coverage"] for r in rows]
    print(f"  bit speed inside its 90 % band: {statistics.mean(bands):.1%} of samples "
          f"(median replicate {statistics.median(bands):.1%}, lowest {min(bands):.1%})")
    slipping = [r for r in rows if r["stuck_true"] >= STICK_SLIP_SHARE]
    steady = [r for r in rows if r["stuck_true"] < STICK_SLIP_SHARE]
    print(f"  stick-slipping records: {len(slipping)} of {n}; their stuck share within "
          f"{args.stuck_tolerance:g} of the truth in {sum(r['stuck_within_tolerance'] for r in slipping)}, "
          f"inside its 90 % range in {sum(r['stuck_inside_90'] for r in slipping)}")
    if steady:
        print(f"  steady records: {len(steady)}, predicted steady (median stuck share below 0.01) in "
              f"{sum(r['stuck_predicted'][1] < STICK_SLIP_SHARE for r in steady)}")
    ratios = [r["epsilon_over_floor"] for r in rows if r["epsilon_over_floor"] is not None]
    warned = [r for r in rows if r["epsilon_over_floor"] is not None and r["epsilon_over_floor"] >= UNCONVERGED]
    print(f"  final ε over the noise floor: median {statistics.median(ratios):.1f}" if ratios else
          "  final ε over the noise floor: none measured")
    print(f"  warned of as unconverged (ε at {UNCONVERGED:g} times the floor or more): {len(warned)}; "
          f"the others' stuck share within {args.stuck_tolerance:g} in "
          f"{sum(r['stuck_within_tolerance'] for r in slipping if r not in warned)} of "
          f"{sum(1 for r in slipping if r not in warned)} stick-slipping")
    print(f"  {statistics.median(r['seconds'] for r in rows):.1f} s per inference (median)")


if __name__ == "__main__":
    main()
