"""SpaceModel: the 3D Eulerian silo and its explicit step (in progress).

The sections' method (docs/physics_and_numerics.md, sections 3-7) on the 3D grid:

1. material step on the nodes: lumped mass ``m = sum rho alpha kappa h^3 / 8``, ``m dv/dt =
   -f_int(alpha (sigma + eta_b tr(D) I)) + f_hg + m g`` (gravity ramped and the mass-
   proportional damping ``c_d = pi c_p / (2 L)`` while filling, the damping after the contact),
   wall and plate contact (:mod:`fipy_hopper.space.contact`), the mirror planes; per loaded
   cell (``alpha >= alpha_min``) the Jaumann rotation, the open divergence as volumetric
   strain, the closing of loose volume and the law's 3D point update
   (:mod:`fipy_hopper.material.principal3d`), the plastic and loose strains
   (:mod:`fipy_hopper.space.momentum`, compiled in :mod:`fipy_hopper.space.stepping`); in
   the internal forces the law's rate-dependent overstress in the cells whose last return was
   plastic (:mod:`fipy_hopper.space.rate3d`, the sections' seam);
2. transport, sub-cycled as in the sections (when the material has crossed ``transport_cfl``
   of a cell at the largest open-face speed, or every ``max_transport_interval`` steps): the
   carried fields ``alpha, alpha sigma (6), alpha eps_p, alpha e_l`` by the bounded van Leer
   step (:mod:`fipy_hopper.space.transport`), the redistribution of alpha above 1, and the
   nodal momentum on the dual grid (:func:`dual_momentum_transport`).

Masses, forces and momenta of the computed part (a quarter, a half or all of the silo) are
reported for the whole silo by ``section_factor`` (4, 2, 1) where a method says so.

The model implements :class:`fipy_hopper.protocol.HopperModelProtocol`, so the shared loop
(:class:`fipy_hopper.simulation.Simulation`) runs it as it runs the sections; its wall loads
and flow measures are 3D (:mod:`fipy_hopper.space.wall`, :mod:`fipy_hopper.space.flow`).  Not
yet: markers, layers, the opening iris (the plate goes at once).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numba
import numpy as np

from .. import resources
from ..stepping import read_cycles
from ..material import principal3d as p3
from ..material.mohr_coulomb import APEX, ELASTIC
from ..transport import material_rows
from . import contact as sc
from . import momentum as sm
from . import stepping
from .boundary import silo_boundary
from .config import SpaceConfig
from .grid import build_grid
from .rate3d import overstress6
from .transport import SpaceTransport, dual_momentum_transport_compiled

GRAVITY = 9.81
#: the carried fields, alpha-weighted but alpha itself
CARRIED = ("alpha", "s_xx", "s_yy", "s_zz", "s_yz", "s_xz", "s_xy", "eps_p", "loose")
MOMENTUM_BUDGET = ("gravity", "damping", "stopped", "outflow")
REDISTRIBUTION_ROOM_MIN = 1e-6
REDISTRIBUTION_ROOM_MIN_FALLBACK = 1e-3


@dataclass
class SpaceState:
    """Everything that evolves (SI): nodal velocity ``v`` (3, nz + 1, ny + 1, nx + 1), cell
    fields ``alpha``, ``sigma`` (..., 6), ``eps_p``, ``loose``, ``flowing`` (1 where the cell's
    last return was plastic: the law's overstress acts there; not carried, a flag of the
    grid's cell as in the sections); the face-flux integrals of the
    three face directions (m); the discharged and lost masses (kg, whole silo); the cumulative
    impulses of every wall and plate entry (kg m/s, rows ``(x, y, z)``, computed part) and the
    vertical momentum budget (:data:`MOMENTUM_BUDGET`)."""

    t: float
    step: int
    stage: str
    v: np.ndarray
    alpha: np.ndarray
    sigma: np.ndarray
    eps_p: np.ndarray
    loose: np.ndarray
    flowing: np.ndarray
    flux_z: np.ndarray
    flux_y: np.ndarray
    flux_x: np.ndarray
    wall_impulse: np.ndarray
    plate_impulse: np.ndarray
    momentum_budget: np.ndarray
    discharged: float = 0.0
    lost: float = 0.0
    flux_time: float = 0.0
    plate_closed: bool = True
    opened_at: float = -1.0

    def copy(self) -> "SpaceState":
        return SpaceState(**{k: (v.copy() if isinstance(v, np.ndarray) else v)
                             for k, v in self.__dict__.items()})


class SpaceModel:
    """The 3D silo of a :class:`~fipy_hopper.space.config.SpaceConfig` on its grid.
    ``backend``: ``"numba"`` (:mod:`fipy_hopper.space.stepping`, the compiled transport) or
    ``"numpy"`` (the reference of every part of a step); ``threads`` the compiled steps'
    numba threads."""

    formulation = "eulerian"
    #: the whole silo (fipy_hopper.protocol)
    dimensions = 3

    def __init__(self, cfg, backend: str = "numba", threads: int | None = None):
        """``cfg``: a :class:`SpaceConfig`, or a run configuration with ``hopper.dimensions
        = 3`` (:meth:`SpaceConfig.from_config`)."""
        if backend not in ("numba", "numpy"):
            raise ValueError(f"backend must be 'numba' or 'numpy', not {backend!r}")
        if not isinstance(cfg, SpaceConfig):
            cfg = SpaceConfig.from_config(cfg)
        self.cfg, self.backend = cfg, backend
        #: numba threads of the compiled steps (default: one per core this process may use,
        #: :func:`fipy_hopper.resources.thread_limit`); the results do not depend on them
        self.threads = int(threads) if threads else resources.thread_limit()
        num = cfg.numerics
        self.boundary = silo_boundary(cfg)
        g = self.grid = build_grid(self.boundary, num.cell_size, num.free_fall_depth,
                                   num.min_open_fraction, cfg.mirror_planes)
        self.law = cfg.material.law()
        self.rho = self.law.rho
        self.c_p = self.law.p_wave_speed
        self.dt = cfg.time_step()
        self.bulk_viscosity = cfg.bulk_viscosity * self.rho * self.c_p * g.h
        self.mu_wall = cfg.wall.friction_coefficient
        self.section_factor = g.factor
        self.ramp_time = cfg.ramp_time
        self.fill_damping = math.pi * self.c_p / (2.0 * max(cfg.hopper.fill_level, g.h))
        self.open_volume = g.kappa * g.h ** 3
        self.hourglass_base = (num.hourglass_coefficient * self.rho * math.sqrt(GRAVITY * g.h)
                               * self.open_volume / (4.0 * g.h))
        self.light_mass = 1e-12 * self.rho * g.h ** 3
        self.hopper_cells = np.broadcast_to((g.centres(2) > 0.0)[:, None, None], g.kappa.shape)
        candidates = sm.scatter_to_nodes((g.kappa > 0).astype(float)) > 0.0
        self.contacts = sc.contact_table(self.boundary, g, candidates, self.mu_wall)
        self.n_wall, self.n_plate = self.contacts[7]
        nodes, ptr = self.contacts[0], self.contacts[1]
        self._node_contacts = np.full(tuple(n + 1 for n in g.kappa.shape), -1,
                                      np.int64)
        self._node_contacts[nodes[:, 0], nodes[:, 1], nodes[:, 2]] = np.arange(len(nodes))
        # transport: FiPy's face orientation and the open/closed outlet
        normals = np.asarray(g.mesh.faceNormals)
        nzf, nyf, _ = g.n_faces
        self.face_sign = np.concatenate([normals[2, :nzf], normals[1, nzf:nzf + nyf],
                                         normals[0, nzf + nyf:]])
        self.outflow_faces = np.zeros(sum(g.n_faces), bool)
        self.outflow_faces[:g.nx * g.ny] = g.outflow_z.ravel()
        self.outlet_faces = np.zeros(sum(g.n_faces), bool)
        k = g.k_outlet
        self.outlet_faces[k * g.nx * g.ny:(k + 1) * g.nx * g.ny] = g.outlet_z.ravel()
        aperture = g.face_aperture
        self.transport_open = SpaceTransport(g.mesh, g.kappa.ravel(), aperture,
                                             self.outflow_faces, backend)
        self.transport_closed = SpaceTransport(g.mesh, g.kappa.ravel(),
                                               np.where(self.outlet_faces, 0.0, aperture),
                                               self.outflow_faces, backend)
        self.open_z = g.aperture_z > 0
        self.open_y = g.aperture_y > 0
        self.open_x = g.aperture_x > 0
        self._mass, self._mass_of = None, None
        self._wall_loads = None
        self._prm = self.law.kernel_parameters()
        #: the law's rate parameters (``[d, rho_s, delta_mu, I_0]``; zeros: none), the
        #: overstress of :mod:`fipy_hopper.space.rate3d` in flowing cells
        self._rate = np.ascontiguousarray(self.law.rate_parameters(), dtype=float)
        n = g.n_cells
        self._work = (np.zeros((8, 3) + g.kappa.shape), np.empty((n, 6)), np.empty((n, 6)),
                      np.empty((n, 6)), np.empty((n, 6)), np.empty(n, np.int8))
        self._node_budget = np.zeros(((g.nz + 1) * (g.ny + 1) * (g.nx + 1), 3))
        self._plane_top = np.zeros(g.nz + 1)
        #: a :class:`fipy_hopper.profiling.PhaseProfile` that the steps add their time to, or
        #: None (the default: nothing is timed)
        self.profile = None
        self._no_cycles = np.zeros(0, np.int64)

    # ------------------------------------------------------------------ the protocol's sizes
    @property
    def n_cells(self) -> int:
        return self.grid.n_cells

    @property
    def cell_size(self) -> float:
        return self.grid.h

    # ------------------------------------------------------------------ state
    def initial_state(self) -> SpaceState:
        """The silo filled to the fill level at rest, stress free, outlet plate closed."""
        g = self.grid
        z_lo, z_hi = g.z_nodes[:-1], g.z_nodes[1:]
        frac = np.clip((self.cfg.hopper.fill_level - z_lo) / (z_hi - z_lo), 0.0, 1.0)
        frac = np.where(z_lo >= 0.0, frac, 0.0)
        alpha = frac[:, None, None] * (g.kappa > 0)
        shape = g.kappa.shape
        return SpaceState(
            t=0.0, step=0, stage="filling", v=np.zeros((3,) + tuple(n + 1 for n in shape)),
            alpha=alpha, sigma=np.zeros(shape + (6,)), eps_p=np.zeros(shape),
            loose=np.zeros(shape), flowing=np.zeros(shape),
            flux_z=np.zeros(g.aperture_z.shape), flux_y=np.zeros(g.aperture_y.shape),
            flux_x=np.zeros(g.aperture_x.shape),
            wall_impulse=np.zeros((self.n_wall, 3)), plate_impulse=np.zeros((self.n_plate, 3)),
            momentum_budget=np.zeros(len(MOMENTUM_BUDGET)))

    def node_mass(self, state: SpaceState) -> np.ndarray:
        """Lumped nodal masses (kg, computed part), cached for the alpha array."""
        if self._mass is None or self._mass_of is not state.alpha:
            self._mass = sm.node_mass(self.rho, state.alpha, self.open_volume)
            self._mass_of = state.alpha
        return self._mass

    def total_mass(self, state) -> float:
        """Mass in the whole domain (kg, whole silo)."""
        return self.section_factor * self.rho * float(np.sum(state.alpha * self.open_volume))

    def mass_in_hopper(self, state) -> float:
        """Mass above the outlet plane (kg, whole silo)."""
        return self.section_factor * self.rho * float(
            np.sum((state.alpha * self.open_volume)[self.hopper_cells]))

    def kinetic_energy(self, state) -> float:
        """Kinetic energy of the nodal velocities (J, whole silo)."""
        return 0.5 * self.section_factor * float(np.sum(self.node_mass(state)
                                                        * (state.v ** 2).sum(axis=0)))

    def vertical_momentum(self, state) -> float:
        """``sum m v_z`` (kg m/s, computed part)."""
        return float(np.sum(self.node_mass(state) * state.v[2]))

    def gravity(self, state) -> float:
        if state.stage == "filling" and self.ramp_time > 0:
            return GRAVITY * min(1.0, state.t / self.ramp_time)
        return GRAVITY

    def open_outlet(self, state) -> None:
        """Remove the outlet plate at once: the discharge starts."""
        state.stage = "discharge"
        state.opened_at = state.t
        state.plate_closed = False

    def check_stable(self, state, limit: float | None = None) -> None:
        limit = 50.0 * math.sqrt(GRAVITY * max(self.boundary.top, 0.1)) if limit is None \
            else limit
        speed = np.sqrt((state.v ** 2).sum(axis=0))
        if not np.all(np.isfinite(speed)) or speed.max() > limit or not np.all(
                np.isfinite(state.sigma)):
            raise FloatingPointError(f"the 3D run went unstable at step {state.step}, t = "
                                     f"{state.t:.6g} s (|v| up to {np.nanmax(speed):.3g} m/s)")

    def reset_caches(self) -> None:
        self._mass = None

    # ------------------------------------------------------------------ diagnostics
    @property
    def material(self):
        """The constitutive law (the loop's fingerprint reads it)."""
        return self.law

    @property
    def wall_loads(self):
        """The wall's patches, the entries and cells located on them and the load maps
        (:class:`fipy_hopper.space.wall.SpaceWallLoads`; built once)."""
        if self._wall_loads is None:
            from .wall import SpaceWallLoads
            self._wall_loads = SpaceWallLoads(self)
        return self._wall_loads

    def summary_extras(self, state) -> dict:
        """The 3D keys of a run's summary: ``dimensions``, ``outlet_offset_m`` (a rectangular
        plan's ``[ex, ey]``, with ``plan``), ``mirror_factor`` (the computed part to the whole
        silo), ``wall_sectors``."""
        out = {"dimensions": 3, "outlet_offset_m": self.boundary.outlet_offset,
               "mirror_factor": self.section_factor, "wall_sectors": self.cfg.wall_sectors}
        if self.boundary.plan == "rectangular":
            out.update(plan="rectangular", outlet_offset_m=list(self.boundary.outlet_offset))
        return out

    def wall_entries(self) -> tuple:
        """``(s, normal, segment)`` of the rows of ``state.wall_impulse``: the arc length
        along the wall profile's meridian of the entry's wall point (m,
        :mod:`fipy_hopper.space.wall`), its contact normal ``(n, 3)`` and the profile's
        segment of its constraint (-1 the tube, -2 a convex corner: the lip).  Its angle
        around the circumference: :meth:`wall_theta`."""
        W = self.wall_loads
        nodes, ptr, normal, _, kind, entry, segment = self.contacts[:7]
        nrm = np.empty((self.n_wall, 3))
        nrm[entry[kind == 0]] = normal[kind == 0]
        return W.entry_s, nrm, segment

    def wall_theta(self) -> np.ndarray:
        """The angle (deg) around its part's axis of each wall entry's wall point
        (:mod:`fipy_hopper.space.wall`: 0 towards the outlet's offset, +y positive)."""
        return np.degrees(self.wall_loads.entry_theta)

    def wall_load_rows(self) -> np.ndarray:
        """The profile's segment whose load each wall entry is (the lip's: the cone's or
        floor's; -1 for the tube's entries, which are no load)."""
        return self.wall_loads.entry_segment

    def wall_stress_points(self, state) -> tuple:
        """``(position, weight, sigma)`` of the cells 0.5 to 2.5 cells inside the material
        from the wall: the arc length ``s`` of the nearest wall point along the meridian (m),
        the weight ``alpha kappa V`` where ``alpha > 1/2`` (else 0) and the stress (six
        components, Pa).  Their angles: :meth:`wall_stress_theta`."""
        cells = self.wall_loads._wall_band()
        flat = cells[0]
        alpha = state.alpha.ravel()[flat]
        w = np.where(alpha > 0.5, (state.alpha * self.open_volume).ravel()[flat], 0.0)
        return cells[2], w, state.sigma.reshape(-1, 6)[flat]

    def wall_stress_theta(self) -> np.ndarray:
        """The angles (deg) of the cells of :meth:`wall_stress_points`."""
        return np.degrees(self.wall_loads._wall_band()[3])

    def contact_slip(self, state) -> tuple:
        """``(slip, axis_speed)`` (m/s) of every wall entry
        (:func:`fipy_hopper.space.flow.contact_slip`)."""
        from .flow import contact_slip
        return contact_slip(self, state)

    def flow_mode_measures(self, state, rule) -> tuple:
        """``(mass-flow index, stagnant fraction)``
        (:func:`fipy_hopper.space.flow.flow_mode_measures`)."""
        from .flow import flow_mode_measures
        return flow_mode_measures(self, state, rule)

    def empty_channel(self, state, rule) -> tuple:
        """``(diameter, height)`` (m) of an empty channel
        (:func:`fipy_hopper.space.flow.empty_channel`)."""
        from .flow import empty_channel
        return empty_channel(self, state, rule)

    def channel_fields(self, state) -> tuple:
        """The fields the loop averages over each window of the discharge for
        :meth:`channel_measures`: the nodes' vertical velocity (m/s) and the cells' material
        fraction (views of the state: the loop copies what it keeps); none for a rectangular
        plan (EN 1991-4's channel is a circular silo's)."""
        if self.boundary.plan == "rectangular":
            return ()
        return state.v[2], state.alpha

    def channel_measures(self, means: tuple) -> list:
        """The flow channel of a window's mean fields (:meth:`channel_fields`) at every node
        plane of the bin, one dict per height (:func:`fipy_hopper.space.channel.field_channel`,
        :data:`fipy_hopper.space.channel.PROFILE_COLUMNS`)."""
        from .channel import field_channel, profile_rows
        if not means:
            return []
        return profile_rows(field_channel(self, *means))

    def bin_lateral_stress_ratio(self, state) -> float:
        """:func:`fipy_hopper.space.flow.bin_lateral_stress_ratio`."""
        from .flow import bin_lateral_stress_ratio
        return bin_lateral_stress_ratio(self, state)

    def wall_measures(self) -> tuple:
        """``(sampler, loads)`` of the loop: one :class:`fipy_hopper.space.wall.PatchLoads`
        in both roles."""
        from .wall import PatchLoads
        loads = PatchLoads(self)
        return loads, loads

    def wall_slip_measures(self, state, previous_impulse, rule) -> tuple:
        """:func:`fipy_hopper.space.flow.wall_slip_measures`."""
        from .flow import wall_slip_measures
        return wall_slip_measures(self, state, previous_impulse, rule)

    def material_speed(self, state, full: float = 0.5) -> float:
        """The rms speed (m/s) of the material above the outlet plane: the cells holding more
        than ``full`` (the mean of their eight nodes' velocities), weighted by ``alpha kappa
        V``, as the sections' :func:`fipy_hopper.diagnostics.material_speed`; 0 where there
        is no material."""
        g, v = self.grid, state.v
        vc = 0.125 * sum(v[:, dk:dk + g.nz, dj:dj + g.ny, di:di + g.nx]
                         for dk in (0, 1) for dj in (0, 1) for di in (0, 1))
        sel = (state.alpha > full) & (g.centres(2) > 0.0)[:, None, None] & (g.kappa > 0)
        w = (state.alpha * self.open_volume)[sel]
        speed2 = (vc ** 2).sum(axis=0)[sel]
        return float(math.sqrt(np.sum(w * speed2) / np.sum(w))) if np.sum(w) > 0 else 0.0

    def heap_angle(self, state, full: float = 0.5) -> float:
        """The angle (deg from the horizontal) of the surface of the material left once the
        flow has stopped, the sections' rule (:func:`fipy_hopper.diagnostics.heap_angle`) on
        the cell columns: in each column above the outlet plane whose top loaded cell has an
        open cell above it and is not cut by the wall, the height where ``alpha`` falls below
        ``full``; the slope of the least-squares line of those heights against the distance
        from the outlet's axis ``(e, 0)``.  NaN with fewer than three columns."""
        g = self.grid
        alpha, kappa = state.alpha, g.kappa
        zc = g.centres(2)
        held = (alpha > full) & (zc > 0.0)[:, None, None]
        any_held = held.any(axis=0)
        top = held.shape[0] - 1 - np.argmax(held[::-1], axis=0)          # (ny, nx)
        jj, ii = np.nonzero(any_held)
        k = top[jj, ii]
        ok = (k + 1 < alpha.shape[0]) & (kappa[np.minimum(k + 1, alpha.shape[0] - 1), jj, ii]
                                         > 0.0) & (kappa[k, jj, ii] >= 1.0)
        jj, ii, k = jj[ok], ii[ok], k[ok]
        if len(k) < 3:
            return math.nan
        a0, a1 = alpha[k, jj, ii], alpha[k + 1, jj, ii]
        frac = np.minimum((a0 - full) / np.maximum(a0 - a1, 1e-12), 1.0)
        height = zc[k] + frac * g.h
        ex, ey = self.boundary.outlet_centre
        radius = np.hypot(g.centres(0)[ii] - ex, g.centres(1)[jj] - ey)
        if np.ptp(radius) <= 0.0:
            return math.nan
        slope = np.polyfit(radius, height, 1)[0]
        return float(np.degrees(np.arctan(abs(slope))))

    # ------------------------------------------------------------------ steps
    def advance(self, state: SpaceState, max_steps: int) -> int:
        """Up to ``max_steps`` explicit steps in place, stopping after a step at which a
        transport was due (the transport included); returns the steps taken."""
        if max_steps < 1:
            return 0
        if self.backend == "numpy":
            for n in range(max_steps):
                if self._step_numpy(state):
                    self.transport_step(state)
                    return n + 1
            return max_steps
        g, num = self.grid, self.cfg.numerics
        profile = self.profile
        setup_started = read_cycles() if profile is not None else 0
        if numba.get_num_threads() != self.threads:
            numba.set_num_threads(self.threads)
        mass = self.node_mass(state)
        carry = np.argwhere(state.alpha != 0.0).astype(np.int64)
        loaded = np.argwhere(state.alpha >= num.alpha_min).astype(np.int64)
        not_loaded = state.alpha < num.alpha_min
        state.sigma[not_loaded] = 0.0
        state.loose[not_loaded] = 0.0
        state.flowing[not_loaded] = 0.0
        moving = np.argwhere((mass > self.light_mass) | np.any(state.v != 0.0, axis=0))
        nodes = np.zeros((len(moving), 5), np.int64)
        nodes[:, :3] = moving
        which = self._node_contacts[moving[:, 0], moving[:, 1], moving[:, 2]]
        ptr = self.contacts[1]
        has = which >= 0
        nodes[has, 3], nodes[has, 4] = ptr[which[has]], ptr[which[has] + 1]
        if len(moving):
            k0, k1 = max(int(moving[:, 0].min()) - 1, 0), int(moving[:, 0].max()) + 1
        else:
            k0 = k1 = 0
        contrib = self._work[0]
        contrib[:] = 0.0
        filling = state.stage == "filling"
        clock = np.array([state.t, float(state.step), state.flux_time])
        _, _, normal, mu, kind, entry = self.contacts[:6]
        cycles = self._no_cycles
        if profile is not None:
            cycles = profile.cycles
            cycles[0] += read_cycles() - setup_started     # "step setup": the lists above
            started = time.perf_counter()
        done, due = stepping.material_steps(
            int(max_steps), clock, state.v, mass, state.alpha, state.sigma, state.loose,
            state.eps_p, state.flowing, state.flux_z, state.flux_y, state.flux_x, carry,
            len(carry), loaded, len(loaded), nodes, len(nodes), k0, k1, self.open_volume,
            g.kappa, g.aperture_z, g.aperture_y, g.aperture_x, self.open_z, self.open_y, self.open_x, g.h,
            self.hourglass_base, self._prm, self.dt, GRAVITY,
            self.ramp_time if filling else 0.0, self.fill_damping if filling else 0.0,
            self.light_mass, num.alpha_min, self.bulk_viscosity, num.transport_cfl,
            num.max_transport_interval, normal, mu, kind, entry, state.plate_closed,
            g.mirror_x, g.mirror_y, state.wall_impulse, state.plate_impulse,
            state.momentum_budget, contrib, *self._work[1:], self._node_budget[:len(nodes)],
            self._plane_top, self._rate, cycles, self.threads)
        if profile is not None:
            profile.compiled_seconds += time.perf_counter() - started
            profile.steps += int(done)
            profile.loaded_cell_steps += int(done) * len(loaded)
        state.t, state.step, state.flux_time = float(clock[0]), state.step + int(done), \
            float(clock[2])
        if due:
            self.transport_step(state)
        return int(done)

    def _step_numpy(self, state: SpaceState) -> bool:
        """One step of the numpy reference; True when a transport is due."""
        g, dt, num = self.grid, self.dt, self.cfg.numerics
        m = self.node_mass(state)
        filling = state.stage == "filling"
        gravity = self.gravity(state)
        loaded = state.alpha >= num.alpha_min
        state.sigma[~loaded] = 0.0
        state.loose[~loaded] = 0.0
        state.flowing[~loaded] = 0.0
        stress = state.sigma
        rated = self._rate[0] != 0.0
        if self.bulk_viscosity > 0.0 or rated:
            # sigma + 2 eta_I D' (flowing cells) + eta_b tr(D) I in loaded cells
            D, _ = sm.strain_rate(state.v, g.h)
            viscous = state.sigma
            if rated:
                viscous = viscous + overstress6(state.sigma, D, state.flowing != 0.0,
                                                self._rate)
            if self.bulk_viscosity > 0.0:
                p_b = self.bulk_viscosity * (D[..., 0] + D[..., 1] + D[..., 2])
                viscous = viscous.copy() if viscous is state.sigma else viscous
                viscous[..., :3] = viscous[..., :3] + p_b[..., None]
            stress = np.where(loaded[..., None], viscous, state.sigma)
        contrib = (-sm.corner_forces(state.alpha[..., None] * stress, self.open_volume, g.h)
                   + sm.hourglass_corner_forces(state.v, self.hourglass_base * state.alpha))
        force = sm.gather(contrib)
        heavy = m > self.light_mass
        budget = state.momentum_budget
        budget[0] -= float(np.sum(np.where(heavy, m * gravity * dt, 0.0)))
        budget[2] -= float(np.sum(np.where(heavy, 0.0, m * state.v[2])))
        safe = np.where(heavy, m, 1.0)
        v = state.v + dt * force / safe
        v[2] = state.v[2] + dt * (force[2] / safe - gravity)
        v = np.where(heavy[None], v, 0.0)
        if g.mirror_x:                 # the mirror planes before the contact too: its
            v[0, :, :, 0] = 0.0        # friction must not see the unbalanced force across
        if g.mirror_y:                 # the plane
            v[1, :, 0, :] = 0.0
        sc.contact_nodes(v, m, self.contacts, state.plate_closed, state.wall_impulse,
                         state.plate_impulse)
        if filling and self.fill_damping > 0.0:
            held = v[2].copy()
            v *= 1.0 / (1.0 + self.fill_damping * dt)
            budget[1] += float(np.sum(m * (v[2] - held)))
        if g.mirror_x:
            v[0, :, :, 0] = 0.0
        if g.mirror_y:
            v[1, :, 0, :] = 0.0
        state.v = v
        # the stress update of the loaded cells
        D, W = sm.strain_rate(v, g.h)
        sigma = sm.jaumann_rotate(state.sigma, W, dt)
        d_eps = D * dt
        div = sm.open_divergence(v, g.aperture_z, g.aperture_y, g.aperture_x, g.kappa, g.h) * dt
        d_eps[..., :3] += ((div - (d_eps[..., 0] + d_eps[..., 1] + d_eps[..., 2])) / 3.0)[..., None]
        compression = -(d_eps[..., 0] + d_eps[..., 1] + d_eps[..., 2])
        closed = np.minimum(state.loose, np.maximum(compression, 0.0))
        share = np.where(closed > 0.0, 1.0 - closed / np.where(closed > 0.0, compression, 1.0),
                         1.0)
        d_eps = d_eps * share[..., None]
        new, dep, status = p3.update6_reference(sigma[loaded], d_eps[loaded], self.law,
                                                return_status=True)
        state.sigma = np.where(loaded[..., None], 0.0, state.sigma)
        state.sigma[loaded] = new
        state.flowing = np.zeros_like(state.flowing)
        state.flowing[loaded] = np.where(status != ELASTIC, 1.0, 0.0)
        loose = np.where(loaded, state.loose - closed, 0.0)
        loose[loaded] += np.where(status == APEX, np.maximum(dep[:, :3].sum(axis=1), 0.0), 0.0)
        state.loose = loose
        state.eps_p[loaded] += p3.equivalent_plastic_strain6(dep)
        vz, vy, vx = sm.face_velocities(v)
        state.flux_z += vz * dt
        state.flux_y += vy * dt
        state.flux_x += vx * dt
        speed = max(float(np.max(np.abs(vz[self.open_z]), initial=0.0)),
                    float(np.max(np.abs(vy[self.open_y]), initial=0.0)),
                    float(np.max(np.abs(vx[self.open_x]), initial=0.0)))
        state.flux_time += dt
        state.t += dt
        state.step += 1
        if round(state.flux_time / dt) >= num.max_transport_interval:
            return True
        return (speed + 1e-30) * (state.flux_time + dt) > num.transport_cfl * g.h

    # ------------------------------------------------------------------ transport
    def transport_step(self, state: SpaceState) -> None:
        """Carry the cell fields and the nodal momentum with the mean face velocities (its
        three parts timed into the run's profile, if any)."""
        g = self.grid
        if state.flux_time <= 0.0:
            return
        started = time.perf_counter()
        dt_T = state.flux_time
        u_n = np.concatenate([state.flux_z.ravel(), state.flux_y.ravel(),
                              state.flux_x.ravel()]) / dt_T * self.face_sign
        closed = state.plate_closed and state.opened_at < 0.0
        transport = self.transport_closed if closed else self.transport_open
        a = state.alpha
        stacked = np.concatenate([a.ravel()[None], (a[..., None] * state.sigma).reshape(-1, 6).T,
                                  (a * state.eps_p).ravel()[None],
                                  (a * state.loose).ravel()[None]])
        rows = None
        if self.backend == "numba":
            rows = material_rows(a.reshape(g.nz, -1))
        new, face_flux = transport.step_stacked(stacked, u_n, dt_T, rows=rows)
        new = np.ascontiguousarray(new)
        advected = time.perf_counter()
        moved = transport.redistribute_fields(new, room_min=REDISTRIBUTION_ROOM_MIN)
        alpha_flux = face_flux[0] + (moved.face_flux if moved.face_flux is not None else 0.0)
        if moved.residual_excess > 0.0 or moved.residual_deficit > 0.0:
            more = transport.redistribute_fields(new, room_min=REDISTRIBUTION_ROOM_MIN_FALLBACK)
            if more.face_flux is not None:
                alpha_flux = alpha_flux + more.face_flux
        redistributed = time.perf_counter()
        shape = a.shape
        new_alpha = new[0].reshape(shape)
        present = new_alpha >= 1e-12
        safe = np.where(present, new_alpha, 1.0)
        sigma = np.where(present[..., None], new[1:7].T.reshape(shape + (6,)) / safe[..., None],
                         0.0)
        sigma[new_alpha < self.cfg.numerics.alpha_min] = 0.0
        eps_p = np.where(present, new[7].reshape(shape) / safe, 0.0)
        loose = np.where(present, np.maximum(new[8].reshape(shape) / safe, 0.0), 0.0)
        oriented = alpha_flux * self.face_sign          # transfers along +z, +y, +x (m^3)
        to_kg = self.section_factor * self.rho
        state.discharged += -to_kg * float(np.sum(oriented[self.outlet_faces]))
        state.lost += -to_kg * float(np.sum(oriented[self.outflow_faces]))
        mass_old = self.node_mass(state)
        mass_new = sm.node_mass(self.rho, new_alpha, self.open_volume)
        nzf, nyf, _ = g.n_faces
        fluxes = (oriented[:nzf].reshape(g.aperture_z.shape),
                  oriented[nzf:nzf + nyf].reshape(g.aperture_y.shape),
                  oriented[nzf + nyf:].reshape(g.aperture_x.shape))
        if self.backend == "numba":
            lo = [material_rows(x.reshape(g.nz, -1), margin=1) for x in (a, new_alpha)]
            lo = [r for r in lo if r[1] > r[0]]
            node_rows = ((min(r[0] for r in lo), max(r[1] for r in lo) + 1) if lo
                         else (0, 0))
            state.v, outflow, stopped = dual_momentum_transport_compiled(
                state.v, mass_old, mass_new, *fluxes, self.rho, self.light_mass, node_rows,
                self.threads)
        else:
            state.v, outflow, stopped = dual_momentum_transport(
                state.v, mass_old, mass_new, *fluxes, self.rho, self.light_mass)
        state.momentum_budget[2] += stopped
        state.momentum_budget[3] += outflow
        state.alpha, state.sigma, state.eps_p, state.loose = new_alpha, sigma, eps_p, loose
        self._mass, self._mass_of = mass_new, new_alpha
        state.flux_z[:] = 0.0
        state.flux_y[:] = 0.0
        state.flux_x[:] = 0.0
        state.flux_time = 0.0
        if self.profile is not None:
            seconds = self.profile.seconds
            seconds["transport: advection"] += advected - started
            seconds["transport: redistribution"] += redistributed - advected
            seconds["transport: fields and momentum"] += time.perf_counter() - redistributed
            self.profile.transports += 1


def dual_momentum_transport(v, mass_old, mass_new, flux_z, flux_y, flux_x, rho, light_mass):
    """Conservative upwind transport of the nodal momentum on the dual grid (numpy), the
    sections' rule in 3D: a primal transfer ``F`` (m^3, along +axis) between two cells changes
    their eight nodes' lumped masses as transfers ``F / 8`` across the dual faces through the
    two cells' centres, so the dual flux between the two nodes of each of a cell's four edges
    along an axis is ``(F_minus + F_plus) / 8`` of its two faces across that axis (summed over
    the four cells round the edge); the bottom boundary's transfer leaves ``F / 4`` from each of
    the face's four nodes.  Momentum moves with the donor node's velocity; the new velocity is
    ``P / m_new`` (rest at nodes no heavier than ``light_mass``).  Returns ``(v_new, outflow,
    stopped)``: the vertical momentum the bottom outflow carried into the grid and that
    stopping light nodes added (kg m/s)."""
    P = mass_old[None] * v
    for axis, flux in ((0, flux_z), (1, flux_y), (2, flux_x)):
        rf = rho * flux
        lo = [slice(None)] * 3
        hi = [slice(None)] * 3
        lo[axis], hi[axis] = slice(None, -1), slice(1, None)
        per_cell = 0.125 * (rf[tuple(lo)] + rf[tuple(hi)])        # (nz, ny, nx)
        shape = list(v.shape[1:])
        shape[axis] -= 1                                          # node-edge array
        gdual = np.zeros(shape)
        others = [d for d in range(3) if d != axis]
        for da in (0, 1):
            for db in (0, 1):
                sl = [slice(None)] * 3
                sl[others[0]] = slice(da, da + per_cell.shape[others[0]])
                sl[others[1]] = slice(db, db + per_cell.shape[others[1]])
                gdual[tuple(sl)] += per_cell
        lo_n = [slice(None)] * 3
        hi_n = [slice(None)] * 3
        lo_n[axis], hi_n[axis] = slice(None, -1), slice(1, None)
        donor = np.where(gdual > 0, v[(slice(None),) + tuple(lo_n)],
                         v[(slice(None),) + tuple(hi_n)])
        d = gdual[None] * donor
        P[(slice(None),) + tuple(lo_n)] -= d
        P[(slice(None),) + tuple(hi_n)] += d
    out = 0.25 * rho * flux_z[0]                                  # (ny, nx), negative: leaving
    node_out = np.zeros(v.shape[2:])
    for dj in (0, 1):
        for di in (0, 1):
            node_out[dj:dj + out.shape[0], di:di + out.shape[1]] += out
    P[:, 0] += node_out[None] * v[:, 0]
    outflow = float(np.sum(node_out * v[2, 0]))
    safe = np.where(mass_new > 0, mass_new, 1.0)
    v_new = np.where(mass_new[None] > 0, P / safe[None], 0.0)
    light = mass_new <= light_mass
    stopped = -float(np.sum((mass_new * v_new[2])[light]))
    v_new[:, light] = 0.0
    return v_new, outflow, stopped
