"""Cost of a time step during discharge, whole and by phase, at 5 and 2.5 mm.

``pytest tests/benchmarks/test_bench_step.py --benchmark-only`` fills the reference hopper at
each cell size, discharges it for 0.2 s (a flowing state: plastic, loose and elastic cells,
the jet, the markers) and then times, on copies of that state:

* ``step``: ``HopperModel.advance`` over 200 steps, transports included (per step);
* the phases of the compiled material step (:mod:`fipy_hopper.stepping`), one step each:
  ``forces`` (internal and hourglass forces of the cells; the bulk viscosity's tr(D) as the
  previous step's strain pass left it, as in every step of a call but its first), ``nodes``
  (nodal velocities, wall contact, plate, axis), ``strain_predictor`` (strain increment,
  Jaumann rotation, open divergence, loose closure and elastic predictor: the stress update
  with every point kept elastic), ``stress_update`` (the same with the Mohr-Coulomb returns:
  the return costs the difference), ``faces`` (face fluxes, marker displacement, transport
  rule);
* per transport: ``transport`` (fields, redistribution, momentum, markers), ``markers``
  (marker advance alone);
* per sample: ``diagnostics`` (flow-mode measures and the wall-pressure profile) and
  ``output`` (one field snapshot to VTU).

The Python glue is what ``step`` costs beyond the phases and the transports (one in about 17
steps at 5 mm).  ``extra_info`` records the cells, the loaded cells and the number of threads.
Under the default ``--benchmark-disable`` the same code runs once on a 1 cm grid.
"""

import warnings

import numba
import numpy as np
import pytest

from fipy_hopper import diagnostics, io, markers, stepping
from fipy_hopper.config import HopperConfig
from fipy_hopper.material import return_fast
from fipy_hopper.model import GRAVITY, HopperModel
from fipy_hopper.simulation import Simulation

PHASES = ("step", "forces", "nodes", "strain_predictor", "stress_update", "faces", "transport",
          "markers", "diagnostics", "output")
_STATES = {}


def discharging(cell_size, disabled):
    """(model, state) 0.2 s into the discharge of the reference hopper (cached per size)."""
    key = (cell_size, disabled)
    if key not in _STATES:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            if disabled:
                cfg = HopperConfig.from_dict({
                    "hopper": {"bin_diameter": 0.2, "bin_height": 0.12, "fill_height": 0.08},
                    "numerics": {"cell_size": 0.01, "gravity_ramp_time": 0.02}})
            else:
                cfg = HopperConfig().replace(numerics={"cell_size": cell_size})
        model = HopperModel(cfg)
        sim = Simulation(model, progress=False, end_time=0.02 if disabled else 0.2)
        sim.run()
        _STATES[key] = (model, sim.state)
    return _STATES[key]


def material_call(model, state, prm=None, part="all"):
    """One material step of ``state`` split into the kernels of ``stepping.material_steps``;
    returns a function that runs ``part`` once (the other parts are not run), the number of
    loaded cells and a function that puts back every array the parts change (velocities,
    stresses, impulses, fluxes), so that each timed call starts from the same state."""
    g, num = model.grid, model.cfg.numerics
    carry_runs, load_runs, block_ptr, contrib, row_speed, row_budget = model._work
    wall, plate = state.wall_impulse.copy(), state.plate_impulse.copy()
    groups = model.contact_groups
    threads = numba.get_num_threads()
    mass = model.node_mass(state)
    n_carry, n_load, n_blocks, j0, j1 = stepping._runs(
        state.alpha, num.alpha_min, state.sigma, state.loose, state.v, contrib, carry_runs,
        load_runs, block_ptr, threads, mass, model.light_mass)     # as material_steps does
    prm = model._prm if prm is None else prm
    cst = return_fast._fast_constants(prm)
    sigma, loose, eps_p = state.sigma.copy(), state.loose.copy(), state.eps_p.copy()
    v, flux, disp = state.v.copy(), state.face_flux_sum.copy(), state.displacement.copy()
    trace = np.zeros_like(state.alpha)      # tr(D) as the strain pass leaves it for the forces
    flowing = state.flowing.copy()
    stepping._stress_update(block_ptr, n_blocks, load_runs, v, sigma.copy(), loose.copy(),
                            eps_p.copy(), flowing, model.r_c, model.flux_radius, model.strain_dims, g.h,
                            model.dt, g.kappa, model._zface_aperture, model._rface_aperture, prm,
                            cst, trace, threads)
    calls = {
        "forces": lambda: stepping._cell_forces(carry_runs, n_carry, state.alpha, sigma, v,
                                                model.open_volume, model.r_c, g.h,
                                                model.hourglass_base, contrib,
                                                model.viscosity, model.bulk_viscosity,
                                                model.cfg.numerics.alpha_min, trace, True,
                                                flowing, model._rate, threads),
        "nodes": lambda: stepping._node_update(j0, j1, v, mass, contrib, GRAVITY, model.dt,
                                               0.0, model.light_mass, groups[0], *groups[2:],
                                               False, -1.0, g.r_nodes, wall, plate,
                                               row_budget),
        "stress": lambda: stepping._stress_update(block_ptr, n_blocks, load_runs, v, sigma,
                                                  loose, eps_p, flowing, model.r_c, model.flux_radius,
                                                  model.strain_dims, g.h, model.dt, g.kappa,
                                                  model._zface_aperture,
                                                  model._rface_aperture, prm, cst,
                                                  trace, threads),
        "faces": lambda: stepping._faces(max(j0 - 1, 0), j1, v, model.dt, model._face_sign,
                                         model._open_face, flux, disp, True, row_speed),
    }
    changed = (v, sigma, loose, eps_p, flux, disp, wall, plate, trace)
    saved = [a.copy() for a in changed]

    def restore():
        for a, b in zip(changed, saved):
            a[...] = b
    return calls[part], int(np.sum(load_runs[:n_load, 2] - load_runs[:n_load, 1])), restore


