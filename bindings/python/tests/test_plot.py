"""bitrock.plot draws the numbers the library computes: the record's samples, each law's
least-squares curve and predictive band, the probabilities, weighted marginals and the map."""

from __future__ import annotations

import math

import numpy as np
import pytest

matplotlib = pytest.importorskip("matplotlib", reason="the plot extra (matplotlib) is part of the test extras")
matplotlib.use("Agg")

import bitrock  # noqa: E402
import bitrock.plot  # noqa: E402

RPM = 2 * math.pi / 60


def _grid(record: bitrock.Record) -> np.ndarray:
    """The speeds (rad/s) the fit figure draws its curves at: 200 over the record's range."""
    speed, _torque = record.calibration()
    return np.linspace(max(0.0, float(speed.min())), float(speed.max()), 200)


def _by_gid(ax, kind: str, gid: str):
    found = [a for a in getattr(ax, kind) if a.get_gid() == gid]
    assert len(found) == 1, f"{gid}: {[a.get_gid() for a in getattr(ax, kind)]}"
    return found[0]


def test_the_fit_figure_draws_the_record_the_fits_and_the_bands(small_run: bitrock.Result) -> None:
    ax = bitrock.plot.fit(small_run)
    speed, torque_nm = small_run.record.calibration()
    points = _by_gid(ax, "collections", "record").get_offsets()
    np.testing.assert_array_equal(points[:, 0], speed / RPM)
    np.testing.assert_array_equal(points[:, 1], torque_nm / 1000.0)  # the demo record is in kN·m
    grid = _grid(small_run.record)
    np.testing.assert_array_equal(_by_gid(ax, "lines", f"fit-{small_run.laws[0]}").get_xdata(), grid / RPM)
    bands = small_run.predictive(grid)
    for f in small_run.document["fits"]:
        line = _by_gid(ax, "lines", f"fit-{f['law']}")
        np.testing.assert_array_equal(line.get_ydata(), bitrock.torque(f["law"], grid, f["params"]))
    for law in bands.law.to_numpy():
        band = _by_gid(ax, "collections", f"band-{law}").get_paths()[0].vertices
        lower, upper = bands["lower"].sel(law=law).to_numpy(), bands["upper"].sel(law=law).to_numpy()
        # fill_between's outline runs along the lower edge and back along the upper one.
        assert np.isin(lower, band[:, 1]).all() and np.isin(upper, band[:, 1]).all()
        median = _by_gid(ax, "lines", f"median-{law}").get_ydata()
        np.testing.assert_array_equal(median, bands["median"].sel(law=law).to_numpy())
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    last = small_run.model_probabilities.iloc[-1]
    for law in bands.law.to_numpy():
        assert f"{law}: P = {last[law]:.3f}, 98% band" in labels
    # Each law in its one colour, the report's and the live page's (Okabe & Ito's palette).
    from matplotlib.colors import to_hex

    expected = {"m1": "#cc79a7", "m2": "#e69f00", "m3": "#009e73", "m4": "#56b4e9"}
    for law in bands.law.to_numpy():
        assert to_hex(_by_gid(ax, "lines", f"median-{law}").get_color()) == expected[law]
    assert bitrock._bitrock.law_colours(list(expected)) == list(expected.values())


def test_the_probabilities_are_the_runs(small_run: bitrock.Result) -> None:
    ax = bitrock.plot.model_probabilities(small_run)
    table = small_run.model_probabilities
    bottom = np.zeros(len(table))
    for law in small_run.laws:
        bars = [p for p in ax.patches if p.get_gid() == f"population-{law}"]
        np.testing.assert_allclose([b.get_height() for b in bars], table[law].to_numpy(), rtol=0, atol=1e-15)
        np.testing.assert_allclose([b.get_y() for b in bars], bottom, rtol=0, atol=1e-12)
        bottom += table[law].to_numpy()


