"""The model evidence of a record's laws: ``bitrock.evidence`` and its result."""

from __future__ import annotations

import json
import math
import os
from typing import Any, Sequence

import numpy as np
import pandas as pd

from . import _bitrock


class Evidence:
    """The marginal likelihood ln Z of each law (tempered SMC per law, Gaussian residuals,
    i.i.d. or AR(1), σ integrated out), its Monte-Carlo error, the posterior law probabilities
    P(m | y) it gives, and what the least-squares fits alone say about telling the laws apart."""

    def __init__(
        self, document: dict[str, Any], record: Any = None, *, computed: Any = None, path: str | None = None
    ) -> None:
        self._doc = document
        self._record = record
        self._computed = computed
        self.path = path
        """The evidence directory that holds this evidence, or ``None`` for one kept in memory
        (:meth:`save` writes it)."""

    def save(self, path: str | os.PathLike[str], *, force: bool = False) -> "Evidence":
        """Writes an evidence kept in memory as the evidence directory ``path`` (``force``
        replaces an evidence there), as :func:`evidence` with ``out=path`` would have written
        it, so that :func:`read_evidence`, :func:`stability`, ``bitrock stability`` and
        ``bitrock report`` read it. Returns the stored evidence."""
        from ._errors import InputError

        if self._computed is None:
            where = f", in {self.path}" if self.path is not None else ""
            raise InputError(f"path: the evidence is stored already{where}", "path")
        self._computed.save(os.fspath(path), force)
        return read_evidence(path)

    @property
    def record(self) -> Any:
        """The :class:`bitrock.Record` the evidence was computed on (an evidence directory's
        stored record, for :func:`read_evidence`)."""
        if self._record is None:
            from ._errors import InputError

            raise InputError("record: this evidence was built from its document alone and holds no record", "record")
        return self._record

    def summary(self) -> pd.DataFrame:
        """Each law's posterior per parameter, as :meth:`bitrock.Result.summary` gives a run's:
        the law's probability, the weighted mean, standard deviation, 1 %, 50 % and 99 %
        quantiles of its posterior sets, in the record's torque unit, and ``identified``: false
        where the posterior's central 98 % still spans over 76 % of the law's box (0.7/0.9 of
        the box's own), so that the box, more than the record, sets those numbers."""
        rows = []
        for entry in self._doc["laws"]:
            frame, weights = self.posterior(entry["law"])
            if len(weights) == 0:
                continue
            for i, name in enumerate(entry["names"]):
                values = frame[name].to_numpy()
                order = np.argsort(values, kind="stable")
                cumulative = np.cumsum(weights[order])
                cumulative /= cumulative[-1]

                def quantile(q: float, values=values, order=order, cumulative=cumulative) -> float:
                    return float(values[order][np.searchsorted(cumulative, q - 1e-12)])

                mean = float(np.sum(weights * values) / np.sum(weights))
                q01, q99 = quantile(0.01), quantile(0.99)
                rows.append(
                    {
                        "law": entry["law"],
                        "parameter": name,
                        "unit": entry["units"][i],
                        "probability": entry["probability"],
                        "mean": mean,
                        "std_dev": float(np.sqrt(np.sum(weights * (values - mean) ** 2) / np.sum(weights))),
                        "q01": q01,
                        "q50": quantile(0.5),
                        "q99": q99,
                        "identified": bool(q99 - q01 < 0.7 / 0.9 * 0.98 * (entry["upper"][i] - entry["lower"][i])),
                    }
                )
        return pd.DataFrame(rows)

    @property
    def document(self) -> dict[str, Any]:
        """``bitrock evidence --json``'s document, with each law's posterior sets."""
        return self._doc

    @property
    def laws(self) -> list[str]:
        return [law["law"] for law in self._doc["laws"]]

    @property
    def table(self) -> pd.DataFrame:
        """One row per law: ln Z (torques in N·m) and its Monte-Carlo error, the prior and
        posterior law probabilities (the latter's standard error from every law's ln Z error in
        ``probability_error``), the rounds of refinement its islands went through
        (``refinements``: each doubled their particles), the best ρ reached, the mean number of tempering steps,
        candidates scored, the parameters whose posterior a box end cuts, and the lag-1
        autocorrelation of the law's least-squares residuals in time order (near 0 where the
        i.i.d. noise model holds). ``prior_share``: the share of the law's box its prior keeps
        (1 where the prior is the box; below 1 where the law's file cuts it to the curves
        within the record's torques, ``document["laws"][k]["prior_curve"]``)."""
        rows = [
            {
                "law": law["law"],
                "ln_z": law["ln_z"],
                "ln_z_error": law["ln_z_error"],
                "prior_probability": law["prior_probability"],
                "probability": law["probability"],
                "probability_error": law.get("probability_error", 0.0),
                "refinements": law.get("refinements", 0),
                "best_rho": law["best_rho"],
                "stages": float(np.mean(law["stages"])),
                "candidates_scored": law["candidates_scored"],
                "cut_by_box": list(law["cut_by_box"]),
                "residual_lag1": law.get("residual_lag1"),
                "prior_share": float(np.exp(law["prior_curve"]["ln_share"])) if law.get("prior_curve") else 1.0,
            }
            for law in self._doc["laws"]
        ]
        return pd.DataFrame(rows).set_index("law")

    @property
    def starts(self) -> pd.DataFrame:
        """Where each law's samplers started from both its box and its fit
        (``start_from="both"``): one row per law and start, its own ln Z (N·m), Monte-Carlo error
        and islands' spread (nats), and whether the law's ln Z kept its islands (both where they
        agree, else the higher: a start that misses part of the posterior errs low). Empty for a single start."""
        rows = [
            {"law": law["law"], **estimate}
            for law in self._doc["laws"]
            for estimate in law.get("starts", [])
        ]
        columns = ["law", "start", "ln_z", "ln_z_error", "island_spread", "kept"]
        return pd.DataFrame(rows, columns=columns)

    @property
    def noise_model(self) -> str:
        """The noise model of the reported evidence: ``"iid"`` or ``"ar1"``."""
        return self._doc["noise_model"]

    @property
    def w_ref_kn(self) -> float | None:
        """W_ref, kN, where the reported evidence scaled each predicted torque by WOB / W_ref
        (its posterior's torque parameters are for W = W_ref); ``None`` where it did not."""
        return self._doc.get("w_ref_kn")

    @property
    def noise_models(self) -> pd.DataFrame:
        """One row per model of the residuals compared: the noise model (``model``: both with
        ``noise="auto"``) and, for a record with a weight-on-bit column, the torque as the law
        gives it or scaled by WOB / ``w_ref_kn``; ln p(y | model) = ln Σ π(m)·Z_m and its
        Monte-Carlo error, the model's probability (equal prior odds), and the law it puts
        first with that law's probability."""
        return pd.DataFrame(self._doc["noise_models"])

    @property
    def answer(self) -> dict[str, Any] | None:
        """The evidence's answer to "which law, how sure": the law of the largest evidence
        (``law``, ``probability``) over the next (``runner_up``), ``ln_b`` ± ``error`` between
        them, ``strength`` as in :attr:`bayes_factors` (never stronger than what the record
        separates; taken back where the check decides fewer than half the records made by the law
        for it, against every other law, or half or more of the runner-up's for it too), ``why``,
        ``check`` (records made by the law decided for it, and by the runner-up for it too, of
        ``replicates``) and the ``sentence`` the command prints last. ``None`` for a document written without
        it."""
        return self._doc.get("answer")

    @property
    def probabilities(self) -> pd.Series:
        """P(m | y) by law."""
        return self.table["probability"]

    def bayes_factor(self, a: str, b: str) -> tuple[float, float]:
        """ln(Z_a / Z_b) and its Monte-Carlo error."""
        laws = {law["law"]: law for law in self._doc["laws"]}
        for name in (a, b):
            if name not in laws:
                from ._errors import InputError

                raise InputError(f"law {name!r} was not compared (compared: {', '.join(laws)})")
        x, y = laws[a], laws[b]
        return x["ln_z"] - y["ln_z"], math.hypot(x["ln_z_error"], y["ln_z_error"])

    @property
    def warnings(self) -> list[str]:
        """What the numbers do not say by themselves, as the command says it beside its table:
        residuals too autocorrelated for the i.i.d. model, islands that disagree, posteriors a
        box end cuts, a lead the boxes make rather than the data."""
        return [w["message"] for w in self._doc.get("warnings", [])]

    @property
    def bayes_factors(self) -> pd.DataFrame:
        """The law of the largest evidence against each other law, one row per pair: ln B and
        its Monte-Carlo error split into the data's part (``data_nats``: ⟨ln L⟩ over the
        favoured law's posterior less the other's) and the boxes' part (``boxes_nats``: the
        Occam factors, which boxes twice as wide move by ln 2 per parameter, less where a law's
        prior is cut to the record's torques), the fits' expected
        gap (``separation_nats``), and the word (``strength``): Kass & Raftery's on the data's
        part, ``decided_by_the_boxes`` where that part is below 1 nat, points the other way, or
        the fits do not separate the pair; ``sensitivity``: ln B's range with one box of either
        law widened or narrowed 2× (``lowest``, ``highest``, the change at each, and
        ``prior_dependent`` where that range changes which law leads). Empty for a document
        written without them."""
        columns = [
            "favoured", "against", "ln_b", "error", "data_nats", "boxes_nats", "separation_nats", "strength",
            "sensitivity",
        ]
        return pd.DataFrame(self._doc.get("bayes_factors", []), columns=columns)

    @property
    def separations(self) -> pd.DataFrame:
        """Per ordered pair (truth, rival): the expected log-likelihood gap in nats if the
        truth's fitted curve made the record, the probability of ranking the rival first, and
        whether the pair is undecided (below 5 nats: the priors decide)."""
        rows = [
            {
                "truth": s["truth"],
                "rival": s["rival"],
                "gap_nats": s["gap_nats"],
                "misranking": s["misranking"],
                "undecided": s["gap_nats"] < 5.0,
            }
            for s in self._doc["separations"]
        ]
        return pd.DataFrame(rows)

    @property
    def check(self) -> pd.DataFrame | None:
        """The check by re-simulation (by default; ``None`` with ``check=0``): one row per law that
        made the synthetic records, with the mean P(m | y) of every law (``p_m1``…), the share
        of replicates ranking each law first (``first_m1``…), and the shares decided for the
        generating law, undecided, and decided for another law. A replicate is decided when
        its first law beats every other law by odds at least positive beyond their Monte-Carlo
        error and by a least-squares fit at least 5 nats of log-likelihood better."""
        check = self._doc.get("check")
        if check is None:
            return None
        rows = []
        for row in check["rows"]:
            entry: dict[str, Any] = {"law": row["law"]}
            for law, p in zip(check["laws"], row["mean_probability"]):
                entry[f"p_{law}"] = p
            for law, f in zip(check["laws"], row["first_share"]):
                entry[f"first_{law}"] = f
            entry["decided_right"] = row["decided_right"]
            entry["undecided"] = row["undecided"]
            entry["decided_wrong"] = row["decided_wrong"]
            rows.append(entry)
        return pd.DataFrame(rows).set_index("law")

    def posterior(self, law: str) -> tuple[pd.DataFrame, np.ndarray]:
        """The law's posterior parameter sets (the record's torque unit, one column per
        parameter) and their weights (summing to 1), as pyABC's ``get_distribution``."""
        for entry in self._doc["laws"]:
            if entry["law"] == law:
                frame = pd.DataFrame(entry["posterior"]["params"], columns=entry["names"])
                return frame, np.asarray(entry["posterior"]["weights"])
        from ._errors import InputError

        raise InputError(f"law {law!r} was not compared (compared: {', '.join(self.laws)})")

    def to_datatree(self, *, draws: int | None = None) -> Any:
        """The evidence as an ``xarray.DataTree``: one node per law with the groups ArviZ reads,
        ``posterior`` (each parameter over ``chain`` × ``draw``, in the record's torque unit) and
        ``sample_stats`` (``island_ln_z``, each chain's ln Z), and at the root each law's
        ``ln_z``, ``ln_z_error`` and ``probability``. The chains are the law's islands: independent
        tempered samplers of the same posterior, so that ArviZ's R-hat says whether they found the
        same one (near 1) or not, as their ln Z's spread does. Each island's weighted particles are
        resampled systematically to ``draws`` equal-weight draws (deterministic; by default as
        many as the island's largest set), so that ArviZ's summaries, which treat draws as equal,
        are those of the island's weighted posterior (a particle drawn more than once gives draws
        side by side, which ArviZ's ESS counts as the correlated draws they are). Every island
        weighs the same here: :meth:`posterior` pools them weighed by
        their Z. An evidence directory written without its islands' membership gives one chain.
        ArviZ 1.x reads a law's node directly (``tree["m2"]``); ArviZ 0.23 through
        ``arviz.InferenceData.from_datatree(tree["m2"])``."""
        import xarray as xr

        from . import __version__, _positive_count, _systematic_resample

        laws = self._doc["laws"]
        nodes: dict[str, xr.Dataset] = {
            "/": xr.Dataset(
                {
                    "ln_z": ("law", [law["ln_z"] for law in laws]),
                    "ln_z_error": ("law", [law["ln_z_error"] for law in laws]),
                    "probability": ("law", [law["probability"] for law in laws]),
                },
                coords={"law": self.laws},
                attrs={"source": self._doc["source"], "ln_z_units": "nats, with torques in N·m"},
            )
        }
        for law in laws:
            frame, weights = self.posterior(law["law"])
            params = frame.to_numpy()
            sets = law["posterior"]
            # Without the islands' membership, the pooled sets are one chain of ln Z the law's.
            island = np.asarray(sets["island"], dtype=int) if "island" in sets else np.zeros(len(weights), dtype=int)
            island_ln_z = law["island_ln_z"] if "island" in sets else [law["ln_z"]]
            chains = [int(i) for i in np.unique(island)]
            members = [np.flatnonzero(island == i) for i in chains]
            count = max((len(m) for m in members), default=0) if draws is None else _positive_count(draws, "draws")
            drawn = np.array([m[_systematic_resample(weights[m], count)] for m in members], dtype=int).reshape(len(chains), count)
            coords = {"chain": np.arange(len(chains)), "draw": np.arange(count)}
            nodes[f"/{law['law']}/posterior"] = xr.Dataset(
                {
                    name: (("chain", "draw"), params[:, i][drawn], {"units": unit})
                    for i, (name, unit) in enumerate(zip(law["names"], law["units"]))
                },
                coords=coords,
                attrs={"law": law["law"], "inference_library": "bitrock", "inference_library_version": __version__},
            )
            nodes[f"/{law['law']}/sample_stats"] = xr.Dataset(
                {"island_ln_z": ("chain", np.array([island_ln_z[i] for i in chains], dtype=float))},
                coords={"chain": coords["chain"]},
            )
        return xr.DataTree.from_dict(nodes)

    def _repr_html_(self) -> str:
        """A notebook's view: the evidence table, the boxes it integrates over, and what the
        command warns about (:attr:`warnings`)."""
        import html

        doc = self._doc
        columns = ["ln_z", "ln_z_error", "probability", "best_rho", "residual_lag1"]
        table = self.table[columns].to_html(float_format=lambda v: f"{v:.4f}")
        notes = self.warnings
        items = "".join(f"<li>warning: {html.escape(n)}</li>" for n in notes)
        answer = self.answer
        return (
            f"<div><b>bitrock.Evidence</b> on {html.escape(doc['source'])} ({doc['data_points']} samples; "
            f"ln Z with torques in N·m; {html.escape(doc['prior'])}){table}"
            + (f"<p><b>answer</b>: {html.escape(answer['sentence'])}</p>" if answer else "")
            + (f"<ul>{items}</ul>" if items else "")
            + "</div>"
        )

    def __repr__(self) -> str:
        best = max(self._doc["laws"], key=lambda law: law["probability"])
        parts = ", ".join(f"P({law['law']}) = {law['probability']:.3f}" for law in self._doc["laws"])
        answer = self.answer
        strength = f" ({answer['strength'].replace('_', ' ')})" if answer else ""
        return f"<bitrock.Evidence {parts}; most probable {best['law']}{strength}>"


