"""A law's torque and a run's posterior predictive from Python (the closed form, the run
directory's envelopes.csv, refusals by name), and how records, runs and evidence show
themselves in a notebook."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

import bitrock


def test_a_laws_torque_is_its_closed_form_in_either_unit() -> None:
    w = np.array([[0.0, 1.0], [5.0, 20.0]])
    expected = (13.0 - 6.5) * np.exp(-0.3 * w) + 6.5
    got = bitrock.torque("m2", w, [13.0, 6.5, 0.3])
    assert got.shape == w.shape
    np.testing.assert_allclose(got, expected, rtol=1e-14)
    # N·m parameters give N·m torques; r scales the torque.
    np.testing.assert_allclose(bitrock.torque("m2", w, [13e3, 6.5e3, 0.3], torque_unit="nm"), 1e3 * expected, rtol=1e-14)
    np.testing.assert_allclose(bitrock.torque("m2", w, [13.0, 6.5, 0.3], r=0.5), 0.5 * expected, rtol=1e-14)
    assert float(bitrock.torque("m4", 2.0, [1.0, 2.0, 3.0, 4.0])) == pytest.approx(1 + 4 + 12 + 32)
    # Speeds in any layout and number type: a strided view, a transposed array, float32,
    # integers and a list give each speed's own torque, and the speeds stay as they were.
    big = np.linspace(0.0, 20.0, 41)
    whole = bitrock.torque("m2", big, [13.0, 6.5, 0.3])
    np.testing.assert_array_equal(bitrock.torque("m2", big[::4], [13.0, 6.5, 0.3]), whole[::4])
    np.testing.assert_array_equal(bitrock.torque("m2", w.T, [13.0, 6.5, 0.3]), got.T)
    np.testing.assert_array_equal(
        bitrock.torque("m2", big.astype(np.float32), [13.0, 6.5, 0.3]),
        bitrock.torque("m2", big.astype(np.float32).astype(float), [13.0, 6.5, 0.3]),
    )
    np.testing.assert_array_equal(bitrock.torque("m2", np.arange(3), [13.0, 6.5, 0.3]), whole[[0, 2, 4]])
    np.testing.assert_array_equal(bitrock.torque("m2", [0.0, 0.5], [13.0, 6.5, 0.3]), whole[:2])
    np.testing.assert_array_equal(big, np.linspace(0.0, 20.0, 41))


@pytest.mark.parametrize(
    ("call", "named"),
    [
        (lambda: bitrock.torque("m2", [1.0], [13.0, 6.5]), "params"),
        (lambda: bitrock.torque("m9", [1.0], [13.0, 6.5, 0.3]), "law"),
        (lambda: bitrock.torque("m2", [float("nan")], [13.0, 6.5, 0.3]), "speed_rad_s"),
        (lambda: bitrock.torque("m2", [1.0], [13.0, 6.5, 0.3], torque_unit="lbft"), "torque_unit"),
    ],
)
def test_a_torque_that_cannot_be_computed_is_refused_by_name(call, named) -> None:
    with pytest.raises(bitrock.InputError, match=named):
        call()


def test_the_predictive_band_is_the_runs_envelopes(demo, tmp_path) -> None:
    result = bitrock.abc(demo, particles=300, seed=11, backend="cpu", max_populations=3, out=tmp_path / "run", progress=False)
    envelopes = pd.read_csv(tmp_path / "run" / "envelopes.csv")
    for law, rows in envelopes.groupby("law"):
        band = result.predictive(rows["speed_rad_s"].to_numpy())
        assert band["lower"].attrs["units"] == "kN·m"
        for name in ("lower", "median", "upper"):
            np.testing.assert_allclose(band[name].sel(law=law).values, rows[f"{name}_knm"].to_numpy(), rtol=2e-6)
    band = result.predictive(np.linspace(1.0, 20.0, 7), level=0.5)
    assert (band["lower"] <= band["median"]).all() and (band["median"] <= band["upper"]).all()
    with pytest.raises(bitrock.InputError, match="level"):
        result.predictive([1.0], level=1.5)
    # A run kept in memory gives the same band as its saved twin.
    twin = bitrock.abc(demo, particles=300, seed=11, backend="cpu", max_populations=3, progress=False)
    np.testing.assert_array_equal(twin.predictive([2.0, 8.0])["median"], result.predictive([2.0, 8.0])["median"])


def test_records_runs_and_evidence_show_themselves_in_a_notebook(demo, small_run) -> None:
    text = repr(demo)
    assert "bitrock.Record" in text and "0x" not in text
    assert f"{len(demo.calibration()[0])} calibration" in text
    page = demo._repr_html_()
    assert page.startswith("<div>") and "<table>" in page and "kN·m" in page and "rpm" in page
    page = small_run._repr_html_()
    assert "in memory" in page and "<table" in page
    for law, p in small_run.model_probabilities.iloc[-1].drop("epsilon").items():
        assert law in page and f"{p:.4f}" in page
    evidence = bitrock.evidence(bitrock.read_record(thin=8), laws=["m2", "m4"], particles=60, islands=2, backend="cpu", check=0)
    page = evidence._repr_html_()
    assert "bitrock.Evidence" in page and "<table" in page
    for law, p in evidence.probabilities.items():
        assert f"{p:.4f}" in page


def test_html_escapes_what_a_record_carries(tmp_path) -> None:
    path = tmp_path / "<b>rig&co.csv"
    path.write_text("speed_rpm,torque_knm\n" + "".join(f"{10 + i},{12 - 0.01 * i}\n" for i in range(50)))
    page = bitrock.read_record(path)._repr_html_()
    assert "&lt;b&gt;rig&amp;co.csv" in page and "<b>rig" not in page


def test_a_run_in_memory_pickles_and_maps_as_before(small_run) -> None:
    import pickle

    again = pickle.loads(pickle.dumps(small_run))
    assert again.document == small_run.document and again.path is None
    for law, (names, params, weights, rho, index) in small_run.particles().items():
        names2, params2, weights2, rho2, index2 = again.particles()[law]
        assert names == names2 and np.array_equal(params, params2) and np.array_equal(weights, weights2)
        assert np.array_equal(rho, rho2) and np.array_equal(index, index2)
    grid = {"omega_rpm": "40:200:5", "wob_kn": "50:500:4", "samples": 30, "backend": "cpu"}
    assert bitrock.stability(again, **grid).equals(bitrock.stability(small_run, **grid))
