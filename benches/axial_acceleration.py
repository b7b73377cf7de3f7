"""Can a drilling record's axial acceleration stand in for the bit's axial speed?

The coupled bit's calibration sorts a record's samples by whether the bit moves down (its wear
flats fully in contact) or is held or lifting; vibration tools log the bit's axial
acceleration, not its speed. This script makes a stick-slip record with ``bitrock coupled``
(its ``axial_acceleration_m_s2``: each sample the mean over its period, as a filtered
accelerometer reads), adds white noise and a constant bias to the acceleration, and estimates
the axial speed from it: the acceleration summed over the samples, less its centred moving
mean over ``--window-s``, plus the rate of penetration's (on average the bit moves down as
fast as it cuts; a centred mean takes a constant bias's linear drift away exactly). It prints
the estimate's root-mean-square error against the record's own axial speed and how often it
sorts the samples as the speed does (moving down above ``--threshold-m-h``).

    target/python-venv/bin/python benches/axial_acceleration.py [--bitrock target/release/bitrock]
"""

import argparse
import os
import subprocess
import sys
import tempfile

import numpy as np
import pandas as pd


def centred_mean(x: np.ndarray, half: int) -> np.ndarray:
    """The mean of x over the samples within `half` of each (fewer at the ends)."""
    c = np.concatenate(([0.0], np.cumsum(x)))
    i = np.arange(len(x))
    lo, hi = np.maximum(0, i - half), np.minimum(len(x), i + half + 1)
    return (c[hi] - c[lo]) / (hi - lo)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--bitrock", default="target/release/bitrock")
    parser.add_argument("--omega-rpm", type=float, default=45.0)
    parser.add_argument("--wob-kn", type=float, default=150.0)
    parser.add_argument("--duration-s", type=float, default=120.0)
    parser.add_argument("--window-s", type=float, default=30.0)
    parser.add_argument("--threshold-m-h", type=float, default=18.0)
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as scratch:
        path = os.path.join(scratch, "rgd.csv")
        done = subprocess.run(
            [args.bitrock, "coupled", "--omega-rpm", str(args.omega_rpm), "--wob-kn", str(args.wob_kn),
             "--settle-s", "10", "--duration-s", str(args.duration_s), "--out", path],
            capture_output=True, text=True)
        if done.returncode != 0:
            sys.exit(done.stderr)
        record = pd.read_csv(path)
    period = float(record.time_s[1] - record.time_s[0])
    speed = record.axial_speed_m_h.to_numpy() / 3600.0
    rop = record.rop_m_h.to_numpy() / 3600.0
    moving = speed > 0.0
    print(f"{args.duration_s:g} s at {args.omega_rpm:g} rpm under {args.wob_kn:g} kN: the bit moves down in "
          f"{moving.mean():.0%} of the samples; window {args.window_s:g} s, threshold {args.threshold_m_h:g} m/h")
    half = int(round(args.window_s / period)) // 2
    rng = np.random.default_rng(args.seed)
    for noise, bias in [(0.0, 0.0), (0.01, 0.0), (0.01, 0.01), (0.05, 0.0), (0.2, 0.0)]:
        a = record.axial_acceleration_m_s2.to_numpy() + bias + rng.normal(0.0, noise, len(record)) * (noise > 0)
        summed = np.cumsum(a * period)
        estimate = summed - centred_mean(summed, half) + centred_mean(rop, half)
        rms_m_h = 3600.0 * np.sqrt(np.mean((estimate - speed) ** 2))
        agree = np.mean((estimate > args.threshold_m_h / 3600.0) == moving)
        print(f"  noise {noise:g} m/s², bias {bias:g} m/s²: axial speed within {rms_m_h:.1f} m/h (rms), "
              f"samples sorted as the speed sorts them: {agree:.0%}")


if __name__ == "__main__":
    main()