def evidence(
    record: Any,
    *,
    laws: str | Sequence[str] | None = None,
    boxes: str = "physical",
    prior_scale: float | None = None,
    delta: float | None = None,
    prior: str | os.PathLike[str] | None = None,
    particles: int | None = None,
    islands: int | None = None,
    seed: int | None = None,
    backend: str = "auto",
    max_stages: int | None = None,
    ess_share: float | None = None,
    max_sweeps: int | None = None,
    refine_rounds: int | None = None,
    bounds: bool = True,
    starts: int | None = None,
    scale_by_wob: bool = False,
    w_ref_kn: float | None = None,
    check: int | None = None,
    noise: str = "auto",
    start_from: str = "both",
    structure: str | None = None,
    inertia_kg_m2: float | None = None,
    omega_n_rad_s: float | None = None,
    damping_ratio: float | None = None,
    fe_file: str | os.PathLike[str] | None = None,
    dp_elements: int | None = None,
    bha_elements: int | None = None,
    alpha: float | None = None,
    beta: float | None = None,
    out: str | os.PathLike[str] | None = None,
    force: bool = False,
    executor: Any = None,
) -> Evidence:
    """The model evidence of the laws (``m1``…``m4``; all by default) on the record's
    calibration samples, as ``bitrock evidence``. ``boxes="physical"`` integrates over boxes
    from each parameter's physical bound over ``prior_scale`` (10) times the record's scale of
    its unit, no fit involved; ``boxes="delta"`` over the paper's boxes φ̂(1 ± ``delta``) around
    the least-squares estimates (the data used twice). ``prior`` is a prior file; ``particles``
    (500) per island, ``islands`` (4) independent samplers per law and start whose spread is the
    Monte-Carlo error; the same ``seed`` gives the same result. ``max_stages`` (500) bounds an
    island's tempering steps, ``ess_share`` (0.5) is the share of the effective sample size each
    step keeps (higher: more, gentler steps) and ``max_sweeps`` (30) bounds the Metropolis sweeps
    after each. A law's islands of one start that end more than a nat apart, where that leaves
    its ln Z uncertain by more than half a nat, are run again with twice the particles, at most
    ``refine_rounds`` (2) times; what is still apart after them is its ln Z's error
    (:attr:`Evidence.laws`' ``refinements`` and ``probability_error``). ``noise`` is the residuals'
    model: ``"iid"``, ``"ar1"`` (correlated from one sample to the next), or ``"auto"``, each
    model's evidence and the one the data favour reported (see :attr:`Evidence.noise_models`).
    ``start_from`` is where each law's samplers start: ``"box"``, the box (the whole tempered path;
    it needs many particles on a narrow curved posterior), ``"fit"``, a Gaussian at its
    least-squares estimate (the fit's covariance, twice as wide) mixed with its box (far fewer
    candidates; it under-estimates a law whose posterior is a funnel wider than its fit's
    covariance, m3 on a record of the law it nests), or ``"both"`` (the default), as many
    islands from each, weighed by their inverse variances where they agree and the higher
    kept where they do not (:attr:`Evidence.starts`); the evidence is of the boxes either way. The answer is then checked
    by re-simulation: ``check`` (4 by default where two laws or more are compared; 0: no check)
    synthetic records per law from its evidence posterior and the record's own residuals, each
    through a lighter evidence over the same boxes (at most 200 particles in 2 islands per law,
    from the replicate's fit where the evidence starts from fits), and the answer made
    undecided where the check decides fewer than half the records made by its law for it
    (against every other law), or half or more of the runner-up's for it too: see
    :attr:`Evidence.check`. ``out`` writes an evidence directory, as
    ``bitrock evidence --out``: :func:`read_evidence` reads it back and
    :func:`stability` maps it (``force=True`` replaces the evidence it holds); meanwhile the
    directory keeps the evidence under way, which :func:`resume_evidence` continues if the call
    is stopped or its process killed.

    ``executor`` scores the samplers' candidates on a pool of workers (a
    ``concurrent.futures`` executor, a ``dask.distributed.Client`` or :func:`ray_executor`;
    each worker on ``backend``), and its check's too: the evidence is the one computed here,
    bit for bit where the workers score on the CPU.

    ``structure``, ``inertia_kg_m2``, ``omega_n_rad_s``, ``damping_ratio``, ``fe_file``,
    ``dp_elements``, ``bha_elements``, ``alpha``, ``beta`` (as for :func:`stability`) give the
    drill string of the advice, kept with the evidence (the paper's where none is given)."""
    from . import _law_names, _note, _record
    from ._distributed import Dispatcher

    options = {
        "boxes": boxes,
        "prior_scale": prior_scale,
        "delta": delta,
        "prior": None if prior is None else os.fspath(prior),
        "particles": particles,
        "islands": islands,
        "seed": seed,
        "backend": backend,
        "max_stages": max_stages,
        "ess_share": ess_share,
        "max_sweeps": max_sweeps,
        "refine_rounds": refine_rounds,
        "bounds": bounds,
        "starts": starts,
        "scale_by_wob": scale_by_wob,
        "w_ref_kn": w_ref_kn,
        "check": check,
        "noise": noise,
        "start_from": start_from,
        "structure": structure,
        "inertia_kg_m2": inertia_kg_m2,
        "omega_n_rad_s": omega_n_rad_s,
        "damping_ratio": damping_ratio,
        "fe_file": None if fe_file is None else os.fspath(fe_file),
        "dp_elements": dp_elements,
        "bha_elements": bha_elements,
        "alpha": alpha,
        "beta": beta,
        "out": None if out is None else os.fspath(out),
        "force": force,
    }
    dispatcher = None if executor is None else Dispatcher(executor)
    computed = _bitrock.evidence(
        _record(record),
        _law_names(laws),
        options,
        _note,
        dispatcher,
        1 if dispatcher is None else dispatcher.parallelism,
    )
    document = json.loads(computed.document)
    if out is not None:
        return _warned(Evidence(document, _record(record), path=os.fspath(out)))
    return _warned(Evidence(document, _record(record), computed=computed))


