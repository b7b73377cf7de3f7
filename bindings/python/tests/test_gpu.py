"""The GPU from Python: parity with the CPU reference and a run on the GPU backend. They need a
Vulkan adapter (Mesa's lavapipe serves); BITROCK_SKIP_GPU_TESTS=1 skips them, as it does the
Rust GPU tests."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

import bitrock
from conftest import run_cli

pytestmark = pytest.mark.skipif(os.environ.get("BITROCK_SKIP_GPU_TESTS") == "1", reason="BITROCK_SKIP_GPU_TESTS=1")


def test_parity_passes_and_is_the_command_lines(cli) -> None:
    report = bitrock.parity(laws=["m2", "m3"], candidates=3000)
    assert report["pass"], report
    assert [law["law"] for law in report["laws"]] == ["m2", "m3"]
    assert all(law["max_rel_diff"] <= report["tolerance"] for law in report["laws"])
    assert report["philox"]["words_differ"] == 0 and report["philox"]["candidates_differ"] == 0
    document = json.loads(run_cli(cli, "parity", "--laws", "m2,m3", "--candidates", "3000", "--json").stdout)
    assert document["adapter"] == report["adapter"]
    assert [law["max_rel_diff"] for law in document["laws"]] == [law["max_rel_diff"] for law in report["laws"]]
    # The simulators' sections: the same strings, the same figures.
    assert report["strings"]["pass"] and report["coupled"]["pass"], (report["strings"], report["coupled"])
    assert document["strings"] == report["strings"] and document["coupled"] == report["coupled"]
    with pytest.raises(bitrock.InputError) as caught:
        bitrock.parity(candidates=0)
    assert caught.value.argument == "candidates"


PARITY_TOLERANCE = 1e-5  # bitrock's CPU/GPU parity tolerance on ρ, relative


def _accepted(result, population):
    """(law, candidate index) → (parameters, ρ) of a population's particles."""
    out = {}
    for law, (_names, params, _weights, rho, index) in result.particles(population).items():
        for k, i in enumerate(index):
            out[(law, int(i))] = (params[k], rho[k])
    return out


def test_a_gpu_run_accepts_the_cpu_runs_candidates_except_within_the_parity_tolerance_of_epsilon(demo) -> None:
    n = 300
    cpu = bitrock.abc(demo, particles=n, seed=11, backend="cpu", max_populations=3, progress=False)
    gpu = bitrock.abc(demo, particles=n, seed=11, backend="gpu", max_populations=3, progress=False)
    assert gpu.document["backend"] != "cpu"
    cpu_pops, gpu_pops = cpu.document["populations"], gpu.document["populations"]
    assert len(cpu_pops) == len(gpu_pops) == 3
    compared = 0
    for g in range(3):
        eps_cpu, eps_gpu = cpu_pops[g]["epsilon"], gpu_pops[g]["epsilon"]
        if g == 0:
            assert eps_cpu is None and eps_gpu is None
        else:
            # ε is the median of the previous population's ρ: the backends' ρ differ within
            # the tolerance, and so may ε.
            assert abs(eps_gpu - eps_cpu) <= PARITY_TOLERANCE * eps_cpu
        # The same candidates are drawn on both. A candidate within the tolerance of ε may be
        # accepted by one backend only, and shifts the population's N-th particle by one: at
        # most two differences per such candidate, counted by both runs.
        near = max(cpu_pops[g]["near_threshold"], gpu_pops[g]["near_threshold"])
        a, b = _accepted(cpu, g), _accepted(gpu, g)
        assert len(a) == len(b) == n
        assert len(a.keys() ^ b.keys()) <= 2 * near, (g, near)
        for key in a.keys() & b.keys():
            (params_a, rho_a), (params_b, rho_b) = a[key], b[key]
            assert np.array_equal(params_a, params_b), key
            assert abs(rho_a - rho_b) <= PARITY_TOLERANCE * rho_a, (key, rho_a, rho_b)
            compared += 1
        # Each difference moves one law's probability by 1/N at most.
        gap = np.abs(cpu.model_probabilities.iloc[g, :4].to_numpy() - gpu.model_probabilities.iloc[g, :4].to_numpy())
        assert gap.max() <= len(a.keys() ^ b.keys()) / n + 1e-12, (g, gap)
    assert compared >= 3 * n - 2 * sum(p["near_threshold"] for p in gpu_pops)


def test_which_gpu_scores_is_logged_not_warned(demo, caplog) -> None:
    import logging
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error", bitrock.BitrockWarning)
        with caplog.at_level(logging.INFO, logger="bitrock"):
            bitrock.abc(demo, laws=["m2"], particles=100, seed=1, backend="gpu", max_populations=1, progress=False)
    assert any(r.name == "bitrock" and r.getMessage().startswith("GPU backend:") for r in caplog.records)


def test_a_gpu_run_prints_no_desktop_session_complaint() -> None:
    """Where no desktop session runs (no XDG_RUNTIME_DIR), Mesa's device-select layer would print
    its complaint twice on the first GPU use: the package switches it off as it loads."""
    import subprocess
    import sys

    env = {k: v for k, v in os.environ.items() if k not in ("XDG_RUNTIME_DIR", "NODEVICE_SELECT")}
    script = "import bitrock; bitrock.abc(bitrock.read_record(), laws=['m2'], particles=100, seed=1, backend='gpu', max_populations=1, progress=False)"
    done = subprocess.run([sys.executable, "-W", "ignore", "-c", script], env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert "XDG_RUNTIME_DIR" not in done.stderr, done.stderr
