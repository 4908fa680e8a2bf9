"""What :class:`~fipy_hopper.simulation.Simulation` asks of a hopper model.

One loop drives every run: the Eulerian :class:`~fipy_hopper.model.HopperModel` and the
updated-Lagrangian :class:`~fipy_hopper.lagrangian.LagrangianModel` both implement this
protocol, and the simulation, the wall loads (:class:`~fipy_hopper.diagnostics.WallLoads`),
the stress-sampled wall profile (:class:`~fipy_hopper.diagnostics.WallSampler`) and the
summary use nothing else of them.  Masses, forces and momenta are per radian of the computed
half-section (kg, N, kg m/s per radian; per metre of a half-wedge in plane strain) unless a
method says "3D": ``section_factor`` converts.

The state a model returns holds at least ``t`` (s), ``step``, ``stage`` (``"filling"`` or
``"discharge"``), ``discharged`` and ``lost`` (kg, 3D: mass through the outlet plane and out
of the domain), and the cumulative load measurements ``wall_impulse`` (one row ``(r, z)`` per
entry of :meth:`HopperModelProtocol.wall_entries`), ``plate_impulse`` (rows ``(r, z)``) and
``momentum_budget`` (gravity, damping, stopped, outflow: vertical impulses).  A model whose
own validity can end a run (a Lagrangian mesh that distorts) gives the state a ``halt``
string: empty while it may go on; else the reason, and the state is the last valid one.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable


@runtime_checkable
class HopperModelProtocol(Protocol):
    """The model side of a run (see the module docstring for the state it returns)."""

    cfg: object              #: the :class:`~fipy_hopper.config.HopperConfig`
    dt: float                #: the explicit time step (s); an upper bound if it varies
    ramp_time: float         #: gravity rises linearly over this time while filling (s)
    mu_wall: float           #: wall friction coefficient
    section_factor: float    #: per radian (or half-wedge) to the whole hopper
    formulation: str         #: ``"eulerian"`` or ``"lagrangian"``
    n_cells: int             #: cells (Eulerian) or elements (Lagrangian)
    cell_size: float         #: the grid's cell size or the mesh's element size (m)

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
        along its chain of the entry's wall point (m), the unit normal into the wall ``(n, 2)``
        and the row of ``cfg.boundary.table`` of its wall segment (for the shorthands 0 the
        free-fall tube, 1 cone or floor, 2 bin wall; -1 a convex corner, the outlet lip)."""

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

    def summary_extras(self, state) -> dict:
        """Keys the model adds to ``summary.json`` (none for the Eulerian model)."""

    def reset_caches(self) -> None:
        """Forget anything derived from a state (after a restore)."""


def halt_reason(state) -> str:
    """The state's ``halt`` (empty for a model that never halts)."""
    return getattr(state, "halt", "") or ""

