"""Figures of bitrock's results on matplotlib (``pip install "bitrock[plot]"``): the record with
each law's fit and posterior predictive band, the model probabilities, the marginal posteriors
(weighted) and the stability map. Each function draws into ``ax`` (or ``fig``) when given and
returns what it drew into, so that a figure can be composed and saved as matplotlib's own.

>>> import bitrock, bitrock.plot
>>> result = bitrock.abc(bitrock.read_record(), particles=2000, seed=1)
>>> bitrock.plot.fit(result).figure.savefig("fit.png")

Speeds are drawn in rpm, torques in the record's unit, weights on bit in kN.
"""

from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np

from ._errors import InputError

__all__ = ["fit", "marginals", "model_probabilities", "stability"]

# Radians per second in one revolution per minute.
_RAD_S_PER_RPM = 2.0 * math.pi / 60.0
# The torque units of documents, as ``bitrock.torque`` names them.
# A record's torque unit as bitrock names it: the name ``torque`` takes, and N·m per unit.
_TORQUE_UNITS = {
    "kN·m": ("knm", 1000.0),
    "N·m": ("nm", 1.0),
    "ft·lbf": ("ftlbf", 1.3558179483314004),
    "kft·lbf": ("kftlbf", 1355.8179483314004),
}


def _pyplot() -> Any:
    try:
        import matplotlib.pyplot as plt
    except ImportError:
        raise ImportError('bitrock.plot draws with matplotlib: pip install "bitrock[plot]"') from None
    return plt


def _axes(ax: Any) -> Any:
    return ax if ax is not None else _pyplot().subplots(figsize=(7, 4.5), layout="constrained")[1]


def _source_kind(source: Any) -> str:
    from . import Evidence, Result

    if isinstance(source, Result):
        return "result"
    if isinstance(source, Evidence):
        return "evidence"
    raise InputError(f"source: give a bitrock.Result or a bitrock.Evidence, got {type(source).__name__}", "source")


def _weighted_quantiles(values: np.ndarray, weights: np.ndarray, qs: Sequence[float]) -> np.ndarray:
    """Quantiles ``qs`` of each column of ``values`` (samples × points) under ``weights``,
    by the inverse of the weighted empirical distribution (the smallest value whose
    cumulative weight reaches q; a run's envelopes interpolate between values instead)."""
    order = np.argsort(values, axis=0, kind="stable")
    sorted_values = np.take_along_axis(values, order, axis=0)
    cumulative = np.cumsum(weights[order], axis=0)
    cumulative /= cumulative[-1]
    out = np.empty((len(qs), values.shape[1]))
    for i, q in enumerate(qs):
        index = np.argmax(cumulative >= q - 1e-12, axis=0)
        out[i] = sorted_values[index, np.arange(values.shape[1])]
    return out


def _bands(source: Any, kind: str, laws: list[str], speeds: np.ndarray, level: float, population: int) -> dict[str, np.ndarray]:
    """Each law's (lower, median, upper) torques at ``speeds`` (rad/s), record unit."""
    if kind == "result":
        bands = source.predictive(speeds, level=level, population=population)
        return {law: np.stack([bands[v].sel(law=law).to_numpy() for v in ("lower", "median", "upper")]) for law in bands.law.to_numpy()}
    from . import torque

    unit = _TORQUE_UNITS[source.document["torque_unit"]][0]
    out = {}
    for law in laws:
        params, weights = source.posterior(law)
        if len(weights) == 0 or weights.sum() <= 0:
            continue
        curves = np.stack([torque(law, speeds, list(p), torque_unit=unit) for p in params.to_numpy()])
        out[law] = _weighted_quantiles(curves, weights, [(1 - level) / 2, 0.5, (1 + level) / 2])
    return out


