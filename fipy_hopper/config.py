"""Validated configuration of a hopper run: frozen dataclasses, TOML in and out.

All values are SI (m, s, kg, Pa); angles are given in degrees at this boundary only.
Every check names the TOML key, the value and the allowed range, and runs before anything
is computed.  The public TOML contract (sections and keys) is::

    [hopper]    shape = "conical": bin_diameter, half_angle_deg, outlet_diameter,
                bin_height, fill_height ("wedge": bin_width, outlet_width);
                shape = "profile": symmetry, section, wall, left_wall, fill_level;
                inserts (any shape: [[hopper.inserts]] outline, friction_angle_deg)
    [material]  density, youngs_modulus, poisson_ratio, friction_angle_deg,
                dilation_angle_deg, cohesion
    [wall]      friction_angle_deg, segment_friction_deg
    [numerics]  cell_size, ...
    [run]       end_time (seconds or "empty"), ...
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import re
import sys
import warnings
from dataclasses import dataclass, field, fields
from functools import cached_property
from pathlib import Path
from typing import Any, Optional, Union

import numpy as np

try:  # Python >= 3.11
    import tomllib
except ModuleNotFoundError:  # pragma: no cover - Python 3.10
    import tomli as tomllib


class ConfigError(ValueError):
    """A configuration value is missing, of the wrong type or outside its allowed range."""


class ResolutionWarning(UserWarning):
    """The grid resolves a feature of the hopper with few cells."""


class ArchingWarning(UserWarning):
    """The outlet is only a few grains wide: it will arch (Beverloo's regime ends)."""


class SamplingWarning(UserWarning):
    """The discharge gets few outputs (a field interval longer than ``run.end_time``)."""


def short_text(text, limit: int = 200) -> str:
    """``text`` (e.g. a path) for a one-line message, shortened in the middle when long."""
    text = str(text)
    return text if len(text) <= limit else \
        f"{text[:100]}...{text[-60:]} ({len(text)} characters)"


def _show(value: Any, limit: int = 40) -> str:
    """A value for a one-line message: repr, shortened (a 400-digit integer says so)."""
    if isinstance(value, int) and not isinstance(value, bool) and abs(value) >= 10 ** 15:
        digits = len(str(abs(value)))
        return f"{'-' if value < 0 else ''}{str(abs(value))[:6]}... (an integer of {digits} digits)"
    if isinstance(value, float):
        return f"{value:g}"
    text = repr(value)
    return text if len(text) <= limit else text[:limit - 3] + "..."


def _interval(low, high, low_open=False, high_open=False, unit: str = "") -> str:
    lo = "-inf" if low is None else f"{low:g}"
    hi = "inf" if high is None else f"{high:g}"
    return (("(" if low_open or low is None else "[") + f"{lo}, {hi}"
            + (")" if high_open or high is None else "]") + unit)


def _check_number(key: str, value: Any, allowed: str = "") -> float:
    """``value`` as a finite float; ``allowed`` (an interval) is named when it is not one."""
    where = f" in {allowed}" if allowed else ""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ConfigError(f"{key} = {_show(value)}: expected a number{where}")
    try:
        number = float(value)
    except OverflowError:          # an integer beyond the float range
        raise ConfigError(f"{key} = {_show(value)}: too large; expected a number{where}") \
            from None
    if not math.isfinite(number):
        raise ConfigError(f"{key} = {_show(value)}: expected a finite number{where}")
    return number


#: ``numerics.bulk_viscosity = "auto"`` with the Eulerian formulation: at this ``b_1`` the
#: discharge loads and the early funnel-flow rate no longer depend on E and the loads converge
#: with the grid (``docs/validation.md``); 0.1 gave larger spreads.
DEFAULT_BULK_VISCOSITY = 0.06


def damped_step_factor(xi: float) -> float:
    """``sqrt(1 + xi^2) - xi``: the explicit step limit of the shortest mode damped at the
    fraction ``xi`` of critical (the bulk viscosity ``b_1``), relative to the undamped one."""
    return math.sqrt(1.0 + xi * xi) - xi


def _check_range(key: str, value: Any, low=None, high=None, low_open=False, high_open=False,
                 unit: str = "") -> float:
    """Check ``low <(=) value <(=) high`` and return the value as float; error names the key."""
    interval = _interval(low, high, low_open, high_open, unit)
    value = _check_number(key, value, interval)
    bad = ((low is not None and (value < low or (low_open and value == low)))
           or (high is not None and (value > high or (high_open and value == high))))
    if bad:
        raise ConfigError(f"{key} = {value:g}{unit}: allowed range is {interval}")
    return value


def _is_zero(value: Any) -> bool:
    """``value`` is the number 0 (not a bool, not a string)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool) and value == 0


def _check_int(key: str, value: Any, low: int, high: int) -> int:
    """An integer (not a bool, not a float) in ``[low, high]``."""
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        raise ConfigError(f"{key} = {_show(value)}: expected an integer in [{low}, {high}]")
    return value


# Bounds of physically meaningful values (SI).  They keep every number the solver derives
# from a configuration finite and refuse typing slips such as lengths in millimetres:
#: Hopper lengths (m): below 1 mm a continuum of grains is meaningless; no silo is 100 m wide
#: or tall.
LENGTH_RANGE = (1e-3, 100.0)
#: Hopper shapes: a cone (axisymmetric), a wedge with a slot outlet (plane strain), or a wall
#: profile drawn as points (either symmetry; a full plane section with both walls).
SHAPES = ("conical", "wedge", "profile")
#: A profile's symmetry (hopper.symmetry) and section (hopper.section).
SYMMETRIES = ("axisymmetric", "plane")
SECTIONS = ("half", "full")
#: The keys of the shorthands (a profile derives them from hopper.wall), and of a profile.
SHORTHAND_KEYS = ("bin_diameter", "half_angle_deg", "outlet_diameter", "bin_height",
                  "fill_height", "bin_width", "outlet_width", "bin_length", "outlet_length")
#: hopper.plan of a 3D silo (hopper.dimensions = 3): "circular" (the default: the section
#: revolved about its axis) or "rectangular" (a bin of bin_width x bin_length over a hopper of
#: plane faces, or a flat floor: fipy_hopper.space.rectangular)
PLANS = ("circular", "rectangular")
#: the keys of a rectangular plan only
RECTANGULAR_KEYS = ("bin_length", "outlet_length")
PROFILE_KEYS = ("wall", "left_wall", "fill_level")
#: the models a run can use (numerics.formulation)
FORMULATIONS = ("eulerian", "lagrangian")
#: hopper.dimensions: 2, a section (axisymmetric or plane, as drawn); 3, the whole circular
#: silo on a 3D grid (fipy_hopper.space)
DIMENSIONS = (2, 3)
#: numerics.mirror_planes of a 3D run: "auto" (a quarter of a centred silo, the half y >= 0
#: of one with an off-centre outlet), "none" (the whole silo), "quarter", "half"
MIRROR_PLANES = ("auto", "none", "quarter", "half")
#: run.wall_sectors of a 3D run: sectors around the circumference of the wall-load maps
WALL_SECTORS_RANGE = (1, 360)
#: Bulk density (kg/m3): the lightest powders (aerogel, ~10) to beyond tungsten (~19,300).
DENSITY_RANGE = (1.0, 2.0e4)
#: Young's modulus (Pa): 1 kPa (loose, cohesive powder) to 1 TPa (stiffer than diamond).
MODULUS_RANGE = (1e3, 1e12)
#: Cohesion (Pa): up to 100 MPa, the strength of strong rock; granular media have kPa.
COHESION_MAX = 1e8
#: The rate dependence above the Mohr–Coulomb limit (material.rate_dependence): the mu(I)
#: overstress with the grain size (fipy_hopper.material.rate), or none (the plain
#: rate-independent law of the published method).
RATE_DEPENDENCES = ("mu_I", "none")
#: Grain diameter (m): 1 um (fine powders) to 0.1 m (coarse gravel, rock fill).
GRAIN_DIAMETER_RANGE = (1e-6, 0.1)
#: An outlet fewer than this many grains wide arches (Beverloo's regime ends; the classic
#: figure for free-flowing grains is about 5 grain diameters): a warning.
ARCHING_GRAINS = 5.0
#: Cell size (m): 0.1 mm (the size of a sand grain) to 10 m.
CELL_SIZE_RANGE = (1e-4, 10.0)
#: Simulated times (s): at most 1e6 s (11.6 days; the largest silos empty in hours).
TIME_MAX = 1e6
#: Time-series samples are taken at most once per check (2 ms); field snapshots are files.
OUTPUT_INTERVAL_MIN, FIELD_INTERVAL_MIN = 1e-4, 1e-3
#: Largest grid, in cells.  Peak resident memory measured (fipy_hopper.model.HopperModel(cfg)
#: of the reference hopper, resource.getrusage, one process): 0.40 GB at 72,346 cells, 1.17 GB
#: at 286,770 and 3.89 GB at 1,141,858, i.e. 3.2-3.6 kB a cell on top of about 0.15-0.26 GB;
#: the peak is the cut-cell sub-sampling of mesh.build_grid, and the initial state, ten steps,
#: a transport, a field snapshot and a checkpoint add nothing beyond it.  2 million cells
#: need about 7 GB (:func:`grid_memory`, rounded up from the measurements) before the run's
#: markers and wall loads (:func:`fipy_hopper.resources.memory_estimate`).
MAX_CELLS = 2_000_000
MEMORY_PER_CELL = 3.5e3            # bytes a cell (measured, see MAX_CELLS)
MEMORY_BASE = 0.2e9                # bytes: Python, FiPy, numba and the compiled kernels
#: bytes a cell that the model and its state keep once the grid is built (measured,
#: tracemalloc: 2.25 kB a cell at 18,414 and 72,346 cells, without markers and wall loads)
MEMORY_KEPT_PER_CELL = 2.3e3
#: The fill's surface lies at least this many cells above the outlet plane (a thinner fill
#: has no cell of material at the wall: measured, a fill a tenth of a cell deep fails its
#: run, one half a cell deep runs; two cells is the least the grid resolves).
FILL_CELLS = 2
#: Most explicit time steps a run may need.  Even at the cost of a step on a tiny grid
#: (measured: 2,937 steps of a 624-cell hopper in 0.43 s, 0.15 ms a step) 1e9 steps take
#: about two days; on the reference grid (0.5 ms a step) a week.  More cannot finish.
MAX_STEPS = 1e9


@dataclass(frozen=True)
class InsertConfig:
    """An insert (``[[hopper.inserts]]``): a closed polygon ``outline`` ``[[x, z], ...]`` (m;
    a body of revolution, or a long bar in plane flow) and its wall friction angle
    ``friction_angle_deg`` (deg; None: the wall's, ``wall.friction_angle_deg``)."""

    outline: tuple = ()
    friction_angle_deg: Optional[float] = None


@dataclass(frozen=True)
class HopperGeometry:
    """A silo's section; the outlet plane is ``z = 0``, ``z`` upward.

    ``shape``: ``"conical"`` (default: a cone below a cylindrical bin, axisymmetric, sized by
    ``bin_diameter`` and ``outlet_diameter``), ``"wedge"`` (a plane-flow hopper: a wedge
    below a bin of parallel walls with a slot outlet, long in the third direction, sized by
    ``bin_width`` and ``outlet_width``; every result is per metre of length) or ``"profile"``
    (any wall drawn as points, below).  For a wedge, ``bin_diameter`` and ``outlet_diameter``
    hold the two widths (the section is the same half-section in ``(x, z)`` as the cone's in
    ``(r, z)``).  ``fill_height`` and ``bin_height`` are measured above the transition.
    ``half_angle_deg`` is the hopper's half-angle from the vertical, in ``(0, 90]``; 90 is a
    flat bottom.  Lengths are in ``[1 mm, 100 m]`` (:data:`LENGTH_RANGE`), the hopper's height
    too (which bounds how steep a narrow-outlet hopper can be).

    A profile: ``wall`` ``[[x, z], ...]`` (m) from the outlet lip (``z = 0``) up to the top,
    never descending; ``symmetry`` ``"axisymmetric"`` (default; ``x`` is the radius) or
    ``"plane"`` (per metre of length); ``section`` ``"half"`` (default: mirrored about
    ``x = 0``, every ``x > 0``) or ``"full"`` (plane only: ``left_wall`` too, any outlet
    position); ``fill_level`` (m above the outlet plane).  ``inserts`` (any shape): closed
    polygons (:class:`InsertConfig`), inside the walls, above the outlet plane.

    The silo itself is :attr:`boundary` (:class:`fipy_hopper.boundary.Boundary`), which every
    part of the code reads.  A profile's shorthand sizes exist only where they describe it:
    when its wall is a cone (a wedge, a flat floor) under a bin in a half-section
    (:attr:`fipy_hopper.boundary.Boundary.hopper_shape`, one slope by length),
    ``bin_diameter`` is twice the bin wall's ``x``, ``half_angle_deg`` that slope,
    :attr:`cone_height` the height of the transition, ``bin_height`` and ``fill_height`` above
    it (the latter negative for a fill below it); for any other wall they are None.
    ``outlet_diameter`` (twice the lip's ``x``, or a full section's outlet width),
    :attr:`width` (the widest span) and :attr:`top` (the lower of the walls' tops) describe
    every silo.
    """

    bin_diameter: float = 0.3
    half_angle_deg: float = 20.0
    outlet_diameter: float = 0.06
    bin_height: float = 0.35
    fill_height: float = 0.3
    shape: str = "conical"
    bin_width: Optional[float] = None
    outlet_width: Optional[float] = None
    symmetry: Optional[str] = None
    section: str = "half"
    wall: Optional[tuple] = None
    left_wall: Optional[tuple] = None
    fill_level: Optional[float] = None
    inserts: tuple = ()
    dimensions: int = 2
    outlet_offset: float = 0.0
    plan: str = "circular"
    bin_length: Optional[float] = None
    outlet_length: Optional[float] = None

    def __post_init__(self):
        lo, hi = LENGTH_RANGE
        if not isinstance(self.shape, str) or self.shape not in SHAPES:
            raise ConfigError(f"hopper.shape = {_show(self.shape)}: expected one of "
                              f"{', '.join(repr(s) for s in SHAPES)}")
        if isinstance(self.dimensions, bool) or self.dimensions not in DIMENSIONS:
            raise ConfigError(f"hopper.dimensions = {_show(self.dimensions)}: expected 2 (a "
                              "section, axisymmetric or plane) or 3 (the whole circular silo)")
        self._check_plan()
        self._check_offset(hi)
        if self.rectangular:
            self._check_section()
            self._check_rectangular(lo, hi)
            object.__setattr__(self, "fill_level", self.cone_height + self.fill_height)
            _check_inserts(self)
            self._check_three_d()
            return
        if self.dimensions == 2 and self.outlet_offset != 0.0:
            raise ConfigError(f"hopper.outlet_offset = {self.outlet_offset:g} m is for "
                              "hopper.dimensions = 3 (a section's outlet lies on its axis; a "
                              "full plane section places its outlet by hopper.left_wall); "
                              "allowed range with dimensions = 2 is [0, 0] m")
        self._check_section()
        if self.shape == "profile":
            _check_profile(self)
        else:
            self._check_shorthand(lo, hi)
            object.__setattr__(self, "fill_level", self.cone_height + self.fill_height)
        _check_inserts(self)
        if self.dimensions == 3:
            self._check_three_d()

    def _check_plan(self) -> None:
        """``plan``: ``"circular"`` or ``"rectangular"``; a rectangular plan only in 3D and by
        the shorthand's keys; its own keys (``bin_length``, ``outlet_length``) refused with a
        circular plan."""
        if not isinstance(self.plan, str) or self.plan not in PLANS:
            raise ConfigError(f"hopper.plan = {_show(self.plan)}: expected one of "
                              f"{', '.join(repr(p) for p in PLANS)}")
        if self.plan == "rectangular":
            if self.dimensions != 3:
                raise ConfigError('hopper.plan = "rectangular" is for hopper.dimensions = 3 (a '
                                  'section is axisymmetric or plane; a long bin in plane flow is '
                                  'shape = "wedge"); allowed with dimensions = 2 is "circular"')
            if self.shape != "conical":
                raise ConfigError(f'hopper.plan = "rectangular" is sized by the shorthand\'s keys '
                                  f'(bin_width, bin_length, half_angle_deg, outlet_width or '
                                  f'outlet_diameter, bin_height, fill_height), not by hopper.shape '
                                  f'= "{self.shape}"; leave hopper.shape out')
            return
        for key in RECTANGULAR_KEYS:
            if getattr(self, key) is not None:
                raise ConfigError(f'hopper.{key} is for plan = "rectangular"; a circular silo '
                                  f'takes hopper.{key.replace("length", "diameter")}')

    def _check_offset(self, hi: float) -> None:
        """``outlet_offset``: a circular silo's one distance along ``+x`` (m, >= 0); a
        rectangular plan's ``[ex, ey]`` (m, either sign; one number is ``[ex, 0]``), kept as a
        pair."""
        e = self.outlet_offset
        if self.plan != "rectangular":
            if isinstance(e, (list, tuple)):
                raise ConfigError(f"hopper.outlet_offset = {_show(list(e))}: a circular silo's "
                                  "outlet is off its axis by one distance along +x (m, >= 0); "
                                  '[ex, ey] is for plan = "rectangular"')
            _check_range("hopper.outlet_offset", e, 0, hi, unit=" m")
            return
        if isinstance(e, (list, tuple)):
            if len(e) != 2:
                raise ConfigError(f"hopper.outlet_offset = {_show(list(e))}: expected [ex, ey] "
                                  "in m (the outlet's centre from the bin's axis), or one "
                                  "number, ex")
            pair = tuple(_check_range(f"hopper.outlet_offset[{i}]", v, -hi, hi, unit=" m")
                         for i, v in enumerate(e))
        else:
            pair = (_check_range("hopper.outlet_offset", e, -hi, hi, unit=" m"), 0.0)
        object.__setattr__(self, "outlet_offset", tuple(float(v) + 0.0 for v in pair))

    def _check_rectangular(self, lo: float, hi: float) -> None:
        """The rectangular plan's sizes (:mod:`fipy_hopper.space.rectangular`): ``bin_width``
        (x, required) and ``bin_length`` (y, default the width: a square bin); the outlet
        rectangular (``outlet_width`` along x, ``outlet_length`` along y, default the width)
        or circular (``outlet_diameter``); ``half_angle_deg`` the half-angle from the vertical
        of the hopper's faces across x (the faces x = const) of the centred hopper, which
        sets the hopper's height ``(bin_width - outlet's x size) / (2 tan)`` (90: a flat
        floor); ``bin_height`` and ``fill_height`` above the transition.  The outlet inside
        the floor or the hopper's foot (:func:`fipy_hopper.space.rectangular.
        outlet_offset_error`).  Sets the shorthand's ``bin_diameter`` (the bin's width) and
        ``outlet_diameter`` (the outlet's smaller size) for what reads them."""
        if self.wall is not None:
            raise ConfigError('hopper.wall is for shape = "profile"; a rectangular plan is sized '
                              'by hopper.bin_width and hopper.bin_length')
        if self.bin_width is None:
            raise ConfigError('hopper.bin_width is required for plan = "rectangular" (the bin\'s '
                              f'size along x, a length in [{lo:g}, {hi:g}] m)')
        width = _check_range("hopper.bin_width", self.bin_width, lo, hi, unit=" m")
        length = width if self.bin_length is None else _check_range(
            "hopper.bin_length", self.bin_length, lo, hi, unit=" m")
        object.__setattr__(self, "bin_length", length)
        if self.outlet_width is None:
            if self.outlet_length is not None:
                raise ConfigError("hopper.outlet_length is for a rectangular outlet, sized by "
                                  "hopper.outlet_width (along x) and hopper.outlet_length "
                                  "(along y); a circular outlet takes hopper.outlet_diameter")
            ox = oy = _check_range("hopper.outlet_diameter", self.outlet_diameter, lo, hi,
                                   unit=" m")
        else:
            ox = _check_range("hopper.outlet_width", self.outlet_width, lo, hi, unit=" m")
            oy = ox if self.outlet_length is None else _check_range(
                "hopper.outlet_length", self.outlet_length, lo, hi, unit=" m")
            object.__setattr__(self, "outlet_length", oy)
            object.__setattr__(self, "outlet_diameter", min(ox, oy))
        object.__setattr__(self, "bin_diameter", width)
        _check_range("hopper.half_angle_deg", self.half_angle_deg, 0, 90, low_open=True,
                     unit=" deg")
        _check_range("hopper.bin_height", self.bin_height, lo, hi, unit=" m")
        _check_range("hopper.fill_height", self.fill_height, lo, hi, unit=" m")
        x_key, y_key = (("outlet_width", "outlet_length") if self.outlet_width is not None
                        else ("outlet_diameter", "outlet_diameter"))
        if ox >= width:
            raise ConfigError(f"hopper.{x_key} = {ox:g} m is not narrower than the bin, "
                              f"hopper.bin_width = {width:g} m")
        if oy >= length:
            raise ConfigError(f"hopper.{y_key} = {oy:g} m is not shorter than the bin, "
                              f"hopper.bin_length = {length:g} m")
        if self.fill_height > self.bin_height:
            raise ConfigError(
                f"hopper.fill_height = {self.fill_height:g} m is above the top of the bin, "
                f"hopper.bin_height = {self.bin_height:g} m")
        rise = 0.5 * (width - ox) / hi
        if self.half_angle_deg < 90.0 and math.tan(math.radians(self.half_angle_deg)) < rise:
            least = _ceil_digits(math.degrees(math.atan(rise)))
            raise ConfigError(
                f"hopper.half_angle_deg = {self.half_angle_deg:g} deg makes the hopper higher "
                f"than {hi:g} m (the largest length allowed); allowed range is "
                f"[{least:.3g}, 90] deg for this bin and outlet")

    @property
    def rectangular(self) -> bool:
        """True for a rectangular plan (``plan = "rectangular"``, 3D only)."""
        return self.plan == "rectangular"

    @property
    def offset_xy(self) -> tuple:
        """The outlet's centre from the silo's axis ``(ex, ey)`` (m): a circular silo's
        ``(outlet_offset, 0)``."""
        e = self.outlet_offset
        return tuple(e) if isinstance(e, tuple) else (float(e), 0.0)

    @property
    def outlet_size(self) -> tuple:
        """A rectangular plan's outlet ``(size along x, size along y, circular?)`` (m)."""
        if self.outlet_width is None:
            return self.outlet_diameter, self.outlet_diameter, True
        return self.outlet_width, self.outlet_length, False

    def _check_three_d(self) -> None:
        """A 3D silo is a circular one: the conical shorthand or an axisymmetric profile
        revolved about its axis (inserts with a centred outlet only), its outlet inside the
        floor or the hopper
        (:func:`fipy_hopper.space.boundary.outlet_offset_error`); or a rectangular plan, its
        outlet inside the floor or the hopper's foot
        (:func:`fipy_hopper.space.rectangular.outlet_offset_error`)."""
        if self.rectangular:
            if self.inserts:
                raise ConfigError(f"hopper.inserts: {len(self.inserts)} insert"
                                  f"{'s' * (len(self.inserts) > 1)} given; hopper.dimensions = "
                                  "3 has no inserts yet")
            from .space.rectangular import outlet_offset_error as rect_error
            ox, oy, round_outlet = self.outlet_size
            error = rect_error(self.bin_width, self.bin_length, ox, oy, round_outlet,
                               self.outlet_offset)
            if error:
                raise ConfigError(f"hopper.{error}")
            return
        if not self.axisymmetric:
            what = ('a wedge (hopper.shape = "wedge")' if self.shape == "wedge" else
                    'a plane profile (hopper.symmetry = "plane")')
            raise ConfigError(f"hopper.dimensions = 3 computes a circular silo (the conical "
                              f"shorthand or an axisymmetric profile revolved about its axis), "
                              f"not {what}; a plane silo runs with dimensions = 2")
        if self.inserts and self.outlet_offset:
            raise ConfigError(f"hopper.inserts: {len(self.inserts)} insert"
                              f"{'s' * (len(self.inserts) > 1)} given with hopper.outlet_offset"
                              f" = {self.outlet_offset:g} m; inserts in 3D (bodies of "
                              "revolution about the silo's axis) need a centred outlet "
                              "(outlet_offset = 0)")
        from .space.boundary import outlet_offset_error
        error = outlet_offset_error(self.wall_points, self.outlet_offset)
        if error:
            raise ConfigError(f"hopper.{error}")

    def _check_section(self) -> None:
        implied = {"conical": "axisymmetric", "wedge": "plane"}.get(self.shape)
        symmetry = self.symmetry if self.symmetry is not None else (implied or SYMMETRIES[0])
        if not isinstance(symmetry, str) or symmetry not in SYMMETRIES:
            raise ConfigError(f"hopper.symmetry = {_show(symmetry)}: expected one of "
                              f"{', '.join(repr(s) for s in SYMMETRIES)}")
        if implied and symmetry != implied:
            raise ConfigError(f'hopper.symmetry = "{symmetry}" does not fit hopper.shape = '
                              f'"{self.shape}" ({implied}); draw the wall as shape = "profile"')
        object.__setattr__(self, "symmetry", symmetry)
        if not isinstance(self.section, str) or self.section not in SECTIONS:
            raise ConfigError(f"hopper.section = {_show(self.section)}: expected one of "
                              f"{', '.join(repr(s) for s in SECTIONS)}")
        if self.section == "full" and symmetry == "axisymmetric":
            raise ConfigError('hopper.section = "full" is for hopper.symmetry = "plane"; an '
                              'axisymmetric silo is computed as its half-section ("half")')
        if self.section == "full" and self.shape != "profile":
            raise ConfigError(f'hopper.section = "full" needs hopper.shape = "profile" with '
                              f'both walls (hopper.wall, hopper.left_wall), not "{self.shape}"')
        if self.section == "half" and self.left_wall is not None:
            raise ConfigError('hopper.left_wall is for hopper.section = "full" (both walls '
                              'drawn); a half-section has the axis x = 0 on its left')
        if self.section == "full" and self.left_wall is None:
            raise ConfigError('hopper.left_wall is required for hopper.section = "full" '
                              '([[x, z], ...] in m, from its lip on z = 0 up to its top)')

    def _check_shorthand(self, lo: float, hi: float) -> None:
        if self.wall is not None:
            raise ConfigError(f'hopper.wall is for shape = "profile"; the {self.shape} '
                              f'shorthand is sized by hopper.{self.size_keys[0]}')
        if self.shape == "wedge":
            for key in ("bin_width", "outlet_width"):
                if getattr(self, key) is None:
                    raise ConfigError(f"hopper.{key} is required for shape = \"wedge\" "
                                      f"(a length in [{lo:g}, {hi:g}] m)")
            object.__setattr__(self, "bin_diameter", self.bin_width)
            object.__setattr__(self, "outlet_diameter", self.outlet_width)
        else:
            for key in ("bin_width", "outlet_width"):
                if getattr(self, key) is not None:
                    raise ConfigError(f"hopper.{key} is for shape = \"wedge\"; a conical "
                                      f"hopper takes hopper.{key.replace('width', 'diameter')}")
        bin_key, outlet_key = self.size_keys
        _check_range(f"hopper.{bin_key}", self.bin_diameter, lo, hi, unit=" m")
        _check_range("hopper.half_angle_deg", self.half_angle_deg, 0, 90, low_open=True,
                     unit=" deg")
        _check_range(f"hopper.{outlet_key}", self.outlet_diameter, lo, hi, unit=" m")
        _check_range("hopper.bin_height", self.bin_height, lo, hi, unit=" m")
        _check_range("hopper.fill_height", self.fill_height, lo, hi, unit=" m")
        if self.outlet_diameter >= self.bin_diameter:
            raise ConfigError(
                f"hopper.{outlet_key} = {self.outlet_diameter:g} m is not narrower than the "
                f"bin, hopper.{bin_key} = {self.bin_diameter:g} m")
        if self.fill_height > self.bin_height:
            raise ConfigError(
                f"hopper.fill_height = {self.fill_height:g} m is above the top of the bin, "
                f"hopper.bin_height = {self.bin_height:g} m")
        # (R - R0) / tan(theta) <= 100 m, written so that a tiny angle cannot divide by zero
        rise = (self.bin_radius - self.outlet_radius) / hi
        if self.half_angle_deg < 90.0 and math.tan(math.radians(self.half_angle_deg)) < rise:
            least = _ceil_digits(math.degrees(math.atan(rise)))
            raise ConfigError(
                f"hopper.half_angle_deg = {self.half_angle_deg:g} deg makes the cone higher "
                f"than {hi:g} m (the largest length allowed); allowed range is "
                f"[{least:.3g}, 90] deg for this bin and outlet")

    @property
    def axisymmetric(self) -> bool:
        """True for an axisymmetric silo (a cone), False in plane flow (per metre)."""
        return self.symmetry == "axisymmetric"

    @property
    def full_section(self) -> bool:
        """True for a full plane section (both walls drawn, no axis)."""
        return self.section == "full"

    @property
    def size_keys(self) -> tuple:
        """The names of the bin's and the outlet's size: diameters, or widths for a wedge."""
        return (("bin_diameter", "outlet_diameter") if self.axisymmetric
                else ("bin_width", "outlet_width"))

    @property
    def wall_points(self) -> tuple:
        """The wall ``((x, z), ...)`` (m) from the lip up: a profile's ``wall``, or the
        shorthand's ``(R0, 0), (R, cone_height), (R, top)``."""
        if self.shape == "profile":
            return self.wall
        if self.rectangular:       # the section through the axis across x, centred
            return ((0.5 * self.outlet_size[0], 0.0), (self.bin_radius, self.cone_height),
                    (self.bin_radius, self.top))
        return ((self.outlet_radius, 0.0), (self.bin_radius, self.cone_height),
                (self.bin_radius, self.top))

    @property
    def n_wall_segments(self) -> int:
        """Segments of the (right) wall: one per ``wall.segment_friction_deg`` value."""
        return len(self.wall_points) - 1

    @property
    def classic(self) -> bool:
        """The silo the classic theories cover: a half-section without inserts in the material
        (an insert wholly above the fill level does not count) whose wall is a cone, a
        wedge's plate or a flat floor under one vertical bin wall (the shorthands, and a
        profile drawn as one: :attr:`fipy_hopper.boundary.Boundary.hopper_shape`).
        Beverloo's rate with the Rose-Tanaka factor, Jenike's critical half-angle, Janssen,
        Walker and EN 1991-4's hopper loads apply to it as a whole; other silos get them
        where a stretch allows (Jenike per stretch of hopper wall, Janssen on a top vertical
        stretch)."""
        if self.rectangular:         # a pyramid or a wedge of plane faces: no closed form here
            return False
        buried = [i for i in self.inserts
                  if min(z for _, z in i.outline) < (self.fill_level or self.top)]
        return not buried and self.boundary.hopper_shape is not None

    @property
    def x_extent(self) -> tuple:
        """``(x_min, x_max)`` (m) of the section: the axis to the widest point, or the two
        walls' extremes in a full section (the width the grid must span)."""
        right = max(x for x, _ in self.wall_points)
        if not self.full_section:
            return 0.0, right
        return min(x for x, _ in self.left_wall), right

    @property
    def width(self) -> float:
        """The silo's widest span (m): the bin's diameter (width) of a shorthand, twice a
        half-section's widest ``x``, or wall to wall of a full section."""
        if self.rectangular:
            return max(self.bin_width, self.bin_length)
        x_min, x_max = self.x_extent
        return 2.0 * x_max if not self.full_section else x_max - x_min

    @cached_property
    def boundary(self):
        """The boundary (:class:`fipy_hopper.boundary.Boundary`), built once; its walls'
        friction is left to ``[wall]`` (nan: see :attr:`HopperConfig.boundary`)."""
        from .boundary import build
        return build(self.wall_points, symmetry=self.symmetry, left_wall=self.left_wall,
                     inserts=[(i.outline, i.friction_angle_deg) for i in self.inserts],
                     fill_level=self.fill_level)

    @property
    def bin_radius(self) -> Optional[float]:
        """The bin's radius, or half its width for a wedge (m); None where there is no one
        bin (:attr:`bin_diameter`)."""
        return None if self.bin_diameter is None else 0.5 * self.bin_diameter

    @property
    def outlet_radius(self) -> float:
        return 0.5 * self.outlet_diameter

    @property
    def half_angle(self) -> Optional[float]:
        """Cone half-angle in radians (None where there is no one hopper angle)."""
        return None if self.half_angle_deg is None else math.radians(self.half_angle_deg)

    @property
    def cone_height(self) -> Optional[float]:
        """Height of the cone-cylinder transition above the outlet, ``(R - R0) / tan(theta)``
        (zero for a flat-bottomed bin); a profile's: the height of its transition where it
        describes a cone under a bin, else None (every silo's is
        :meth:`fipy_hopper.boundary.Boundary.transition_height`)."""
        if self.shape == "profile":
            return None if self.half_angle_deg is None else _bin_bottom(self.wall)
        if self.half_angle_deg >= 90.0:
            return 0.0
        if self.rectangular:
            return 0.5 * (self.bin_width - self.outlet_size[0]) / math.tan(self.half_angle)
        return (self.bin_radius - self.outlet_radius) / math.tan(self.half_angle)

    @property
    def top(self) -> float:
        """Height of the top of the bin above the outlet plane."""
        if self.shape == "profile":
            return min(c[-1][1] for c in (self.wall, self.left_wall) if c is not None)
        return self.cone_height + self.bin_height

    def fill_volume(self) -> float:
        """Volume of the filled material: frustum plus cylinder (m^3); for a wedge, trapezoid
        plus rectangle per metre of length (m^3/m); a profile or inserts: the boundary's
        (:meth:`fipy_hopper.boundary.Boundary.fill_volume`)."""
        if self.rectangular:       # a prismatoid (a sheared one as well) and the bin's box
            a0, b0 = self.outlet_size[:2]     # the hopper's foot (a round outlet's square)
            a1, b1, h = self.bin_width, self.bin_length, self.cone_height
            middle = 0.25 * (a0 + a1) * (b0 + b1)
            return h / 6.0 * (a0 * b0 + 4.0 * middle + a1 * b1) + a1 * b1 * self.fill_height
        if self.shape == "profile" or self.inserts:
            return self.boundary.fill_volume()
        r0, r1, h = self.outlet_radius, self.bin_radius, self.cone_height
        if not self.axisymmetric:
            return (r0 + r1) * h + 2.0 * r1 * self.fill_height
        cone = math.pi * h / 3.0 * (r0 * r0 + r0 * r1 + r1 * r1)
        return cone + math.pi * r1 * r1 * self.fill_height


def _bin_bottom(wall) -> float:
    """The height (m) where the wall's top vertical stretch starts (its top if it slopes)."""
    k = len(wall) - 1
    while k > 0 and wall[k - 1][0] == wall[k][0]:
        k -= 1
    return wall[k][1]


def _point_text(p) -> str:
    return f"[{p[0]:g}, {p[1]:g}]"


def _points(key: str, value, least: int) -> tuple:
    """``value`` as points ``((x, z), ...)`` (m), each two numbers within 100 m."""
    what = f"expected a list of at least {least} points [x, z] in m"
    if isinstance(value, (str, bytes, dict)) or not isinstance(value, (list, tuple)):
        raise ConfigError(f"{key} = {_show(value)}: {what}")
    if len(value) < least:
        raise ConfigError(f"{key} has {len(value)} point{'s' * (len(value) != 1)}: {what}")
    hi = LENGTH_RANGE[1]
    out = []
    for i, p in enumerate(value):
        if not isinstance(p, (list, tuple)) or len(p) != 2:
            raise ConfigError(f"{key}[{i}] = {_show(p)}: expected a point [x, z] of two "
                              f"numbers in m")
        x = _check_range(f"{key}[{i}] x", p[0], -hi, hi, unit=" m")
        z = _check_range(f"{key}[{i}] z", p[1], -hi, hi, unit=" m")
        if out and (x, z) == out[-1]:
            raise ConfigError(f"{key}[{i}] = {_point_text((x, z))}: repeats the previous point")
        out.append((x, z))
    return tuple(out)


def _check_wall(key: str, wall: tuple, half: bool) -> None:
    """A wall: its lip on ``z = 0``, never descending, not crossing the axis or itself."""
    from .boundary import self_crossing

    if wall[0][1] != 0.0:
        raise ConfigError(f"{key}[0] = {_point_text(wall[0])}: the lip must lie on the outlet "
                          f"plane, z = 0")
    for i, p in enumerate(wall):
        if half and p[0] <= 0.0:
            raise ConfigError(f"{key}[{i}] = {_point_text(p)}: x = {p[0]:g} m crosses the "
                              f"axis; in a half-section (hopper.section = \"half\") every x "
                              f"must be > 0")
        if i and p[1] < wall[i - 1][1]:
            raise ConfigError(f"{key}[{i}] = {_point_text(p)}: z = {p[1]:g} m is below the "
                              f"previous point's {wall[i - 1][1]:g} m; the wall must not "
                              f"descend from the lip to the top")
    _check_wall_segments(key, wall)
    crossing = self_crossing(wall, closed=False)
    if crossing:
        i, j = crossing
        raise ConfigError(f"{key} crosses itself: its segment {i} {_point_text(wall[i])}-"
                          f"{_point_text(wall[i + 1])} meets segment {j} "
                          f"{_point_text(wall[j])}-{_point_text(wall[j + 1])}")


def _check_wall_segments(key: str, wall: tuple) -> None:
    """No segment of a wall along the outlet plane over the outlet (the lip is the wall's
    point on ``z = 0`` nearest the outlet, or the outlet's width would be misread), and none
    shorter than the least length of :data:`LENGTH_RANGE` (a sliver that no grid resolves,
    which at the lip would be taken for the hopper's slope)."""
    pts = np.asarray(wall, dtype=float)
    left = key.endswith("left_wall")
    lip = pts[0, 0]
    over = np.flatnonzero((pts[1:, 1] == 0.0) & ((pts[1:, 0] > lip) if left
                                                  else (pts[1:, 0] < lip))) + 1
    if len(over):
        i = int(over[0])
        raise ConfigError(
            f"{key}[{i}] = {_point_text(wall[i])}: the wall runs along the outlet plane, "
            f"z = 0, over the outlet from its lip {key}[0] = {_point_text(wall[0])}; the lip is "
            f"the wall's point on z = 0 nearest the outlet: start {key} there (allowed on "
            f"z = 0: x {'<=' if left else '>='} {lip:g} m)")
    lo, hi = LENGTH_RANGE
    lengths = np.hypot(*np.diff(pts, axis=0).T)
    short = np.flatnonzero(lengths < lo)
    if len(short):
        i = int(short[0])
        raise ConfigError(
            f"{key}: segment {i}, {_point_text(wall[i])} to {_point_text(wall[i + 1])}, is "
            f"{lengths[i]:.3g} m long; allowed range is [{lo:g}, {hi:g}] m (a sliver no grid "
            f"resolves, which at the lip would be taken for the hopper's slope): draw it as "
            f"part of its neighbours")


def _wall_x_at(wall: tuple, z: float) -> float:
    """The wall's ``x`` (m) at height ``z`` (:func:`fipy_hopper.boundary.wall_x`)."""
    from .boundary import profile_rows, wall_x
    return float(wall_x(z, profile_rows(wall), wall[0][0]))


def _check_profile(geom: "HopperGeometry") -> None:
    """Check a profile's walls and fill level; set its points and derived sizes."""
    from .boundary import first_meeting, profile_rows, wall_x

    if geom.wall is None:
        raise ConfigError('hopper.wall is required for shape = "profile" ([[x, z], ...] in m, '
                          'from the outlet lip on z = 0 up to the top)')
    wall = _points("hopper.wall", geom.wall, 2)
    _check_wall("hopper.wall", wall, half=not geom.full_section)
    object.__setattr__(geom, "wall", wall)
    width, outlet = 2.0 * max(x for x, _ in wall), 2.0 * wall[0][0]
    if geom.full_section:
        left = _points("hopper.left_wall", geom.left_wall, 2)
        _check_wall("hopper.left_wall", left, half=False)
        object.__setattr__(geom, "left_wall", left)
        if left[0][0] >= wall[0][0]:
            raise ConfigError(f"hopper.left_wall[0] = {_point_text(left[0])}: the left lip is "
                              f"not left of the right one, hopper.wall[0] = "
                              f"{_point_text(wall[0])}: the outlet has no width")
        for key, points, other, sign in (("hopper.left_wall", left, wall, 1.0),
                                         ("hopper.wall", wall, left, -1.0)):
            xz = np.asarray(points, dtype=float)
            x_others = wall_x(xz[:, 1], profile_rows(other), other[0][0])   # all at once
            bad = np.flatnonzero(sign * (x_others - xz[:, 0]) <= 0.0)
            if len(bad):
                i = int(bad[0])
                (x, z), x_other = points[i], float(x_others[i])
                raise ConfigError(
                    f"{key}[{i}] = {_point_text((x, z))}: "
                    f"{'right' if sign > 0 else 'left'} of (or on) the "
                    f"{'right' if sign > 0 else 'left'} wall, at x = {x_other:g} m at "
                    f"z = {z:g} m; the left wall must stay left of the right wall")
        top = max(wall[-1][1], left[-1][1])
        tall = [p + ((p[-1][0], top),) for p in (left, wall)]
        meet = first_meeting(tall[0][:-1], tall[0][1:], tall[1][:-1], tall[1][1:])
        if meet is not None:
            i, j = meet
            raise ConfigError(
                f"hopper.left_wall crosses hopper.wall: its segment from "
                f"{_point_text(tall[0][i])} meets the right wall's from "
                f"{_point_text(tall[1][j])}; the left wall must stay left of it")
        width = max(x for x, _ in wall) - min(x for x, _ in left)
        outlet = wall[0][0] - left[0][0]
    elif geom.left_wall is not None:    # (refused by _check_section)
        raise AssertionError
    if outlet >= width:
        raise ConfigError(f"hopper.wall: the outlet ({outlet:g} m) is as wide as the silo's "
                          f"widest span ({width:g} m); it must be narrower")
    top = geom.top
    if geom.fill_level is None:
        raise ConfigError('hopper.fill_level is required for shape = "profile" (m above the '
                          'outlet plane, up to the top of the wall)')
    level = _check_number("hopper.fill_level", geom.fill_level,
                          _interval(LENGTH_RANGE[0], top, unit=" m"))
    if level > top:
        raise ConfigError(f"hopper.fill_level = {level:g} m is above the top of the wall, "
                          f"z = {top:g} m; allowed range is "
                          f"{_interval(LENGTH_RANGE[0], top, unit=' m')}")
    _check_range("hopper.fill_level", level, LENGTH_RANGE[0], top, unit=" m")
    object.__setattr__(geom, "fill_level", level)
    # the hopper's slope: the lowest sloping segment of the wall (in a full section whose
    # right wall rises straight up from its lip, of the left wall)
    key, sloped = "hopper.wall", wall
    if geom.full_section and all(p[0] == q[0] for p, q in zip(wall, wall[1:])):
        key, sloped = "hopper.left_wall", geom.left_wall
    slope, nxt = next((p, q) for p, q in zip(sloped, sloped[1:]) if p[0] != q[0])
    cone = _bin_bottom(wall)
    angle = round(math.degrees(math.atan2(abs(nxt[0] - slope[0]), nxt[1] - slope[1])), 9)
    if angle <= 0.0:
        raise ConfigError(f"{key}: the wall rises vertically from the lip at "
                          f"{_point(sloped[0])} (its first slope, {_point(slope)} to "
                          f"{_point(nxt)}, is vertical to round-off): give the hopper or the "
                          f"floor a slope")
    from .boundary import hopper_shape
    shape = None if geom.full_section else hopper_shape(wall)
    sizes = {"bin_diameter": None, "half_angle_deg": None, "bin_height": None,
             "fill_height": None}
    if shape is not None:
        sizes = {"bin_diameter": 2.0 * shape.bin_x, "half_angle_deg": shape.half_angle_deg,
                 "bin_height": top - cone, "fill_height": level - cone}
    for key, value in (("outlet_diameter", outlet), *sizes.items(),
                       ("bin_width", None), ("outlet_width", None)):
        object.__setattr__(geom, key, value)


def _point(p) -> str:
    """A point ``(x, z)`` for a message."""
    return f"({p[0]:g}, {p[1]:g})"


def _check_inserts(geom: "HopperGeometry") -> None:
    """Each insert: a table of ``outline`` (a closed polygon inside the walls, above the
    outlet plane, apart from the other inserts) and ``friction_angle_deg``."""
    from .boundary import first_meeting, polygon_integrals, profile_rows, self_crossing, wall_x

    value = geom.inserts
    if isinstance(value, (str, bytes, dict)) or not isinstance(value, (list, tuple)):
        raise ConfigError(f"hopper.inserts = {_show(value)}: expected a list of tables "
                          f"([[hopper.inserts]] with outline and friction_angle_deg)")
    half = not geom.full_section
    walls = [("hopper.wall", geom.wall_points)] + (
        [] if half else [("hopper.left_wall", geom.left_wall)])
    top, done = geom.top, []
    rows = {wkey: profile_rows(wall) for wkey, wall in walls}
    allowed = [f.name for f in fields(InsertConfig)]
    for m, item in enumerate(value):
        key = f"hopper.inserts[{m}]"
        if isinstance(item, InsertConfig):
            item = dataclasses.asdict(item)
        if not isinstance(item, dict):
            raise ConfigError(f"{key} = {_show(item)}: expected a table with outline = "
                              f"[[x, z], ...] and friction_angle_deg")
        for name in item:
            if name not in allowed:
                raise ConfigError(_unknown_message(f"key in {key}", str(name), allowed,
                                                   prefix=f"{key}."))
        if item.get("outline") is None:
            raise ConfigError(f"{key}.outline is required: a closed polygon [[x, z], ...] in m")
        pts = list(_points(f"{key}.outline", item["outline"], 3))
        if len(pts) > 3 and pts[-1] == pts[0]:
            pts.pop()                                    # closed by repeating the first
        if len(pts) < 3:
            raise ConfigError(f"{key}.outline has {len(pts)} distinct points: a closed "
                              f"polygon needs at least 3")
        friction = item.get("friction_angle_deg")
        if friction is not None:
            friction = _check_range(f"{key}.friction_angle_deg", friction, 0, 90,
                                    high_open=True, unit=" deg")
        outline = f"{key}.outline"
        (x0, z0), (x1, z1) = pts[0], pts[1]
        if all((x1 - x0) * (z - z0) == (z1 - z0) * (x - x0) for x, z in pts[2:]):
            raise ConfigError(f"{outline} encloses no area (its points are on one line): "
                              f"expected a closed polygon")
        crossing = self_crossing(pts, closed=True)
        if crossing:              # a bow-tie too: its signed area may be zero
            i, j = crossing
            raise ConfigError(f"{outline} crosses itself: its edge from {_point_text(pts[i])} "
                              f"meets the edge from {_point_text(pts[j])}")
        if polygon_integrals(pts)[0] == 0.0:       # (not reached: kept as the last guard)
            raise ConfigError(f"{outline} encloses no area: expected a closed polygon")
        heights = np.asarray(pts, dtype=float)[:, 1]
        x_walls = {wkey: wall_x(heights, rows[wkey], wall[0][0]) for wkey, wall in walls}
        for i, (x, z) in enumerate(pts):
            where = f"{outline}[{i}] = {_point_text((x, z))}"
            if z < 0.0:
                raise ConfigError(f"{where}: z = {z:g} m is below the outlet plane, z = 0")
            if z > top:
                raise ConfigError(f"{where}: z = {z:g} m is above the top of the wall, "
                                  f"z = {top:g} m")
            if half and x < 0.0:
                raise ConfigError(f"{where}: x = {x:g} m crosses the axis; in a half-section "
                                  f"an insert lies at x >= 0 (a body of revolution, or a bar "
                                  f"on the mid-plane)")
            for wkey, wall in walls:
                x_wall = float(x_walls[wkey][i])
                if (x - x_wall) * (1.0 if wkey == "hopper.wall" else -1.0) >= 0.0:
                    raise ConfigError(f"{where}: in or on the wall ({wkey} is at x = "
                                      f"{x_wall:g} m at z = {z:g} m); an insert lies inside "
                                      f"the walls")
        edges = list(zip(pts, pts[1:] + pts[:1]))
        if half and sum(p[0] == 0.0 and q[0] == 0.0 for p, q in edges) > 1:
            raise ConfigError(f"{outline} lies along the axis with more than one edge; at "
                              f"most one")
        ends = [p for p, _ in edges], [q for _, q in edges]
        for wkey, wall in walls:
            meet = first_meeting(*ends, wall[:-1], wall[1:])
            if meet is not None:
                (p, q), k = edges[meet[0]], meet[1]
                raise ConfigError(f"{outline} cuts {wkey}: its edge from "
                                  f"{_point_text(p)} to {_point_text(q)} meets the "
                                  f"wall's segment {k}")
        from .boundary import inside_polygon
        for n, other in done:
            if (first_meeting(*ends, other, other[1:] + other[:1]) is not None
                    or inside_polygon(pts[0][0], pts[0][1], np.asarray(other))
                    or inside_polygon(other[0][0], other[0][1], np.asarray(pts))):
                raise ConfigError(f"{outline} overlaps hopper.inserts[{n}]; inserts must lie "
                                  f"apart")
        done.append((m, pts))
    object.__setattr__(geom, "inserts", tuple(
        InsertConfig(tuple(pts), None if item.get("friction_angle_deg") is None else
                     float(item["friction_angle_deg"]))
        for (_, pts), item in zip(done, [i if isinstance(i, dict) else dataclasses.asdict(i)
                                         for i in value])))


@dataclass(frozen=True)
class MaterialConfig:
    """Bulk granular material (SI; angles in degrees).

    Ranges: density ``[1, 20000]`` kg/m3 (:data:`DENSITY_RANGE`), Young's modulus
    ``[1 kPa, 1 TPa]`` (:data:`MODULUS_RANGE`), cohesion ``[0, 100 MPa]``.

    The grains: ``grain_diameter`` d (m, ``[1 um, 0.1 m]``; 1 mm by default, a medium to
    coarse silica sand: docs/physics_and_numerics.md §2) and ``grain_density`` rho_s (kg/m3,
    not below the bulk density; 2650, quartz).  ``rate_dependence``: ``"mu_I"`` (the default)
    adds the mu(I) rise of the friction in flowing material to the Mohr–Coulomb law
    (:mod:`fipy_hopper.material.rate`: ``friction_rise`` delta_mu = mu_2 - mu_s in ``(0, 2]``,
    ``inertial_number_i0`` I_0 in ``(0, 10]``), with d as its length; ``"none"`` is the plain
    rate-independent law of the published method (d then only enters the comparisons with
    Beverloo's correlation, and may be 0).
    """

    density: float = 1500.0
    youngs_modulus: float = 5.0e6
    poisson_ratio: float = 0.3
    friction_angle_deg: float = 30.0
    dilation_angle_deg: float = 0.0
    cohesion: float = 0.0
    grain_diameter: float = 1.0e-3
    grain_density: float = 2650.0
    rate_dependence: str = "mu_I"
    friction_rise: float = 0.26
    inertial_number_i0: float = 0.28

    def __post_init__(self):
        _check_range("material.density", self.density, *DENSITY_RANGE, unit=" kg/m3")
        _check_range("material.youngs_modulus", self.youngs_modulus, *MODULUS_RANGE,
                     unit=" Pa")
        _check_range("material.poisson_ratio", self.poisson_ratio, -1, 0.5, True, True)
        _check_range("material.friction_angle_deg", self.friction_angle_deg, 0, 90, True, True,
                     " deg")
        _check_range("material.dilation_angle_deg", self.dilation_angle_deg, 0,
                     self.friction_angle_deg, unit=" deg")
        _check_range("material.cohesion", self.cohesion, 0, COHESION_MAX, unit=" Pa")
        if not isinstance(self.rate_dependence, str) \
                or self.rate_dependence not in RATE_DEPENDENCES:
            raise ConfigError(f"material.rate_dependence = {_show(self.rate_dependence)}: "
                              f"expected one of {', '.join(repr(r) for r in RATE_DEPENDENCES)}")
        plain = self.rate_dependence == "none"
        if not (plain and _is_zero(self.grain_diameter)):     # the plain law may have none
            _check_range("material.grain_diameter", self.grain_diameter,
                         *GRAIN_DIAMETER_RANGE,
                         unit=" m" + ('; or 0 with rate_dependence = "none"' if plain else ""))
        _check_range("material.grain_density", self.grain_density, *DENSITY_RANGE,
                     unit=" kg/m3")
        if self.grain_density < self.density:
            raise ConfigError(f"material.grain_density = {self.grain_density:g} kg/m3 is below "
                              f"the bulk density material.density = {self.density:g} kg/m3: "
                              f"allowed range is [{self.density:g}, {DENSITY_RANGE[1]:g}] kg/m3")
        _check_range("material.friction_rise", self.friction_rise, 0, 2, low_open=True)
        _check_range("material.inertial_number_i0", self.inertial_number_i0, 0, 10,
                     low_open=True)

    @property
    def rheology(self):
        """The rate dependence of the law: a :class:`fipy_hopper.material.rate.
        InertialRheology`, or None for ``rate_dependence = "none"``."""
        if self.rate_dependence == "none":
            return None
        from .material.rate import InertialRheology
        return InertialRheology(grain_diameter=self.grain_diameter,
                                grain_density=self.grain_density,
                                friction_rise=self.friction_rise,
                                inertial_number_i0=self.inertial_number_i0)

    def law(self):
        """The constitutive law of this material (:mod:`fipy_hopper.material.law`): a
        :class:`fipy_hopper.material.MohrCoulomb` in the Abaqus form, with the mu(I)
        overstress of :attr:`rheology` unless ``rate_dependence = "none"``."""
        from .material import MohrCoulomb
        return MohrCoulomb(E=self.youngs_modulus, nu=self.poisson_ratio, rho=self.density,
                           phi=self.friction_angle_deg, psi=self.dilation_angle_deg,
                           c=self.cohesion, rate=self.rheology)

    @property
    def p_wave_speed(self) -> float:
        """``c_p = sqrt(E (1 - nu) / ((1 + nu)(1 - 2 nu) rho))`` in m/s, the law's."""
        return self.law().p_wave_speed


@dataclass(frozen=True)
class WallConfig:
    """Hopper wall: Coulomb friction angle between material and wall (degrees), and
    optionally one per segment of ``hopper.wall`` from the lip up (``segment_friction_deg``:
    a lined hopper under a rough bin; the shorthands' wall has two segments, the cone or
    floor and the bin).  The left wall of a full section and inserts without an angle of
    their own take ``friction_angle_deg``."""

    friction_angle_deg: float = 15.0
    segment_friction_deg: Optional[tuple] = None

    def __post_init__(self):
        _check_range("wall.friction_angle_deg", self.friction_angle_deg, 0, 90, high_open=True,
                     unit=" deg")
        angles = self.segment_friction_deg
        if angles is None:
            return
        if isinstance(angles, (str, bytes, dict)) or not isinstance(angles, (list, tuple)) \
                or not angles:
            raise ConfigError(f"wall.segment_friction_deg = {_show(angles)}: expected a list "
                              f"of angles in [0, 90) deg, one per segment of hopper.wall")
        object.__setattr__(self, "segment_friction_deg", tuple(
            _check_range(f"wall.segment_friction_deg[{i}]", a, 0, 90, high_open=True,
                         unit=" deg") for i, a in enumerate(angles)))

    @property
    def friction_coefficient(self) -> float:
        return math.tan(math.radians(self.friction_angle_deg))


@dataclass(frozen=True)
class NumericsConfig:
    """Discretisation and time-stepping knobs.

    - ``cell_size`` (m): square cells of the fixed grid.
    - ``dt_safety``: explicit step ``dt = dt_safety * cell_size / c_p``.
    - ``transport_cfl``: sub-cycled transport runs when the material has moved this fraction of a
      cell at the largest face speed of the open faces, and at least every
      ``max_transport_interval`` steps.
    - ``hourglass_coefficient``: viscous hourglass force per unit area
      ``kappa_hg * rho * sqrt(g h)`` times the cell's checkerboard velocity.  The velocity scale
      is the grid's free-fall speed ``sqrt(g h)``, not the elastic wave speed: a damping that
      grows with ``sqrt(E)`` acts as an artificial viscosity that makes the discharge rate
      depend on the stiffness used (measured: doubling ``kappa_hg * c_p`` slowed the flow by
      8%), while this one vanishes under refinement.
    - ``grid_viscosity`` ``b`` (dimensionless, 0: off): a viscous stress ``2 eta D`` added to
      the stress of every loaded cell in the internal forces (not to the stored elastoplastic
      stress), ``eta = b rho sqrt(g h) h`` (Pa s), from the cell's strain rate ``D``.  Like the
      hourglass control it is scaled by the grid's free-fall speed, not the wave speed: it
      damps grid-scale stress waves at a rate ``~ b sqrt(g / h)`` whatever the stiffness, and
      ``eta`` vanishes as ``h^1.5`` under refinement.  At 5 mm, ``b = 0.25`` gives ``eta =
      0.41 Pa s``, the order of the rate dependence of a 1 mm sand (``mu(I)``).  Eulerian
      formulation only.
    - ``viscosity_length`` ``l`` (m, 0: the cell size, the default): the length in ``eta``,
      ``eta = b rho sqrt(g l) l``: a viscosity of fixed size, the same on every grid.  A
      numerical knob only: the material's own length, which gives a shear band such as the
      edge of a funnel's flow channel a width that does not shrink with the cells, is the
      grain size of the law's rate dependence (``material.grain_diameter``,
      ``docs/physics_and_numerics.md`` section 2).
    - ``bulk_viscosity`` ``b_1`` (dimensionless, 0: off; ``"auto"``, the default, is
      :data:`DEFAULT_BULK_VISCOSITY` with the Eulerian formulation and 0 with the Lagrangian
      one, see :attr:`HopperConfig.bulk_viscosity`): a viscous pressure ``eta_b tr(D)``
      added to the normal stresses of every loaded cell in the internal forces, ``eta_b = b_1
      rho c_p h`` (Pa s), the linear bulk viscosity of explicit dynamics codes: it damps the
      shortest compression wave at about the fraction ``b_1`` of critical, and the time step
      is reduced by ``sqrt(1 + b_1^2) - b_1`` for it.  It acts on volume changes only, which
      plastic flow at zero dilation does not make; in flowing material it removes most of the
      cells that the ringing of compression waves drives to the stress-free apex
      (``docs/physics_and_numerics.md`` §4).  Eulerian formulation only.
    - ``alpha_min``: cells with less material fraction carry no stress.
    - ``free_fall_depth``: depth of the free-fall zone below the outlet, in outlet diameters.
    - ``gravity_ramp_time``: gravity rises linearly during filling over ``gravity_ramp_periods``
      periods of the filled column's lowest elastic mode, ``4 L / c_p`` (``"auto"``, the
      default), or over this many seconds.  In periods the fill is quasi-static whatever the
      stiffness and the size of the silo, so that the filled loads are a property of the
      hopper (measured on a 0.2 m hopper at 1 cm: E = 2 and 20 MPa give wall pressures within
      0.02 % over 10 periods; a fixed time is a different number of periods for each).
    - ``settle_kinetic_energy``: filling is at rest when the kinetic energy falls below this
      fraction of ``M g L`` (``L`` = fill depth) after the ramp, and
      ``settle_damping_fraction``: ... and the damping carries less than this fraction of the
      weight (the wall and the plate hold the rest).
    - ``max_fill_time`` (s): filling stops (and says so) if not at rest by then.
    - ``min_open_fraction``: cut cells with a smaller open fraction are closed.
    - ``formulation``: ``"eulerian"`` (the default: a fixed grid the material flows through,
      :class:`fipy_hopper.model.HopperModel`) or ``"lagrangian"`` (a mesh that moves with the
      material, :class:`fipy_hopper.lagrangian.LagrangianModel`, conical hoppers only: it
      stops when the mesh distorts, long before the hopper is empty).
    - ``mirror_planes`` (``hopper.dimensions = 3`` only): the part of the silo computed between
      its mirror planes, the results given for the whole silo: ``"auto"`` (the default: a
      quarter of a centred silo, the half ``y >= 0`` of one with an off-centre outlet),
      ``"quarter"`` (a centred outlet only), ``"half"`` or ``"none"`` (the whole silo).

    ``cell_size`` is in ``[0.1 mm, 10 m]``, times in ``[0, 1e6 s]``; the gravity ramp may not
    exceed ``max_fill_time`` (filling would stop before gravity is complete; for ``"auto"``
    this is checked with the material, by :class:`HopperConfig`).
    """

    cell_size: float = 0.005
    dt_safety: float = 0.4
    transport_cfl: float = 0.25
    max_transport_interval: int = 50
    hourglass_coefficient: float = 0.1
    grid_viscosity: float = 0.0
    viscosity_length: float = 0.0
    bulk_viscosity: Union[float, str] = "auto"
    alpha_min: float = 1.0e-3
    free_fall_depth: float = 1.0
    gravity_ramp_time: Union[float, str] = "auto"
    gravity_ramp_periods: float = 10.0
    settle_kinetic_energy: float = 1.0e-6
    settle_damping_fraction: float = 1.0e-4
    max_fill_time: float = 2.0
    min_open_fraction: float = 0.05
    formulation: str = "eulerian"
    mirror_planes: str = "auto"

    def __post_init__(self):
        if not isinstance(self.formulation, str) or self.formulation not in FORMULATIONS:
            raise ConfigError(f"numerics.formulation = {_show(self.formulation)}: expected one "
                              f"of {', '.join(repr(f) for f in FORMULATIONS)}")
        if not isinstance(self.mirror_planes, str) or self.mirror_planes not in MIRROR_PLANES:
            raise ConfigError(f"numerics.mirror_planes = {_show(self.mirror_planes)}: expected "
                              f"one of {', '.join(repr(m) for m in MIRROR_PLANES)}")
        _check_range("numerics.cell_size", self.cell_size, *CELL_SIZE_RANGE, unit=" m")
        _check_range("numerics.dt_safety", self.dt_safety, 0, 1, low_open=True)
        _check_range("numerics.transport_cfl", self.transport_cfl, 0, 0.5, low_open=True)
        _check_int("numerics.max_transport_interval", self.max_transport_interval, 1, 100_000)
        _check_range("numerics.hourglass_coefficient", self.hourglass_coefficient, 0, 100)
        _check_range("numerics.grid_viscosity", self.grid_viscosity, 0, 10)
        _check_range("numerics.viscosity_length", self.viscosity_length, 0, 1, unit=" m")
        if self.bulk_viscosity != "auto":
            _check_range("numerics.bulk_viscosity", self.bulk_viscosity, 0, 1,
                         unit='; or "auto"')
        _check_range("numerics.alpha_min", self.alpha_min, 0, 0.5, low_open=True)
        _check_range("numerics.free_fall_depth", self.free_fall_depth, 0.25, 10)
        if isinstance(self.gravity_ramp_time, str):
            if self.gravity_ramp_time != "auto":
                raise ConfigError(f"numerics.gravity_ramp_time = {_show(self.gravity_ramp_time)}"
                                  f': expected a time in seconds in [0, {TIME_MAX:g}] or "auto"')
        else:
            _check_range("numerics.gravity_ramp_time", self.gravity_ramp_time, 0, TIME_MAX,
                         unit=" s")
        _check_range("numerics.gravity_ramp_periods", self.gravity_ramp_periods, 0, 1000)
        _check_range("numerics.settle_damping_fraction", self.settle_damping_fraction, 0, 1,
                     low_open=True)
        _check_range("numerics.settle_kinetic_energy", self.settle_kinetic_energy, 0, 1,
                     low_open=True)
        _check_range("numerics.max_fill_time", self.max_fill_time, 0, TIME_MAX, low_open=True,
                     unit=" s")
        _check_range("numerics.min_open_fraction", self.min_open_fraction, 0, 0.5)
        if self.gravity_ramp_time != "auto" and self.gravity_ramp_time > self.max_fill_time:
            raise ConfigError(
                f"numerics.gravity_ramp_time = {self.gravity_ramp_time:g} s is longer than "
                f"numerics.max_fill_time = {self.max_fill_time:g} s: filling would stop before "
                f"gravity is complete; allowed range is [0, {self.max_fill_time:g}] s")


@dataclass(frozen=True)
class RunConfig:
    """What to run: ``end_time`` in seconds of discharge, or ``"empty"``; 0 stops when the fill
    is at rest (the static design case: the filled loads, no discharge).

    ``"empty"`` stops when less than ``empty_fraction`` of the initial mass is left, or when
    nothing moves any more (a heel at rest), or at ``max_time`` seconds of discharge.
    ``wall_time_limit`` (s) stops any run; 0 means none.  ``markers_per_side``: passive
    marker points per cell side (``n x n`` per full cell) for the layer pictures; 0 = none.

    ``load_window`` (s): the wall loads of a discharge stage are averaged over this time (from
    the moment 90 % and 50 % of the mass is left), and the discharge envelope is the largest
    of such windows per bin; ``"auto"`` (the default) is 0.1 s, or the whole discharge when
    ``end_time`` is shorter (:attr:`load_window_s`).

    ``wall_bin_width`` (m): the resolution of the wall-load profiles along the wall: the
    traction recovered from the wall's reaction is a spline on knots this far apart and is
    reported as its mean over bins of this width (:mod:`fipy_hopper.wall_traction`).
    ``"auto"`` (the default) is a twentieth of the silo's widest span (the bin's diameter or
    width), but at least three
    cells (:meth:`HopperConfig.wall_bin_width_m`); a width in metres stays the same under
    refinement, so profiles of different cell sizes compare bin by bin.

    ``opening_time`` (s): the outlet opens from the axis outwards over this time, as an iris
    whose radius grows as ``R_0 (t - t_open) / opening_time``: a plate node is let go when the
    radius passes it.  0 (the default) removes the whole plate at once.  The discharge's time
    counts from the start of the opening; the at-rest rule waits for its end.

    ``wall_sectors`` (``hopper.dimensions = 3`` only; 1 to 360, default 12): the sectors
    around the circumference of the 3D wall-load maps (``wall_pressure.csv``'s ``theta_deg``),
    centred on ``360 k / n`` deg from the outlet's offset.

    Times are at most 1e6 s; ``end_time <= max_time``; ``output_interval`` and
    ``load_window`` may not exceed the discharge (``end_time``, or ``max_time`` for
    ``"empty"``): the steady rate needs samples; ``output_interval >= 0.1 ms``,
    ``field_interval >= 1 ms``.
    """

    end_time: Union[float, str] = "empty"
    max_time: float = 60.0
    empty_fraction: float = 0.005
    wall_time_limit: float = 0.0
    output_interval: float = 0.05
    field_interval: float = 0.25
    markers_per_side: int = 2
    load_window: Union[float, str] = "auto"
    opening_time: float = 0.0
    wall_bin_width: Union[float, str] = "auto"
    wall_sectors: int = 12

    def __post_init__(self):
        _check_int("run.wall_sectors", self.wall_sectors, *WALL_SECTORS_RANGE)
        if isinstance(self.end_time, str):
            if self.end_time != "empty":
                raise ConfigError(f'run.end_time = {_show(self.end_time)}: expected a time in '
                                  f'seconds in [0, {TIME_MAX:g}] or "empty"')
        else:
            _check_range("run.end_time", self.end_time, 0, TIME_MAX, unit=" s")
        _check_range("run.max_time", self.max_time, 0, TIME_MAX, low_open=True, unit=" s")
        _check_range("run.empty_fraction", self.empty_fraction, 0, 1, True, True)
        _check_range("run.wall_time_limit", self.wall_time_limit, 0, None, unit=" s")
        _check_range("run.output_interval", self.output_interval, OUTPUT_INTERVAL_MIN,
                     TIME_MAX, unit=" s")
        _check_range("run.field_interval", self.field_interval, FIELD_INTERVAL_MIN, TIME_MAX,
                     unit=" s")
        _check_int("run.markers_per_side", self.markers_per_side, 0, 6)
        _check_range("run.opening_time", self.opening_time, 0, TIME_MAX, unit=" s")
        if isinstance(self.load_window, str):
            if self.load_window != "auto":
                raise ConfigError(f"run.load_window = {_show(self.load_window)}: expected a time "
                                  f'in seconds in [{OUTPUT_INTERVAL_MIN:g}, {TIME_MAX:g}] or "auto"')
        else:
            _check_range("run.load_window", self.load_window, OUTPUT_INTERVAL_MIN, TIME_MAX,
                         unit=" s")
        if isinstance(self.wall_bin_width, str):
            if self.wall_bin_width != "auto":
                raise ConfigError(f"run.wall_bin_width = {_show(self.wall_bin_width)}: expected "
                                  f"a length in metres in [{LENGTH_RANGE[0]:g}, "
                                  f'{LENGTH_RANGE[1]:g}] or "auto"')
        else:       # bins finer than a millimetre resolve nothing a continuum of grains has
            _check_range("run.wall_bin_width", self.wall_bin_width, *LENGTH_RANGE, unit=" m")
        if self.end_time != "empty" and self.end_time > self.max_time:
            raise ConfigError(
                f"run.end_time = {self.end_time:g} s is beyond run.max_time = "
                f"{self.max_time:g} s, which would stop the run first; allowed range is "
                f"[0, {self.max_time:g}] s (or raise run.max_time)")
        if self.discharge_time == 0.0:             # fill only: nothing is sampled in time
            return
        what = ("run.end_time" if self.end_time != "empty"
                else 'run.max_time (run.end_time = "empty")')
        if self.output_interval > self.discharge_time:
            raise ConfigError(
                f"run.output_interval = {self.output_interval:g} s is longer than the discharge, "
                f"{what} = {self.discharge_time:g} s: too few samples for a rate; allowed "
                f"range is [{OUTPUT_INTERVAL_MIN:g}, {self.discharge_time:g}] s")
        if self.opening_time > self.discharge_time:
            raise ConfigError(
                f"run.opening_time = {self.opening_time:g} s is longer than the discharge, "
                f"{what} = {self.discharge_time:g} s: the outlet would never be open; allowed "
                f"range is [0, {self.discharge_time:g}] s")
        if self.load_window != "auto" and self.load_window > self.discharge_time:
            raise ConfigError(
                f"run.load_window = {self.load_window:g} s is longer than the discharge, "
                f"{what} = {self.discharge_time:g} s; allowed range is "
                f"[{OUTPUT_INTERVAL_MIN:g}, {self.discharge_time:g}] s")

    @property
    def load_window_s(self) -> float:
        """The load window in seconds: ``load_window``, or for ``"auto"`` 0.1 s, but no more
        than the discharge."""
        if self.load_window != "auto":
            return float(self.load_window)
        return min(0.1, self.discharge_time) if self.discharge_time > 0 else 0.1

    @property
    def discharge_time(self) -> float:
        """The longest the discharge can last (s): ``end_time``, or ``max_time`` for "empty"."""
        return self.max_time if self.end_time == "empty" else float(self.end_time)


_SECTIONS = {"hopper": HopperGeometry, "material": MaterialConfig, "wall": WallConfig,
             "numerics": NumericsConfig, "run": RunConfig}


@dataclass(frozen=True)
class HopperConfig:
    """A complete, validated run configuration (one dataclass per TOML section).

    Beyond each section's own checks: at least 3 cells across the outlet radius; at most
    :data:`MAX_CELLS` cells (the memory a run needs, :meth:`memory_estimate`); at most
    :data:`MAX_STEPS` time steps (:meth:`step_estimate`); ``run.field_interval`` no longer than
    both filling and discharge.  All are checked before anything is allocated.
    """

    hopper: HopperGeometry = field(default_factory=HopperGeometry)
    material: MaterialConfig = field(default_factory=MaterialConfig)
    wall: WallConfig = field(default_factory=WallConfig)
    numerics: NumericsConfig = field(default_factory=NumericsConfig)
    run: RunConfig = field(default_factory=RunConfig)

    def __post_init__(self):
        for name, kind in _SECTIONS.items():
            if not isinstance(getattr(self, name), kind):
                raise ConfigError(f"[{name}]: expected a {kind.__name__}, got "
                                  f"{_show(getattr(self, name))}")
        if self.hopper.dimensions == 3:
            self._check_three_d()
        else:
            self._check_section_only()
        cells_across_outlet = self.hopper.outlet_radius / self.numerics.cell_size
        across = "radius" if self.hopper.axisymmetric else "half-width"
        if cells_across_outlet < 3:
            raise ConfigError(
                f"numerics.cell_size = {self.numerics.cell_size:g} m leaves "
                f"{cells_across_outlet:.2f} cells across the outlet {across} "
                f"({self.hopper.outlet_radius:g} m); at least 3 are needed "
                f"(cell_size <= {self.hopper.outlet_radius / 3:.4g} m)")
        self._check_fill_depth()
        if self.numerics.formulation == "lagrangian" and not self.hopper.axisymmetric:
            raise ConfigError('numerics.formulation = "lagrangian" models conical hoppers only; '
                              'a wedge (hopper.shape = "wedge") runs with "eulerian"')
        if self.numerics.formulation == "lagrangian" and not self.hopper.classic:
            raise ConfigError('numerics.formulation = "lagrangian" meshes a cone or a flat '
                              'floor under one vertical bin wall, without inserts in the '
                              f'material; this {self.hopper.n_wall_segments}-segment wall'
                              f'{" with inserts" if self.hopper.inserts else ""} runs with '
                              '"eulerian"')
        if self.numerics.formulation == "lagrangian" and self.hopper.fill_height <= 0.0:
            raise ConfigError(f'numerics.formulation = "lagrangian" meshes a fill that reaches '
                              f'the bin; hopper.fill_level = {self.hopper.fill_level:g} m is '
                              f'at or below the transition, z = {self.hopper.cone_height:g} m '
                              '(allowed range is above it); this fill runs with "eulerian"')
        if self.numerics.formulation == "lagrangian" and self.wall.segment_friction_deg \
                and len(set(self.wall.segment_friction_deg)) > 1:
            raise ConfigError('numerics.formulation = "lagrangian" takes one wall friction '
                              '(wall.friction_angle_deg); wall.segment_friction_deg with '
                              'different angles runs with "eulerian"')
        angles = self.wall.segment_friction_deg
        if angles is not None and len(angles) != self.hopper.n_wall_segments:
            what = ("hopper.wall has" if self.hopper.shape == "profile" else
                    f"the {self.hopper.shape} shorthand's wall has (the hopper, the bin)")
            raise ConfigError(f"wall.segment_friction_deg has {len(angles)} value"
                              f"{'s' * (len(angles) != 1)}; {what} "
                              f"{self.hopper.n_wall_segments} segments: one angle per segment, "
                              f"from the lip up")
        self._check_grains()
        if self.numerics.formulation == "lagrangian" and self.run.opening_time > 0.0:
            raise ConfigError(f"run.opening_time = {self.run.opening_time:g} s applies to "
                              'numerics.formulation = "eulerian" only; allowed range with '
                              '"lagrangian" is [0, 0] s')
        for key, value in (("grid_viscosity", self.numerics.grid_viscosity),
                           ("bulk_viscosity", self.bulk_viscosity)):
            if self.numerics.formulation == "lagrangian" and value > 0.0:
                raise ConfigError(f"numerics.{key} = {value:g} applies to "
                                  'numerics.formulation = "eulerian" only; allowed range with '
                                  '"lagrangian" is [0, 0]')
        self._check_grid_size()
        self._check_step_count()
        if self.ramp_time > self.numerics.max_fill_time:
            raise ConfigError(
                f"numerics.gravity_ramp_periods = {self.numerics.gravity_ramp_periods:g} periods "
                f"of the filled column ({self.column_period:.4g} s each) ramp gravity over "
                f"{self.ramp_time:.4g} s, longer than numerics.max_fill_time = "
                f"{self.numerics.max_fill_time:g} s: filling would stop before gravity is "
                f"complete; raise numerics.max_fill_time to at least {2 * self.ramp_time:.3g} s")
        run, fill = self.run, self.numerics.max_fill_time
        if run.field_interval > max(fill, run.discharge_time):
            raise ConfigError(
                f"run.field_interval = {run.field_interval:g} s is longer than both the filling "
                f"(numerics.max_fill_time = {fill:g} s) and the discharge ({run.discharge_time:g}"
                f" s): no snapshot in between; allowed range is [{FIELD_INTERVAL_MIN:g}, "
                f"{max(fill, run.discharge_time):g}] s")
        if run.end_time != "empty" and 0 < run.end_time < run.field_interval:
            warnings.warn(f"run.field_interval = {run.field_interval:g} s is longer than "
                          f"run.end_time = {run.end_time:g} s: the discharge gets only its "
                          "first and last field snapshots", SamplingWarning, stacklevel=3)
        if cells_across_outlet < 6:
            warnings.warn(f"only {cells_across_outlet:.1f} cells across the outlet {across}; "
                          "6 or more are recommended for a discharge rate", ResolutionWarning,
                          stacklevel=3)

    def _check_section_only(self) -> None:
        """A section (``hopper.dimensions = 2``) has no 3D options: refuse any set away from
        its default."""
        if self.numerics.mirror_planes != "auto":
            raise ConfigError(f'numerics.mirror_planes = "{self.numerics.mirror_planes}" is for '
                              'hopper.dimensions = 3 (a section is computed as drawn); allowed '
                              'with dimensions = 2 is "auto"')
        if self.run.wall_sectors != 12:
            raise ConfigError(f"run.wall_sectors = {self.run.wall_sectors} is for "
                              "hopper.dimensions = 3 (a section's wall has no circumference); "
                              "allowed with dimensions = 2 is 12, the default")

    def _check_three_d(self) -> None:
        """What the 3D model (:mod:`fipy_hopper.space`) does not do yet, refused in one line
        each: the Lagrangian formulation, the opening iris, markers (the default
        ``run.markers_per_side = 2`` resolves to 0: a 3D run has none), the quarter with an
        off-centre outlet."""
        num, run = self.numerics, self.run
        if num.formulation != "eulerian":
            raise ConfigError(f'numerics.formulation = "{num.formulation}" is for sections; '
                              'hopper.dimensions = 3 runs with "eulerian"')
        if run.opening_time > 0.0:
            raise ConfigError(f"run.opening_time = {run.opening_time:g} s: the 3D model "
                              "(hopper.dimensions = 3) removes the outlet plate at once; "
                              "allowed range with dimensions = 3 is [0, 0] s")
        if run.markers_per_side == RunConfig.markers_per_side:
            object.__setattr__(self, "run", dataclasses.replace(run, markers_per_side=0))
        elif run.markers_per_side != 0:
            raise ConfigError(f"run.markers_per_side = {run.markers_per_side}: the 3D model "
                              "(hopper.dimensions = 3) carries no layer markers yet; allowed "
                              "with dimensions = 3 is 0 (the default 2 is taken as 0)")
        ex, ey = self.hopper.offset_xy
        if num.mirror_planes == "quarter" and (ex != 0.0 or ey != 0.0):
            where = (f"{ex:g} m" if not self.hopper.rectangular
                     else f"[{ex:g}, {ey:g}] m")
            raise ConfigError(f'numerics.mirror_planes = "quarter" needs a centred outlet; '
                              f"hopper.outlet_offset = {where} is "
                              f"symmetric about {'y' if ey == 0.0 else 'x'} = 0 only: "
                              '"auto", "half" or "none"' if ex == 0.0 or ey == 0.0 else
                              f'numerics.mirror_planes = "quarter" needs a centred outlet; '
                              f"hopper.outlet_offset = {where} has no mirror plane: "
                              '"auto" or "none"')
        if num.mirror_planes == "half" and ex != 0.0 and ey != 0.0:
            raise ConfigError(f'numerics.mirror_planes = "half" needs the outlet on x = 0 or '
                              f"y = 0; hopper.outlet_offset = [{ex:g}, {ey:g}] m is on neither: "
                              '"auto" or "none"')

    def space_config(self):
        """The 3D model's settings (:meth:`fipy_hopper.space.config.SpaceConfig.from_config`)
        of a ``hopper.dimensions = 3`` configuration."""
        from .space.config import SpaceConfig
        return SpaceConfig.from_config(self)

    def _check_fill_depth(self) -> None:
        """The fill's surface at least :data:`FILL_CELLS` cells above the outlet plane: a
        thinner fill is not resolved by the grid (it has no cell of material at the wall to
        measure, and its run fails)."""
        geom, h = self.hopper, self.numerics.cell_size
        least = FILL_CELLS * h
        if geom.fill_level >= least:
            return
        if geom.shape == "profile":
            key, value, low = "hopper.fill_level", geom.fill_level, least
        else:
            key, value, low = "hopper.fill_height", geom.fill_height, least - geom.cone_height
        high = geom.top - (0.0 if geom.shape == "profile" else geom.cone_height)
        raise ConfigError(
            f"{key} = {value:g} m puts the fill's surface {geom.fill_level:g} m above the "
            f"outlet plane, less than {FILL_CELLS} cells (numerics.cell_size = {h:g} m): the "
            f"grid cannot resolve it; allowed range is [{_ceil_digits(low):.3g}, {high:g}] m")

    @cached_property
    def boundary(self):
        """The boundary (:class:`fipy_hopper.boundary.Boundary`) with every segment's wall
        friction: ``wall.segment_friction_deg`` or ``wall.friction_angle_deg`` on the walls,
        an insert's own angle or the wall's, 0 on the free-fall tubes.  Built once."""
        return self.hopper.boundary.with_friction(self.wall.friction_angle_deg,
                                                  self.wall.segment_friction_deg)

    # ------------------------------------------------------------ size of a run
    def grid_shape(self, cell_size: float = None) -> tuple:
        """``(nr, nz)`` of the grid :func:`fipy_hopper.mesh.build_grid` builds (same rules);
        in 3D ``(nx, ny, nz)`` of the computed part's grid
        (:func:`fipy_hopper.space.estimate.grid_shape`)."""
        h = self.numerics.cell_size if cell_size is None else cell_size
        if self.hopper.dimensions == 3:
            from .space.estimate import grid_shape
            return grid_shape(self.space_config(), h)
        return _grid_shape(self.hopper, self.numerics, h)

    @property
    def n_cells(self) -> int:
        return math.prod(self.grid_shape())

    @property
    def wall_bin_width_m(self) -> float:
        """The wall-load bins' width (m): ``run.wall_bin_width``, or for ``"auto"`` a twentieth
        of the silo's widest span (:attr:`HopperGeometry.width`: the bin's diameter, a wedge's
        width), at least three cells.  Three cells is what
        averages the cut cells' pattern of the wall's reaction to a smooth profile (the
        traction's spline spans four bins); a twentieth of the silo resolves its loads
        (15 mm in the reference hopper) independently of the cell size."""
        return self.wall_bin_width_at(self.numerics.cell_size)

    def wall_bin_width_at(self, cell_size: float) -> float:
        """:attr:`wall_bin_width_m` on a grid of ``cell_size`` m."""
        if self.run.wall_bin_width != "auto":
            return float(self.run.wall_bin_width)
        return max(3.0 * cell_size, self.hopper.width / 20.0)

    def memory_estimate(self) -> float:
        """Peak resident memory of a run (bytes): the grid, its markers and its wall loads
        (:func:`fipy_hopper.resources.memory_estimate`)."""
        from .resources import memory_estimate
        return memory_estimate(self)

    @property
    def time_step(self) -> float:
        """The explicit time step ``dt_safety * cell_size / c_p`` (the law's
        :meth:`~fipy_hopper.material.MohrCoulomb.stable_time_step`) times
        :func:`damped_step_factor` of the bulk viscosity (s), as the model takes it."""
        return (self.material.law().stable_time_step(self.numerics.cell_size,
                                                     self.numerics.dt_safety)
                * damped_step_factor(self.bulk_viscosity))

    def step_estimate(self) -> float:
        """Most time steps a run can take: filling up to ``max_fill_time`` plus the discharge."""
        return (self.numerics.max_fill_time + self.run.discharge_time) / self.time_step

    def _check_grains(self) -> None:
        """The outlet against the grains: no wider grain than the outlet (an error), and an
        outlet under :data:`ARCHING_GRAINS` grains wide arches (a warning, :class:`
        ArchingWarning`): Beverloo's regime, and the continuum's, end there."""
        d = self.material.grain_diameter
        if d <= 0.0:
            return
        width = 2.0 * self.hopper.outlet_radius
        what = "diameter" if self.hopper.axisymmetric else "width"
        if d >= width:
            raise ConfigError(f"material.grain_diameter = {d:g} m is not smaller than the "
                              f"outlet's {what} {width:g} m: allowed range is (0, {width:g}) m")
        if width < ARCHING_GRAINS * d:
            warnings.warn(f"the outlet's {what} {width:g} m is {width / d:.2f} grain diameters "
                          f"(material.grain_diameter = {d:g} m), fewer than about "
                          f"{ARCHING_GRAINS:g}: such an outlet arches and does not flow "
                          f"steadily; Beverloo's correlation and this continuum do not "
                          f"describe it", ArchingWarning, stacklevel=3)

    def _check_grid_size(self) -> None:
        h = self.numerics.cell_size
        n = self.n_cells
        if n <= MAX_CELLS:
            return
        # the smallest cell size whose grid fits: the count never grows with the cell size,
        # so bisect on the exact count, then round up to 3 digits
        lo, hi = h, max(h, 2 * (self.hopper.top + self.hopper.width))
        for _ in range(100):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if math.prod(self.grid_shape(mid)) > MAX_CELLS else (lo, mid)
        smallest = _ceil_digits(hi)
        while math.prod(self.grid_shape(smallest)) > MAX_CELLS:   # float noise of the rounding
            smallest = _ceil_digits(smallest * 1.001)
        limit = self.hopper.outlet_radius / 3
        what = (f"cell_size >= {smallest:.3g} m" if smallest <= limit else
                f"no cell size fits: {smallest:.3g} m or more would leave fewer than 3 cells "
                f"across the outlet radius; a smaller hopper or a wider outlet")
        raise ConfigError(
            f"numerics.cell_size = {h:g} m makes a "
            f"{'3D grid (its computed part) ' if self.hopper.dimensions == 3 else 'grid '}of "
            f"{n:,} cells (about "
            f"{grid_memory(n) / 1e9:.3g} GB for the grid alone); at most {MAX_CELLS:,} cells "
            f"(about {grid_memory(MAX_CELLS) / 1e9:.2g} GB) are allowed: "
            f"{what}")

    def _check_step_count(self) -> None:
        steps = self.step_estimate()
        if steps <= MAX_STEPS:
            return
        num, run = self.numerics, self.run
        end = "run.end_time" if run.end_time != "empty" else "run.max_time"
        h = _ceil_digits(num.cell_size * steps / MAX_STEPS)
        finer = (f"numerics.cell_size >= {h:.3g} m, " if h <= self.hopper.outlet_radius / 3
                 else "")
        raise ConfigError(
            f"numerics.cell_size = {num.cell_size:g} m with numerics.dt_safety = "
            f"{num.dt_safety:g} and c_p = {self.material.p_wave_speed:.4g} m/s gives a time "
            f"step of {self.time_step:.3g} s and up to {steps:.3g} steps over "
            f"numerics.max_fill_time + {end} = {num.max_fill_time:g} + {run.discharge_time:g}"
            f" s; at most {MAX_STEPS:.0e} can finish: {finer}a smaller c_p "
            f"(material.youngs_modulus, material.poisson_ratio) or shorter times")

    @property
    def column_period(self) -> float:
        """Period of the lowest elastic mode of the filled column, ``4 L / c_p`` (s): a quarter
        wave, fixed at the plate and free at the surface, ``L`` the fill level above the outlet
        (at least a cell)."""
        column = max(self.hopper.fill_level, self.numerics.cell_size)
        return 4.0 * column / self.material.p_wave_speed

    @property
    def ramp_time(self) -> float:
        """The time over which gravity rises during filling (s): ``gravity_ramp_periods``
        column periods for ``gravity_ramp_time = "auto"``, else ``gravity_ramp_time``."""
        num = self.numerics
        if num.gravity_ramp_time == "auto":
            return num.gravity_ramp_periods * self.column_period
        return float(num.gravity_ramp_time)

    @property
    def bulk_viscosity(self) -> float:
        """The bulk viscosity ``b_1`` the model uses: ``numerics.bulk_viscosity``, or for
        ``"auto"`` :data:`DEFAULT_BULK_VISCOSITY` with the Eulerian formulation and 0 with the
        Lagrangian one (which has no bulk viscosity)."""
        num = self.numerics
        if num.bulk_viscosity == "auto":
            return DEFAULT_BULK_VISCOSITY if num.formulation == "eulerian" else 0.0
        return float(num.bulk_viscosity)

    @classmethod
    def from_dict(cls, data: dict) -> "HopperConfig":
        """Build from nested dictionaries (as read from TOML); unknown keys are refused."""
        if not isinstance(data, dict):
            raise ConfigError("configuration: expected a table of sections")
        unknown = [k for k in data if k not in _SECTIONS]
        if unknown:
            if not isinstance(unknown[0], str):
                raise ConfigError(f"configuration: a section must be a name, got "
                                  f"{_show(unknown[0])}")
            raise ConfigError(_unknown_message("section", unknown[0], list(_SECTIONS)))
        sections = {}
        for name, kind in _SECTIONS.items():
            values = data.get(name, {})
            if not isinstance(values, dict):
                raise ConfigError(f"[{name}]: expected a table of keys, got {_show(values)}")
            allowed = [f.name for f in fields(kind)]
            for key in values:
                if not isinstance(key, str):
                    raise ConfigError(f"[{name}]: a key must be a name, got {_show(key)}")
                if key not in allowed:
                    raise ConfigError(_unknown_message(f"key in [{name}]", key, allowed,
                                                       prefix=f"{name}."))
            if name == "hopper":
                _check_shape_keys(values)
            sections[name] = kind(**values)
        return cls(**sections)

    @classmethod
    def from_toml(cls, path: Union[str, Path]) -> "HopperConfig":
        """Read and validate a TOML file."""
        path = Path(path)
        try:       # UTF-8, with or without the byte-order mark some editors write first
            text = path.read_text(encoding="utf-8-sig")
        except OSError as exc:
            raise ConfigError(f"cannot read configuration {path}: {exc.strerror}") from None
        except UnicodeDecodeError as exc:
            raise ConfigError(f"{path} is not valid TOML: not UTF-8 text (byte {exc.start})") \
                from None
        try:
            data = tomllib.loads(text)
        except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
            twice = str(exc).startswith(("Cannot overwrite", "Cannot declare"))
            raise ConfigError(f"{path} is not valid TOML: "
                              f"{twice and _duplicate_key(text) or short_text(exc)}") from None
        except ValueError:      # an integer beyond Python's limit of digits
            limit = sys.get_int_max_str_digits()
            raise ConfigError(f"{path} is not valid TOML: {_toml_place(text, _long_integer)}"
                              f"an integer of more than {limit:,} digits") from None
        except RecursionError:
            raise ConfigError(f"{path} is not valid TOML: {_toml_place(text, _nesting_over())}"
                              "arrays or inline tables nested too deeply (a configuration "
                              "is [section] and key = value)") from None
        return cls.from_dict(data)

    def to_dict(self) -> dict:
        """The sections as dictionaries; the hopper's sizes under the keys its shape takes
        (diameters for a cone, widths for a wedge, the points of a profile), so that the
        dictionary reads back; points as lists, keys left at None out."""
        out = _plain(dataclasses.asdict(self))
        hopper = out["hopper"]
        geom = self.hopper
        if geom.rectangular:
            unused = PROFILE_KEYS + ("symmetry", "section", "shape", "bin_diameter") + (
                ("outlet_width", "outlet_length") if geom.outlet_width is None
                else ("outlet_diameter",))
        elif geom.shape == "profile":
            unused = SHORTHAND_KEYS + (("left_wall",) if geom.left_wall is None else ())
        else:
            unused = PROFILE_KEYS + ("symmetry", "section") + (
                ("bin_width", "outlet_width") if geom.shape == "conical"
                else ("bin_diameter", "outlet_diameter"))
        if not geom.rectangular:        # a circular silo's file reads as before the plans
            unused += ("plan",) + tuple(k for k in RECTANGULAR_KEYS if k not in unused)
        if geom.dimensions == 2:        # a section's file reads as before the 3D keys
            unused += ("dimensions", "outlet_offset")
            del out["numerics"]["mirror_planes"], out["run"]["wall_sectors"]
        for key in unused + (() if geom.inserts else ("inserts",)):
            del hopper[key]
        for item in hopper.get("inserts", ()):
            if item["friction_angle_deg"] is None:
                del item["friction_angle_deg"]
        if self.wall.segment_friction_deg is None:
            del out["wall"]["segment_friction_deg"]
        return out

    def to_toml(self) -> str:
        """The resolved configuration as TOML text (every key, defaults included)."""
        lines = ["# fipy_hopper resolved configuration (SI units, angles in degrees)"]
        for name, values in self.to_dict().items():
            lines.append(f"\n[{name}]")
            for key, value in values.items():
                lines.append(f"{key} = {_toml_value(value)}")
        return "\n".join(lines) + "\n"

    def replace(self, **sections) -> "HopperConfig":
        """A copy with some fields changed, e.g. ``cfg.replace(numerics={"cell_size": 0.01})``."""
        new = {}
        for name, kind in _SECTIONS.items():
            current = getattr(self, name)
            change = sections.pop(name, None)
            if change and not isinstance(change, dict):
                raise ConfigError(f"[{name}]: expected a dict of keys, got {_show(change)}")
            allowed = [f.name for f in fields(kind)]
            for key in change or ():
                if key not in allowed:
                    raise ConfigError(_unknown_message(f"key in [{name}]", str(key), allowed,
                                                       prefix=f"{name}."))
            if name == "hopper" and change:
                _check_shape_keys({"shape": current.shape, "plan": current.plan, **change})
                if change.get("shape", current.shape) != current.shape:
                    new[name] = _reshaped(current, change)
                    continue
            new[name] = dataclasses.replace(current, **change) if change else current
        if sections:
            raise ConfigError(_unknown_message("section", next(iter(sections)), list(_SECTIONS)))
        return HopperConfig(**new)


def _reshaped(current: HopperGeometry, change: dict) -> HopperGeometry:
    """:meth:`HopperConfig.replace` to another ``hopper.shape``: the geometry of ``change``
    with what the two shapes share carried over (between a cone and a wedge their half-angle
    and heights; always the inserts; to a profile, the symmetry), never what belongs to the
    old shape (a cone's symmetry into a wedge, a profile's points into a cone)."""
    shared = ("half_angle_deg", "bin_height", "fill_height")
    carried = {"inserts": current.inserts, "dimensions": current.dimensions,
               "outlet_offset": current.outlet_offset}
    if change["shape"] == "profile":
        carried["symmetry"] = current.symmetry
    elif current.shape != "profile":
        carried.update({key: getattr(current, key) for key in shared})
    return HopperGeometry(**{**carried, **change})


def _ceil_digits(x: float, digits: int = 3) -> float:
    """``x`` rounded up to ``digits`` significant digits (a bound that stays admissible)."""
    step = 10.0 ** (math.floor(math.log10(x)) - digits + 1)
    return float(f"{math.ceil(x / step * (1 - 1e-12)) * step:.{digits}g}")


def _check_shape_keys(values: dict) -> None:
    """Refuse the keys of another shape (or plan) in a ``[hopper]`` table (before any is
    used)."""
    shape = values.get("shape", "conical")
    if values.get("plan") == "rectangular":
        if "bin_diameter" in values:
            raise ConfigError('hopper.bin_diameter is for a circular plan; a rectangular bin '
                              '(plan = "rectangular") takes hopper.bin_width (along x) and '
                              'hopper.bin_length (along y)')
        if values.get("outlet_diameter") is not None and values.get("outlet_width") is not None:
            raise ConfigError("hopper.outlet_diameter (a circular outlet) and hopper.outlet_width "
                              "(a rectangular one) are both given; give one")
    if shape == "wedge":
        for key in ("bin_diameter", "outlet_diameter"):
            if key in values:
                raise ConfigError(
                    f"hopper.{key} is for a conical hopper; a wedge (shape = "
                    f"\"wedge\") takes hopper.{key.replace('diameter', 'width')}")
    if shape == "profile":
        for key in SHORTHAND_KEYS:
            if values.get(key) is not None:
                raise ConfigError(f"hopper.{key} is for the conical and wedge shorthands; a "
                                  f"profile (shape = \"profile\") takes its sizes from "
                                  f"hopper.wall")
    elif shape in SHAPES:
        for key in PROFILE_KEYS:
            if values.get(key) is not None:
                instead = (" (a shorthand takes hopper.fill_height, above the transition)"
                           if key == "fill_level" else "")
                raise ConfigError(f"hopper.{key} is for shape = \"profile\", not "
                                  f"\"{shape}\"{instead}")


def _plain(value):
    """Tuples as lists, recursively (for TOML and JSON)."""
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


def _grid_shape(geom: HopperGeometry, num: NumericsConfig, h: float) -> tuple:
    """``(nr, nz)`` by the rules of :func:`fipy_hopper.mesh.build_grid` for cell size ``h``."""
    nr, n_below, n_above = grid_rows(geom, num, h)
    return nr, n_below + n_above


def grid_rows(geom: HopperGeometry, num: NumericsConfig, h: float) -> tuple:
    """``(nr, n_below, n_above)``: the columns of the grid (across
    :attr:`HopperGeometry.x_extent`), its rows below the outlet plane and above it, by the
    rules of :func:`fipy_hopper.mesh.build_grid` for cell size ``h``."""
    x0, nr = grid_columns(geom, h)
    n_below = max(int(math.ceil(num.free_fall_depth * geom.outlet_diameter / h - 1e-9)), 3)
    n_above = int(math.ceil(geom.top / h - 1e-9)) + 1
    return nr, n_below, n_above


def grid_columns(geom: HopperGeometry, h: float) -> tuple:
    """``(x0, nr)``: the grid's first node column ``x0`` (m) and its number of columns.  A
    half-section starts on the axis (``x0 = 0``) and ends two cells beyond its widest point;
    a full section starts two cells beyond its left wall's extreme on a multiple of ``h``
    (so ``x = 0``, the middle of a centred slot, is a node column) and ends two cells beyond
    its right wall's."""
    x_min, x_max = geom.x_extent
    x0 = 0.0 if not geom.full_section else -h * (math.ceil(-x_min / h - 1e-9) + 2)
    return x0, int(math.ceil((x_max - x0) / h - 1e-9)) + 2


def grid_memory(n_cells: int, kept: bool = False) -> float:
    """Peak bytes of building a grid of ``n_cells`` cells and its model (measured, see
    :data:`MAX_CELLS`), or with ``kept`` what they keep once built
    (:data:`MEMORY_KEPT_PER_CELL`); a run adds its markers and wall loads
    (:func:`fipy_hopper.resources.memory_estimate`)."""
    return MEMORY_BASE + (MEMORY_KEPT_PER_CELL if kept else MEMORY_PER_CELL) * n_cells


_TOML_HEADER = re.compile(r"\s*\[\[?([^\[\]]+)\]\]?\s*(#.*)?$")
_TOML_KEY = re.compile(r"\s*([A-Za-z0-9_\-. \t\"']+?)\s*=")


def _toml_keys(text: str, tables: bool = False):
    """``(line number, dotted key)`` of each ``key = value`` line of a TOML text, with the name
    of its table (and ``[table]`` for each table header when ``tables``): a line scan for
    messages only, which does not follow multi-line values."""
    table = ""
    for number, line in enumerate(text.splitlines(), start=1):
        header = _TOML_HEADER.match(line)
        if header:
            table = _dotted(header.group(1))
            if tables and not line.lstrip().startswith("[["):
                yield number, f"[{table}]"
            continue
        key = _TOML_KEY.match(line)
        if key and not line.lstrip().startswith("#"):
            yield number, ".".join(p for p in (table, _dotted(key.group(1))) if p)


def _dotted(name: str) -> str:
    return ".".join(part.strip().strip("\"'") for part in name.split("."))


def _duplicate_key(text: str) -> str:
    """'the key 'a.b' is set twice (lines m and n)' for the first key (or table) set twice,
    or ''."""
    seen = {}
    for number, key in _toml_keys(text, tables=True):
        if key in seen:
            what = "table" if key.startswith("[") else "key"
            return (f"the {what} '{short_text(key, 60)}' is set twice (lines {seen[key]} and "
                    f"{number})")
        seen[key] = number
    return ""


def _long_integer(line: str) -> bool:
    limit = sys.get_int_max_str_digits()
    return any(len(run.replace("_", "")) > limit for run in re.findall(r"[0-9][0-9_]*", line))


def _nesting_over(limit: int = 100):
    """A test of successive lines: true from the line where the brackets still open pass
    ``limit``."""
    depth = 0

    def is_here(line: str) -> bool:
        nonlocal depth
        for c in line:
            depth += (c in "[{") - (c in "]}")
            if depth > limit:
                return True
        return False
    return is_here


def _toml_place(text: str, is_here) -> str:
    """'line n (key 'a.b'): ' of the first line of ``text`` where ``is_here(line)``, or ''."""
    keys = dict(_toml_keys(text))
    key = ""
    for number, line in enumerate(text.splitlines(), start=1):
        key = keys.get(number, key)
        if is_here(line):
            return f"line {number}" + (f" (key '{short_text(key, 60)}')" if key else "") + ": "
    return ""


def _toml_value(value) -> str:
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, dict):         # an inline table
        return "{" + ", ".join(f"{k} = {_toml_value(v)}" for k, v in value.items()) + "}"
    return repr(value)


def _unknown_message(what: str, key: str, allowed: list, prefix: str = "") -> str:
    close = difflib.get_close_matches(key, allowed, n=1)
    hint = f"; did you mean '{prefix}{close[0]}'?" if close else ""
    name = repr(key)[1:-1] if key.isprintable() is False else key   # one line: escape
    name = name if len(name) <= 40 else name[:37] + "..."
    return f"unknown {what} '{prefix}{name}'{hint} (allowed: {', '.join(allowed)})"


def reference_config(**sections) -> HopperConfig:
    """The reference hopper: D = 0.3 m, 20 deg cone, D0 = 0.06 m, 0.3 m fill, dry sand, 15 deg wall."""
    return HopperConfig().replace(**sections) if sections else HopperConfig()
