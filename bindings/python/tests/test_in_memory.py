"""A run kept in memory is first-class: it saves to the run directory the command line would
have written, pickles whole, and is mapped and checked like a stored run."""

from __future__ import annotations

import json
import pickle

import numpy as np
import pytest

import bitrock
from conftest import run_cli

SETTINGS = dict(laws=["m2", "m3"], particles=200, seed=13, backend="cpu", max_populations=3, progress=False)


@pytest.fixture(scope="module")
def in_memory(demo: bitrock.Record) -> bitrock.Result:
    return bitrock.abc(demo, **SETTINGS)


def test_a_saved_run_is_the_run_out_writes(cli, demo, in_memory, tmp_path) -> None:
    written = bitrock.abc(demo, out=tmp_path / "out", **SETTINGS)
    saved = in_memory.save(tmp_path / "saved")
    assert saved.path == tmp_path / "saved" and in_memory.path is None
    # Every particle of every population byte for byte; the whole run as JSON alike but for the
    # wall-clock times two runs measure.
    for g in range(3):
        ours = run_cli(cli, "export", str(tmp_path / "saved"), "--population", str(g)).stdout
        theirs = run_cli(cli, "export", str(tmp_path / "out"), "--population", str(g)).stdout
        assert ours == theirs, f"population {g}"
    ours = json.loads(run_cli(cli, "export", str(tmp_path / "saved"), "--format", "json").stdout)
    theirs = json.loads(run_cli(cli, "export", str(tmp_path / "out"), "--format", "json").stdout)
    assert _untimed(ours) == _untimed(theirs)
    for name in ("envelopes.csv", "data.csv"):
        assert (tmp_path / "saved" / name).read_bytes() == (tmp_path / "out" / name).read_bytes(), name
    assert _untimed(saved.document) == _untimed(written.document)
    # Continued, it gives the populations the run written by `out` gives.
    more = dict(max_populations=4, progress=False)
    with pytest.warns(bitrock.BitrockWarning, match="continuing"):
        a = bitrock.resume(tmp_path / "saved", **more)
    with pytest.warns(bitrock.BitrockWarning, match="continuing"):
        b = bitrock.resume(tmp_path / "out", **more)
    assert len(a.populations) == 4
    for law, (_n, params, weights, *_rest) in b.particles().items():
        assert np.array_equal(params, a.particles()[law][1]) and np.array_equal(weights, a.particles()[law][2])


def test_a_saved_run_refuses_to_overwrite_and_a_stored_run_has_nothing_to_save(in_memory, tmp_path) -> None:
    stored = in_memory.save(tmp_path / "run")
    with pytest.raises(bitrock.InputError, match="pass `force` to replace it") as caught:
        in_memory.save(tmp_path / "run")
    assert caught.value.argument == "out"
    assert in_memory.save(tmp_path / "run", force=True).path == tmp_path / "run"
    with pytest.raises(bitrock.InputError, match="stored already") as caught:
        stored.save(tmp_path / "other")
    assert caught.value.argument == "path"
    assert not (tmp_path / "other").exists()


def test_a_pickled_run_in_memory_saves_and_checks_alike(in_memory, tmp_path) -> None:
    copy = pickle.loads(pickle.dumps(in_memory))
    copy.save(tmp_path / "copy")
    in_memory.save(tmp_path / "original")
    for g in range(3):
        a = bitrock.open_run(tmp_path / "copy").particles(g)
        b = bitrock.open_run(tmp_path / "original").particles(g)
        for law in b:
            assert np.array_equal(a[law][1], b[law][1]) and np.array_equal(a[law][2], b[law][2])


def test_a_run_in_memory_is_checked_as_its_saved_directory_is(cli, in_memory, tmp_path) -> None:
    matrix = bitrock.check_selection(in_memory, replicates=2, backend="cpu", progress=False)
    assert matrix.attrs["document"]["run_dir"] is None
    in_memory.save(tmp_path / "run")
    document = json.loads(run_cli(cli, "check-selection", str(tmp_path / "run"), "--replicates", "2", "--backend", "cpu", "--json", "-q").stdout)
    assert [r["law"] for r in document["rows"]] == list(matrix.index)
    for ours, theirs in zip(matrix.attrs["document"]["rows"], document["rows"]):
        assert ours["mean_probability"] == theirs["mean_probability"]
        assert ours["first_share"] == theirs["first_share"]
        assert ours["verdict"] == theirs["verdict"]
    with pytest.raises(bitrock.InputError) as caught:
        bitrock.check_selection(42, replicates=2)
    assert caught.value.argument == "source"


def _untimed(document):
    """``document`` without what two runs of the same settings measure differently: seconds."""
    if isinstance(document, dict):
        return {k: _untimed(v) for k, v in document.items() if "seconds" not in k and not k.endswith("_unix_s")}
    if isinstance(document, list):
        return [_untimed(v) for v in document]
    return document
