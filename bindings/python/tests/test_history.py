"""pyABC's plots draw a bitrock run through Result.history(), with the run's numbers."""

from __future__ import annotations

import numpy as np
import pytest

import bitrock

pyabc = pytest.importorskip("pyabc", reason="pyabc is part of the test extras")
import matplotlib  # noqa: E402

matplotlib.use("Agg")


@pytest.fixture(scope="module")
def smc(demo: bitrock.Record) -> bitrock.Result:
    return bitrock.abc(demo, laws=["m2", "m3"], particles=300, sampler="smc", seed=8, backend="cpu", max_populations=4, progress=False)


def test_plot_model_probabilities_draws_the_runs(smc) -> None:
    history = smc.history()
    ax = pyabc.visualization.plot_model_probabilities(history)
    table = smc.model_probabilities
    heights = np.array([p.get_height() for p in ax.patches]).reshape(2, -1)  # one bar group per model
    np.testing.assert_array_equal(heights, table[["m2", "m3"]].to_numpy().T)
    assert history.get_model_probabilities(t=0).index.name == "m"


def test_plot_epsilons_draws_the_schedule(smc) -> None:
    ax = pyabc.visualization.plot_epsilons(smc.history(), yscale="linear")
    expected = smc.populations["epsilon"].to_numpy()
    drawn = ax.lines[0].get_ydata()
    np.testing.assert_array_equal(drawn, expected)


def test_plot_credible_intervals_are_the_weighted_quantiles(smc) -> None:
    history = smc.history()
    axes = pyabc.visualization.plot_credible_intervals(history, m=1, levels=[0.9], show_mean=True)
    assert len(axes) == 6  # m3's a0..a5
    frame, w = smc.get_distribution("m3", history.max_t)
    mean = float(np.sum(frame["a0"].to_numpy() * w))
    # The mean line of the first parameter ends at the last population's weighted mean.
    lines = [line for line in axes[0].lines if len(line.get_ydata()) == history.max_t + 1]
    assert any(np.isclose(line.get_ydata()[-1], mean, rtol=1e-12) for line in lines)


def test_kde_and_ess_plots_read_the_view(smc) -> None:
    history = smc.history()
    frame, w = history.get_distribution(m="m2")
    pyabc.visualization.plot_kde_1d_highlevel(history, x="tsb", m=0)
    pyabc.visualization.plot_kde_matrix_highlevel(history, m=0)
    ax = pyabc.visualization.plot_effective_sample_sizes(history)
    ess = []
    for t in range(history.max_t + 1):
        weights = history.get_weighted_distances(t)["w"].to_numpy()
        assert weights.sum() == pytest.approx(1.0, abs=1e-12)
        ess.append(weights.sum() ** 2 / (weights**2).sum())
    np.testing.assert_allclose(ax.lines[0].get_ydata(), ess, rtol=1e-12)
    assert len(frame) == len(w)
    with pytest.raises(bitrock.InputError) as caught:
        history.get_distribution(m=5)
    assert caught.value.argument == "m"
