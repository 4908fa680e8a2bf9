"""Ctrl-C at any moment: exit code 130, a manifest in a finished state, the right advice.

Each case is a real ``fipy-hopper run`` in a subprocess that sends itself SIGINT (or SIGTERM)
at one moment of its life: while an earlier run's files are removed, right after the
manifest is begun, while filling, in the middle of writing a checkpoint, during the
discharge, half-way through taking a sample of the time series, while the summary and the tables are written, while the manifest is ended, while
the pictures are drawn, while the summary is printed.  Whatever the moment, the run exits
with 130, says what to do in one line (``--resume`` only when there is a checkpoint to
resume from), and leaves a whole ``summary.json`` and a manifest that is not "running".
"""

import json
import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from fipy_hopper.io import read_csv

REPO = Path(__file__).resolve().parents[1]

COARSE = """\
[hopper]
bin_diameter = 0.2
outlet_diameter = 0.06
bin_height = 0.25
fill_height = 0.15

[numerics]
cell_size = 0.01
gravity_ramp_time = 0.05

[run]
end_time = 0.05
output_interval = 0.01
field_interval = 0.05
"""

#: moment -> (the function to wrap, which call of it, signal before (True) or after it)
DRIVER = textwrap.dedent("""\
    import importlib, os, signal, sys
    moment, name, argv = sys.argv[1], sys.argv[2], sys.argv[3:]
    number = getattr(signal, name)
    where = {
        "opening": ("fipy_hopper.io:RunDirectory._remove_outputs", 1, True),
        "set-up": ("fipy_hopper.io:Manifest.begin_session", 1, False),
        "filling": ("fipy_hopper.simulation:StabilityCheck.__call__", 3, False),
        "checkpoint": ("numpy.lib.format:write_array", 0, True),   # see below
        "discharge": ("fipy_hopper.simulation:Simulation._log_sample", 3, False),
        "sampling": ("fipy_hopper.model:HopperModel.flow_mode_measures", 3, True),
        "summary": ("fipy_hopper.api:_summary", 1, True),
        "manifest": ("fipy_hopper.io:Manifest.end_session", 1, True),
        "pictures": ("fipy_hopper.plotting:plot_run", 1, True),
        "printing": ("fipy_hopper.cli:_print_summary", 1, True),
    }[moment]
    target, nth, before = where
    module, _, attr = target.partition(":")
    owner = importlib.import_module(module)
    *path, last = attr.split(".")
    for part in path:
        owner = getattr(owner, part)
    original = getattr(owner, last)
    calls = [0]

    def wrapped(*args, **kwargs):
        calls[0] += 1
        if calls[0] == nth and before:
            os.kill(os.getpid(), number)
        result = original(*args, **kwargs)
        if calls[0] == nth and not before:
            os.kill(os.getpid(), number)
        return result

    setattr(owner, last, wrapped)
    if moment == "checkpoint":     # the fifth array of the second checkpoint
        from fipy_hopper.simulation import Simulation
        checkpoint = Simulation.checkpoint

        def counted(self, path):
            counted.n += 1
            calls[0] = 0
            where_nth[0] = 5 if counted.n == 2 else -1
            return checkpoint(self, path)

        counted.n, where_nth = 0, [-1]

        def wrapped(*args, **kwargs):
            calls[0] += 1
            if calls[0] == where_nth[0]:
                os.kill(os.getpid(), number)
            return original(*args, **kwargs)

        setattr(owner, last, wrapped)
        Simulation.checkpoint = counted
    from fipy_hopper.cli import main
    sys.exit(main(argv))
""")


