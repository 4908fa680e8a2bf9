"""The phase profile of a run (``fipy-hopper run --profile``, :mod:`fipy_hopper.profiling`).

* Timing a run changes none of its numbers: the same steps with and without a profile give
  equal states, to the bit.
* The profile accounts for the run: every phase was timed, the phases add up to the wall time,
  and the compiled phases, counted in processor cycles inside the compiled loop, agree with
  ``time.perf_counter`` around the compiled calls (two independent clocks).
* The command line writes ``profile.json`` and prints it; ``--force`` removes an old one;
  the Lagrangian formulation, which has no compiled step, is refused before anything runs.
* The same for the 3D model (a small silo on 2 cm cubes): the same phases, its own kernels.
"""

import json
import time
import warnings

import numpy as np
import pytest

from fipy_hopper import api, io, stepping
from fipy_hopper.cli import main
from fipy_hopper.config import HopperConfig
from fipy_hopper.model import HopperModel
from fipy_hopper.profiling import PhaseProfile
from fipy_hopper.simulation import Simulation
from fipy_hopper.space.model import SpaceModel

SMALL = {"hopper": {"bin_diameter": 0.2, "outlet_diameter": 0.06, "bin_height": 0.25,
                    "fill_height": 0.15},
         "numerics": {"cell_size": 0.01, "gravity_ramp_time": 0.05},
         "run": {"end_time": 0.1, "output_interval": 0.02, "field_interval": 0.05}}
#: a small 3D silo (a quarter, 2 cm cubes: 3 across the outlet's radius)
SMALL_3D = {"hopper": {"bin_diameter": 0.24, "outlet_diameter": 0.12, "bin_height": 0.12,
                       "fill_height": 0.08, "half_angle_deg": 30.0, "dimensions": 3},
            "numerics": {"cell_size": 0.02, "gravity_ramp_time": 0.05},
            "run": {"end_time": 0.1, "output_interval": 0.02, "field_interval": 0.05}}
COUNTER = pytest.mark.skipif(not stepping.HAS_CYCLE_COUNTER,
                             reason="no cycle counter that user code may read on this processor")


def small_config(settings=SMALL) -> HopperConfig:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")       # 3 cells across the outlet radius: coarse, fast
        return HopperConfig.from_dict(settings)


@pytest.fixture(scope="module")
def discharging():
    """A small hopper filled and 0.05 s into its discharge (markers on)."""
    model = HopperModel(small_config())
    sim = Simulation(model, progress=False, end_time=0.05)
    sim.run()
    return model, sim.state


def advance(model, state, steps):
    done = 0
    while done < steps:
        done += model.advance(state, steps - done)
    return state


def profiled(model, state, steps):
    """``steps`` steps of a copy of ``state`` with a fresh profile attached to ``model`` (and
    detached after): ``(the copy after them, the profile)``."""
    model.profile = profile = PhaseProfile()
    try:
        return advance(model, state.copy(), steps), profile
    finally:
        model.profile = None


def test_a_profile_changes_no_number_of_the_run(discharging):
    model, state = discharging
    plain = advance(model, state.copy(), 600)
    timed, profile = profiled(model, state, 600)
    for name in ("v", "sigma", "alpha", "eps_p", "loose", "layer", "face_flux_sum",
                 "wall_impulse", "plate_impulse", "momentum_budget", "markers"):
        assert np.array_equal(getattr(timed, name), getattr(plain, name)), name
    assert (timed.t, timed.step, timed.discharged) == (plain.t, plain.step, plain.discharged)
    assert profile.steps == 600
    # the loaded cells are counted per step: one step's count is the state's
    _, one = profiled(model, state, 1)
    assert one.loaded_cell_steps == np.count_nonzero(state.alpha >= model.cfg.numerics.alpha_min)
    assert profile.transports > 10          # about one transport in 15-40 steps here
    assert profile.compiled_seconds > 0.0
    for part in ("transport: advection", "transport: redistribution",
                 "transport: fields and momentum", "transport: markers"):
        assert profile.seconds[part] > 0.0, part


@COUNTER
def test_the_cycle_counter_rises_at_a_constant_rate():
    first, started = stepping.read_cycles(), time.perf_counter()
    time.sleep(0.05)
    middle, halfway = stepping.read_cycles(), time.perf_counter()
    time.sleep(0.05)
    last, ended = stepping.read_cycles(), time.perf_counter()
    rate_1 = (middle - first) / (halfway - started)
    rate_2 = (last - middle) / (ended - halfway)
    assert 1e8 < rate_1 < 1e11              # a counter of 0.1-100 GHz
    assert rate_2 == pytest.approx(rate_1, rel=0.02)   # sleeps of 50 ms: timer jitter < 1 %


@COUNTER
def test_the_compiled_phases_agree_with_the_clock_around_the_compiled_calls(discharging):
    model, state = discharging
    _, profile = profiled(model, state, 1500)
    report = profile.report()
    compiled = sum(v for k, v in report["phases_s"].items() if k.startswith("step: "))
    assert all(profile.cycles > 0)
    # the cycles inside the compiled loop, converted at the counter's rate measured against
    # perf_counter, are the perf_counter time of the calls less the cost of calling them
    # (the arguments' unboxing, tens of microseconds a call on a ~1 ms call)
    assert 0.8 * report["compiled_calls_s"] < compiled <= report["compiled_calls_s"]
    assert sum(report["phases_s"].values()) == pytest.approx(report["wall_time_s"], rel=1e-9)
    assert report["phases_s"]["other"] >= 0.0


