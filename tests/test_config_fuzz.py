"""Property-based fuzzing of the configuration: any TOML-able input gives either a
valid :class:`HopperConfig` or a one-line :class:`ConfigError`, never another exception.

The inputs are random tables with every key of every section, each either left out, given a
value near its allowed range (so that most configurations get past the first key and reach
the cross-checks: resolution, grid size, time steps, intervals) or any TOML value (numbers of
any size, NaN, infinities, strings, booleans, dates, lists, nested tables); random unknown keys
and sections, and sections that are not tables.  A configuration that passes must give the
numbers ``fipy-hopper validate`` prints (:func:`fipy_hopper.api.expected_quantities`, the
grid size, the time step) without an exception, finite where they are defined, and must
survive its own TOML round trip.  The same inputs written as TOML files go through
``fipy-hopper validate`` itself: exit 0, or exit 2 with one line and no traceback, drawing
nothing (a picture is drawn only with ``--picture``: tests/test_boundary.py).  The ``[hopper]``
tables mostly hold the keys of the shape drawn (a profile's walls, fill level, inserts; a
shorthand's sizes), sometimes the other shape's too.

Only configuration parsing and validation run here (no grid, no simulation): 2,000 cases in
a few seconds.  ``FUZZ_EXAMPLES=N`` runs N cases of each test with fresh random seeds.
"""

import contextlib
import datetime
import io
import math
import os
import tempfile
import warnings
from dataclasses import fields
from unittest import mock

import pytest

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

from fipy_hopper import config as fconfig  # noqa: E402
from fipy_hopper.boundary import Boundary  # noqa: E402
from fipy_hopper.api import expected_quantities  # noqa: E402
from fipy_hopper.cli import main  # noqa: E402
from fipy_hopper.config import ConfigError, HopperConfig  # noqa: E402

EXAMPLES = int(os.environ.get("FUZZ_EXAMPLES", "0"))
SETTINGS = dict(max_examples=EXAMPLES or 1000, deadline=None, derandomize=not EXAMPLES,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])

# ---------------------------------------------------------------- strategies
huge_ints = st.integers(min_value=-10 ** 400, max_value=10 ** 400)
any_float = st.floats(allow_nan=True, allow_infinity=True)
scalars = st.one_of(
    st.integers(), huge_ints, any_float, st.booleans(), st.text(max_size=30),
    st.sampled_from(["empty", "Empty", "", "0.1", "nan", "1e9"]),
    st.datetimes(timezones=st.none()), st.dates(), st.times())
any_value = st.recursive(
    scalars,
    lambda inner: st.one_of(st.lists(inner, max_size=3),
                            st.dictionaries(st.text(min_size=1, max_size=8), inner, max_size=3)),
    max_leaves=6)


def near(low, high, integer=False):
    """``(inside, wild)`` strategies: values in ``[low, high]``; and on the bounds, just
    outside, far off, or anything at all."""
    inside = (st.integers(int(low), int(high)) if integer else
              st.floats(low, high) | st.floats(low, high).map(lambda x: float(f"{x:.3g}")))
    edges = st.sampled_from([low, high, -low, 0, 2 * high, low / 2 if low else -1e-9,
                             high * (1 + 1e-12)])
    wide = (st.integers(-10 ** 12, 10 ** 12) if integer else
            st.floats(min_value=-1e30, max_value=1e30, allow_nan=False))
    return inside, st.one_of(edges, wide, huge_ints, any_float, any_value)


def walls(sign=1.0):
    """``(inside, wild)``: walls from a lip on ``z = 0`` up, never descending, mostly outward
    (``sign = -1``: a left wall); they may still cross, or be too narrow for the outlet."""
    coordinate = st.floats(0.0, 1.5) | st.floats(0.0, 1.5).map(lambda x: float(f"{x:.2g}"))
    steps = st.lists(st.tuples(coordinate, coordinate), min_size=1, max_size=4)
    inside = st.tuples(st.floats(0.01, 0.2), steps).map(lambda w: [
        [sign * (w[0] + sum(dx for dx, _ in w[1][:k])), sum(dz for _, dz in w[1][:k])]
        for k in range(len(w[1]) + 1)])
    return inside, st.one_of(any_value, st.lists(st.lists(near(-2.0, 2.0)[1], max_size=3),
                                                 max_size=4))


