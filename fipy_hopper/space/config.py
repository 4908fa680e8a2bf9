"""The settings of a 3D run, until the run configuration takes them: the sections' dataclasses
(:mod:`fipy_hopper.config`) and the two 3D choices."""

from __future__ import annotations

from dataclasses import dataclass, field

from ..config import (HopperGeometry, MaterialConfig, NumericsConfig, WallConfig,
                      damped_step_factor)

#: the bulk viscosity b_1 of ``numerics.bulk_viscosity = "auto"`` (the Eulerian default)
DEFAULT_BULK_VISCOSITY = 0.06


@dataclass(frozen=True)
class SpaceConfig:
    """A 3D run: the silo ``hopper`` (an axisymmetric :class:`HopperGeometry`, the conical
    shorthand or a profile, without inserts), ``material``, ``wall``, ``numerics`` (its
    ``cell_size`` is the cube's side; the sections' ``3 cells across the outlet radius`` is
    not required here), the outlet's offset from the silo's axis along ``+x``
    (``outlet_offset``, m) and the computed part (``mirror_planes``: ``"auto"``, ``"none"``,
    ``"quarter"``, ``"half"``, :mod:`fipy_hopper.space.grid`)."""

    hopper: HopperGeometry = field(default_factory=HopperGeometry)
    material: MaterialConfig = field(default_factory=MaterialConfig)
    wall: WallConfig = field(default_factory=WallConfig)
    numerics: NumericsConfig = field(default_factory=lambda: NumericsConfig(cell_size=0.02))
    outlet_offset: float = 0.0
    mirror_planes: str = "auto"

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
        from dataclasses import replace
        out = {}
        for key, value in changes.items():
            if isinstance(value, dict):
                value = replace(getattr(self, key), **value)
            out[key] = value
        return replace(self, **out)


def small_silo(**changes) -> SpaceConfig:
    """A small conical silo for coarse 3D tests (2 cm cells): a 0.28 m bin on a 30 deg cone to
    a 0.12 m outlet, filled 0.1 m above the transition."""
    geom = HopperGeometry(bin_diameter=0.28, half_angle_deg=30.0, outlet_diameter=0.12,
                          bin_height=0.16, fill_height=0.1)
    cfg = SpaceConfig(hopper=geom)
    return cfg.with_(**changes) if changes else cfg