def test_run_profile_writes_and_prints_where_the_time_went(tmp_path, capsys):
    config = tmp_path / "small.toml"
    config.write_text(small_config().to_toml())
    out = tmp_path / "run"
    assert main(["run", str(config), "--out", str(out), "--profile"]) == 0
    report = json.loads((out / "profile.json").read_text())
    printed = capsys.readouterr().out
    assert "where the time went" in printed and "stress update" in printed
    phases = report["phases_s"]
    assert phases["pictures"] > 0.0 and phases["snapshots and checkpoints"] > 0.0
    assert sum(phases.values()) == pytest.approx(report["wall_time_s"], rel=1e-9)
    assert sum(report["fractions"].values()) == pytest.approx(1.0, rel=1e-9)
    summary = json.loads((out / "summary.json").read_text())
    assert report["steps"] == summary["steps"]
    # a run without --profile into the same directory leaves no profile of the earlier run
    assert main(["run", str(config), "--out", str(out), "--force", "--quiet"]) == 0
    assert not (out / "profile.json").exists()


def test_a_resumed_run_starts_without_the_profile_of_the_earlier_session(tmp_path):
    """Opening the directory to resume keeps the earlier profile (a checkpoint refused after
    that must leave the directory as it was); the run removes it once the checkpoint is
    restored (``remove_profile``; end to end in test_resume.py)."""
    for name in ("config.toml", "checkpoint.npz", "profile.json"):
        (tmp_path / name).write_text("x")
    folder = io.RunDirectory(tmp_path, resume=True)
    try:
        assert (tmp_path / "profile.json").exists()
        folder.remove_profile()
        assert not (tmp_path / "profile.json").exists()
        assert (tmp_path / "checkpoint.npz").exists()
    finally:
        folder.close()


def test_profile_of_the_lagrangian_formulation_is_refused_before_anything_runs(tmp_path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cfg = small_config().replace(numerics={"formulation": "lagrangian"})
    with pytest.raises(api.ConfigError, match="lagrangian"):
        api.run(cfg, tmp_path / "run", profile=True)
    assert not (tmp_path / "run").exists()


# ---------------------------------------------------------------- the 3D model
@pytest.fixture(scope="module")
def discharging_3d():
    """The small 3D silo filled and 0.05 s into its discharge."""
    model = SpaceModel(small_config(SMALL_3D))
    sim = Simulation(model, progress=False, end_time=0.05)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sim.run()
    return model, sim.state


def test_a_profile_changes_no_number_of_a_3d_run(discharging_3d):
    model, state = discharging_3d
    plain = advance(model, state.copy(), 300)
    timed, profile = profiled(model, state, 300)
    for name in ("v", "sigma", "alpha", "eps_p", "loose", "flowing", "flux_z", "wall_impulse",
                 "plate_impulse", "momentum_budget"):
        assert np.array_equal(getattr(timed, name), getattr(plain, name)), name
    assert (timed.t, timed.step, timed.discharged) == (plain.t, plain.step, plain.discharged)
    assert profile.steps == 300 and profile.transports > 5
    assert profile.loaded_cell_steps > 0 and profile.compiled_seconds > 0.0
    for part in ("transport: advection", "transport: redistribution",
                 "transport: fields and momentum"):
        assert profile.seconds[part] > 0.0, part


@COUNTER
def test_the_3d_compiled_phases_agree_with_the_clock_around_the_compiled_calls(discharging_3d):
    model, state = discharging_3d
    _, profile = profiled(model, state, 600)
    report = profile.report()
    assert all(profile.cycles > 0)
    # the cycles in the compiled loop (forces, nodes, stress update, faces) are the clock's
    # time of the calls less the cost of calling them; "step setup" is the lists made in
    # Python before each call, outside the calls
    inside = sum(report["phases_s"][f"step: {name}"] for name in stepping.PHASES[1:])
    assert 0.7 * report["compiled_calls_s"] < inside <= report["compiled_calls_s"]
    assert report["phases_s"]["step: step setup"] > 0.0
    assert sum(report["phases_s"].values()) == pytest.approx(report["wall_time_s"], rel=1e-9)


def test_run_profile_of_a_3d_run(tmp_path, capsys):
    config = tmp_path / "small_3d.toml"
    config.write_text(small_config(SMALL_3D).to_toml())
    out = tmp_path / "run"
    assert main(["run", str(config), "--out", str(out), "--profile"]) == 0
    report = json.loads((out / "profile.json").read_text())
    assert "stress update" in capsys.readouterr().out
    phases = report["phases_s"]
    assert phases["pictures"] > 0.0 and phases["snapshots and checkpoints"] > 0.0
    assert phases["transport: advection"] > 0.0
    assert sum(phases.values()) == pytest.approx(report["wall_time_s"], rel=1e-9)
    assert report["steps"] == json.loads((out / "summary.json").read_text())["steps"]