point = st.tuples(st.floats(0.0, 0.4), st.floats(0.0, 1.5)).map(list)
insert = st.fixed_dictionaries({"outline": st.lists(point, min_size=3, max_size=5)},
                               optional={"friction_angle_deg": near(0.0, 45.0)[0]})

PLAUSIBLE = {
    "hopper": {"bin_diameter": near(0.2, 3.0), "half_angle_deg": near(5.0, 90.0),
               "outlet_diameter": near(0.02, 0.15), "bin_height": near(0.5, 5.0),
               "fill_height": near(0.02, 1.0),
               "shape": (st.sampled_from(["conical", "wedge", "profile"]),
                         st.sampled_from(["", "Wedge", "cylinder"]) | any_value),
               "bin_width": near(0.2, 3.0), "outlet_width": near(0.02, 0.15),
               "symmetry": (st.sampled_from(["axisymmetric", "plane"]),
                            st.sampled_from(["", "Plane", "cylindrical"]) | any_value),
               "section": (st.sampled_from(["half", "full"]),
                           st.sampled_from(["", "Full", "both"]) | any_value),
               "wall": walls(), "left_wall": walls(-1.0), "fill_level": near(0.05, 1.5),
               "inserts": (st.lists(insert, max_size=2),
                           any_value | st.lists(any_value | insert, max_size=2)),
               "dimensions": (st.sampled_from([2, 3]), st.sampled_from([1, 4, 2.0, "3"])
                              | any_value),
               "outlet_offset": (near(0.0, 0.3)[0] | st.lists(near(-0.3, 0.3)[0], min_size=2,
                                                               max_size=2),
                                 near(0.0, 0.3)[1] | st.lists(near(-0.3, 0.3)[1], max_size=3)),
               "plan": (st.sampled_from(["circular", "rectangular"]),
                        st.sampled_from(["", "Rectangular", "square"]) | any_value),
               "bin_length": near(0.2, 3.0), "outlet_length": near(0.02, 0.15)},
    "material": {"density": near(100.0, 5000.0), "youngs_modulus": near(1e4, 1e9),
                 "poisson_ratio": near(-0.5, 0.49), "friction_angle_deg": near(5.0, 60.0),
                 "dilation_angle_deg": near(0.0, 30.0), "cohesion": near(0.0, 1e4),
                 "grain_diameter": near(1e-4, 5e-3), "grain_density": near(1500.0, 8000.0),
                 "rate_dependence": (st.sampled_from(["mu_I", "none"]),
                                     st.sampled_from(["", "muI", "mu(I)"]) | any_value),
                 "friction_rise": near(0.01, 1.0), "inertial_number_i0": near(0.01, 2.0)},
    "wall": {"friction_angle_deg": near(0.0, 45.0),
             "segment_friction_deg": (st.lists(near(0.0, 45.0)[0], min_size=1, max_size=4),
                                      any_value | st.lists(near(0.0, 45.0)[1], max_size=4))},
    "numerics": {"cell_size": near(0.002, 0.02), "dt_safety": near(0.05, 1.0),
                 "transport_cfl": near(0.05, 0.5),
                 "max_transport_interval": near(1, 200, integer=True),
                 "hourglass_coefficient": near(0.0, 1.0), "grid_viscosity": near(0.0, 1.0),
                 "viscosity_length": near(0.0, 0.02),
                 "bulk_viscosity": near(0.0, 1.0),
                 "alpha_min": near(1e-4, 0.1),
                 "free_fall_depth": near(0.25, 10.0),
                 "gravity_ramp_time": (near(0.0, 1.0)[0] | st.just("auto"),
                                       near(0.0, 1.0)[1] | st.sampled_from(["", "Auto", "slow"])),
                 "gravity_ramp_periods": near(0.0, 50.0),
                 "settle_kinetic_energy": near(1e-8, 1e-2),
                 "settle_damping_fraction": near(1e-8, 1e-1), "max_fill_time": near(0.1, 5.0),
                 "min_open_fraction": near(0.0, 0.5),
                 "formulation": (st.sampled_from(["eulerian", "lagrangian"]),
                                 st.sampled_from(["", "Lagrangian", "ale"]) | any_value),
                 "mirror_planes": (st.sampled_from(["auto", "none", "quarter", "half"]),
                                   st.sampled_from(["", "Half", "eighth"]) | any_value)},
    "run": {"end_time": (near(0.0, 60.0)[0] | st.just("empty"),
                         near(0.0, 60.0)[1] | st.sampled_from(["", "Empty", "forever"])),
            "load_window": (near(1e-3, 1.0)[0] | st.just("auto"),
                            near(1e-3, 1.0)[1] | st.sampled_from(["", "AUTO", "all"])),
            "max_time": near(0.1, 120.0), "empty_fraction": near(0.001, 0.5),
            "wall_time_limit": near(0.0, 1e4), "output_interval": near(1e-3, 1.0),
            "field_interval": near(1e-2, 5.0), "markers_per_side": near(0, 6, integer=True),
            "opening_time": near(0.0, 1.0), "wall_sectors": near(1, 360, integer=True),
            "wall_bin_width": (near(1e-3, 0.1)[0] | st.just("auto"),
                               near(1e-3, 0.1)[1] | st.sampled_from(["", "Auto", "fine"]))},
}