def _warned(result: Evidence) -> Evidence:
    """``result``, each of its warnings said as a ``BitrockWarning`` (as the command says them
    beside its table)."""
    import warnings

    from ._errors import BitrockWarning

    for message in result.warnings:
        warnings.warn(message, BitrockWarning, stacklevel=3)
    return result


def resume_evidence(
    directory: str | os.PathLike[str],
    *,
    backend: str | None = None,
    check: int | None = None,
    executor: Any = None,
) -> Evidence:
    """Continues the evidence under way in ``directory`` (one that ``bitrock.evidence(...,
    out=directory)`` or ``bitrock evidence --out`` started and that was stopped or killed
    part-way) from its last saved state, with its record and settings, then writes the
    directory: the evidence the uninterrupted call gives, bit for bit on the same backend.
    ``backend`` (default: the evidence's), ``check`` (the check is this call's: the small one
    unless it says otherwise) and ``executor`` as for :func:`evidence`.
    As ``bitrock evidence --resume``."""
    from . import _note
    from ._distributed import Dispatcher

    dispatcher = None if executor is None else Dispatcher(executor)
    computed = _bitrock.resume_evidence(
        os.fspath(directory),
        backend,
        check,
        _note,
        dispatcher,
        1 if dispatcher is None else dispatcher.parallelism,
    )
    return _warned(Evidence(json.loads(computed.document), _stored_record(directory), path=os.fspath(directory)))


def read_evidence(directory: str | os.PathLike[str]) -> Evidence:
    """The evidence stored in ``directory`` (``bitrock evidence --out`` or
    ``bitrock.evidence(..., out=...)``), each law's posterior sets included."""
    directory = os.fspath(directory)
    return Evidence(json.loads(_bitrock.read_evidence(directory)), _stored_record(directory), path=directory)


def _stored_record(directory: str | os.PathLike[str]) -> Any:
    """The record an evidence directory keeps (``record.json``), if it keeps one."""
    from . import Record

    stored = os.path.join(os.fspath(directory), "record.json")
    if not os.path.exists(stored):
        return None
    with open(stored, encoding="utf-8") as file:
        return Record._from_state(file.read())
