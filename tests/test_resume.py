"""Interrupt and resume: a run stopped after a checkpoint and continued with ``--resume`` ends
with exactly the outputs of an uninterrupted run.

The interruption is a wall-time callback (where the command line's checkpoints are written)
that writes the checkpoint into the run directory at a chosen simulated time and raises
``KeyboardInterrupt`` right after, as Ctrl-C would.  The interrupted run keeps what it had
written (``stop_reason`` "interrupted"); ``fipy-hopper run ... --resume`` restores the
checkpoint, drops the snapshots taken after it and continues.  The run is deterministic, so the
summary numbers, the time series, the wall samples and every field snapshot, the final one
included, must be *bitwise* equal to the uninterrupted run's.
"""

import json
import shutil
import warnings

import meshio
import numpy as np
import pytest

from fipy_hopper import api
from fipy_hopper.cli import main
from fipy_hopper.io import marker_file, read_markers, read_snapshot_index

CONFIG = """\
[hopper]
bin_diameter = 0.2
outlet_diameter = 0.06
bin_height = 0.25
fill_height = 0.15

[numerics]
cell_size = 0.01
gravity_ramp_time = 0.05

[run]
end_time = 0.12
output_interval = 0.02
field_interval = 0.05
markers_per_side = 2
"""


@pytest.fixture(scope="module")
def setup_dirs(tmp_path_factory):
    folder = tmp_path_factory.mktemp("resume")
    config = folder / "coarse.toml"
    config.write_text(CONFIG)
    reference = folder / "uninterrupted"
    assert main(["run", str(config), "--out", str(reference), "--quiet"]) == 0
    return folder, config, reference


def interrupt_when(condition, out):
    """A ``setup(sim)`` hook: checkpoint and Ctrl-C at the first check where ``condition``."""

    def setup(sim):
        def maybe_interrupt(sim_, state):
            if condition(sim_, state):
                sim_.checkpoint(out / "checkpoint.npz")
                raise KeyboardInterrupt

        sim.add_wall_time_callback(maybe_interrupt, 0.0)    # every check

    return setup


def interrupt_and_resume(folder, config, name, condition):
    out = folder / name
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(KeyboardInterrupt):
            api.run(config, out, setup=interrupt_when(condition, out), plots=False)
    summary = json.loads((out / "summary.json").read_text())
    manifest = json.loads((out / "manifest.json").read_text())
    assert summary["stop_reason"] == "interrupted" and manifest["status"] == "interrupted"
    assert (out / "checkpoint.npz").is_file()
    assert main(["run", str(config), "--out", str(out), "--resume", "--quiet"]) == 0
    return out


def assert_same_outputs(resumed, reference):
    a = json.loads((resumed / "summary.json").read_text())
    b = json.loads((reference / "summary.json").read_text())
    a.pop("wall_time_s"), b.pop("wall_time_s")
    assert a == b                                     # every number, bitwise (JSON repr)
    for name in ("timeseries.csv", "wall_pressure.csv", "fields/snapshots.csv",
                 "fields/fields.pvd", "config.toml"):
        assert (resumed / name).read_text() == (reference / name).read_text(), name
    snaps = read_snapshot_index(reference / "fields")
    assert sorted(p.name for p in (resumed / "fields").glob("fields_*.vtu")) == \
        [s["file"] for s in snaps]
    assert sorted(p.name for p in (resumed / "fields").glob("markers_*.vtu")) == \
        [marker_file(s["file"]) for s in snaps]
    for entry in snaps:
        markers_a = read_markers(resumed / "fields" / marker_file(entry["file"]))
        markers_b = read_markers(reference / "fields" / marker_file(entry["file"]))
        np.testing.assert_array_equal(markers_a, markers_b)
        m_a = meshio.read(resumed / "fields" / entry["file"])
        m_b = meshio.read(reference / "fields" / entry["file"])
        for key in m_b.cell_data:
            np.testing.assert_array_equal(m_a.cell_data[key][0], m_b.cell_data[key][0],
                                          err_msg=f"{entry['file']}: {key}")
        np.testing.assert_array_equal(m_a.point_data["node_velocity"],
                                      m_b.point_data["node_velocity"])
    manifest = json.loads((resumed / "manifest.json").read_text())
    assert manifest["status"] == "finished" and len(manifest["sessions"]) == 2
    assert manifest["sessions"][1]["resumed_from_step"] > 0
    assert not (resumed / "checkpoint.npz").exists()
    assert (resumed / "flow_pattern.png").is_file() and (resumed / "discharge.gif").is_file()


def test_resume_during_discharge_equals_uninterrupted(setup_dirs):
    folder, config, reference = setup_dirs
    out = interrupt_and_resume(
        folder, config, "discharge",
        lambda sim, st: st.stage == "discharge" and st.t - sim.t_open >= 0.071)
    assert_same_outputs(out, reference)