def test_the_strategies_cover_every_key():
    for name, kind in fconfig._SECTIONS.items():
        assert sorted(PLAUSIBLE[name]) == sorted(f.name for f in fields(kind))


@st.composite
def configurations(draw):
    """Sections of keys with values in range, then 0-2 of them made wild; sometimes a section
    left out or replaced by anything, an unknown key or an unknown section."""
    data = {}
    for name, keys in PLAUSIBLE.items():
        choice = draw(st.integers(0, 39))
        # (rare cases on middle values: hypothesis draws the bounds of a range more often)
        if choice == 17:
            continue                                    # section left out
        if choice == 29:
            data[name] = draw(any_value)                # anything, a table or not
            continue
        present = draw(st.lists(st.sampled_from(sorted(keys)), unique=True))
        if name == "hopper":            # mostly the keys of the shape drawn
            shape = draw(keys["shape"][0])
            other = (fconfig.SHORTHAND_KEYS if shape == "profile" else
                     fconfig.PROFILE_KEYS + ("symmetry", "section"))
            if draw(st.integers(0, 9)):
                present = [key for key in present if key not in other]
            if shape == "profile":
                present = list(dict.fromkeys(present + ["wall", "fill_level"]))
            present = [key for key in present if key != "shape"] + ["shape"]
            data[name] = {key: draw(keys[key][0]) for key in present[:-1]}
            data[name]["shape"] = shape
            continue
        data[name] = {key: draw(keys[key][0]) for key in present}
    sections = [n for n in data if isinstance(data[n], dict)]
    for _ in range((0, 0, 0, 1, 1, 2)[draw(st.integers(0, 5))] if sections else 0):
        name = draw(st.sampled_from(sections))
        key = draw(st.sampled_from(sorted(PLAUSIBLE[name])))
        data[name][key] = draw(PLAUSIBLE[name][key][1])
    if sections and draw(st.integers(0, 19)) == 11:   # an unknown key
        data[draw(st.sampled_from(sections))][draw(st.text(min_size=1, max_size=12))] = \
            draw(any_value)
    if draw(st.integers(0, 39)) == 23:                  # an unknown section
        data[draw(st.text(min_size=1, max_size=12))] = draw(any_value)
    return data


