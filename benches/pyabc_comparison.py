"""Run pyABC's default ABC-SMC on the problem of a bitrock ``abc`` run.

Compares bitrock's SMC model selection with pyABC 0.13's ``ABCSMC`` on the
same data, priors, model prior, distance and final tolerance, so that their
simulation counts, tolerances, effective sample sizes and model probabilities
can be set side by side.

The run directory is one written by

    bitrock abc RECORD.csv --out DIR --particles N --eps-min EPS \\
        --backend cpu --seed S --quiet --json

From it this script reads

* ``DIR/data.csv``: the rows with ``set == "calibration"`` (bit speed w in
  rad/s and torque y, in the torque unit bitrock used for the record);
* ``DIR/run.json``: ``priors`` (per law: parameter names, uniform box
  ``lower``/``upper`` in the same units as the data, prior model probability
  ``weight``; a box with ``lower == upper`` is a fixed parameter) and
  ``config.sampler`` (``particles`` = N, ``eps_min`` = final tolerance; a
  nested ``config.sampler.base`` is also accepted).

The problem is deterministic: a law's "simulation" is its torque T(w) at the
observed speeds, and the distance is rho = sum((y - T)^2) / sum(y^2).
pyABC is run with ``population_size=N``, a ``SingleCoreSampler``, the model
prior as an ``RV("rv_discrete")`` over model indices and otherwise its
defaults (``MedianEpsilon`` started from a calibration sample,
``MultivariateNormalTransition``, ``ModelPerturbationKernel``), with
``minimum_epsilon=eps_min`` and ``max_nr_populations=40``.

Simulation count: before population 0, pyABC draws a calibration sample of N
prior simulations (all accepted) to set the first epsilon. History records it
as a population with ``t = History.PRE_TIME = -1``. ``total_simulations``
in the output is ``History.total_nr_simulations``, the sum of ``nr_samples``
over all recorded populations *including* t = -1; the calibration count is
also given on its own (``calibration_simulations``) and the per-population
list starts with the t = -1 entry. ``wall_seconds`` times ``abc.run`` (the
calibration sample, all populations and pyABC's sqlite writes).

``--unit-box`` samples each free parameter as u ~ U(0, 1) with
theta = lower + u * (upper - lower) inside the model, instead of
``RV("uniform", lower, upper - lower)`` on theta. The two are the same
algorithm (pyABC's defaults are invariant under this diagonal affine map; the
per-model Jacobians cancel in the importance weights), but the unit box keeps
the kernel covariance well conditioned. With SciPy 1.17 (what
``pip install "pyabc==0.13.*"`` installs on Python 3.11 in November 2026),
``multivariate_normal(allow_singular=True)`` treats a kernel
covariance whose smallest eigenvalue is below about 2e-10 of the largest as
singular and gives density 0 to the kernel's own proposals (drawn with the
full covariance), so the weights become NaN and pyABC stops with "The
population total weight nan is not normalized" (the m4 cubic on the N·m
rig record, where c3 ~ 1e-5 and c0 ~ 3).

Needs a virtual environment with pyABC 0.13:

    python3 -m venv pyabc-venv
    pyabc-venv/bin/pip install "pyabc==0.13.*"
    pyabc-venv/bin/python benches/pyabc_comparison.py DIR --seed S \\
        [--unit-box] [--out result.json]

It prints the result JSON, and writes it to ``--out`` if given.
"""

import argparse
import csv
import json
import os
import random
import sys
import tempfile
import time

import numpy as np
import pyabc
from pyabc.weighted_statistics import effective_sample_size


def _law_m1(w, b0, b1, b2, b3):
    return b0 * (np.tanh(b1 * w) + b2 * w / (1.0 + b3 * w**2))


def _law_m2(w, tsb, tcb, g):
    return (tsb - tcb) * np.exp(-g * w) + tcb


def _law_m3(w, a0, a1, a2, a3, a4, a5):
    return a0 * np.exp(-a1 * (w - a2) ** 2) + a3 - a4 * np.tanh(a5 * w)


def _law_m4(w, c0, c1, c2, c3):
    return c0 + c1 * w + c2 * w**2 + c3 * w**3


# Torque laws T(w) with r = 1, parameters in bitrock's order.
LAWS = {"m1": _law_m1, "m2": _law_m2, "m3": _law_m3, "m4": _law_m4}


def read_calibration(path):
    """Speed (rad/s) and torque arrays of the calibration rows of data.csv."""
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        cols = reader.fieldnames
        torque_col = next(c for c in cols if c.startswith("torque"))
        rows = [r for r in reader if r["set"] == "calibration"]
    w = np.array([float(r["speed_rad_s"]) for r in rows])
    y = np.array([float(r[torque_col]) for r in rows])
    return w, y, torque_col


def distance(x, x0):
    """rho = sum((y - T)^2) / sum(y^2)."""
    y = x0["torque"]
    return float(np.sum((y - x["torque"]) ** 2) / np.sum(y**2))


