"""HopperModel: the state of the Eulerian hopper and one explicit time step.

The method: docs/physics_and_numerics.md, sections 3-5.

A step is an operator split:

1. material step on the fixed grid's nodes: lumped mass ``m = sum rho alpha kappa V / 4``,
   ``m dv/dt = -f_int(alpha sigma) + f_hourglass + m g``, wall contact, axis and outlet plate;
   the cell strain rate ``D`` and spin drive a Jaumann stress rotation and the Mohr-Coulomb
   update (elastic predictor + return mapping);
2. transport, sub-cycled: the face velocities of the material steps are averaged and the cell
   fields ``alpha``, ``alpha sigma``, ``alpha eps_p``, ``alpha layer`` are carried
   conservatively (van Leer); nodal momentum is carried on the dual grid with the same mass
   fluxes.  Transport runs when the material has moved ``transport_cfl`` of a cell.

Dense and loose material (docs/physics_and_numerics.md, section 6; the "disconnected" phase of
Dunatunga & Kamrin 2015).  ``alpha = 1`` is the dense (filled) state.  Each cell carries the loose volumetric
strain ``e_l >= 0`` of its material, transported with it like ``eps_p``:

* a return to the stress-free apex (the grains separate) adds its plastic dilation,
  ``e_l += tr d_eps_p`` (:func:`fipy_hopper.dense_loose.separation_strain`);
* a compressive increment first closes loose volume, ``e_l -= min(e_l, -tr d_eps)``, and only
  the rest of the increment loads the grains (:func:`fipy_hopper.dense_loose.close_loose_volume`),
  so loose material carries no stress until it is dense again.

The volumetric strain of the stress update is the transport's divergence: the net flux of
the nodal velocities' face values through each cell's open face areas over its open volume
(:func:`fipy_hopper.momentum.open_divergence`; in full cells exactly the Q1 mean ``tr D``).
So in every cell, cut cells at the wall included, compression that raises ``alpha`` raises
the pressure (or closes loose volume) by the same amount.  Measured on a 0.2 m hopper, 1 s of
discharge at 7.5 mm: with the Q1 ``tr D`` in cut cells the excess above ``alpha = 1`` that
redistribution had to move was 2.8 kg for 3.7 kg discharged (66 % of it in cut cells, and
the rate 14-17 % higher); with the open divergence 0.085 kg.  In cells only partly filled (free
surfaces, fronts smeared by transport) the cell's mean strain is not the material's; there
the loose/dense rule is approximate.

Passive marker points (:mod:`fipy_hopper.markers`) are moved at every transport with the
integrated nodal velocity of the interval (``state.displacement``); they never act on the
physics and give the sharp layer pictures.

The model only steps; :mod:`fipy_hopper.simulation` owns the run (stages, stop rules, output).
Masses are reported for the full 3D hopper (``2 pi`` times the per-radian values).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from functools import partial

import numpy as np

import numba

from . import (dense_loose, fipy_adapter, markers, material, momentum, profiling,
               resources, stepping)
from .config import HopperConfig, damped_step_factor
from .mesh import HopperGrid, build_grid
from .protocol import SectionMeasures
from .material.law import compiled_refusal, transported_fields
from .transport import material_rows

GRAVITY = 9.81  # m/s^2

#: Boxed-in excess alpha goes to the nearest cell with at least this much room (fraction of its
#: volume).  1e-6 keeps it local (the micro-voids of packed material).  1e-3 is 5x cheaper, but
#: it sends the excess compacted above the outlet into the open jet below it. Measured: that
#: raised the early discharge rate by 8% against the Lagrangian run of the same case.
REDISTRIBUTION_ROOM_MIN = 1e-6
#: What the first pass leaves (it stops after 50 sweeps) goes to cells with this much room.
REDISTRIBUTION_ROOM_MIN_FALLBACK = 1e-3

TRANSPORTED = ("alpha", "s_rr", "s_zz", "s_tt", "s_rz", "eps_p", "layer", "loose")
#: the terms of ``State.momentum_budget``: cumulative vertical impulses (kg m/s per radian)
MOMENTUM_BUDGET = ("gravity", "damping", "stopped", "outflow")


def runaway_speed(geom) -> float:
    """The speed (m/s) that no node of a sound run reaches: ``50 sqrt(g max(top, 0.1 m))``,
    fifty times the free-fall speed from the hopper's top."""
    return 50.0 * math.sqrt(GRAVITY * max(geom.top, 0.1))


def ramped_gravity(state, ramp: float) -> float:
    """Gravity (m/s^2, downward) of a model's state: rising linearly over ``ramp`` s during
    filling, then :data:`GRAVITY` (every model's; the compiled steps carry its twin)."""
    if state.stage == "filling" and ramp > 0:
        return GRAVITY * min(1.0, state.t / ramp)
    return GRAVITY


class InstabilityError(RuntimeError):
    """The explicit solution went unstable (NaN or runaway velocity)."""


@dataclass
class State:
    """Everything that evolves (enough to checkpoint and resume)."""

    t: float
    step: int
    stage: str                      # "filling" or "discharge"
    v: np.ndarray                   # (2, nz+1, nr+1) nodal velocity, m/s
    alpha: np.ndarray               # (nz, nr) material fraction of the open cell volume
    sigma: np.ndarray               # (nz, nr, 4) material stress (rr, zz, tt, rz), Pa
    eps_p: np.ndarray               # (nz, nr) accumulated equivalent plastic strain
    layer: np.ndarray               # (nz, nr) layer tracer (layer index, 0 = bottom)
    discharged: float = 0.0         # kg through the outlet plane (3D)
    lost: float = 0.0               # kg through the bottom of the free-fall zone (3D)
    flux_time: float = 0.0          # time accumulated for the next transport
    face_flux_sum: np.ndarray = None  # (n_faces,) integrated normal velocity * dt
    plate_closed: bool = True
    opened_at: float = -1.0         # s: when the outlet began to open (-1: not yet)
    last_outlet_mass: float = 0.0   # kg that crossed the outlet in the last transport
    last_transport_dt: float = 0.0
    loose: np.ndarray = None        # (nz, nr) loose volumetric strain (0 = dense), see step()
    markers: np.ndarray = None      # (n, 3) passive marker points (r, z, layer), fipy_hopper.markers
    displacement: np.ndarray = None  # (2, nz+1, nr+1) int v dt since the last transport, m
    # measurements (read by diagnostics, never by the physics), cumulative since the start,
    # per radian (kg m/s): the impulse m dv of every wall contact and of every contact with
    # the outlet plate, in the order of HopperModel.contact_list / plate_list, and the vertical
    # momentum budget (gravity, damping, light nodes stopped, outflow through the bottom)
    wall_impulse: np.ndarray = None   # (n_contacts, 2)
    plate_impulse: np.ndarray = None  # (n_plate, 2)
    momentum_budget: np.ndarray = None  # (4,) see MOMENTUM_BUDGET
    # 1.0 where the cell's last return was plastic, else 0.0 (nz, nr): the cells in which the
    # law's rate-dependent overstress acts in the next step's forces (not transported)
    flowing: np.ndarray = None

    def copy(self) -> "State":
        return State(**{k: (v.copy() if isinstance(v, np.ndarray) else v)
                        for k, v in self.__dict__.items()})


