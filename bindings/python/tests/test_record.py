"""Reading records: CSV files, DataFrames at N·m and kN·m scale, and the refusals."""

from __future__ import annotations

import errno
import warnings

import numpy as np
import pandas as pd
import pytest

import bitrock
from conftest import DEMO_CSV


def test_the_demo_record_is_the_repository_csv(demo: bitrock.Record) -> None:
    from_file = bitrock.read_record(DEMO_CSV)
    assert (demo.rows_read, demo.rows_used) == (9000, 5374)
    assert demo.columns == ("bit_speed_rpm", "torque_knm", "wob_kn", "time_s")
    assert (demo.torque_unit, demo.speed_unit) == ("kN·m", "rpm")
    for a, b in zip(demo.calibration() + demo.validation(), from_file.calibration() + from_file.validation()):
        assert np.array_equal(a, b)


def test_a_dataframe_reads_as_its_csv_bit_for_bit(demo: bitrock.Record) -> None:
    frame = pd.read_csv(DEMO_CSV)
    record = bitrock.read_record(frame)
    assert record.source == "<DataFrame>"
    assert (record.rows_read, record.rows_used) == (demo.rows_read, demo.rows_used)
    for a, b in zip(record.calibration() + record.validation(), demo.calibration() + demo.validation()):
        assert np.array_equal(a, b)


def test_arrays_read_as_their_csv_bit_for_bit(demo: bitrock.Record) -> None:
    frame = pd.read_csv(DEMO_CSV)
    record = bitrock.read_record(
        speed=frame["bit_speed_rpm"].to_numpy(),
        torque=frame["torque_knm"].to_list(),
        wob=frame["wob_kn"].to_numpy(),
        time=frame["time_s"].to_numpy(),
        speed_unit="rpm",
        torque_unit="knm",
        wob_unit="kn",
    )
    assert record.source == "<arrays>"
    assert (record.rows_read, record.rows_used) == (demo.rows_read, demo.rows_used)
    for a, b in zip(record.calibration() + record.validation(), demo.calibration() + demo.validation()):
        assert np.array_equal(a, b)
    # The same numbers in N·m and rad/s are the same samples.
    si = bitrock.read_record(speed=frame["bit_speed_rpm"].to_numpy() * np.pi / 30, torque=frame["torque_knm"].to_numpy() * 1000, speed_unit="rad_s", torque_unit="nm")
    np.testing.assert_allclose(si.calibration()[1], demo.calibration()[1], rtol=1e-15)


@pytest.mark.parametrize(
    ("arguments", "argument"),
    [
        ({"speed": [1.0, 2.0], "torque": [3.0, 4.0], "torque_unit": "knm"}, "speed_unit"),
        ({"speed": [1.0, 2.0], "torque": [3.0, 4.0], "speed_unit": "rpm"}, "torque_unit"),
        ({"speed": [1.0, 2.0], "speed_unit": "rpm", "torque_unit": "knm"}, "torque"),
        ({"speed": [1.0, 2.0], "torque": [3.0], "speed_unit": "rpm", "torque_unit": "knm"}, "torque"),
        ({"speed": [[1.0, 2.0]], "torque": [3.0, 4.0], "speed_unit": "rpm", "torque_unit": "knm"}, "speed"),
        ({"speed": ["a", "b"], "torque": [3.0, 4.0], "speed_unit": "rpm", "torque_unit": "knm"}, "speed"),
        ({"speed": [1.0, 2.0], "torque": [3.0, 4.0], "wob": [1.0, 1.0], "speed_unit": "rpm", "torque_unit": "knm"}, "wob_unit"),
        ({"source": DEMO_CSV, "speed": [1.0], "torque": [1.0], "speed_unit": "rpm", "torque_unit": "knm"}, "source"),
    ],
)
def test_arrays_without_units_or_of_the_wrong_shape_are_refused(arguments, argument) -> None:
    with pytest.raises(bitrock.InputError) as caught:
        bitrock.read_record(**arguments)
    assert caught.value.argument == argument


def test_samples_are_in_si(demo: bitrock.Record) -> None:
    speed, torque = demo.calibration()
    frame = pd.read_csv(DEMO_CSV)
    kept = frame[frame["bit_speed_rpm"] >= 5.0].head(len(speed))
    np.testing.assert_allclose(speed, kept["bit_speed_rpm"] * np.pi / 30, rtol=1e-15)
    np.testing.assert_allclose(torque, kept["torque_knm"] * 1e3, rtol=1e-15)


