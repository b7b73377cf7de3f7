"""Compute the model evidence of a bitrock ``evidence`` directory by nested sampling (dynesty).

An independent reference for bitrock's tempered-SMC evidence, and a comparison of cost: the
same record, the same likelihood and the same prior boxes, integrated by dynesty's static
nested sampler instead. For each law it prints bitrock's ln Z and Monte-Carlo error beside
dynesty's, their difference in joint standard errors, and what each scored to get there.

The evidence directory is one written by

    bitrock evidence RECORD.csv --noise iid --out DIR [--backend cpu] [--seed S]

(the i.i.d. model of the residuals: the only one this script implements). From it this
script reads

* ``DIR/record.json``: the calibration samples, exactly as bitrock used them (bit speed w in
  rad/s, torque y in N·m, weight on bit in N where the record has it);
* ``DIR/evidence.json``: each law's uniform prior box (``lower``/``upper`` in the law's
  ``units``), its ln Z (a density over the torques in ``ln_z_torque_unit``, N·m), its error
  and candidates scored, the least-squares fits (``fits``: the check below) and ``w_ref_kn``
  (set where the torque was scaled by WOB / W_ref: then each torque is r·T(w), r = WOB / W_ref).

The likelihood is bitrock's i.i.d. Gaussian one with σ integrated out under Jeffreys' prior:

    ln p(y | θ) = ln Γ(n/2) − ln 2 − (n/2)·ln(π·S(θ)),   S(θ) = Σ (y_i − r_i·T(w_i; θ))²  [N·m²]

with the law's torque T from ``bitrock.torque`` (the library's own, law files included). Before
sampling, S at each law's least-squares estimate is checked against the ρ = S / Σy² that
bitrock reported for it (relative 1e-9): the data, the scaling and the torque are bitrock's.

Where a law's prior is its box cut to the curves within a torque (``prior_curve``: |T(w)| at
most ``limit`` at ``speeds`` speeds from rest to the fastest, at r = 1), the likelihood is 0 outside the
cut, so that dynesty integrates L over the box's part inside it, and ln Z is that less ln of the
part's share of the box, estimated here by this script's own Monte Carlo (``--share-draws``).

Needs the Python package with dynesty (both installed by ``./scripts/test.sh`` into
``target/python-venv``: dynesty is among the package's test extras), or:

    target/python-venv/bin/pip install "dynesty==2.1.*"
    target/python-venv/bin/python benches/evidence_nested.py DIR [--nlive 500] \\
        [--dlogz 0.05] [--sample rwalk] [--seed 1] [--laws m1,m3] [--share-draws 200000] \\
        [--out result.json]
"""

import argparse
import json
import math
import pathlib
import sys
import time

import numpy as np

import bitrock

try:
    import dynesty
except ImportError:
    sys.exit("dynesty is not installed: pip install 'dynesty==2.1.*'")

# The torque unit names bitrock.torque takes, by the unit a law's parameters are given in.
TORQUE_UNITS = {"kN·m": ("knm", 1000.0), "N·m": ("nm", 1.0)}


def law_torque_unit(units: list[str]) -> tuple[str, float]:
    """bitrock.torque's unit for a law whose parameters are in ``units``, and N·m per it."""
    for unit in units:
        for name, (argument, newton_metres) in TORQUE_UNITS.items():
            if unit == name or unit.startswith(name + "·"):
                return argument, newton_metres
    return "nm", 1.0