def test_the_window_extremes_resume_exactly(setup_dirs):
    """The smallest and the largest windowed wall pressure of every bin (the loop's
    ``window_extremes``, what the studies' envelopes read) of a run interrupted in discharge and
    resumed equal the uninterrupted run's bit for bit, over the same number of windows (at
    least three, so that the checkpoint lies between windows and the extremes differ)."""
    folder, _, _ = setup_dirs
    config = folder / "windows.toml"
    config.write_text(CONFIG + "load_window = 0.02\n")
    runs = {}

    def keep(name):
        return lambda sim: runs.__setitem__(name, sim)

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        api.run(config, folder / "windows_whole", setup=keep("whole"), plots=False,
                quiet=True)
        out = folder / "windows_resumed"
        with pytest.raises(KeyboardInterrupt):
            api.run(config, out, plots=False, setup=interrupt_when(
                lambda sim, st: st.stage == "discharge" and st.t - sim.t_open >= 0.061, out))
        api.run(config, out, resume=True, setup=keep("resumed"), plots=False, quiet=True)
    whole, resumed = runs["whole"], runs["resumed"]
    assert whole.record.envelope_windows == resumed.record.envelope_windows >= 3
    for a, b in zip(whole.window_extremes, resumed.window_extremes):
        np.testing.assert_array_equal(a, b)
    low, high = whole.window_extremes
    measured = np.isfinite(low)
    assert measured.sum() >= 10 and np.all(low[measured] <= high[measured])
    assert np.any(low[measured] < high[measured])
    np.testing.assert_array_equal(high[measured], whole.envelope[measured])


def test_resume_during_filling_equals_uninterrupted(setup_dirs):
    folder, config, reference = setup_dirs
    out = interrupt_and_resume(folder, config, "filling",
                               lambda sim, st: st.stage == "filling" and st.t >= 0.02)
    assert_same_outputs(out, reference)


def test_resume_from_a_check_that_takes_a_sample(setup_dirs):
    folder, config, reference = setup_dirs

    def on_a_sample(sim, st):
        """The first check after a time-series sample (taken at its own step, between
        checks: the checkpoint holds the sample and the next sample time)."""
        if st.stage != "discharge" or st.t - sim.t_open < 0.05:
            return False
        since = st.t - sim.t_open - sim.record.t[-1]
        return bool(sim.record.t and 0.0 <= since <= 0.002 + 1e-12)

    out = interrupt_and_resume(folder, config, "on_sample", on_a_sample)
    assert_same_outputs(out, reference)