def test_the_marginals_are_weighted(small_run: bitrock.Result) -> None:
    law = small_run.laws[1]
    frame, weights = small_run.get_distribution(law)
    fig = bitrock.plot.marginals(small_run, law, bins=25)
    axes = fig.axes
    assert len(axes) == frame.shape[1]
    for ax, name in zip(axes, frame.columns):
        bars = [p for p in ax.patches if p.get_gid() == f"marginal-{name}"]
        widths = np.array([b.get_width() for b in bars])
        heights = np.array([b.get_height() for b in bars])
        centres = np.array([b.get_x() + b.get_width() / 2 for b in bars])
        assert (heights * widths).sum() == pytest.approx(1.0, abs=1e-9)
        # The histogram's mean is the weighted mean within half a bin.
        mean = float(np.sum(frame[name].to_numpy() * weights))
        assert abs(float(np.sum(centres * heights * widths)) - mean) <= widths[0] / 2


def test_the_stability_figure_draws_the_maps(small_run: bitrock.Result) -> None:
    maps = bitrock.stability(small_run, omega_rpm="20:200:10", wob_kn="10:200:12", samples=30, backend="cpu")
    law = str(maps.law.to_numpy()[0])
    ax = bitrock.plot.stability(maps, law=law)
    mesh = _by_gid(ax, "collections", "probability-unstable")
    np.testing.assert_array_equal(np.asarray(mesh.get_array()).reshape(12, 10), maps.probability_unstable.sel(law=law).to_numpy().T)
    np.testing.assert_array_equal(_by_gid(ax, "lines", "map-boundary").get_ydata(), maps.map_wob_kn.sel(law=law).to_numpy())
    ax = bitrock.plot.stability(maps)
    mesh = _by_gid(ax, "collections", "probability-unstable")
    p = maps.probability.to_numpy()
    mixture = np.tensordot(p / p.sum(), maps.probability_unstable.to_numpy(), axes=1)
    np.testing.assert_allclose(np.asarray(mesh.get_array()).reshape(12, 10), mixture.T, rtol=0, atol=1e-12)
    with pytest.raises(bitrock.InputError) as caught:
        bitrock.plot.stability(maps, law="m9")
    assert caught.value.argument == "law"


def test_the_evidence_draws_its_posterior(demo: bitrock.Record) -> None:
    ev = bitrock.evidence(demo, laws=["m2", "m4"], particles=100, islands=2, backend="cpu", noise="iid", check=0)
    ax = bitrock.plot.model_probabilities(ev)
    bars = [p for p in ax.patches if p.get_gid() == "probabilities"]
    np.testing.assert_array_equal([b.get_height() for b in bars], ev.probabilities.to_numpy())
    # Without a record, the evidence's own; an evidence made from its document alone has none.
    own = bitrock.plot.fit(ev, laws=["m2"])
    np.testing.assert_array_equal(_by_gid(own, "collections", "record").get_offsets(), _by_gid(bitrock.plot.fit(ev, demo, laws=["m2"]), "collections", "record").get_offsets())
    with pytest.raises(bitrock.InputError) as caught:
        bitrock.plot.fit(bitrock.Evidence(ev.document))
    assert caught.value.argument == "record"
    ax = bitrock.plot.fit(ev, demo, laws=["m2"])
    grid = _grid(demo)
    params, weights = ev.posterior("m2")
    curves = np.stack([bitrock.torque("m2", grid, list(p)) for p in params.to_numpy()])
    median = _by_gid(ax, "lines", "median-m2").get_ydata()
    # The weighted median: at least half the weight at or below it, and at or above it.
    below = np.array([weights[curves[:, i] <= median[i]].sum() for i in range(len(grid))])
    above = np.array([weights[curves[:, i] >= median[i]].sum() for i in range(len(grid))])
    assert (below >= 0.5 - 1e-9).all() and (above >= 0.5 - 1e-9).all()
    with pytest.raises(bitrock.InputError) as caught:
        bitrock.plot.fit("not a result")
    assert caught.value.argument == "source"
