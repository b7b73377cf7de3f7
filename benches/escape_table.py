"""The escape table of docs/stick-slip.md in an integrator bitrock did not write: m2 at the
paper's estimate on the paper's 1-DOF string, settled into its cycle at 60 rpm and 244 kN (from
steady rotation kicked by a tenth, 60 s), then the top drive or the weight changed: the share of
the second minute with the bit below 1 rpm. The integrator is scipy's LSODA with its own stick
events (`integrate` in bindings/python/tests/test_strings.py).

    python benches/escape_table.py
"""

import pathlib
import sys

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "bindings" / "python" / "tests"))
import test_strings as reference  # noqa: E402


def main():
    chain, p = reference.one_dof(), np.array([13e3, 6.5e3, 0.3])
    omega = 60 * reference.RPM
    steady = reference.torque_law("m2")(p, omega) / chain[1][0]
    _, cycle = reference.integrate(chain, "m2", p, omega, 1.0, (np.array([steady, 1.1 * omega]), False, 1.0), 60.0, 20.0)
    print("then                stuck (below 1 rpm), second minute")
    for rpm, wob_kn in [(85, 244.2), (120, 244.2), (150, 244.2), (60, 122.1), (60, 73.26)]:
        speeds, _ = reference.integrate(chain, "m2", p, rpm * reference.RPM, wob_kn / 244.2, cycle, 60.0, 60.0)
        print(f"{rpm:>4} rpm, {wob_kn:>5.1f} kN   {100 * reference.stuck_share(speeds):.1f} %")


if __name__ == "__main__":
    main()
