"""Which structure do simulated records show? The tables of docs/coupled.md.

Makes bit records of the coupled bit (``bitrock coupled``) and of each torsional law on the
paper's string (``bitrock simulate``), 40 s at 50 Hz, adds white noise (1 rpm to the bit speed,
0.3 kN·m to the torque on bit, 3 kN to the weight on bit; numpy's generator seeded by the row),
and gives each to ``bitrock coupled --select``: the true structure's probability, the
structure and the family called, and the choice's wall time, as a Markdown table. With
``--surface``, the same strings' surface records instead (top-drive speed, surface torque with
0.2 kN·m of white noise, weight on bit; 60 s at 10 Hz), given to ``--select --from-surface``.

    target/python-venv/bin/python benches/coupled_choice.py [--bitrock target/release/bitrock] [--surface]
"""

import argparse
import csv
import json
import os
import subprocess
import tempfile
import time

import numpy as np

# (structure, top-drive speed rpm, weight on bit kN for RGD, a law's weight fluctuation kN)
ROWS = [
    ("RGD", 45, 150, None),
    ("RGD", 60, 160, None),
    ("RGD", 120, 150, None),
    ("m1", 40, None, None),
    ("m2", 60, None, None),
    ("m3", 60, None, None),
    ("m4", 60, None, None),
    ("m1", 40, None, 5),
    ("m1", 40, None, 15),
]
# White noise per column, in the column's unit: of a bit record, and of a surface record.
NOISE = {"bit_speed_rpm": 1.0, "torque_on_bit_knm": 0.3, "torque_knm": 0.3, "wob_kn": 3.0}
SURFACE_NOISE = {"surface_torque_knm": 0.2}
SURFACE_COLUMNS = ["time_s", "top_drive_rpm", "surface_torque_knm", "wob_kn"]


def record(bitrock: str, row: int, truth: str, rpm: float, wob_kn, fluctuation_kn, folder: str, surface: bool) -> str:
    raw = os.path.join(folder, f"raw{row}.csv")
    clock = ["--duration-s", "60", "--sample-hz", "10"] if surface else ["--duration-s", "40"]
    if truth == "RGD":
        command = [bitrock, "coupled", "--omega-rpm", str(rpm), "--wob-kn", str(wob_kn)] + clock
    else:
        command = [bitrock, "simulate", "--law", truth, "--omega-rpm", str(rpm), "--settle-s", "30",
                   "--kick-rpm", "5"] + clock
        if surface:
            command += ["--channels", "all"]
        if fluctuation_kn:
            command += ["--wob-fluctuation-kn", str(fluctuation_kn)]
    subprocess.run(command + ["--out", raw], check=True, capture_output=True)
    with open(raw, newline="") as f:
        rows = list(csv.DictReader(f))
    names = SURFACE_COLUMNS if surface else list(rows[0])
    noise = SURFACE_NOISE if surface else NOISE
    rng = np.random.default_rng(row)
    noisy = os.path.join(folder, f"record{row}.csv")
    with open(noisy, "w", newline="") as f:
        out = csv.writer(f)
        out.writerow(names)
        for r in rows:
            out.writerow([float(r[n]) + (rng.normal(0.0, noise[n]) if n in noise else 0.0) for n in names])
    return noisy


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--bitrock", default="target/release/bitrock")
    parser.add_argument("--surface", action="store_true", help="surface records, chosen from with --from-surface")
    args = parser.parse_args()
    print("| record | P(true) | structure called | family called | time |")
    print("|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as folder:
        for row, (truth, rpm, wob_kn, fluctuation_kn) in enumerate(ROWS):
            path = record(args.bitrock, row, truth, rpm, wob_kn, fluctuation_kn, folder, args.surface)
            drive = ["--from-surface"] if args.surface else ["--omega-rpm", str(rpm)]
            started = time.monotonic()
            done = subprocess.run([args.bitrock, "coupled", "--select", path, "--json"] + drive,
                                  check=True, capture_output=True, text=True)
            took = time.monotonic() - started
            choice = json.loads(done.stdout)
            p = {s["structure"]: s["probability"] for s in choice["structures"]}
            name = f"{truth} {rpm} rpm" + (f", {wob_kn} kN" if wob_kn else "")
            if fluctuation_kn:
                name += f", weight wandering ±{fluctuation_kn} kN (20 s)"
            leader = max(p, key=p.get)
            called = choice["decided"] or f"undecided ({leader} leads)"
            family = {"coupled": "the coupled bit", "torsional": "a torsional law"}.get(choice["family"]["decided"],
                                                                                       "undecided")
            print(f"| {name} | {p[truth]:.2f} | {called} | {family} | {took:.0f} s |",
                  flush=True)


if __name__ == "__main__":
    main()