def test_a_laboratory_record_in_newton_metres_and_rad_s_with_negative_speeds() -> None:
    frame = pd.read_csv(DEMO_CSV)
    lab = pd.DataFrame(
        {
            "t_s": frame["time_s"],
            # A rig turning backwards at times: negative and near-zero speeds are stick, dropped.
            "speed_rad_s": (frame["bit_speed_rpm"] - 20.0) * np.pi / 30,
            "torque_nm": frame["torque_knm"] * 1e3,
            "note": "rig A",
        }
    )
    record = bitrock.read_record(lab, time_col="t_s", min_speed_rpm=1.0)
    assert (record.torque_unit, record.speed_unit) == ("N·m", "rad/s")
    assert record.columns == ("speed_rad_s", "torque_nm", None, "t_s")
    assert record.rows_used == int((lab["speed_rad_s"] >= np.pi / 30).sum())
    speed, torque = record.calibration()
    assert speed.min() >= np.pi / 30 * (1 - 1e-12)
    np.testing.assert_allclose(torque[:5], lab["torque_nm"][lab["speed_rad_s"] >= np.pi / 30][:5], rtol=1e-15)


def test_time_columns_of_dataframes_are_seconds() -> None:
    frame = pd.read_csv(DEMO_CSV)
    timed = frame.assign(time_s=pd.to_timedelta(frame["time_s"], unit="s"))
    dated = frame.assign(time_s=pd.Timestamp("2026-01-01") + pd.to_timedelta(frame["time_s"], unit="s"))
    window = bitrock.read_record(frame, t_start_s=20.0, t_end_s=60.0)
    for other in (timed, dated):
        record = bitrock.read_record(other, t_start_s=20.0, t_end_s=60.0)
        assert record.rows_used == window.rows_used
        np.testing.assert_allclose(record.calibration()[1], window.calibration()[1], rtol=0)


def test_splits_and_thinning_follow_their_arguments() -> None:
    block = bitrock.read_record(calibration_fraction=0.25)
    interleaved = bitrock.read_record(calibration_fraction=0.25, split="interleaved")
    thinned = bitrock.read_record(thin=3)
    assert len(block.calibration()[0]) == int(np.ceil(0.25 * block.rows_used))
    assert abs(len(interleaved.calibration()[0]) - 0.25 * interleaved.rows_used) <= 1
    assert thinned.rows_used < block.rows_used / 2


def test_a_missing_file_is_file_not_found() -> None:
    with pytest.raises(FileNotFoundError) as caught:
        bitrock.read_record("no/such/record.csv")
    assert caught.value.errno == errno.ENOENT
    assert caught.value.filename == "no/such/record.csv"


def test_a_bad_cell_names_file_line_and_column(tmp_path) -> None:
    path = tmp_path / "bad.csv"
    path.write_text("time_s,bit_speed_rpm,torque_knm\n0,60,10\n0.02,61,x\n0.04,62,9\n")
    with pytest.raises(bitrock.InputError) as caught:
        bitrock.read_record(path)
    assert caught.value.argument is None
    assert str(caught.value) == f"{path}:3:3: column 'torque_knm': 'x' is not a number"


def test_dataframe_refusals_name_column_and_row() -> None:
    frame = pd.read_csv(DEMO_CSV).head(50)
    frame.loc[7, "torque_knm"] = np.nan
    with pytest.raises(bitrock.InputError, match=r"^<DataFrame>: column 'torque_knm', row 7: NaN is not a finite number$"):
        bitrock.read_record(frame)
    labelled = pd.read_csv(DEMO_CSV).head(50).assign(comment="ok")
    with pytest.raises(bitrock.InputError, match=r"column 'comment' does not hold numbers"):
        bitrock.read_record(labelled, torque_col="comment", torque_unit="knm")


def test_arguments_are_named_as_the_caller_wrote_them() -> None:
    with pytest.raises(bitrock.InputError, match=r"no column named 'rpm' \(given by `speed_col`\)"):
        bitrock.read_record(speed_col="rpm")
    with pytest.raises(bitrock.InputError) as caught:
        bitrock.read_record(speed_unit="furlongs")
    assert caught.value.argument == "speed_unit"
    assert str(caught.value) == "speed_unit: unknown unit `furlongs`"
    with pytest.raises(bitrock.InputError) as caught:
        bitrock.read_record(calibration_fraction=1.5)
    assert caught.value.argument == "calibration_fraction"
    assert isinstance(caught.value, ValueError)


def test_a_torque_in_nm_under_a_knm_name_is_warned_of_where_it_is_read() -> None:
    frame = pd.read_csv(DEMO_CSV)
    frame["torque_knm"] *= 1000.0
    with pytest.warns(bitrock.BitrockWarning, match=r"column 'torque_knm' read in kN·m have a median of \d+ kN·m") as caught:
        record = bitrock.read_record(frame)
    assert len(caught) == 1 and caught[0].filename == __file__
    assert record.warnings == [str(caught[0].message)]
    # The demo record, in its stated units, raises none.
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert bitrock.read_record(None).warnings == []