class HopperModel(SectionMeasures):
    """The hopper on its grid, with material, wall and numerics from a :class:`HopperConfig`.

    ``backend``: ``"numba"`` (the compiled steps of :mod:`fipy_hopper.stepping`, the compiled
    return, transport, redistribution and markers) or ``"numpy"``, the plain-numpy reference
    of every part of a step (:func:`fipy_hopper.material.update_reference`, the numpy
    transport and redistribution, :func:`fipy_hopper.markers.advance_reference`), which a
    test holds the compiled path to over a short run.  ``threads``: numba threads of the
    compiled steps (default: one per core this process may use,
    :func:`~fipy_hopper.resources.thread_limit`).  ``law``: the constitutive law
    (:mod:`fipy_hopper.material.law`; default the configuration's Mohr–Coulomb material), from
    which the model takes its time step, its transported internal variables and its stress
    update; its density must be the configuration's.  The compiled step fuses Mohr-Coulomb's
    return: on ``backend="numba"`` a law with a stress update of its own is refused
    (:func:`~fipy_hopper.material.law.compiled_refusal`), ``backend="numpy"`` runs it.
    """

    def __init__(self, cfg: HopperConfig, grid: HopperGrid | None = None,
                 backend: str = "numba", threads: int | None = None, law=None):
        from .transport import Transport

        if backend not in ("numba", "numpy"):
            raise ValueError(f"backend must be 'numba' or 'numpy', not {backend!r}")
        self.backend = backend
        self.cfg = cfg
        #: callables ``hook(state)`` run after every transport step (the only place alpha,
        #: the carried fields and the markers change): measurements that read the state and
        #: never change it, e.g. the bounds of alpha over a run
        self.after_transport: list = []
        #: a :class:`fipy_hopper.profiling.PhaseProfile` that the steps add their time to, or
        #: None (the default: nothing is timed)
        self.profile = None
        self.grid = grid if grid is not None else build_grid(cfg)
        #: the constitutive law (fipy_hopper.material.law): its time step, its internal
        #: variables (transported) and its stress update
        self.material = law if law is not None else cfg.material.law()
        if self.material.rho != cfg.material.density:
            raise ValueError(f"the law's density {self.material.rho} kg/m3 is not "
                             f"material.density = {cfg.material.density} kg/m3")
        refusal = compiled_refusal(self.material) if backend == "numba" else ""
        if refusal:
            raise NotImplementedError(
                f"{refusal}: the compiled step runs Mohr-Coulomb's return mapping; run it "
                f'with HopperModel(cfg, law=..., backend="numpy"), whose step calls the '
                f"law's own update_reference")
        if transported_fields(self.material) != TRANSPORTED:
            raise NotImplementedError(
                f"the compiled step carries the fields {TRANSPORTED}; a law with the internal "
                f"variables {self.material.internal_variables} needs them in the kernels")
        self._advance_markers = (markers.advance if backend == "numba"
                                 else markers.advance_reference)
        g = self.grid
        self.rho = self.material.rho
        self.c_p = self.material.p_wave_speed
        #: bulk viscosity ``eta_b = b_1 rho c_p h`` (Pa s; ``numerics.bulk_viscosity`` b_1): about
        #: the fraction b_1 of critical damping for the shortest compression wave
        self.bulk_viscosity = cfg.bulk_viscosity * self.rho * self.c_p * g.h
        self.dt = (self.material.stable_time_step(g.h, cfg.numerics.dt_safety)
                   * damped_step_factor(cfg.bulk_viscosity))
        rate = getattr(self.material, "rate", None)
        if rate is not None:
            # the overstress is a viscosity of at most eta_I = delta_mu d sqrt(rho_s p) / I_0
            # (material.rate); its explicit limit rho h^2 / (8 eta_I) at the hydrostatic
            # pressure of the fill's depth lies far above the wave's step on every grid in use
            # (at 5 mm, d = 1 mm and a 0.3 m fill 1.5e-3 s against 2.8e-5 s), but holds it
            depth = max(cfg.hopper.fill_level, g.h)
            eta = rate.viscosity_bound(self.rho * GRAVITY * depth)
            if eta > 0.0:
                self.dt = min(self.dt, self.rho * g.h ** 2 / (8.0 * eta))
        self.mu_wall = cfg.wall.friction_coefficient
        #: the boundary (fipy_hopper.boundary): the walls, inserts and the section as data
        self.boundary = cfg.boundary
        section = self.boundary.section
        # the symmetry as data: an axisymmetric section, or a plane one (per metre)
        axisymmetric = cfg.hopper.axisymmetric
        #: radius of the hoop terms (infinite in plane strain: they vanish)
        self.r_c = g.r_cells if axisymmetric else np.full(g.nr, np.inf)
        #: radial weights of the face fluxes in the open divergence (1 in plane strain)
        self.flux_radius = g.r_nodes if axisymmetric else np.ones(g.nr + 1)
        #: normal strains that share the open-divergence correction
        self.strain_dims = 3.0 if axisymmetric else 2.0
        #: the computed section to the whole hopper: 2 pi rad (m^3/rad -> m^3), both halves of
        #: a plane half-section, or 1 for a full plane section (per metre of length)
        self.section_factor = section.factor
        self.open_volume = g.kappa * g.cell_volume          # (nz, nr) m^3/rad (m^2 for a wedge)
        # "axisymmetric": FiPy's van Leer update with the reconstruction distances of the
        # cylindrical cells corrected; FiPy's own geometry over/undershoots on cylindrical
        # grids (see fipy_hopper.transport.vanleer), this one stays within [0, 1]
        self.transport_open = Transport(g.mesh, g.kappa.ravel(), g.face_aperture,
                                        g.outflow_faces, TRANSPORTED, backend=backend,
                                        scheme="axisymmetric")
        # with the outlet plate closed, no transfer (flux or redistribution) crosses the outlet
        plate_aperture = np.where(g.outlet_faces, 0.0, g.face_aperture)
        self.transport_closed = Transport(g.mesh, g.kappa.ravel(), plate_aperture,
                                          g.outflow_faces, TRANSPORTED, backend=backend,
                                          scheme="axisymmetric")
        normals = np.asarray(g.mesh.faceNormals)
        nzf = g.n_zfaces
        self.face_sign = np.concatenate([normals[1, :nzf], normals[0, nzf:]])
        self.face_area = np.asarray(fipy_adapter.face_areas(g.mesh)) * g.face_aperture
        # wall contact: every node within half a cell in front of a wall segment (or behind
        # it) is constrained by that segment's normal, with its friction; nodes round a convex
        # corner (a lip) by the normal towards the nearest wall point, with the friction of
        # the nearest segment that is not a tube.  The free-fall tubes are frictionless.
        RN, ZN = np.meshgrid(g.r_nodes, g.z_nodes)
        reach = 0.5 * g.h
        table = self.boundary.table
        #: friction coefficient of each segment of the boundary's table (tubes: 0)
        self.segment_mu = np.array([0.0 if tube else math.tan(math.radians(f))
                                    for tube, f in zip(table.tube, table.friction_deg)])
        self.contact_passes = []
        segments, owners = [], []     # per pass: its table row (-1: convex corners), owners
        covered = np.zeros_like(RN, dtype=bool)
        for k, mask, n_r, n_z in self.boundary.segment_contacts(RN, ZN, reach):
            normal = np.array([n_r, n_z])[:, None, None] * np.ones((2,) + RN.shape)
            self.contact_passes.append((mask, normal, self.segment_mu[k]))
            segments.append(np.full(np.count_nonzero(mask), k))
            owners.append(segments[-1])
            covered |= mask
        corner = (g.node_distance < reach) & ~covered
        owner = self.boundary.load_row(RN, ZN)
        self.contact_passes.append((corner, g.node_normal, self.segment_mu[owner]))
        segments.append(np.full(np.count_nonzero(corner), -1))
        owners.append(owner[corner])
        #: row of ``boundary.table`` of each entry of ``contact_list`` (for the conical and
        #: wedge shorthands 0 the tube, 1 the cone or floor, 2 the bin wall), -1 at a convex
        #: corner (the outlet lip)
        self.contact_segment = np.concatenate(segments)
        #: the table row whose load each entry is: its segment's, or at a convex corner the
        #: nearest segment's that is not a tube (:meth:`Boundary.load_row`)
        self.contact_owner = np.concatenate(owners)
        x_left, x_right = self.boundary.outlet
        self.plate_nodes = ((np.abs(ZN) < 1e-12) & (RN >= x_left - 1e-12)
                            & (RN <= x_right + 1e-12))
        #: the outlet's half-width (its radius in a half-section, m) and each node column's
        #: distance from the section's centreline (m): the iris of ``run.opening_time`` opens
        #: from the centreline outwards over these
        self.outlet_half_width = x_right if section.half else 0.5 * (x_right - x_left)
        self.node_offset = np.abs(g.r_nodes - section.centreline)
        #: the node column at the centreline (the axis, or the middle of a full section's
        #: outlet): the axis speed of the flow-mode rule
        self.centre_column = int(np.argmin(self.node_offset))
        self.plate_normal = np.array([0.0, -1.0])[:, None, None] * np.ones((2,) + RN.shape)
        self.contact_list = _contact_list(self.contact_passes)
        self.plate_list = _contact_list([(self.plate_nodes, self.plate_normal, self.mu_wall)])
        self.light_mass = 1e-12 * self.rho * g.h ** 3
        self.open_faces = self.face_area > 0
        self.hopper_cells = (g.z_cells[:, None] > 0.0) & np.ones((1, g.nr), bool)
        self.hourglass_base = (cfg.numerics.hourglass_coefficient * self.rho
                               * math.sqrt(GRAVITY * g.h)
                               * self.open_volume / g.h)
        #: grid viscosity ``eta = b rho sqrt(g l) l`` (Pa s; ``numerics.grid_viscosity`` b, the
        #: length ``l`` ``numerics.viscosity_length``, the cell size when 0)
        length = cfg.numerics.viscosity_length or g.h
        self.viscosity = (cfg.numerics.grid_viscosity * self.rho * math.sqrt(GRAVITY * length)
                          * length)
        # mass-proportional damping during filling only: critical for the column's lowest mode
        column = max(cfg.hopper.fill_level, g.h)
        self.fill_damping = math.pi * self.c_p / (2.0 * column)
        #: gravity rises linearly over this time during filling (s): ``HopperConfig.ramp_time``
        self.ramp_time = cfg.ramp_time
        self._mass = None
        self._mass_of = None
        self._zface_aperture = g.zface_aperture()
        self._rface_aperture = g.rface_aperture()
        n = g.nz * g.nr
        # compiled steps (fipy_hopper.stepping): contacts grouped by node row, list order kept
        # the walls and the plate of every node in contact, grouped by node and row
        # ... with each wall's tributary length at its node, which shares a corner node's
        # impulse among its walls (stepping._contact_node)
        self.contact_groups = momentum.contact_groups(
            self.contact_list, self.plate_list, g.nz + 1, weights=self.contact_weights())
        self._face_sign = np.ascontiguousarray(self.face_sign, dtype=float)
        self._work = (np.empty((n, 3), np.int64), np.empty((n, 3), np.int64),
                      np.empty(n + 1, np.int64), np.zeros((8, g.nz, g.nr)), np.zeros(g.nz + 1),
                      np.zeros((g.nz + 1, 3)))
        self._rate_trace = np.zeros((g.nz, g.nr))   # tr(D) of the loaded cells, 1/s
        self._open_face = self.open_faces.astype(float)
        self._stacked = np.empty((len(TRANSPORTED), n))
        self._carried = (np.empty((len(TRANSPORTED), n)),
                         np.empty((len(TRANSPORTED), len(g.face_aperture))))
        self._prm = self.material.kernel_parameters()
        #: the law's rate parameters (``law.rate_parameters()``: zeros for the plain law)
        self._rate = np.ascontiguousarray(self.material.rate_parameters(), dtype=float)
        self._no_displacement = np.zeros((2, 1, 1))
        self._no_cycles = np.zeros(0, dtype=np.int64)      # material_steps: no phase timing
        self.threads = int(threads) if threads else resources.thread_limit()

    # ------------------------------------------------------------------ state
    def initial_state(self, n_layers: int = 8) -> State:
        """The hopper filled to ``fill_level`` at rest, stress free, outlet plate closed."""
        g, geom = self.grid, self.cfg.hopper
        z_lo, z_hi = g.z_nodes[:-1], g.z_nodes[1:]
        frac = np.clip((geom.fill_level - z_lo) / (z_hi - z_lo), 0.0, 1.0)
        frac = np.where(z_lo >= 0.0, frac, 0.0)
        alpha = np.repeat(frac[:, None], g.nr, axis=1) * (g.kappa > 0)
        layer_index = np.floor(np.clip(g.z_cells / geom.fill_level, 0, 0.999999) * n_layers)
        layer = np.repeat(layer_index[:, None], g.nr, axis=1)
        return State(t=0.0, step=0, stage="filling",
                     v=np.zeros((2, g.nz + 1, g.nr + 1)), alpha=alpha,
                     sigma=np.zeros((g.nz, g.nr, 4)), eps_p=np.zeros((g.nz, g.nr)),
                     layer=layer, face_flux_sum=np.zeros(len(g.face_aperture)),
                     loose=np.zeros((g.nz, g.nr)),
                     markers=self._seed_markers(alpha, layer), flowing=np.zeros((g.nz, g.nr)),
                     displacement=np.zeros((2, g.nz + 1, g.nr + 1)),
                     **self._measurements())

    def _measurements(self) -> dict:
        """Zero load measurements of a state (:class:`State`)."""
        return {"wall_impulse": np.zeros((len(self.contact_list[0]), 2)),
                "plate_impulse": np.zeros((len(self.plate_list[0]), 2)),
                "momentum_budget": np.zeros(len(MOMENTUM_BUDGET))}

    def _seed_markers(self, alpha, layer):
        per_side = self.cfg.run.markers_per_side
        if per_side == 0:
            return None
        return markers.seed(self.grid, self.cfg.hopper, alpha, layer, per_side=per_side)

    def node_mass(self, state: State) -> np.ndarray:
        # cached for the alpha array it was computed from (transport replaces the array)
        if self._mass is None or self._mass_of is not state.alpha:
            self._mass = momentum.node_mass(self.rho, state.alpha, self.open_volume)
            self._mass_of = state.alpha
        return self._mass

    def mass_in_hopper(self, state: State) -> float:
        """Mass above the outlet plane (kg, 3D; kg/m for a wedge)."""
        return self.section_factor * self.rho * float(np.sum((state.alpha * self.open_volume)
                                                             [self.hopper_cells]))

    def total_mass(self, state: State) -> float:
        """Mass in the whole domain (kg, 3D; kg/m for a wedge)."""
        return self.section_factor * self.rho * float(np.sum(state.alpha * self.open_volume))

    def kinetic_energy(self, state: State) -> float:
        """Kinetic energy of the nodal velocities (J, 3D; J/m for a wedge)."""
        m = self.node_mass(state)
        return (0.5 * self.section_factor) * float(np.sum(m * (state.v[0] ** 2
                                                               + state.v[1] ** 2)))

    def gravity(self, state: State) -> float:
        """Gravity (m/s^2, downward) at this time (:func:`ramped_gravity`)."""
        return ramped_gravity(state, self.ramp_time)

    def open_outlet(self, state: State) -> None:
        """Open the outlet: discharge starts.  The plate goes at once, or over
        ``run.opening_time`` from the axis outwards (:meth:`plate_opening_radius`)."""
        state.stage = "discharge"
        state.opened_at = state.t
        state.plate_closed = self.cfg.run.opening_time > 0.0

    def plate_opening_radius(self, state: State) -> float:
        """Radius (m) inside which the plate has let go at ``state.t``: ``R_0 (t - t_open) /
        opening_time`` while the outlet opens, -1 before (the whole plate holds)."""
        return stepping.opening_radius(state.t, self._opening(state))

    def _opening(self, state: State) -> np.ndarray:
        """``[t_open, opening_time, R_0]`` of :func:`stepping.opening_radius` (``t_open`` -1
        unless the outlet is opening)."""
        opening = state.plate_closed and state.opened_at >= 0.0
        return np.array([state.opened_at if opening else -1.0, self.cfg.run.opening_time,
                         self.outlet_half_width])

    def _end_opening(self, state: State) -> None:
        """The plate is gone once the opening time has passed."""
        if self.plate_opening_radius(state) == np.inf:
            state.plate_closed = False

    # ------------------------------------------------------------------ the run's protocol
    #: the formulation (fipy_hopper.protocol): a fixed grid the material moves through
    formulation = "eulerian"

    @property
    def n_cells(self) -> int:
        return self.grid.n_cells

    @property
    def cell_size(self) -> float:
        return self.grid.h

    def vertical_momentum(self, state: State) -> float:
        """``sum m v_z`` over the grid's nodes (kg m/s per radian)."""
        return float(np.sum(self.node_mass(state) * state.v[1]))

    def check_stable(self, state: State, limit: float | None = None) -> None:
        """Raise :class:`InstabilityError` naming the first node of a non-finite or runaway
        velocity (above ``limit``, by default :func:`runaway_speed`), or the first cell of a
        non-finite material fraction or stress."""
        v, g = state.v, self.grid
        speed = np.hypot(v[0], v[1])
        limit = runaway_speed(self.cfg.hopper) if limit is None else limit
        bad = ~np.isfinite(speed) | (speed > limit)
        if bad.any():
            j, i = np.argwhere(bad)[0]
            kind = "runaway" if np.isfinite(speed[j, i]) else "non-finite"
            raise InstabilityError(
                f"{kind} velocity at step {state.step}, t = {state.t:.6g} s, node r = "
                f"{g.r_nodes[i]:.4g} m, z = {g.z_nodes[j]:.4g} m (|v| = {speed[j, i]:.3g} m/s, "
                f"limit {limit:.3g} m/s)")
        broken = ~np.isfinite(state.alpha) | ~np.isfinite(state.sigma).all(axis=-1)
        if broken.any():
            j, i = np.argwhere(broken)[0]
            raise InstabilityError(
                f"non-finite material fraction or stress at step {state.step}, t = "
                f"{state.t:.6g} s, cell r = {g.r_cells[i]:.4g} m, z = {g.z_cells[j]:.4g} m")

    def contact_weights(self) -> tuple:
        """The tributary length (m) of every wall and plate entry at its node: the length of
        the entry's segment inside the node's dual cell (the square of side ``h`` around it),
        0 for a tube (frictionless, a guard of the free fall that the material leaves) and
        for a convex corner's own normal (a vertex).  ``(wall (n_contacts,), plate
        (n_plate,))``; they share a corner node's impulse among its walls
        (:func:`fipy_hopper.stepping._contact_node`)."""
        g, tab = self.grid, self.boundary.table
        j, i, _, _ = self.contact_list
        row = self.contact_segment
        seg = np.maximum(row, 0)
        wall = _length_in_boxes(g.r_nodes[i], g.z_nodes[j], 0.5 * g.h, tab.a[seg], tab.b[seg])
        wall = np.where((row < 0) | tab.tube[seg], 0.0, wall)
        pj, pi, _, _ = self.plate_list
        x_left, x_right = self.boundary.outlet
        a = np.tile([x_left, 0.0], (len(pj), 1))
        b = np.tile([x_right, 0.0], (len(pj), 1))
        plate = _length_in_boxes(g.r_nodes[pi], g.z_nodes[pj], 0.5 * g.h, a, b)
        return wall, plate

    def wall_entries(self) -> tuple:
        """``(s, normal, segment)`` of every entry of ``contact_list`` (the rows of
        ``State.wall_impulse``): the arc length along its chain of the node's wall point on
        the segment whose load it is (m; :meth:`wall_load_rows`, clipped to the segment: the
        lip's entries at ``s = 0``), the contact normal and ``contact_segment`` (the
        boundary's table row, -1 at a convex corner)."""
        return self._entry_arc_length, self.contact_list[2], self.contact_segment

    def wall_load_rows(self) -> np.ndarray:
        """The row of ``boundary.table`` whose load each contact entry is
        (:attr:`contact_owner`)."""
        return self.contact_owner

    @property
    def _entry_arc_length(self) -> np.ndarray:
        if not hasattr(self, "_entry_s"):
            g, tab = self.grid, self.boundary.table
            j, i, _, _ = self.contact_list
            row = self.contact_owner
            a, b = tab.a[row], tab.b[row]
            ab = b - a
            length = np.hypot(ab[:, 0], ab[:, 1])
            t = ((g.r_nodes[i] - a[:, 0]) * ab[:, 0] + (g.z_nodes[j] - a[:, 1]) * ab[:, 1])
            self._entry_s = tab.s0[row] + np.clip(t / length ** 2, 0.0, 1.0) * length
        return self._entry_s

    def _wall_band(self):
        """The cells whose centres lie 0.5 to 2.5 cells from a wall or an insert (not a
        tube), with their nearest wall point at or above the outlet plane and below the fill
        level, and that point's position along the chains (:meth:`Boundary.position`;
        cached)."""
        if not hasattr(self, "_band"):
            g, bnd = self.grid, self.boundary
            R, Z = np.meshgrid(g.r_cells, g.z_cells)
            d = bnd.signed_distance(R, Z)
            _, pz, chain, _, s = bnd.nearest(R, Z)
            tube = np.array([c.kind == "tube" for c in bnd.chains])[chain]
            band = (d >= 0.5 * g.h) & (d <= 2.5 * g.h) & ~tube & (pz >= 0) & (
                pz < bnd.fill_level)
            cells = np.flatnonzero(band.ravel())
            self._band = (cells, bnd.position(chain.ravel()[cells], s.ravel()[cells]))
        return self._band

    def wall_stress_points(self, state: State) -> tuple:
        """``(position, weight, sigma)`` of the cells 0.5 to 2.5 cells off the walls: the
        position of the nearest wall point along the chains (m), the weight ``alpha kappa V``
        where ``alpha > 1/2`` (else 0: fronts and free surfaces) and the stress."""
        cells, s = self._wall_band()
        alpha = state.alpha.ravel()[cells]
        w = np.where(alpha > 0.5, (state.alpha * self.open_volume).ravel()[cells], 0.0)
        return s, w, state.sigma.reshape(-1, 4)[cells]

    def contact_slip(self, state: State) -> tuple:
        """``(slip, axis_speed)`` (m/s) of every entry of ``contact_list``: the slip speed
        down the wall of the entry's node (its velocity in ``state.v``, after the step's
        contact) and the downward speed of the node of the same row on the centreline (the
        axis; beside an insert on it, the material's nearest node column:
        :func:`~fipy_hopper.diagnostics.axis_columns`)."""
        from . import diagnostics
        j, i, normals, _ = self.contact_list
        side = self.boundary.table.side[self.contact_owner]
        if not hasattr(self, "_axis_columns"):
            self._axis_columns = diagnostics.axis_columns(self.grid, self.boundary,
                                                          self.centre_column)
        return (diagnostics.entry_slip(state.v[:, j, i].T, normals, side),
                -state.v[1, j, self._axis_columns[j]])

    def flow_mode_measures(self, state: State, rule) -> tuple:
        from . import diagnostics
        return diagnostics.flow_mode_measures(self, state, rule)

    def channel_fields(self, state) -> tuple:
        """None: a section has no eccentric flow channel to measure per window."""
        return ()

    def channel_measures(self, means: tuple) -> list:
        """None (:meth:`channel_fields`)."""
        return []

    def empty_channel(self, state: State, rule) -> tuple:
        from . import diagnostics
        return diagnostics.empty_channel(self, state, rule)

    def bin_lateral_stress_ratio(self, state: State) -> float:
        from . import diagnostics
        return diagnostics.bin_lateral_stress_ratio(self, state)

    def summary_extras(self, state: State) -> dict:
        return {}

    def reset_caches(self) -> None:
        self._mass = None

    # ------------------------------------------------------------------ step
    def step(self, state: State) -> State:
        """Advance ``state`` by one explicit step ``self.dt`` (in place) and return it."""
        self.advance(state, 1)
        return state

    def advance(self, state: State, max_steps: int) -> int:
        """Advance ``state`` by up to ``max_steps`` explicit steps, in place.

        Stops early after a step at which a transport was due (the transport included), so a
        caller that checks the state every ``k`` steps calls ``advance(state, k - done)``.
        Returns the number of steps taken.  The compiled path runs the steps in one call of
        :func:`fipy_hopper.stepping.material_steps`; the numpy path is the reference.
        """
        if max_steps < 1:
            return 0
        if self.backend == "numpy":
            for n in range(max_steps):
                due = self._step_numpy(state)
                self._end_opening(state)
                if due:
                    self.transport_step(state)
                    return n + 1
            return max_steps
        g, num = self.grid, self.cfg.numerics
        if state.markers is not None:
            displacement, with_markers = state.displacement, True
        else:
            displacement, with_markers = self._no_displacement, False
        ramp = self.ramp_time if state.stage == "filling" else 0.0
        damping = self.fill_damping if state.stage == "filling" else 0.0
        clock = np.array([state.t, float(state.step), state.flux_time])
        row_nodes, _, node_i, node_ptr, normal, mu, kind, entry = self.contact_groups
        if numba.get_num_threads() != self.threads:
            numba.set_num_threads(self.threads)
        profile = self.profile
        started = time.perf_counter() if profile is not None else 0.0
        done, due = stepping.material_steps(
            int(max_steps), clock, state.v, self.node_mass(state), state.alpha, state.sigma,
            state.loose, state.eps_p, state.face_flux_sum, displacement, with_markers,
            self.open_volume, self.r_c, self.flux_radius, self.strain_dims, g.h,
            self.hourglass_base, g.kappa,
            self._zface_aperture, self._rface_aperture, self._face_sign, self._open_face,
            self._prm, self.dt, GRAVITY, ramp, damping, self.light_mass, num.alpha_min,
            num.transport_cfl, num.max_transport_interval, row_nodes, node_i, node_ptr,
            normal, mu, kind, entry, state.plate_closed, self._opening(state), self.node_offset,
            state.wall_impulse, state.plate_impulse, state.momentum_budget, self._work,
            self.viscosity, self.bulk_viscosity, self._rate_trace, state.flowing, self._rate,
            self.threads,
            self._no_cycles if profile is None else profile.cycles)
        if profile is not None:
            profile.compiled_seconds += time.perf_counter() - started
            profile.steps += int(done)
            profile.loaded_cell_steps += int(done) * int(np.count_nonzero(
                state.alpha >= num.alpha_min))      # alpha is constant within the call
        state.t, state.flux_time = float(clock[0]), float(clock[2])
        self._end_opening(state)
        state.step += int(done)
        if due:
            self.transport_step(state)
        return int(done)

    def _step_numpy(self, state: State) -> bool:
        """One step of the numpy reference; True when a transport is due."""
        g, dt = self.grid, self.dt
        alpha_min = self.cfg.numerics.alpha_min
        m = self.node_mass(state)
        damping = self.fill_damping if state.stage == "filling" else 0.0
        v = self._nodal_update_numpy(state, m, damping)
        state.v = v
        D, omega = momentum.strain_rate(v, self.r_c, g.h)
        sigma = momentum.jaumann_rotate(state.sigma, omega, dt)
        d_eps = D * dt
        # The volumetric strain of the stress update is the transport's: the divergence of
        # the nodal velocities over each cell's open volume (momentum.open_divergence; in full
        # cells the Q1 mean tr D, in cut cells what alpha sees through the face apertures).
        # Dense and loose material: compression first closes the loose volume, only the rest
        # loads the grains; returns to the stress-free apex record the volume the material
        # separates by (dense_loose.close_loose_volume / separation_strain).
        loaded = (state.alpha >= alpha_min).ravel()
        div = momentum.open_divergence(v, self._zface_aperture, self._rface_aperture,
                                       g.kappa, self.flux_radius, g.h) * dt
        dims = int(self.strain_dims)
        d_eps[..., :dims] += ((div - (d_eps[..., 0] + d_eps[..., 1] + d_eps[..., 2]))
                              / self.strain_dims)[..., None]
        d_skeleton, loose = dense_loose.close_loose_volume(d_eps.reshape(-1, 4),
                                                        state.loose.ravel())
        sig_new, deps_p, status = self._material_update(sigma.reshape(-1, 4), d_skeleton)
        loose = np.where(loaded, loose + dense_loose.separation_strain(deps_p, status), 0.0)
        sig_new[~loaded] = 0.0
        state.flowing = np.where(loaded & (status != material.ELASTIC), 1.0,
                                 0.0).reshape(state.alpha.shape)
        state.eps_p += np.where(loaded, material.equivalent_plastic_strain(deps_p),
                                0.0).reshape(state.eps_p.shape)
        state.loose = loose.reshape(state.alpha.shape)
        state.sigma = sig_new.reshape(state.sigma.shape)

        u_n = momentum.face_normal_velocity(v) * self.face_sign
        state.face_flux_sum += u_n * dt
        if state.markers is not None:
            state.displacement += dt * v
        state.flux_time += dt
        state.t += dt
        state.step += 1
        return self._transport_due(state, u_n)

    def _material_update(self, sigma: np.ndarray, d_eps: np.ndarray):
        """The law's reference stress update (the numpy path's; the compiled steps update
        the stress themselves): ``(sigma_new, d_eps_p, status)``."""
        return self.material.update_reference(sigma, d_eps, return_status=True)

    def _nodal_update_numpy(self, state: State, m: np.ndarray, damping: float) -> np.ndarray:
        """Reference (numpy) nodal update: forces, velocity, damping, contact, axis."""
        g, dt = self.grid, self.dt
        stress = state.sigma
        rated = self._rate[0] != 0.0
        if self.viscosity > 0.0 or self.bulk_viscosity > 0.0 or rated:
            # the grid viscosity, the law's overstress where flowing and the bulk viscosity:
            # sigma + 2 eta D + 2 eta_I D' + eta_b tr(D) I in loaded cells
            D, _ = momentum.strain_rate(state.v, self.r_c, g.h)
            loaded = (state.alpha >= self.cfg.numerics.alpha_min)[..., None]
            viscous = state.sigma
            if self.viscosity > 0.0:
                viscous = viscous + 2.0 * self.viscosity * D
            if rated:
                viscous = viscous + self.material.overstress_reference(
                    state.sigma, D, state.flowing != 0.0)
            if self.bulk_viscosity > 0.0:
                p_b = self.bulk_viscosity * (D[..., 0] + D[..., 1] + D[..., 2])
                viscous = viscous + np.stack([p_b, p_b, p_b, np.zeros_like(p_b)], axis=-1)
            stress = np.where(loaded, viscous, state.sigma)
        mixture = state.alpha[..., None] * stress
        force = -momentum.internal_force(mixture, self.open_volume, self.r_c, g.h)
        force += momentum.hourglass_force(state.v, self.hourglass_base * state.alpha)
        force[1] -= m * self.gravity(state)
        heavy = m > self.light_mass
        v = np.where(heavy[None], state.v + dt * force / np.where(heavy, m, 1.0)[None], 0.0)
        budget = state.momentum_budget
        budget[0] -= np.sum(np.where(heavy, m * self.gravity(state) * dt, 0.0))
        budget[2] -= np.sum(np.where(heavy, 0.0, m * state.v[1]))
        r_open = self.plate_opening_radius(state)
        node_i = self.contact_groups[2]
        plate_on = state.plate_closed & (self.node_offset[node_i] >= r_open)
        momentum.contact_nodes(v, m, self.contact_groups, plate_on,
                               state.wall_impulse, state.plate_impulse)
        if damping > 0.0:              # after the contact: a wall, not the damping, holds
            held = v[1].copy()         # what rests on it
            v *= 1.0 / (1.0 + damping * dt)
            budget[1] += np.sum(m * (v[1] - held))
        v[0, :, 0] = 0.0
        return v

    def _transport_due(self, state: State, u_n: np.ndarray) -> bool:
        num = self.cfg.numerics
        steps = round(state.flux_time / self.dt)
        if steps >= num.max_transport_interval:
            return True
        speed = float(np.max(np.abs(u_n[self.open_faces]))) if self.open_faces.any() else 0.0
        return (speed + 1e-30) * (state.flux_time + self.dt) > num.transport_cfl * self.grid.h

    def transport_step(self, state: State) -> None:
        """Carry the cell fields and nodal momentum with the averaged face velocities."""
        g = self.grid
        if state.flux_time <= 0.0:
            return
        dt_T = state.flux_time
        u_mean = state.face_flux_sum / dt_T
        closed = state.plate_closed and state.opened_at < 0.0     # open from the opening on
        transport = self.transport_closed if closed else self.transport_open
        compiled = self.backend != "numpy"
        timed = partial(profiling.timed, self.profile)
        with timed("transport: advection"):
            new, face_flux = self._advect(state, transport, u_mean, dt_T, compiled)
        with timed("transport: redistribution"):
            # compaction above alpha = 1 (and round-off below 0) is moved to face neighbours
            # with room, conservatively; the alpha-weighted fields move with the same fractions
            moved = transport.redistribute_fields(new, room_min=REDISTRIBUTION_ROOM_MIN)
            alpha_flux = face_flux[0] + (moved.face_flux if moved.face_flux is not None
                                         else 0.0)
            if moved.residual_excess > 0.0 or moved.residual_deficit > 0.0:
                # boxed-in excess that filling the micro-voids shell by shell did not place
                # within the sweeps goes on to cells with real room
                more = transport.redistribute_fields(new,
                                                     room_min=REDISTRIBUTION_ROOM_MIN_FALLBACK)
                if more.face_flux is not None:
                    alpha_flux = alpha_flux + more.face_flux
        with timed("transport: fields and momentum"):
            self._carried_fields_and_momentum(state, new, alpha_flux, dt_T, compiled)
        if state.markers is not None:
            with timed("transport: markers"):
                state.markers = self._advance_markers(state.markers, state.displacement, g,
                                                      self.cfg.hopper)
                state.displacement[:] = 0.0
        if self.profile is not None:
            self.profile.transports += 1
        state.face_flux_sum[:] = 0.0
        state.flux_time = 0.0
        if not stepping.all_finite(state.v) or not stepping.all_finite(state.sigma):
            self.check_stable(state, limit=math.inf)     # names the node or the cell
        for hook in self.after_transport:
            hook(state)

    def _advect(self, state: State, transport, u_mean: np.ndarray, dt_T: float,
                compiled: bool) -> tuple:
        """The carried fields (``TRANSPORTED``, stacked) after the van Leer step over
        ``dt_T`` with the mean face velocities ``u_mean``, and their face transfers."""
        if compiled:
            stacked = self._stacked
            stepping.pack_fields(state.alpha, state.sigma, state.eps_p, state.layer,
                                 state.loose, stacked)
            new, face_flux = transport.step_stacked(
                stacked, u_mean, dt_T, out=self._carried, rows=material_rows(state.alpha))
        else:
            alpha = state.alpha
            fields = {"alpha": alpha,
                      "s_rr": alpha * state.sigma[..., 0], "s_zz": alpha * state.sigma[..., 1],
                      "s_tt": alpha * state.sigma[..., 2], "s_rz": alpha * state.sigma[..., 3],
                      "eps_p": alpha * state.eps_p, "layer": alpha * state.layer,
                      "loose": alpha * state.loose}
            stacked = np.stack([np.ascontiguousarray(fields[k]).ravel() for k in TRANSPORTED])
            new, face_flux = transport.step_stacked(stacked, u_mean, dt_T)
        return new, face_flux

    def _carried_fields_and_momentum(self, state: State, new: np.ndarray,
                                     alpha_flux: np.ndarray, dt_T: float,
                                     compiled: bool) -> None:
        """The cell fields of ``state`` from the carried ones ``new``, the outlet and outflow
        bookkeeping of the face transfers ``alpha_flux`` (m^3 per rad) of the transport over
        ``dt_T`` (s), and the nodal momentum carried on the dual grid."""
        g = self.grid
        shape = state.alpha.shape
        if compiled:
            new_alpha, sigma = np.empty(shape), np.empty(shape + (4,))
            eps_p, layer, loose = np.empty(shape), np.empty(shape), np.empty(shape)
            stepping.unpack_fields(new, self.cfg.numerics.alpha_min, new_alpha, sigma, eps_p,
                                   layer, loose)
        else:
            new_alpha = new[0].reshape(shape)
            carried = {k: new[i].reshape(shape) for i, k in enumerate(TRANSPORTED)}
            safe = np.where(new_alpha >= 1e-12, new_alpha, 1.0)
            present = new_alpha >= 1e-12
            sigma = np.stack([carried[k] for k in ("s_rr", "s_zz", "s_tt", "s_rz")], axis=-1)
            sigma = np.where(present[..., None], sigma / safe[..., None], 0.0)
            sigma[new_alpha < self.cfg.numerics.alpha_min] = 0.0
            eps_p = np.where(present, carried["eps_p"] / safe, 0.0)
            layer = np.where(present, carried["layer"] / safe, 0.0)
            loose = np.where(present, np.maximum(carried["loose"] / safe, 0.0), 0.0)

        # outlet and outflow bookkeeping with the same face values
        nzf = g.n_zfaces
        oriented = alpha_flux * self.face_sign          # transfer along +z / +r
        through_outlet = -float(np.sum(oriented[g.outlet_faces]))
        through_bottom = -float(np.sum(oriented[g.outflow_faces]))
        to_kg = self.section_factor * self.rho
        state.last_outlet_mass = to_kg * through_outlet
        state.discharged += to_kg * through_outlet
        state.lost += to_kg * through_bottom
        state.last_transport_dt = dt_T

        # momentum on the dual grid
        mass_old = self.node_mass(state)
        flux_z = oriented[:nzf].reshape(g.nz + 1, g.nr)
        flux_r = oriented[nzf:].reshape(g.nz, g.nr + 1)
        if compiled:
            mass_new = np.empty_like(mass_old)
            momentum.node_mass_kernel(self.rho, new_alpha, self.open_volume, mass_new)
            v_new = np.empty_like(state.v)
            outflow, stopped = momentum.dual_momentum_kernel(
                state.v, mass_old, mass_new, np.ascontiguousarray(flux_z),
                np.ascontiguousarray(flux_r), self.rho, self.light_mass, v_new)
            state.v = v_new
        else:
            mass_new = momentum.node_mass(self.rho, new_alpha, self.open_volume)
            v_old = state.v
            state.v = momentum.dual_momentum_transport(state.v, mass_old, mass_new, flux_z,
                                                       flux_r, self.rho)
            leaving = 0.5 * self.rho * flux_z[0]
            outflow = float(np.sum(np.concatenate([leaving, [0.0]]) * v_old[1, 0])
                            + np.sum(np.concatenate([[0.0], leaving]) * v_old[1, 0]))
            # round-off traces of material (content ~1e-30) get no velocity, as in the
            # nodal update
            light = mass_new <= self.light_mass
            stopped = -float(np.sum((mass_new * state.v[1])[light]))
            state.v[:, light] = 0.0
        if state.momentum_budget is not None:
            state.momentum_budget[2] += stopped
            state.momentum_budget[3] += outflow
        state.alpha = new_alpha
        state.sigma = sigma
        state.eps_p = eps_p
        state.layer = layer
        state.loose = loose
        self._mass, self._mass_of = mass_new, new_alpha


