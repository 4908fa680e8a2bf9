"""Validated configuration of a hopper run: frozen dataclasses, TOML in and out.

All values are SI (m, s, kg, Pa); angles are given in degrees at this boundary only.
Every check names the TOML key, the value and the allowed range, and runs before anything
is computed.  The public TOML contract (sections and keys) is::

    [hopper]    bin_diameter, half_angle_deg, outlet_diameter, bin_height, fill_height
    [material]  density, youngs_modulus, poisson_ratio, friction_angle_deg,
                dilation_angle_deg, cohesion
    [wall]      friction_angle_deg
    [numerics]  cell_size, ...
    [run]       end_time (seconds or "empty"), ...
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import warnings
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any, Union

try:  # Python >= 3.11
    import tomllib
except ModuleNotFoundError:  # pragma: no cover - Python 3.10
    import tomli as tomllib


class ConfigError(ValueError):
    """A configuration value is missing, of the wrong type or outside its allowed range."""


class ResolutionWarning(UserWarning):
    """The grid resolves a feature of the hopper with few cells."""


def _check_number(key: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ConfigError(f"{key} = {value!r}: expected a number")
    value = float(value)
    if not math.isfinite(value):
        raise ConfigError(f"{key} = {value!r}: expected a finite number")
    return value


def _check_range(key: str, value: Any, low=None, high=None, low_open=False, high_open=False,
                 unit: str = "") -> float:
    """Check ``low <(=) value <(=) high`` and return the value as float; error names the key."""
    value = _check_number(key, value)
    bad = ((low is not None and (value < low or (low_open and value == low)))
           or (high is not None and (value > high or (high_open and value == high))))
    if bad:
        lo = "-inf" if low is None else f"{low:g}"
        hi = "inf" if high is None else f"{high:g}"
        interval = ("(" if low_open or low is None else "[") + f"{lo}, {hi}" + (
            ")" if high_open or high is None else "]")
        raise ConfigError(f"{key} = {value:g}{unit}: allowed range is {interval}{unit}")
    return value


@dataclass(frozen=True)
class HopperGeometry:
    """Conical hopper below a cylindrical bin; the outlet plane is ``z = 0``, ``z`` upward.

    ``fill_height`` and ``bin_height`` are measured above the cone-cylinder transition.
    ``half_angle_deg`` is the cone half-angle from the vertical, in ``(0, 90]``; 90 is a
    flat-bottomed bin.
    """

    bin_diameter: float = 0.3
    half_angle_deg: float = 20.0
    outlet_diameter: float = 0.06
    bin_height: float = 0.35
    fill_height: float = 0.3

    def __post_init__(self):
        _check_range("hopper.bin_diameter", self.bin_diameter, 0, None, low_open=True, unit=" m")
        _check_range("hopper.half_angle_deg", self.half_angle_deg, 0, 90, low_open=True,
                     unit=" deg")
        _check_range("hopper.outlet_diameter", self.outlet_diameter, 0, None, low_open=True,
                     unit=" m")
        _check_range("hopper.bin_height", self.bin_height, 0, None, low_open=True, unit=" m")
        _check_range("hopper.fill_height", self.fill_height, 0, None, low_open=True, unit=" m")
        if self.outlet_diameter >= self.bin_diameter:
            raise ConfigError(
                f"hopper.outlet_diameter = {self.outlet_diameter:g} m is not narrower than the "
                f"bin, hopper.bin_diameter = {self.bin_diameter:g} m")
        if self.fill_height > self.bin_height:
            raise ConfigError(
                f"hopper.fill_height = {self.fill_height:g} m is above the top of the bin, "
                f"hopper.bin_height = {self.bin_height:g} m")

    @property
    def bin_radius(self) -> float:
        return 0.5 * self.bin_diameter

    @property
    def outlet_radius(self) -> float:
        return 0.5 * self.outlet_diameter

    @property
    def half_angle(self) -> float:
        """Cone half-angle in radians."""
        return math.radians(self.half_angle_deg)

    @property
    def cone_height(self) -> float:
        """Height of the cone-cylinder transition above the outlet, ``(R - R0) / tan(theta)``
        (zero for a flat-bottomed bin)."""
        if self.half_angle_deg >= 90.0:
            return 0.0
        return (self.bin_radius - self.outlet_radius) / math.tan(self.half_angle)

    @property
    def top(self) -> float:
        """Height of the top of the bin above the outlet plane."""
        return self.cone_height + self.bin_height

    @property
    def fill_level(self) -> float:
        """Height of the levelled fill surface above the outlet plane."""
        return self.cone_height + self.fill_height

    def fill_volume(self) -> float:
        """Volume of the filled material (full 3D, m^3): frustum plus cylinder."""
        r0, r1, h = self.outlet_radius, self.bin_radius, self.cone_height
        cone = math.pi * h / 3.0 * (r0 * r0 + r0 * r1 + r1 * r1)
        return cone + math.pi * r1 * r1 * self.fill_height


@dataclass(frozen=True)
class MaterialConfig:
    """Bulk granular material (SI; angles in degrees)."""

    density: float = 1500.0
    youngs_modulus: float = 5.0e6
    poisson_ratio: float = 0.3
    friction_angle_deg: float = 30.0
    dilation_angle_deg: float = 0.0
    cohesion: float = 0.0

    def __post_init__(self):
        _check_range("material.density", self.density, 0, None, low_open=True, unit=" kg/m3")
        _check_range("material.youngs_modulus", self.youngs_modulus, 0, None, low_open=True,
                     unit=" Pa")
        _check_range("material.poisson_ratio", self.poisson_ratio, -1, 0.5, True, True)
        _check_range("material.friction_angle_deg", self.friction_angle_deg, 0, 90, True, True,
                     " deg")
        _check_range("material.dilation_angle_deg", self.dilation_angle_deg, 0,
                     self.friction_angle_deg, unit=" deg")
        _check_range("material.cohesion", self.cohesion, 0, None, unit=" Pa")

    def mohr_coulomb(self):
        """The :class:`fipy_hopper.material.MohrCoulomb` of this material."""
        from .material import MohrCoulomb
        return MohrCoulomb(E=self.youngs_modulus, nu=self.poisson_ratio, rho=self.density,
                           phi=self.friction_angle_deg, psi=self.dilation_angle_deg,
                           c=self.cohesion)

    @property
    def p_wave_speed(self) -> float:
        """``c_p = sqrt(E (1 - nu) / ((1 + nu)(1 - 2 nu) rho))`` in m/s."""
        E, nu = self.youngs_modulus, self.poisson_ratio
        return math.sqrt(E * (1 - nu) / ((1 + nu) * (1 - 2 * nu) * self.density))


@dataclass(frozen=True)
class WallConfig:
    """Hopper wall: Coulomb friction angle between material and wall (degrees)."""

    friction_angle_deg: float = 15.0

    def __post_init__(self):
        _check_range("wall.friction_angle_deg", self.friction_angle_deg, 0, 90, high_open=True,
                     unit=" deg")

    @property
    def friction_coefficient(self) -> float:
        return math.tan(math.radians(self.friction_angle_deg))


@dataclass(frozen=True)
class NumericsConfig:
    """Discretisation and time-stepping knobs.

    - ``cell_size`` (m): square cells of the fixed grid.
    - ``dt_safety``: explicit step ``dt = dt_safety * cell_size / c_p``.
    - ``transport_cfl``: sub-cycled transport runs when the material has moved this fraction of a
      cell (mass-weighted speed), and at most every ``max_transport_interval`` steps.
    - ``hourglass_coefficient``: viscous hourglass force per unit area
      ``kappa_hg * rho * sqrt(g h)`` times the cell's checkerboard velocity.  The velocity scale
      is the grid's free-fall speed ``sqrt(g h)``, not the elastic wave speed: a damping that
      grows with ``sqrt(E)`` acts as an artificial viscosity that makes the discharge rate
      depend on the stiffness used (measured: doubling ``kappa_hg * c_p`` slowed the flow by
      8%), while this one vanishes under refinement.
    - ``alpha_min``: cells with less material fraction carry no stress.
    - ``free_fall_depth``: depth of the free-fall zone below the outlet, in outlet diameters.
    - ``gravity_ramp_time`` (s): gravity rises linearly during filling (avoids a dynamic overshoot
      locked in by wall friction).
    - ``settle_kinetic_energy``: filling is at rest when the kinetic energy falls below this
      fraction of ``M g L`` (``L`` = fill depth) after the ramp.
    - ``max_fill_time`` (s): filling stops (and says so) if not at rest by then.
    - ``min_open_fraction``: cut cells with a smaller open fraction are closed.
    """

    cell_size: float = 0.005
    dt_safety: float = 0.4
    transport_cfl: float = 0.25
    max_transport_interval: int = 50
    hourglass_coefficient: float = 0.1
    alpha_min: float = 1.0e-3
    free_fall_depth: float = 1.0
    gravity_ramp_time: float = 0.2
    settle_kinetic_energy: float = 1.0e-6
    max_fill_time: float = 2.0
    min_open_fraction: float = 0.05

    def __post_init__(self):
        _check_range("numerics.cell_size", self.cell_size, 0, None, low_open=True, unit=" m")
        _check_range("numerics.dt_safety", self.dt_safety, 0, 1, low_open=True)
        _check_range("numerics.transport_cfl", self.transport_cfl, 0, 0.5, low_open=True)
        if isinstance(self.max_transport_interval, bool) or not isinstance(
                self.max_transport_interval, int) or self.max_transport_interval < 1:
            raise ConfigError(f"numerics.max_transport_interval = {self.max_transport_interval!r}:"
                              " expected an integer >= 1")
        _check_range("numerics.hourglass_coefficient", self.hourglass_coefficient, 0, 100)
        _check_range("numerics.alpha_min", self.alpha_min, 0, 0.5, low_open=True)
        _check_range("numerics.free_fall_depth", self.free_fall_depth, 0.25, 10)
        _check_range("numerics.gravity_ramp_time", self.gravity_ramp_time, 0, None, unit=" s")
        _check_range("numerics.settle_kinetic_energy", self.settle_kinetic_energy, 0, 1,
                     low_open=True)
        _check_range("numerics.max_fill_time", self.max_fill_time, 0, None, low_open=True,
                     unit=" s")
        _check_range("numerics.min_open_fraction", self.min_open_fraction, 0, 0.5)


@dataclass(frozen=True)
class RunConfig:
    """What to run: ``end_time`` in seconds of discharge, or ``"empty"``.

    ``"empty"`` stops when less than ``empty_fraction`` of the initial mass is left, or when
    nothing moves any more (a heel at rest), or at ``max_time`` seconds of discharge.
    ``wall_time_limit`` (s) stops any run; 0 means none.  ``markers_per_side``: passive
    marker points per cell side (``n x n`` per full cell) for the layer pictures; 0 = none.
    """

    end_time: Union[float, str] = "empty"
    max_time: float = 60.0
    empty_fraction: float = 0.005
    wall_time_limit: float = 0.0
    output_interval: float = 0.05
    field_interval: float = 0.25
    markers_per_side: int = 2

    def __post_init__(self):
        if isinstance(self.end_time, str):
            if self.end_time != "empty":
                raise ConfigError(f'run.end_time = {self.end_time!r}: expected a time in seconds'
                                  ' or "empty"')
        else:
            _check_range("run.end_time", self.end_time, 0, None, low_open=True, unit=" s")
        _check_range("run.max_time", self.max_time, 0, None, low_open=True, unit=" s")
        _check_range("run.empty_fraction", self.empty_fraction, 0, 1, True, True)
        _check_range("run.wall_time_limit", self.wall_time_limit, 0, None, unit=" s")
        _check_range("run.output_interval", self.output_interval, 0, None, low_open=True,
                     unit=" s")
        _check_range("run.field_interval", self.field_interval, 0, None, low_open=True,
                     unit=" s")
        if not isinstance(self.markers_per_side, int) or isinstance(self.markers_per_side, bool):
            raise ConfigError(f"run.markers_per_side = {self.markers_per_side!r}: expected an "
                              "integer in [0, 6]")
        _check_range("run.markers_per_side", self.markers_per_side, 0, 6)


_SECTIONS = {"hopper": HopperGeometry, "material": MaterialConfig, "wall": WallConfig,
             "numerics": NumericsConfig, "run": RunConfig}


@dataclass(frozen=True)
class HopperConfig:
    """A complete, validated run configuration (one dataclass per TOML section)."""

    hopper: HopperGeometry = field(default_factory=HopperGeometry)
    material: MaterialConfig = field(default_factory=MaterialConfig)
    wall: WallConfig = field(default_factory=WallConfig)
    numerics: NumericsConfig = field(default_factory=NumericsConfig)
    run: RunConfig = field(default_factory=RunConfig)

    def __post_init__(self):
        cells_across_outlet = self.hopper.outlet_radius / self.numerics.cell_size
        if cells_across_outlet < 3:
            raise ConfigError(
                f"numerics.cell_size = {self.numerics.cell_size:g} m leaves "
                f"{cells_across_outlet:.2f} cells across the outlet radius "
                f"({self.hopper.outlet_radius:g} m); at least 3 are needed "
                f"(cell_size <= {self.hopper.outlet_radius / 3:.4g} m)")
        if cells_across_outlet < 6:
            warnings.warn(f"only {cells_across_outlet:.1f} cells across the outlet radius; "
                          "6 or more are recommended for a discharge rate", ResolutionWarning,
                          stacklevel=3)

    @classmethod
    def from_dict(cls, data: dict) -> "HopperConfig":
        """Build from nested dictionaries (as read from TOML); unknown keys are refused."""
        if not isinstance(data, dict):
            raise ConfigError("configuration: expected a table of sections")
        unknown = [k for k in data if k not in _SECTIONS]
        if unknown:
            raise ConfigError(_unknown_message("section", unknown[0], list(_SECTIONS)))
        sections = {}
        for name, kind in _SECTIONS.items():
            values = data.get(name, {})
            if not isinstance(values, dict):
                raise ConfigError(f"[{name}]: expected a table of keys, got {values!r}")
            allowed = [f.name for f in fields(kind)]
            for key in values:
                if key not in allowed:
                    raise ConfigError(_unknown_message(f"key in [{name}]", key, allowed,
                                                       prefix=f"{name}."))
            sections[name] = kind(**values)
        return cls(**sections)

    @classmethod
    def from_toml(cls, path: Union[str, Path]) -> "HopperConfig":
        """Read and validate a TOML file."""
        path = Path(path)
        try:
            text = path.read_text(encoding="utf-8")
        except OSError as exc:
            raise ConfigError(f"cannot read configuration {path}: {exc.strerror}") from None
        except UnicodeDecodeError as exc:
            raise ConfigError(f"{path} is not valid TOML: not UTF-8 text (byte {exc.start})") \
                from None
        try:
            data = tomllib.loads(text)
        except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
            raise ConfigError(f"{path} is not valid TOML: {exc}") from None
        return cls.from_dict(data)

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

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
        for name in _SECTIONS:
            current = getattr(self, name)
            change = sections.pop(name, None)
            new[name] = dataclasses.replace(current, **change) if change else current
        if sections:
            raise ConfigError(_unknown_message("section", next(iter(sections)), list(_SECTIONS)))
        return HopperConfig(**new)


def _toml_value(value) -> str:
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, bool):
        return "true" if value else "false"
    return repr(value)


def _unknown_message(what: str, key: str, allowed: list, prefix: str = "") -> str:
    close = difflib.get_close_matches(key, allowed, n=1)
    hint = f"; did you mean '{prefix}{close[0]}'?" if close else ""
    return f"unknown {what} '{prefix}{key}'{hint} (allowed: {', '.join(allowed)})"


def reference_config(**sections) -> HopperConfig:
    """The reference hopper: D = 0.3 m, 20 deg cone, D0 = 0.06 m, 0.3 m fill, dry sand, 15 deg wall."""
    return HopperConfig().replace(**sections) if sections else HopperConfig()