@pytest.mark.parametrize("phase", PHASES)
@pytest.mark.parametrize("cell_size", [0.005, 0.0025])
def test_bench_discharge_step(benchmark, cell_size, phase, tmp_path):
    if benchmark.disabled and cell_size != 0.005:
        pytest.skip("one size when benchmarks are disabled")
    model, state = discharging(cell_size, benchmark.disabled)
    info = {"cells": model.grid.n_cells, "threads": numba.get_num_threads(),
            "dt_s": model.dt, "markers": 0 if state.markers is None else len(state.markers)}
    if phase == "step":
        steps = 20 if benchmark.disabled else 200

        def setup():
            return (state.copy(),), {}

        def run(st):
            done = 0
            while done < steps:
                done += model.advance(st, steps - done)
        benchmark.pedantic(run, setup=setup, rounds=1 if benchmark.disabled else 5)
        info["steps_per_round"] = steps
        st = state.copy()     # what was timed conserves mass: the domain's plus what left it
        run(st)               # (``discharged`` counts the outlet plane, inside the domain)
        before = model.total_mass(state) + state.lost
        assert abs(model.total_mass(st) + st.lost - before) < 1e-12 * before
    elif phase in ("forces", "nodes", "faces", "strain_predictor", "stress_update"):
        prm = model._prm.copy()
        part = "stress" if phase in ("strain_predictor", "stress_update") else phase
        if phase == "strain_predictor":
            prm[9] = 1e30          # a cohesion no stress reaches: every point stays elastic
        call, info["loaded_cells"], restore = material_call(model, state, prm=prm, part=part)
        benchmark.pedantic(call, setup=restore, rounds=1 if benchmark.disabled else 300)
    elif phase == "transport":
        def setup():
            st = state.copy()
            while True:                   # some flux to carry: steps that end without one
                trial = st.copy()
                if model.advance(trial, 5) == 5 and trial.flux_time > 0.0:
                    return (trial,), {}
                st = trial
        benchmark.pedantic(model.transport_step, setup=setup,
                           rounds=1 if benchmark.disabled else 50)
    elif phase == "markers":
        disp = np.full_like(state.v, 0.25 * model.grid.h)
        benchmark(markers.advance, state.markers, disp, model.grid, model.cfg.hopper)
    elif phase == "diagnostics":
        sampler = diagnostics.WallSampler(model)

        def measure():
            diagnostics.flow_mode_measures(model, state)
            sampler.profile_all(state)
        benchmark(measure)
    elif phase == "output":
        writer = io.FieldWriter(tmp_path / "fields", model.grid)
        benchmark.pedantic(writer.write, args=(state, 0.0), rounds=1 if benchmark.disabled else 5)
    benchmark.extra_info.update(info)
    assert np.all(np.isfinite(state.v)) and np.all(np.isfinite(state.sigma))
