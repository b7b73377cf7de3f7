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
    with pytest.raises(bitrock.InputError) as caught:
        bitrock.parity(candidates=0)
    assert caught.value.argument == "candidates"


def test_a_gpu_run_keeps_the_cpu_runs_particles_away_from_epsilon(demo) -> None:
    cpu = bitrock.abc(demo, particles=300, seed=11, backend="cpu", max_populations=3, progress=False)
    gpu = bitrock.abc(demo, particles=300, seed=11, backend="gpu", max_populations=3, progress=False)
    assert gpu.document["backend"] != "cpu"
    # The same candidates are drawn on both; ρ agrees within the parity tolerance, so the
    # populations agree unless a ρ lies that close to ε (counted by the run).
    near = sum(p["near_threshold"] for p in gpu.document["populations"])
    if near == 0:
        for law, (_n, params, *_r) in cpu.particles().items():
            assert np.array_equal(params, gpu.particles()[law][1])
    np.testing.assert_allclose(cpu.model_probabilities.iloc[0, :4], gpu.model_probabilities.iloc[0, :4], atol=0)