def test_a_record_pickles_to_the_bit(demo) -> None:
    import pickle

    again = pickle.loads(pickle.dumps(demo))
    assert repr(again) == repr(demo)
    for a, b in zip(demo.calibration() + demo.validation(), again.calibration() + again.validation()):
        assert np.array_equal(a, b)
    assert again.warnings == demo.warnings and again.columns == demo.columns
    assert again.torque_unit == demo.torque_unit and again.source == demo.source
    # The same record gives the same run, bit for bit.
    runs = [bitrock.abc(r, particles=200, seed=3, backend="cpu", max_populations=2, progress=False) for r in (demo, again)]
    assert runs[0].model_probabilities.equals(runs[1].model_probabilities)


def test_a_rig_export_with_iso_stamps_mnemonics_and_imperial_units(tmp_path) -> None:
    """A rig's export of the demo record (ISO 8601 stamps at +01:00, ``RPM_DH``/``TOB``
    mnemonics, weight in klbf, torque in kft·lbf) reads as the demo record by path and as a
    DataFrame, its clock counted from midnight UTC (13:30 UTC = 48,600 s)."""
    frame = pd.read_csv(DEMO_CSV)
    stamps = pd.Timestamp("2026-11-29T14:30:00+01:00") + pd.to_timedelta(frame["time_s"], unit="s")
    rig = pd.DataFrame(
        {
            "TIME": stamps.dt.strftime("%Y-%m-%dT%H:%M:%S.%f%z").str.replace(r"(\d\d)(\d\d)$", r"\1:\2", regex=True),
            "RPM_DH": frame["bit_speed_rpm"],
            "TOB (kft.lbf)": frame["torque_knm"] * 1e3 / 1355.8179483314004,
            "WOB [klbf]": frame["wob_kn"] * 1e3 / 4448.2216152605,
        }
    )
    path = tmp_path / "rig.csv"
    rig.to_csv(path, index=False, float_format="%.17g")
    window = {"t_start_s": 48_610.0, "t_end_s": 48_620.0}
    demo = bitrock.read_record(frame, t_start_s=10.0, t_end_s=20.0)
    read = [
        bitrock.read_record(str(path), **window),
        bitrock.read_record(pd.read_csv(path), **window),
        bitrock.read_record(pd.read_csv(path, parse_dates=["TIME"]), **window),
    ]
    for record in read:
        assert record.rows_used == demo.rows_used
        assert record.torque_unit == "kft·lbf"
        speed, torque = record.calibration()
        np.testing.assert_array_equal(speed, demo.calibration()[0])
        np.testing.assert_allclose(torque, demo.calibration()[1], rtol=1e-12)
    # Given by keyword, the imperial units are accepted as the command's flags are.
    renamed = pd.read_csv(path).rename(columns={"TOB (kft.lbf)": "TOB", "WOB [klbf]": "WOB"})
    record = bitrock.read_record(renamed, torque_unit="kftlbf", wob_unit="klbf", **window)
    np.testing.assert_allclose(record.calibration()[1], demo.calibration()[1], rtol=1e-12)


def test_a_column_map_names_a_rig_s_columns_and_units(tmp_path) -> None:
    """``column_map`` reads a rig's columns by the command's column map file; a keyword beside
    it wins."""
    frame = pd.read_csv(DEMO_CSV)
    rig = pd.DataFrame({"T": frame["time_s"], "CH1": frame["bit_speed_rpm"], "CH2": frame["torque_knm"]})
    path = tmp_path / "rig.csv"
    rig.to_csv(path, index=False)
    column_map = tmp_path / "rig.toml"
    column_map.write_text('speed = "CH1"\nspeed_unit = "rpm"\ntorque = "CH2"\ntorque_unit = "kN.m"\ntime = "T"\n')
    demo = bitrock.read_record(frame)
    record = bitrock.read_record(path, column_map=column_map)
    np.testing.assert_array_equal(record.calibration()[1], demo.calibration()[1])
    assert record.columns[:2] == ("CH1", "CH2")
    assert bitrock.read_record(path, column_map=column_map, torque_unit="nm").torque_unit == "N·m"
    column_map.write_text('speed = "CH1"\ntorque_unit = "daN.m"\n')
    with pytest.raises(bitrock.InputError, match="a unit bitrock does not read"):
        bitrock.read_record(path, column_map=column_map)