def fit(
    source: Any,
    record: Any = None,
    *,
    laws: Sequence[str] | None = None,
    level: float = 0.98,
    population: int = -1,
    ax: Any = None,
) -> Any:
    """The record's calibration samples (torque against bit speed) with each law's
    least-squares fit (dashed) and its posterior predictive band at ``level`` (pointwise
    weighted quantiles of the posterior's torque curves: a run's ``predictive``, the
    evidence posterior's inverse weighted distribution), labelled with the law's posterior
    probability. ``source``: a :class:`bitrock.Result` (its ``population``, the last by
    default) or a :class:`bitrock.Evidence` (its posterior), drawn over the record it was
    computed on unless ``record`` is given. Returns the axes."""
    kind = _source_kind(source)
    if not 0 < level < 1:
        raise InputError(f"level: must lie in (0, 1), got {level}", "level")
    if record is None:
        record = source.record
    doc = source.document
    unit = doc["torque_unit"] if kind == "evidence" else doc["data"]["torque_unit"]
    scale = _TORQUE_UNITS[unit][1]
    chosen = list(source.laws if laws is None else laws)
    speed, torque_nm = record.calibration()
    grid = np.linspace(max(0.0, float(np.min(speed))), float(np.max(speed)), 200)
    ax = _axes(ax)
    ax.scatter(speed / _RAD_S_PER_RPM, torque_nm / scale, s=3, color="0.6", alpha=0.5, linewidths=0, label="record (calibration)", gid="record")
    probabilities = _probabilities(source, kind, population)
    bands = _bands(source, kind, chosen, grid, level, population)
    from . import torque

    fits = {f["law"]: f for f in doc["fits"]}
    for law, colour in zip(chosen, _law_colours(chosen)):
        p = probabilities.get(law, 0.0)
        if law in bands:
            lower, median, upper = bands[law]
            ax.fill_between(grid / _RAD_S_PER_RPM, lower, upper, color=colour, alpha=0.25, linewidth=0, label=f"{law}: P = {p:.3f}, {level:.0%} band", gid=f"band-{law}")
            ax.plot(grid / _RAD_S_PER_RPM, median, color=colour, linewidth=1.2, gid=f"median-{law}")
        if law in fits and all(v is not None for v in fits[law]["params"]):
            curve = torque(law, grid, fits[law]["params"], torque_unit=_TORQUE_UNITS[unit][0])
            ax.plot(grid / _RAD_S_PER_RPM, curve, color=colour, linestyle="--", linewidth=1.0, label=f"{law} least squares", gid=f"fit-{law}")
    ax.set_xlabel("bit speed (rpm)")
    ax.set_ylabel(f"torque on bit ({unit})")
    ax.legend(fontsize="small", loc="best")
    return ax


def _law_colours(laws: Sequence[str]) -> list[str]:
    """Each law's colour, the one of the report's figures and the watch's page (Okabe & Ito's
    palette, told apart with any colour vision)."""
    from . import _bitrock

    return _bitrock.law_colours(list(laws))


def _probabilities(source: Any, kind: str, population: int) -> dict[str, float]:
    if kind == "evidence":
        return {law["law"]: law["probability"] for law in source.document["laws"]}
    table = source.model_probabilities
    row = table.iloc[population]
    return {law: float(row[law]) for law in source.laws}


def model_probabilities(source: Any, *, ax: Any = None) -> Any:
    """The laws' probabilities: for a :class:`bitrock.Result`, stacked bars per population
    (labelled with its ε); for a :class:`bitrock.Evidence`, one bar per law, P(m | y) with the
    Bayes factor's Monte-Carlo error written beside it. Returns the axes."""
    kind = _source_kind(source)
    ax = _axes(ax)
    if kind == "evidence":
        laws = source.document["laws"]
        names = [law["law"] for law in laws]
        values = [law["probability"] for law in laws]
        bars = ax.bar(names, values, color=_law_colours(names), gid="probabilities")
        for bar, law in zip(bars, laws):
            ax.annotate(f"ln Z {law['ln_z']:.1f} ± {law['ln_z_error']:.1f}", (bar.get_x() + bar.get_width() / 2, bar.get_height()), ha="center", va="bottom", fontsize="small")
        ax.set_ylabel("P(m | y)")
        ax.set_ylim(0, 1.1)
        return ax
    table = source.model_probabilities
    bottom = np.zeros(len(table))
    x = np.arange(len(table))
    for law, colour in zip(source.laws, _law_colours(source.laws)):
        values = table[law].to_numpy()
        ax.bar(x, values, bottom=bottom, label=law, color=colour, gid=f"population-{law}")
        bottom += values
    ax.set_xticks(x, [f"{g}\nε {'∞' if math.isinf(e) else f'{e:.3g}'}" for g, e in zip(table.index, table["epsilon"])], fontsize="small")
    ax.set_xlabel("population")
    ax.set_ylabel("P(m | ρ < ε), the paper's ABC")
    ax.set_ylim(0, 1)
    ax.legend(fontsize="small", loc="upper left")
    return ax


