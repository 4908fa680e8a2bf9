"""What :class:`~fipy_hopper.simulation.Simulation` asks of a hopper model.

One loop drives every run: the Eulerian section :class:`~fipy_hopper.model.HopperModel`, the
updated-Lagrangian section :class:`~fipy_hopper.lagrangian.LagrangianModel` and the 3D
circular silo :class:`~fipy_hopper.space.model.SpaceModel` implement this protocol, and the
simulation, its wall loads and the summary use nothing else of them.  The wall loads are the
model's own (:meth:`HopperModelProtocol.wall_measures`: the sections'
:class:`~fipy_hopper.diagnostics.WallSampler` and :class:`~fipy_hopper.diagnostics.WallLoads`,
the 3D :class:`~fipy_hopper.space.wall.PatchLoads`), used through :class:`WallLoadsProtocol`.
Masses, forces and momenta are per radian of the computed half-section (kg, N, kg m/s per
radian; per metre of a half-wedge in plane strain; of the computed part of a 3D silo, a
quarter, a half or all of it) unless a method says "3D": ``section_factor`` converts.

The state a model returns holds at least ``t`` (s), ``step``, ``stage`` (``"filling"`` or
``"discharge"``), ``discharged`` and ``lost`` (kg, 3D: mass through the outlet plane and out
of the domain), and the cumulative load measurements ``wall_impulse`` (one row ``(r, z)``, in
3D ``(x, y, z)``, per entry of :meth:`HopperModelProtocol.wall_entries`), ``plate_impulse``
(rows likewise) and ``momentum_budget`` (gravity, damping, stopped, outflow: vertical
impulses).  The state of a model whose runs are checkpointed (the Eulerian ones) holds float64
arrays and plain numbers, strings or bools, what a checkpoint holds.  A model whose own validity can end a run (a Lagrangian mesh
that distorts) gives the state a ``halt`` string: empty while it may go on; else the reason,
and the state is the last valid one.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable


@runtime_checkable
class HopperModelProtocol(Protocol):
    """The model side of a run (see the module docstring for the state it returns)."""

    #: the run's configuration: a :class:`~fipy_hopper.config.HopperConfig`, or the 3D
    #: model's :class:`~fipy_hopper.space.config.SpaceConfig`; the loop reads its ``run``,
    #: ``numerics``, ``material``, ``hopper.fill_level``, ``bulk_viscosity``, ``boundary``
    #: (a section's: the outlet, the inserts, the hopper stretches; in 3D the centred
    #: silo's axisymmetric section) and ``to_toml()`` (the run's fingerprint)
    cfg: object
    dt: float                #: the explicit time step (s); an upper bound if it varies
    ramp_time: float         #: gravity rises linearly over this time while filling (s)
    mu_wall: float           #: wall friction coefficient
    section_factor: float    #: per radian (or half-wedge) to the whole hopper
    formulation: str         #: ``"eulerian"`` or ``"lagrangian"``
    n_cells: int             #: cells (Eulerian) or elements (Lagrangian)
    cell_size: float         #: the grid's cell size or the mesh's element size (m)
    dimensions: int          #: 2: a section; 3: the whole silo (:mod:`fipy_hopper.space`)
    material: object         #: the constitutive law (a run's fingerprint reads its parameters)

    def initial_state(self):
        """The filled hopper at rest, stress free, outlet plate closed."""

    def advance(self, state, max_steps: int) -> int:
        """Up to ``max_steps`` explicit steps in place; returns the number taken (fewer only
        when ``state.halt`` is set)."""

    def transport_step(self, state) -> None:
        """Bring the carried fields up to date (nothing to do in a Lagrangian model)."""

    def open_outlet(self, state) -> None:
        """Remove the outlet plate: the discharge starts."""

    def total_mass(self, state) -> float:
        """Mass in the whole domain (kg, 3D)."""

    def mass_in_hopper(self, state) -> float:
        """Mass above the outlet plane (kg, 3D)."""

    def kinetic_energy(self, state) -> float:
        """Kinetic energy (J, 3D)."""

    def vertical_momentum(self, state) -> float:
        """``sum m v_z`` over the nodes (kg m/s per radian)."""

    def check_stable(self, state) -> None:
        """Raise :class:`~fipy_hopper.model.InstabilityError` on a non-finite or runaway
        state, naming where and when."""

    def wall_entries(self) -> tuple:
        """``(s, normal, segment)`` of the rows of ``state.wall_impulse``: the arc length
        along its chain of the entry's wall point (m; in 3D along the wall profile's
        meridian), the unit normal into the wall ``(n, d)`` (``d`` = 2, or 3 in 3D) and the row
        of ``cfg.boundary.table`` of its wall segment (for the shorthands 0 the free-fall
        tube, 1 cone or floor, 2 bin wall; -1 a convex corner, the outlet lip; in 3D the
        profile's segment, -1 a tube, -2 the lip)."""

    def wall_load_rows(self):
        """The row of ``cfg.boundary.table`` whose load each entry of ``state.wall_impulse``
        is (a convex corner's: its nearest segment that is not a tube)."""

    def wall_stress_points(self, state) -> tuple:
        """``(position, weight, sigma)`` of the material next to the walls: the position of
        the nearest wall point along the chains (m, :meth:`Boundary.position`), a volume
        weight and the stress ``(rr, zz, tt, rz)`` (Pa)."""

    def flow_mode_measures(self, state, rule) -> tuple:
        """``(mass-flow index, stagnant fraction)`` by
        :class:`~fipy_hopper.diagnostics.FlowModeRule`."""

    def empty_channel(self, state, rule) -> tuple:
        """``(diameter, height)`` (m) of an empty channel through the material
        (:class:`~fipy_hopper.diagnostics.OutcomeRule`), NaN if none."""

    def channel_fields(self, state) -> tuple:
        """The arrays the loop averages over each window of the discharge (at its checks) for
        :meth:`channel_measures`; ``()`` for a model that measures no flow channel."""

    def channel_measures(self, means: tuple) -> list:
        """The flow channel of a window's mean fields (:meth:`channel_fields`'s, in its
        order): rows (dicts of floats, one per height), ``[]`` for none."""

    def contact_slip(self, state) -> tuple:
        """``(slip, axis_speed)`` (m/s) of every wall entry: its slip speed down the wall and
        the downward speed at the axis at its height (the flow-mode rule's ratio)."""

    def bin_lateral_stress_ratio(self, state) -> float:
        """The bin's lateral stress ratio ``sigma_rr / sigma_zz`` (NaN where not measured)."""

    def wall_slip_measures(self, state, previous_impulse, rule) -> tuple:
        """``(ratio, fraction, stretch ratios, stretch fractions, profile, sectors)`` of
        :class:`~fipy_hopper.diagnostics.FlowModeRule` at one sample, the loads since
        ``previous_impulse`` (``state.wall_impulse`` at the previous sample, or None): the
        first five :func:`~fipy_hopper.diagnostics.wall_slip_measures`'s; ``sectors`` the 3D
        ratio per hopper stretch and sector (None for a section)."""

    def material_speed(self, state) -> float:
        """The rms speed of the material above the outlet plane (m/s; the at-rest rule)."""

    def heap_angle(self, state) -> float:
        """The angle of the surface of the material left once the flow has stopped (deg; NaN
        where not measured)."""

    def wall_measures(self) -> tuple:
        """``(sampler, loads)``: the run's stress-sampled wall profile and its wall loads from
        the wall's reaction (:class:`WallLoadsProtocol`), new objects for a run."""

    def summary_extras(self, state) -> dict:
        """Keys the model adds to ``summary.json`` (none for the Eulerian model)."""

    def reset_caches(self) -> None:
        """Forget anything derived from a state (after a restore)."""


@runtime_checkable
class WallLoadsProtocol(Protocol):
    """What the loop asks of a model's wall loads (:meth:`HopperModelProtocol.wall_measures`).
    A *bin* is a piece of wall: a section's bins along its walls
    (:class:`~fipy_hopper.diagnostics.WallBins`), in 3D a patch of a height bin and a sector
    (bin-major).  Readings are :meth:`reading` dicts; a window is two of them."""

    def reading(self, model, state) -> dict:
        """The cumulative measurements now: ``t``, ``wall``, ``plate``, ``budget``,
        ``momentum``."""

    def balance(self, start: dict, end: dict) -> dict:
        """The vertical momentum balance over a window (a row of ``loads.csv``)."""

    def profile(self, start: dict, end: dict) -> tuple:
        """``(s, r, z, p_n, tau)`` per bin over a window, recovered from the reaction; in 3D
        with ``tau_theta`` after them."""

    def raw_profile(self, start: dict, end: dict) -> tuple:
        """``(s, r, z, p_n, tau)``: the plain binning of the reaction."""

    def membrane_forces(self, start: dict, end: dict, p_n, tau=None) -> tuple:
        """``(hoop, meridional, at the transition (2,))``: the wall's forces (NaN in 3D)."""

    def hoop_force(self, p_n):
        """The hoop force per bin of a pressure profile (NaN in 3D)."""

    def chain_forces(self, start: dict, end: dict) -> dict:
        """``{wall or insert: [F_x, F_z]}`` over a window (N, whole silo)."""

    def corner_forces(self, p_n, tau) -> list:
        """The forces at the walls' corners (none in 3D)."""

    def wall_k(self, p_n, state) -> float:
        """The lateral pressure ratio at the bin wall at rest (NaN without a bin wall)."""

    def summary(self, sim) -> dict:
        """The wall-load numbers of ``summary.json`` from a run's record."""


class SectionMeasures:
    """The protocol's measures of a section model (2D, Eulerian or Lagrangian), by the
    functions of :mod:`fipy_hopper.diagnostics`."""

    #: a section (the 3D model is :class:`fipy_hopper.space.model.SpaceModel`)
    dimensions = 2

    def wall_measures(self) -> tuple:
        from .diagnostics import WallLoads, WallSampler
        sampler = WallSampler(self)
        return sampler, WallLoads(self, sampler)

    def wall_slip_measures(self, state, previous_impulse, rule) -> tuple:
        from .diagnostics import wall_slip_measures
        return wall_slip_measures(self, state, previous_impulse, rule) + (None,)

    def material_speed(self, state) -> float:
        from .diagnostics import material_speed
        return material_speed(self, state)

    def heap_angle(self, state) -> float:
        from .diagnostics import heap_angle
        return heap_angle(self, state)


def halt_reason(state) -> str:
    """The state's ``halt`` (empty for a model that never halts)."""
    return getattr(state, "halt", "") or ""