def make_model(law, names, fixed, boxes, w):
    """A pyABC model: parameters -> {"torque": T(w)} at the observed speeds.

    ``fixed`` maps fixed parameters to their values; ``boxes`` maps free
    parameters sampled on the unit box to (lower, width), empty otherwise.
    """
    fun = LAWS[law]

    def value(pars, n):
        if n in fixed:
            return fixed[n]
        if n in boxes:
            lo, width = boxes[n]
            return lo + pars[n] * width
        return pars[n]

    def model(pars):
        return {"torque": fun(w, *[value(pars, n) for n in names])}

    model.__name__ = law
    return model


def make_prior(names, lower, upper, unit_box):
    """Uniform prior per free parameter; fixed parameters (lower == upper)."""
    free, fixed, boxes = {}, {}, {}
    for n, lo, hi in zip(names, lower, upper):
        if hi <= lo:
            fixed[n] = lo
        elif unit_box:
            free[n] = pyabc.RV("uniform", 0.0, 1.0)
            boxes[n] = (lo, hi - lo)
        else:
            free[n] = pyabc.RV("uniform", lo, hi - lo)
    return pyabc.Distribution(**free), fixed, boxes


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("run_dir", help="bitrock abc --out directory")
    parser.add_argument("--seed", type=int, required=True)
    parser.add_argument("--out", help="write the result JSON here")
    parser.add_argument(
        "--unit-box",
        action="store_true",
        help="sample free parameters on [0, 1], mapped to the box in the model",
    )
    args = parser.parse_args()

    with open(os.path.join(args.run_dir, "run.json")) as f:
        run = json.load(f)
    sampler_cfg = run["config"]["sampler"]
    sampler_cfg = sampler_cfg.get("base", sampler_cfg)
    n_particles = int(sampler_cfg["particles"])
    eps_min = float(sampler_cfg["eps_min"])
    w, y, torque_col = read_calibration(os.path.join(args.run_dir, "data.csv"))

    laws, models, priors, weights = [], [], [], []
    for p in run["priors"]:
        prior, fixed, boxes = make_prior(
            p["names"], p["lower"], p["upper"], args.unit_box
        )
        laws.append(p["law"])
        models.append(make_model(p["law"], p["names"], fixed, boxes, w))
        priors.append(prior)
        weights.append(float(p["weight"]))
    weights = np.array(weights) / np.sum(weights)
    model_prior = pyabc.RV(
        "rv_discrete", values=(np.arange(len(laws)), weights)
    )

    # Consistency check: our distance at bitrock's least-squares fits.
    fit_check = {}
    for fit in run.get("fits", []):
        if fit["law"] in LAWS:
            t = LAWS[fit["law"]](w, *fit["params"])
            fit_check[fit["law"]] = {
                "bitrock_rho": fit["rho"],
                "python_rho": distance({"torque": t}, {"torque": y}),
            }

    np.random.seed(args.seed)
    random.seed(args.seed)

    abc = pyabc.ABCSMC(
        models,
        priors,
        distance,
        population_size=n_particles,
        sampler=pyabc.sampler.SingleCoreSampler(),
        model_prior=model_prior,
    )
    with tempfile.TemporaryDirectory() as tmp:
        db = "sqlite:///" + os.path.join(tmp, "pyabc.db")
        abc.new(db, {"torque": y})
        start = time.perf_counter()
        history = abc.run(minimum_epsilon=eps_min, max_nr_populations=40)
        wall = time.perf_counter() - start

        pops = history.get_all_populations().sort_values("t")
        populations = []
        for _, row in pops.iterrows():
            t = int(row["t"])
            entry = {
                "t": t,
                "epsilon": float(row["epsilon"]),
                "simulations": int(row["samples"]),
            }
            if t >= 0:
                wd = history.get_weighted_distances(t=t)
                entry["ess"] = float(effective_sample_size(wd["w"].to_numpy()))
            populations.append(entry)

        final = history.get_weighted_distances()  # weights over all models
        probs = history.get_model_probabilities(history.max_t)
        model_probabilities = {law: 0.0 for law in laws}
        for m, p in probs["p"].items():  # indexed by model index m
            model_probabilities[laws[int(m)]] = float(p)
        calibration = sum(
            p["simulations"] for p in populations if p["t"] == history.PRE_TIME
        )
        final_eps = float(pops["epsilon"].iloc[-1])
        result = {
            "pyabc_version": pyabc.__version__,
            "record": run["data"]["source"],
            "run_dir": os.path.abspath(args.run_dir),
            "seed": args.seed,
            "particles": n_particles,
            "parametrisation": "unit_box" if args.unit_box else "box",
            "eps_min": eps_min,
            "torque_column": torque_col,
            "calibration_rows": int(len(y)),
            "laws": laws,
            "model_prior": dict(zip(laws, weights.tolist())),
            "fit_check": fit_check,
            "final_epsilon": final_eps,
            "reached_eps_min": final_eps <= eps_min * (1 + 1e-12),
            "populations_run": int(history.max_t) + 1,
            "populations": populations,
            "calibration_simulations": int(calibration),
            "total_simulations": int(history.total_nr_simulations),
            "final_ess": float(effective_sample_size(final["w"].to_numpy())),
            "model_probabilities": model_probabilities,
            "wall_seconds": wall,
        }

    text = json.dumps(result, indent=2)
    if args.out:
        with open(args.out, "w") as f:
            f.write(text + "\n")
    print(text)


if __name__ == "__main__":
    sys.exit(main())