def marginals(source: Any, law: str, *, population: int = -1, bins: int = 40, fig: Any = None) -> Any:
    """The law's marginal posteriors, one panel per parameter: histograms of its particles
    weighted by their weights (a density), the least-squares estimate marked. ``source``: a
    :class:`bitrock.Result` (its ``population``) or a :class:`bitrock.Evidence`. Returns the
    figure."""
    kind = _source_kind(source)
    if kind == "result":
        frame, weights = source.get_distribution(law, population)
    else:
        frame, weights = source.posterior(law)
    if len(weights) == 0:
        raise InputError(f"law: {law} has no particles to draw", "law")
    plt = _pyplot()
    if fig is None:
        fig = plt.figure(figsize=(3.2 * frame.shape[1], 3), layout="constrained")
    axes = fig.subplots(1, frame.shape[1], squeeze=False)[0]
    fits = {f["law"]: f for f in source.document["fits"]}
    units = fits[law]["units"] if law in fits else [""] * frame.shape[1]
    (colour,) = _law_colours([law])
    for j, (ax, name) in enumerate(zip(axes, frame.columns)):
        ax.hist(frame[name].to_numpy(), bins=bins, weights=weights, density=True, color=colour, alpha=0.7, gid=f"marginal-{name}")
        if law in fits and fits[law]["params"][j] is not None:
            ax.axvline(fits[law]["params"][j], color="k", linestyle="--", linewidth=1, gid=f"fit-{name}")
        ax.set_xlabel(f"{name} ({units[j]})" if units[j] else name)
        ax.set_yticks([])
    axes[0].set_ylabel(f"{law}: posterior density")
    return fig


def stability(maps: Any, *, law: str | None = None, ax: Any = None) -> Any:
    """The stochastic stability map over top-drive speed Ω (rpm) and weight on bit W (kN):
    the probability of stick-slip at each cell (``bitrock.stability``'s ``probability_unstable``
    for ``law``; without one, the mixture Σ P(m)·P(unstable | m) over the laws), the MAP's
    boundary and the percentile boundary. Returns the axes."""
    if not hasattr(maps, "probability_unstable"):
        raise InputError(f"maps: give the dataset bitrock.stability returns, got {type(maps).__name__}", "maps")
    laws = [str(v) for v in maps.law.to_numpy()]
    if law is not None and law not in laws:
        raise InputError(f"law: the maps hold {', '.join(laws)}, got {law!r}", "law")
    omega = maps.omega_rpm.to_numpy()
    wob = maps.wob_kn.to_numpy()
    if law is None and len(laws) > 1:
        weights = maps.probability.to_numpy()
        probability = np.tensordot(weights / weights.sum(), maps.probability_unstable.to_numpy(), axes=1)
        title = "mixture of " + ", ".join(f"{m} ({p:.2f})" for m, p in zip(laws, weights))
        boundary = maps["mixture_p_wob_kn"].to_numpy() if "mixture_p_wob_kn" in maps else None
        map_boundary = None
    else:
        law = law or laws[0]
        probability = maps.probability_unstable.sel(law=law).to_numpy()
        title = law
        boundary = maps.p_wob_kn.sel(law=law).to_numpy()
        map_boundary = maps.map_wob_kn.sel(law=law).to_numpy()
    ax = _axes(ax)
    mesh = ax.pcolormesh(omega, wob, probability.T, shading="nearest", cmap="Blues", vmin=0, vmax=1, gid="probability-unstable")
    ax.figure.colorbar(mesh, ax=ax, label="P(stick-slip)")
    if map_boundary is not None:
        ax.plot(omega, map_boundary, color="k", linewidth=1.5, label="MAP boundary", gid="map-boundary")
    if boundary is not None:
        percentile = maps.attrs.get("percentile", "")
        ax.plot(omega, boundary, color="k", linestyle="--", linewidth=1.2, label=f"{percentile} % boundary", gid="percentile-boundary")
    ax.set_xlabel("top-drive speed Ω (rpm)")
    ax.set_ylabel("weight on bit W (kN)")
    ax.set_title(title, fontsize="medium")
    if map_boundary is not None or boundary is not None:
        ax.legend(fontsize="small", loc="upper left")
    ax.set_ylim(wob.min(), wob.max())
    return ax