def test_sigterm_then_resume_from_the_periodic_checkpoint(setup_dirs, capsys):
    """The real thing: ``fipy-hopper run`` writes its periodic checkpoints, is stopped by SIGTERM
    (as a batch scheduler does) at whatever point it has reached, exits 130 with everything
    written so far, and ``--resume`` finishes the run with a seamless time series and field
    series.  The signal comes from a watcher thread once the first checkpoint exists."""
    import os
    import signal
    import threading
    import time

    folder, config, reference = setup_dirs
    out = folder / "terminated"

    def watch():
        deadline = time.monotonic() + 60
        while not (out / "checkpoint.npz").exists() and time.monotonic() < deadline:
            time.sleep(0.01)
        os.kill(os.getpid(), signal.SIGTERM)

    # a SIGTERM arriving after the run must not end the test session
    previous = signal.signal(signal.SIGTERM, lambda signum, frame: None)
    try:
        watcher = threading.Thread(target=watch, daemon=True)
        watcher.start()
        code = main(["run", str(config), "--out", str(out), "--quiet",
                     "--checkpoint-interval", "0.02"])
        watcher.join(timeout=60)
    finally:
        signal.signal(signal.SIGTERM, previous)
    err = capsys.readouterr().err
    assert code == 130, err
    assert "--resume" in err and "Traceback" not in err
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["status"] == "interrupted" and manifest["checkpoints_written"] >= 1

    assert main(["run", str(config), "--out", str(out), "--resume", "--quiet"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    expected = json.loads((reference / "summary.json").read_text())
    assert summary["stop_reason"] == "end_time" and summary["steps"] == expected["steps"]
    ts = (out / "timeseries.csv").read_text().splitlines()
    t = np.array([float(line.split(",")[0]) for line in ts[1:]])
    assert len(t) == len((reference / "timeseries.csv").read_text().splitlines()) - 1
    gaps = np.diff(t)[:-1]                                 # the last sample is the end state
    assert np.all(np.abs(gaps - 0.02) < 0.0025)           # every 0.02 s, on 2 ms checks
    snaps = read_snapshot_index(out / "fields")
    assert [s["index"] for s in snaps] == list(range(len(snaps)))
    assert np.all(np.diff([s["t_s"] for s in snaps]) > 0)
    assert sorted(p.name for p in (out / "fields").glob("fields_*.vtu")) == \
        [s["file"] for s in snaps]
    assert len(json.loads((out / "manifest.json").read_text())["sessions"]) == 2


def test_a_checkpoint_without_the_stretch_fractions_resumes_with_them_unknown_before(
        setup_dirs):
    """A checkpoint written before the record kept each stretch's slip fraction per sample
    (``wall_slip_stretch_fractions``): the run resumes, the samples before the checkpoint
    have it unknown (NaN), and every table and every number of the summary equals the
    uninterrupted run's (those samples lie before the flow-mode window)."""
    folder, config, reference = setup_dirs
    out = folder / "older"
    condition = (lambda sim, st: st.stage == "discharge" and st.t - sim.t_open >= 0.071)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(KeyboardInterrupt):
            api.run(config, out, setup=interrupt_when(condition, out), plots=False)
    path = out / "checkpoint.npz"
    with np.load(path) as data:
        arrays = {k: data[k] for k in data.files}
    meta = json.loads(str(arrays["__meta__"]))
    assert len(meta["record"].pop("wall_slip_stretch_fractions")) > 0
    arrays["__meta__"] = np.array(json.dumps(meta))
    with open(path, "wb") as fh:
        np.savez(fh, **arrays)
    assert main(["run", str(config), "--out", str(out), "--resume", "--quiet"]) == 0
    for name in ("timeseries.csv", "wall_pressure.csv", "loads.csv", "wall_slip.csv"):
        assert (out / name).read_bytes() == (reference / name).read_bytes(), name
    summary_a = json.loads((out / "summary.json").read_text())
    summary_b = json.loads((reference / "summary.json").read_text())
    summary_a.pop("wall_time_s"), summary_b.pop("wall_time_s")
    assert summary_a == summary_b


# ---------------------------------------------------------------- crafted checkpoints
@pytest.fixture(scope="module")
def interrupted(setup_dirs):
    """An interrupted run (during discharge) with its checkpoint and its profile.json."""
    folder, config, _ = setup_dirs
    out = folder / "interrupted"
    condition = (lambda sim, st: st.stage == "discharge" and st.t - sim.t_open >= 0.05)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(KeyboardInterrupt):
            api.run(config, out, setup=interrupt_when(condition, out), plots=False,
                    profile=True)
    assert (out / "profile.json").is_file() and (out / "summary.json").is_file()
    return out


def rewrite_checkpoint(path, change):
    """Apply ``change(arrays, meta)`` to the checkpoint at ``path``, in place."""
    with np.load(path) as data:
        arrays = {k: data[k] for k in data.files}
    meta = json.loads(str(arrays.pop("__meta__")))
    change(arrays, meta)
    with open(path, "wb") as fh:
        np.savez(fh, __meta__=np.array(json.dumps(meta)), **arrays)


def state(key, value):
    return lambda arrays, meta: meta["state"].__setitem__(key, value)


def record(key, value):
    return lambda arrays, meta: meta["record"].__setitem__(key, value)


CRAFTED = [
    ("a step of 2**70", state("step", 2 ** 70), ["state step = 1180591620717411303424",
                                                 "a whole number in [0, "]),
    ("a step that is a bool", state("step", True), ["state step = True"]),
    ("a time of 1e300 s", state("t", 1e300), ["state time t = 1e+300", "[0, "]),
    ("a negative time", state("t", -1.0), ["state time t = -1.0"]),
    ("a time as text", state("t", "0.3"), ["state time t = 0.3"]),
    ("an unknown stage", state("stage", "emptying"), ["state stage = emptying"]),
    ("a closed plate as a number", state("plate_closed", 1), ["plate_closed = 1", "bool"]),
    ("an infinite discharged mass", state("discharged", float("inf")),
     ["discharged = inf", "finite number"]),
    ("a time series of text", record("t", ["a", "b"]), ["record's t"]),
    ("a stop reason that is a number", record("stop_reason", 3), ["record's stop_reason"]),
    ("a negative step count", record("steps", -5), ["record's steps"]),
    ("an unknown record field", record("surprise", 1), ["unknown field 'surprise'"]),
    ("time series of different lengths", lambda a, m: m["record"]["rate"].append(0.0),
     ["different lengths"]),
    ("an envelope of another length",
     lambda a, m: a.update(envelope=np.zeros(5)), ["'envelope'", "shape (5,)"]),
    ("a wall sample of another grid's bins",
     lambda a, m: [a.__setitem__(f"wall__filling__{k}", np.zeros(3)) for k in range(5)],
     ["'wall__filling__0'", "shape (3,)"]),
    ("a reading of another contact count",
     lambda a, m: a.update(reading__sample__wall=np.zeros((2, 2))),
     ["'reading__sample__wall'", "shape"]),
    ("an unknown stage of the wall samples",
     lambda a, m: [m["wall_times"].__setitem__("flood", 0.0)]
     + [a.__setitem__(f"wall__flood__{k}", a[f"wall__filling__{k}"]) for k in range(5)],
     ["unknown stage 'flood'"]),
    ("a schedule that is text", lambda a, m: m["schedules"].__setitem__(0, "soon"),
     ["schedule times"]),
    ("a state without its loose strain", lambda a, m: a.pop("loose"),
     ["array 'loose' of the state is missing"]),
    ("a wall stage without its forces in the wall",
     lambda a, m: [a.pop(f"wallforces__filling__{k}") for k in range(3)],
     ["'wallforces__filling__0' is missing"]),
    ("an opening time that is NaN", lambda a, m: m.__setitem__("t_open", float("nan")),
     ["its t_open = nan", "opening time", "allowed range [0, "]),
    ("an opening after the checkpoint's time",
     lambda a, m: m.__setitem__("t_open", m["state"]["t"] + 100.0), ["its t_open = "]),
    ("a next sample far ahead", lambda a, m: m.__setitem__("next_sample", 1e5),
     ["its next_sample = 100000", "allowed range ["]),
    ("an envelope window that never ends", lambda a, m: m.__setitem__("next_envelope", 1e9),
     ["its next_envelope = 1000000000.0"]),
    ("an initial mass that is NaN", record("initial_mass", float("nan")),
     ["its record's initial_mass = nan", "(0, inf) kg"]),
    ("negative mass books", lambda a, m: m.__setitem__("mass_books", -1.0),
     ["its mass_books = -1.0", "(0, inf) kg"]),
    ("a schedule in the far future", lambda a, m: m["schedules"].__setitem__(1, 1e5),
     ["its schedule time 100000.0", "allowed range [0, "]),
    ("another run's fingerprint", lambda a, m: m.__setitem__("fingerprint", "0" * 64),
     ["belongs to another run"]),
    ("no fingerprint", lambda a, m: m.pop("fingerprint"), ["no fingerprint"]),
]


def snapshot_of(folder):
    return {p.relative_to(folder): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file()}


@pytest.mark.parametrize("name, change, words", CRAFTED, ids=[c[0] for c in CRAFTED])
def test_a_crafted_checkpoint_is_refused_before_anything_is_touched(
        interrupted, setup_dirs, tmp_path, capsys, name, change, words):
    """Wrong types, absurd times and steps, another grid's measurements, another run: one
    line naming the checkpoint and what is wrong, exit 2, and every file of the run directory
    (summary.json, profile.json, the snapshots) as it was."""
    _, config, _ = setup_dirs
    out = tmp_path / "run"
    shutil.copytree(interrupted, out)
    rewrite_checkpoint(out / "checkpoint.npz", change)
    before = snapshot_of(out)
    assert main(["run", str(config), "--out", str(out), "--resume", "--quiet"]) == 2
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if "warning:" not in line]
    assert len(lines) == 1 and lines[0].startswith(
        f"fipy-hopper: error: checkpoint {out / 'checkpoint.npz'}: "), err
    for word in words:
        assert word in lines[0], (word, lines[0])
    assert snapshot_of(out) == before


def test_another_runs_checkpoint_of_the_same_grid_is_refused(interrupted, setup_dirs, tmp_path,
                                                             capsys):
    """A checkpoint of a run of another material on the same grid (the arrays fit): refused
    by the fingerprint of the configuration, before the mass check could notice."""
    folder, config, _ = setup_dirs
    other = tmp_path / "other.toml"
    other.write_text(CONFIG.replace("[run]", "[material]\ndensity = 1400.0\n\n[run]"))
    foreign = tmp_path / "foreign"
    condition = (lambda sim, st: st.stage == "filling" and st.t >= 0.02)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(KeyboardInterrupt):
            api.run(other, foreign, setup=interrupt_when(condition, foreign), plots=False)
    out = tmp_path / "run"
    shutil.copytree(interrupted, out)
    shutil.copy(foreign / "checkpoint.npz", out / "checkpoint.npz")
    before = snapshot_of(out)
    assert main(["run", str(config), "--out", str(out), "--resume", "--quiet"]) == 2
    assert "belongs to another run" in capsys.readouterr().err
    assert snapshot_of(out) == before


def test_a_good_checkpoint_still_resumes_and_drops_the_old_profile(interrupted, setup_dirs,
                                                                    tmp_path):
    _, config, reference = setup_dirs
    out = tmp_path / "run"
    shutil.copytree(interrupted, out)
    assert main(["run", str(config), "--out", str(out), "--resume", "--quiet"]) == 0
    assert not (out / "profile.json").exists()
    assert_same_outputs(out, reference)