class Likelihood:
    """bitrock's i.i.d. likelihood of one law on the calibration samples; 0 outside a prior's cut
    (``cut``: the limit in N·m and the speeds it holds at) where the law's prior has one."""

    def __init__(self, law: str, units: list[str], speed: np.ndarray, torque_nm: np.ndarray, r: np.ndarray,
                 cut: tuple[float, np.ndarray] | None = None):
        self.law = law
        self.unit, self.newton_metres = law_torque_unit(units)
        self.speed, self.y, self.r = speed, torque_nm, r
        self.n = len(speed)
        self.sum_y2 = float(np.sum(torque_nm * torque_nm))
        self.constant = math.lgamma(self.n / 2) - math.log(2.0) - self.n / 2 * math.log(math.pi)
        self.cut = cut
        self.calls = 0

    def inside_cut(self, params: np.ndarray) -> bool:
        if self.cut is None:
            return True
        limit_nm, speeds = self.cut
        t = bitrock.torque(self.law, speeds, list(params), torque_unit=self.unit) * self.newton_metres
        return bool(np.all(np.abs(t) <= limit_nm))

    def sum_of_squares(self, params: np.ndarray) -> float:
        t = bitrock.torque(self.law, self.speed, list(params), torque_unit=self.unit) * self.newton_metres
        e = self.y - self.r * t
        return float(np.dot(e, e))

    def __call__(self, params: np.ndarray) -> float:
        self.calls += 1
        if not self.inside_cut(params):
            return -1e300
        s = self.sum_of_squares(params)
        if not math.isfinite(s) or s <= 0.0:
            return -1e300
        return self.constant - self.n / 2 * math.log(s)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("dir", type=pathlib.Path, help="an evidence directory (bitrock evidence --noise iid --out DIR)")
    parser.add_argument("--nlive", type=int, default=500, help="live points (default 500)")
    parser.add_argument("--dlogz", type=float, default=0.05, help="dynesty's stopping criterion (default 0.05 nats)")
    parser.add_argument("--sample", default="rwalk", help="dynesty's way of sampling within its bounds (default rwalk; rslice, slice, unif)")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--laws", help="comma-separated laws (default: every law of the evidence)")
    parser.add_argument("--share-draws", type=int, default=200_000,
                        help="draws of a cut prior's box that estimate the share it keeps (default 200,000)")
    parser.add_argument("--out", type=pathlib.Path, help="write the results as JSON here")
    args = parser.parse_args()

    evidence = json.loads((args.dir / "evidence.json").read_text())
    record = json.loads((args.dir / "record.json").read_text())
    if evidence.get("noise_model") != "iid":
        sys.exit(f"{args.dir}: the evidence's model of the residuals is {evidence.get('noise_model')!r}; "
                 "this script implements 'iid' (bitrock evidence --noise iid)")
    if evidence.get("ln_z_torque_unit") != "N·m":
        sys.exit(f"{args.dir}: ln Z is a density over torques in {evidence.get('ln_z_torque_unit')!r}, not N·m")
    calibration = record["calibration"]
    speed = np.asarray(calibration["speed_rad_s"], dtype=float)
    torque_nm = np.asarray(calibration["torque_nm"], dtype=float)
    w_ref_kn = evidence.get("w_ref_kn")
    if w_ref_kn is None:
        r = np.ones_like(speed)
    else:
        r = np.asarray(calibration["wob_n"], dtype=float) / (w_ref_kn * 1000.0)
    fits = {f["law"]: f for f in evidence["fits"]}
    wanted = None if args.laws is None else args.laws.split(",")

    results = []
    for law in evidence["laws"]:
        name = law["law"]
        if wanted is not None and name not in wanted:
            continue
        lower, upper = np.asarray(law["lower"], dtype=float), np.asarray(law["upper"], dtype=float)
        cut = None
        if law.get("prior_curve"):
            curve = law["prior_curve"]
            limit_nm = curve["limit"] * TORQUE_UNITS[evidence["torque_unit"]][1]
            cut = (limit_nm, np.linspace(0.0, curve["speeds_rad_s"][1], curve["speeds"]))
        likelihood = Likelihood(name, law["units"], speed, torque_nm, r, cut)
        fit = fits[name]
        rho = likelihood.sum_of_squares(np.asarray(fit["params"])) / likelihood.sum_y2
        if abs(rho - fit["rho"]) > 1e-9 * fit["rho"]:
            sys.exit(f"{name}: ρ at the least-squares estimate is {rho!r} here and {fit['rho']!r} in bitrock's fit: "
                     "not the same data, scaling or torque")
        likelihood.calls = 0
        width = upper - lower

        def prior_transform(u: np.ndarray, lower=lower, width=width) -> np.ndarray:
            return lower + u * width

        sampler = dynesty.NestedSampler(
            likelihood,
            prior_transform,
            len(lower),
            nlive=args.nlive,
            bound="multi",
            sample=args.sample,
            rstate=np.random.default_rng(args.seed),
        )
        started = time.perf_counter()
        sampler.run_nested(dlogz=args.dlogz, print_progress=False)
        seconds = time.perf_counter() - started
        run = sampler.results
        ln_z, ln_z_error = float(run.logz[-1]), float(run.logzerr[-1])
        share = None
        if cut is not None:
            # The box's share inside the cut, by this script's own draws: ln Z over the cut prior
            # is ln ∫ L over the box (what dynesty integrated, L being 0 outside) less its ln.
            draws = np.random.default_rng(args.seed).uniform(lower, upper, size=(args.share_draws, len(lower)))
            inside = sum(likelihood.inside_cut(p) for p in draws)
            if inside == 0:
                sys.exit(f"{name}: none of {args.share_draws} draws of its box lies inside its prior's cut")
            share = inside / args.share_draws
            ln_z -= math.log(share)
            ln_z_error = math.hypot(ln_z_error, math.sqrt((1.0 - share) / inside))
        joint = math.hypot(ln_z_error, law["ln_z_error"])
        results.append({
            "law": name,
            "bitrock_ln_z": law["ln_z"],
            "bitrock_ln_z_error": law["ln_z_error"],
            "bitrock_candidates": law["candidates_scored"],
            "dynesty_ln_z": ln_z,
            "dynesty_ln_z_error": ln_z_error,
            "dynesty_likelihood_calls": likelihood.calls,
            "prior_share": share,
            "dynesty_seconds": seconds,
            "difference": law["ln_z"] - ln_z,
            "difference_in_joint_errors": (law["ln_z"] - ln_z) / joint if joint > 0 else math.inf,
        })
        row = results[-1]
        print(f"{name}: bitrock {row['bitrock_ln_z']:.2f} ± {row['bitrock_ln_z_error']:.2f} "
              f"({row['bitrock_candidates']:,} candidates); dynesty {ln_z:.2f} ± {ln_z_error:.2f} "
              f"({likelihood.calls:,} likelihood calls, {seconds:.0f} s); "
              f"difference {row['difference']:+.2f} = {row['difference_in_joint_errors']:+.1f} joint errors",
              flush=True)

    summary = {
        "dir": str(args.dir),
        "nlive": args.nlive,
        "dlogz": args.dlogz,
        "seed": args.seed,
        "sample": args.sample,
        "dynesty": dynesty.__version__,
        "bitrock_seconds": evidence.get("seconds"),
        "bitrock_backend": evidence.get("backend"),
        "laws": results,
    }
    if args.out is not None:
        args.out.write_text(json.dumps(summary, indent=2) + "\n")


if __name__ == "__main__":
    main()
