"""The settings of a 3D run: the sections' dataclasses (:mod:`fipy_hopper.config`) and the 3D
choices.  A run configuration with ``[hopper] dimensions = 3`` maps to them in one place,
:meth:`SpaceConfig.from_config` (and back, :meth:`SpaceConfig.to_config`): ``outlet_offset``
is ``hopper.outlet_offset``, ``mirror_planes`` ``numerics.mirror_planes``, ``wall_sectors``
``run.wall_sectors``."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Optional

import numpy as np

from ..config import (HopperConfig, HopperGeometry, MaterialConfig, NumericsConfig,
                      RunConfig, WallConfig, damped_step_factor)

#: the bulk viscosity b_1 of ``numerics.bulk_viscosity = "auto"`` (the Eulerian default)
DEFAULT_BULK_VISCOSITY = 0.06


@dataclass(frozen=True)
class SpaceConfig:
    """A 3D run: the silo ``hopper`` (an axisymmetric :class:`HopperGeometry`, the conical
    shorthand or a profile, inserts with a centred outlet; or a rectangular plan,
    :mod:`fipy_hopper.space.rectangular`), ``material``, ``wall``, ``numerics`` (its
    ``cell_size`` is the cube's side; the sections' ``3 cells across the outlet radius`` is
    not required here), the outlet's offset from the silo's axis along ``+x``
    (``outlet_offset``, m; a rectangular plan's ``(ex, ey)``, always its geometry's
    ``hopper.outlet_offset``) and the computed part (``mirror_planes``: ``"auto"``, ``"none"``,
    ``"quarter"``, ``"half"``, :mod:`fipy_hopper.space.grid`); ``run`` the sections'
    :class:`~fipy_hopper.config.RunConfig` (the stop rules, the sampling, the load window, the
    wall bins' width) and ``wall_sectors``, the sectors of the wall-load maps around the
    circumference (:mod:`fipy_hopper.space.wall`)."""

    hopper: HopperGeometry = field(default_factory=HopperGeometry)
    material: MaterialConfig = field(default_factory=MaterialConfig)
    wall: WallConfig = field(default_factory=WallConfig)
    numerics: NumericsConfig = field(default_factory=lambda: NumericsConfig(cell_size=0.02))
    outlet_offset: float = 0.0
    mirror_planes: str = "auto"
    run: RunConfig = field(default_factory=RunConfig)
    wall_sectors: int = 12
    #: the run configuration this was made from (:meth:`from_config`), if any
    source: Optional[HopperConfig] = field(default=None, compare=False, repr=False)

    def __post_init__(self):
        if self.hopper.rectangular:     # the plan's offset is its geometry's, (ex, ey)
            e, own = self.outlet_offset, self.hopper.offset_xy
            if not (isinstance(e, (int, float)) and e == 0.0) and tuple(
                    float(v) for v in np.atleast_1d(e)) != own:
                raise ValueError(f"outlet_offset = {e!r}: a rectangular plan's outlet is at "
                                 f"its hopper.outlet_offset, {list(own)}")
            object.__setattr__(self, "outlet_offset", own)
        if not (isinstance(self.wall_sectors, int) and 1 <= self.wall_sectors <= 360):
            raise ValueError(f"wall_sectors = {self.wall_sectors!r}: expected a whole number "
                             "in [1, 360]")

    @classmethod
    def from_config(cls, cfg: HopperConfig) -> "SpaceConfig":
        """The 3D settings of a run configuration with ``hopper.dimensions = 3`` (the one
        mapping: module docstring)."""
        if cfg.hopper.dimensions != 3:
            raise ValueError("a SpaceConfig is made from a configuration with "
                             f"hopper.dimensions = 3, not {cfg.hopper.dimensions}")
        offset = (cfg.hopper.outlet_offset if cfg.hopper.rectangular
                  else float(cfg.hopper.outlet_offset))
        return cls(hopper=cfg.hopper, material=cfg.material, wall=cfg.wall,
                   numerics=cfg.numerics, outlet_offset=offset,
                   mirror_planes=cfg.numerics.mirror_planes, run=cfg.run,
                   wall_sectors=cfg.run.wall_sectors, source=cfg)

    def to_config(self) -> HopperConfig:
        """The run configuration of these settings: the one they were made from, or one built
        from them (validated as any configuration: :class:`~fipy_hopper.config.ConfigError`
        for settings a run configuration refuses)."""
        if self.source is not None:
            return self.source
        return HopperConfig(
            hopper=replace(self.hopper, dimensions=3, outlet_offset=(
                tuple(self.outlet_offset) if self.hopper.rectangular
                else float(self.outlet_offset))),
            material=self.material, wall=self.wall,
            numerics=replace(self.numerics, mirror_planes=self.mirror_planes),
            run=replace(self.run, wall_sectors=self.wall_sectors))

    def to_toml(self) -> str:
        """The run configuration's resolved TOML (:meth:`to_config`): what a run's
        fingerprint and ``config.toml`` hold."""
        return self.to_config().to_toml()

    @property
    def boundary(self):
        """The centred silo's axisymmetric section (:class:`fipy_hopper.boundary.Boundary`,
        with the walls' friction): the wall profile that the 3D wall loads are binned along
        (the meridian's arc length ``s``)."""
        return self.hopper.boundary.with_friction(self.wall.friction_angle_deg,
                                                  self.wall.segment_friction_deg)

    def wall_bin_width_at(self, cell_size: float) -> float:
        """The wall bins' width along the meridian (m), the sections' rule:
        ``run.wall_bin_width``, or a twentieth of the silo's widest span (the bin's diameter),
        at least three cells."""
        if self.run.wall_bin_width != "auto":
            return float(self.run.wall_bin_width)
        return max(3.0 * cell_size, self.hopper.width / 20.0)

    @property
    def wall_bin_width_m(self) -> float:
        return self.wall_bin_width_at(self.numerics.cell_size)

    def section_config(self, **run) -> HopperConfig:
        """The axisymmetric section of the same silo, material, wall and numerics (the 3D
        model's comparison; its outlet is centred whatever ``outlet_offset``); ``run``: keys
        of its ``[run]`` replacing this one's."""
        if self.hopper.rectangular:
            raise ValueError("a rectangular plan has no axisymmetric section")
        section = replace(self.run, wall_sectors=12, **run)
        return HopperConfig(hopper=replace(self.hopper, dimensions=2, outlet_offset=0.0),
                            material=self.material, wall=self.wall,
                            numerics=replace(self.numerics, mirror_planes="auto"),
                            run=section)

    @property
    def bulk_viscosity(self) -> float:
        """``b_1``: ``numerics.bulk_viscosity``, or :data:`DEFAULT_BULK_VISCOSITY` for
        ``"auto"``."""
        b = self.numerics.bulk_viscosity
        return DEFAULT_BULK_VISCOSITY if b == "auto" else float(b)

    @property
    def ramp_time(self) -> float:
        """Gravity's ramp while filling (s): ``gravity_ramp_periods`` periods ``4 L / c_p`` of
        the filled column (``"auto"``), or ``gravity_ramp_time``."""
        num = self.numerics
        if num.gravity_ramp_time == "auto":
            column = max(self.hopper.fill_level, num.cell_size)
            return num.gravity_ramp_periods * 4.0 * column / self.material.p_wave_speed
        return float(num.gravity_ramp_time)

    def time_step(self) -> float:
        """``dt_safety h / c_p`` times the bulk viscosity's factor (s)."""
        return (self.numerics.dt_safety * self.numerics.cell_size / self.material.p_wave_speed
                * damped_step_factor(self.bulk_viscosity))

    @property
    def wall_friction_deg(self) -> float:
        return self.wall.friction_angle_deg

    def with_(self, **changes) -> "SpaceConfig":
        """A copy with sections or fields replaced (sections given as dicts of changes)."""
        out = {"source": None}
        for key, value in changes.items():
            if isinstance(value, dict):
                value = replace(getattr(self, key), **value)
            out[key] = value
        if "hopper" in out and out["hopper"].rectangular and "outlet_offset" not in out:
            out["outlet_offset"] = out["hopper"].offset_xy
        return replace(self, **out)


def small_silo(**changes) -> SpaceConfig:
    """A small conical silo for coarse 3D tests (2 cm cells): a 0.28 m bin on a 30 deg cone to
    a 0.12 m outlet, filled 0.1 m above the transition."""
    geom = HopperGeometry(bin_diameter=0.28, half_angle_deg=30.0, outlet_diameter=0.12,
                          bin_height=0.16, fill_height=0.1)
    cfg = SpaceConfig(hopper=geom)
    return cfg.with_(**changes) if changes else cfg