def _length_in_boxes(x, z, half, a, b) -> np.ndarray:
    """Length (m) of each segment ``a``-``b`` (n, 2) inside the square of half-side ``half``
    around ``(x, z)`` (Liang-Barsky clipping)."""
    d = b - a
    lo, hi = np.zeros(len(x)), np.ones(len(x))
    for p, q in ((-d[:, 0], a[:, 0] - (x - half)), (d[:, 0], (x + half) - a[:, 0]),
                 (-d[:, 1], a[:, 1] - (z - half)), (d[:, 1], (z + half) - a[:, 1])):
        parallel = p == 0.0
        t = q / np.where(parallel, 1.0, p)
        lo = np.where(~parallel & (p < 0), np.maximum(lo, t), lo)
        hi = np.where(~parallel & (p > 0), np.minimum(hi, t), hi)
        hi = np.where(parallel & (q < 0), -1.0, hi)          # parallel and outside
    return np.maximum(hi - lo, 0.0) * np.hypot(d[:, 0], d[:, 1])


def _contact_list(passes):
    """Flatten contact passes ``(mask, normal, mu)`` (``mu`` one coefficient or one per
    node) into ordered arrays ``(j, i, normals (K, 2), mu (K,))``."""
    js, is_, normals, mus = [], [], [], []
    for mask, normal, mu in passes:
        j, i = np.nonzero(mask)
        js.append(j)
        is_.append(i)
        normals.append(np.stack([normal[0][j, i], normal[1][j, i]], axis=1))
        mus.append(mu[j, i] if np.ndim(mu) == 2 else np.full(len(j), mu))
    return (np.concatenate(js).astype(np.int64), np.concatenate(is_).astype(np.int64),
            np.ascontiguousarray(np.concatenate(normals)), np.concatenate(mus))