def _default_sigint():
    """The child's Ctrl-C as a terminal gives it: an ignored SIGINT is inherited across
    ``exec`` (a test process that started a Dask cluster or a multiprocessing pool may have
    left it ignored), and a process started so never sees Ctrl-C at all."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def run_cli(moment, argv, signame="SIGINT"):
    env = dict(os.environ, PYTHONPATH=str(REPO), NUMBA_NUM_THREADS="1")
    return subprocess.run([sys.executable, "-c", DRIVER, moment, signame, *argv],
                          capture_output=True, text=True, env=env, timeout=600,
                          preexec_fn=_default_sigint)


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    path = tmp_path_factory.mktemp("interrupts")
    (path / "coarse.toml").write_text(COARSE)
    return path


MOMENTS = [("opening", "SIGINT"), ("set-up", "SIGINT"), ("filling", "SIGINT"),
           ("checkpoint", "SIGINT"), ("discharge", "SIGTERM"), ("sampling", "SIGINT"),
           ("summary", "SIGINT"),
           ("manifest", "SIGINT"), ("pictures", "SIGINT"), ("printing", "SIGINT")]


@pytest.mark.parametrize("moment, signame", MOMENTS, ids=[m for m, _ in MOMENTS])
def test_ctrl_c_at_any_moment_ends_with_130_and_a_finished_manifest(folder, moment, signame):
    out = folder / moment
    config = folder / "coarse.toml"
    if moment == "opening":              # an earlier run whose files --force removes
        earlier = run_cli("printing", ["run", str(config), "--out", str(out), "--quiet"])
        assert earlier.returncode == 0, earlier.stderr
    argv = ["run", str(config), "--out", str(out), "--force",
            "--checkpoint-interval", "0.001" if moment == "checkpoint" else "60"]
    argv += [] if moment == "printing" else ["--quiet"]
    done = run_cli(moment, argv, signame)
    errors = [line for line in done.stderr.splitlines() if "warning:" not in line]
    assert done.returncode == 130, done.stderr
    assert len(errors) == 1 and errors[0].startswith("fipy-hopper: error: interrupted"), \
        done.stderr
    assert "Traceback" not in done.stderr
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["status"] in ("interrupted", "finished"), manifest["status"]
    summary = json.loads((out / "summary.json").read_text()) \
        if (out / "summary.json").exists() else None
    resumable = (out / "checkpoint.npz").is_file()
    if manifest["status"] == "interrupted":
        assert summary is None or summary["stop_reason"] == "interrupted"
        assert ("--resume" in errors[0]) == resumable
        assert resumable or "--force" in errors[0]
    else:                                # the run had finished: its results are whole
        assert summary["stop_reason"] == "end_time" and not resumable
        assert "are complete" in errors[0] and "fipy-hopper plot" in errors[0]
    assert not (out / ".lock").exists() and not (out / "error.log").exists()
    if (out / "timeseries.csv").exists():     # whole tables: a half-taken sample dropped
        table = read_csv(out / "timeseries.csv")
        if summary is not None and summary.get("discharge_time_s") is not None:
            assert len(table["t_s"]) == 0 or table["t_s"][-1] <= summary["discharge_time_s"]
    if moment == "sampling":
        assert summary["steady_discharge_rate_kg_s"] is not None   # the whole summary
    if moment == "checkpoint":           # a checkpoint written before: the advice holds
        assert resumable
        again = run_cli("printing", ["run", str(config), "--out", str(out), "--resume",
                                     "--quiet"])
        assert again.returncode == 0, again.stderr
        assert json.loads((out / "manifest.json").read_text())["status"] == "finished"


def test_an_error_raised_while_handling_ctrl_c_is_still_an_interrupt(folder):
    """Ctrl-C inside a writer whose clean-up then fails (its error raised while handling the
    KeyboardInterrupt): the run is interrupted, not failed."""
    import warnings

    from fipy_hopper import api

    out = folder / "cleanup"

    def setup(sim):
        def writer(sim_, state):
            if state.stage == "discharge":
                try:
                    raise KeyboardInterrupt
                finally:
                    raise OSError("the half-written file could not be closed")
        sim.add_callback(writer, 0.01, stages=("discharge",))

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(KeyboardInterrupt):
            api.run(folder / "coarse.toml", out, setup=setup, plots=False,
                    checkpoint_interval=0)
    assert json.loads((out / "manifest.json").read_text())["status"] == "interrupted"
    assert json.loads((out / "summary.json").read_text())["stop_reason"] == "interrupted"
    assert not (out / "error.log").exists()