# ---------------------------------------------------------------- checks
def check(data):
    """Valid configuration with finite derived numbers, or a one-line ConfigError."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            cfg = HopperConfig.from_dict(data)
        except ConfigError as exc:
            message = str(exc)
            assert message and "\n" not in message and len(message) < 600, message
            return None
        again = HopperConfig.from_dict(tomllib.loads(cfg.to_toml()))
    assert again == cfg
    e = expected_quantities(cfg)
    classic = ("beverloo_rate_kg_s", "rose_tanaka_factor", "cone_height_m")
    for key in ("fill_mass_kg", "p_wave_speed_m_s", "beverloo_flat_rate_kg_s",
                "expected_discharge_time_s", "transition_height_m") + (
                    classic if cfg.hopper.classic else ()):
        assert math.isfinite(e[key]) and e[key] >= 0, (key, e[key])
    assert cfg.hopper.classic or not any(key in e for key in classic)
    assert e["jenike_flow_mode"] in ("mass", "funnel", "unknown")
    assert 0 < cfg.n_cells <= fconfig.MAX_CELLS
    assert 0 < cfg.step_estimate() <= fconfig.MAX_STEPS
    assert cfg.time_step > 0 and math.isfinite(cfg.memory_estimate())
    return cfg


RESULTS = {"valid": 0, "refused": 0}


@settings(**SETTINGS)
@given(configurations())
def test_any_table_gives_a_config_or_a_config_error(data):
    RESULTS["valid" if check(data) is not None else "refused"] += 1


def test_the_fuzzing_reaches_valid_and_refused_configurations():
    """The run above explores both outcomes (else it would test only the first checks)."""
    if not RESULTS["valid"] + RESULTS["refused"]:
        pytest.skip("run together with test_any_table_gives_a_config_or_a_config_error")
    print(RESULTS)
    assert RESULTS["valid"] >= 50 and RESULTS["refused"] >= 200, RESULTS


# ---------------------------------------------------------------- as TOML through the CLI
def _key(key: str) -> str:
    return _string(key)


def _string(text: str) -> str:
    escaped = "".join(c if c.isprintable() and c not in '"\\' else f"\\u{ord(c):04x}"
                      if ord(c) < 0x10000 else f"\\U{ord(c):08x}" for c in text)
    return f'"{escaped}"'


def toml_value(value) -> str:
    """``value`` as TOML (inline tables and arrays for nested values)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return "nan" if value != value else ("inf" if value > 0 else "-inf") \
            if math.isinf(value) else repr(value)
    if isinstance(value, str):
        return _string(value)
    if isinstance(value, (datetime.datetime, datetime.date, datetime.time)):
        return value.isoformat()
    if isinstance(value, list):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{_key(k)} = {toml_value(v)}" for k, v in value.items()) + "}"
    raise TypeError(type(value))


def toml_text(data: dict) -> str:
    lines = [f"{_key(k)} = {toml_value(v)}" for k, v in data.items() if not isinstance(v, dict)]
    for name, table in data.items():
        if isinstance(table, dict):
            lines.append(f"[{_key(name)}]")
            lines += [f"{_key(k)} = {toml_value(v)}" for k, v in table.items()]
    return "\n".join(lines) + "\n"


@pytest.fixture(scope="module")
def folder():
    with tempfile.TemporaryDirectory() as path:
        yield path


def test_toml_writer_round_trips():
    data = {"run": {"end_time": "empty", "x": [1, 2.5, {"a": float("inf")}]}, "y": 10 ** 30,
            "numerics": {"cell_size": 1e-300, "é\n": datetime.date(2020, 1, 2)}}
    assert tomllib.loads(toml_text(data)) == data


@settings(**{**SETTINGS, "max_examples": EXAMPLES or 1000})
@given(configurations())
def test_validate_command_exits_0_or_2_with_one_line(folder, data):
    path = os.path.join(folder, "fuzz.toml")
    with open(path, "w", encoding="utf-8") as fh:
        fh.write(toml_text(data))
    out, err = io.StringIO(), io.StringIO()
    drawn = []              # a picture would be noted here: none is drawn unless asked
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err), \
            mock.patch.object(Boundary, "draw", lambda self, p: drawn.append(p)):
        code = main(["validate", path])
    assert not drawn                  # validate draws only when asked (--picture)
    errors = [line for line in err.getvalue().splitlines() if "warning:" not in line]
    if code == 0:
        assert not errors and out.getvalue().startswith(f"{path}: valid"), err.getvalue()
    else:
        assert code == 2, (code, err.getvalue())
        assert len(errors) == 1 and errors[0].startswith("fipy-hopper: error: "), err.getvalue()
    assert "Traceback" not in err.getvalue() + out.getvalue()
