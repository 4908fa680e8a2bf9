"""The Lagrangian mode: same physics, moving mesh; it stops by distortion, the Eulerian
run of the same hopper empties.

Coarse case (1 cm cells, a 0.2 m bin, 0.06 m outlet, 20 deg cone, 0.15 m fill, wall 15 deg):
one Lagrangian run (fill, discharge until an element passes its limits) and one Eulerian run
(fill, discharge until less than 9.5% of the mass is left), both through
``studies/lagrangian_vs_eulerian.py`` so that the study is exercised too.
"""

import importlib.util
import json
import math
import pathlib
import warnings

import numpy as np
import pytest

from fipy_hopper import geometry, momentum
from fipy_hopper.config import HopperConfig
from fipy_hopper.simulation import Simulation
from fipy_hopper.lagrangian import (DistortionLimits, LagrangianModel, _force_kernel,
                                    _quality_kernel, _strain_kernel, build_mesh,
                                    element_gradients, element_quality, hourglass_force,
                                    internal_force, strain_rate)

STUDY = pathlib.Path(__file__).resolve().parents[1] / "studies" / "lagrangian_vs_eulerian.py"
STOP_KINDS = ("inverted", "aspect_ratio", "min_angle")


def load_study():
    spec = importlib.util.spec_from_file_location("lagrangian_vs_eulerian_study", STUDY)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def coarse_config(**numerics):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return HopperConfig.from_dict({
            "hopper": {"bin_diameter": 0.2, "outlet_diameter": 0.06, "half_angle_deg": 20.0,
                       "bin_height": 0.17, "fill_height": 0.15},
            "wall": {"friction_angle_deg": 15.0},
            "numerics": {"cell_size": 0.01, "gravity_ramp_time": 0.1, **numerics},
            "run": {"end_time": "empty", "max_time": 6.0}})


@pytest.fixture(scope="module")
def study():
    return load_study()


@pytest.fixture(scope="module")
def both(study):
    """The coarse case run both ways (the study's setup); the Eulerian run stops when less than
    9.5% of the mass is left, i.e. past 90% discharged."""
    return study.setup(config=coarse_config(), empty_fraction=0.095)


# ------------------------------------------------------------------------ the headline claim
def test_lagrangian_run_stops_by_distortion_before_30_percent(both):
    lag_model, rec, state = both["lagrangian"]
    assert rec.fill_at_rest
    assert rec.stop_kind in STOP_KINDS, rec.stop_reason
    assert rec.stop_kind in rec.stop_reason and "element" in rec.stop_reason
    assert 0.0 < rec.stop_time and rec.stop_step == state.step
    assert 0.0 < rec.discharged_fraction < 0.30
    assert rec.discharged_fraction == pytest.approx(
        lag_model.discharged_mass(state) / rec.initial_mass, rel=1e-12)
    # the state kept is the last valid step: every active element within the limits
    assert lag_model.check_distortion(state) is None
    q = lag_model.quality(state)[state.active]
    assert q[:, 0].min() > 0 and q[:, 1].max() <= 10.0 and q[:, 2].min() >= 10.0


def test_eulerian_run_of_the_same_case_continues_past_90_percent(both):
    eul = both["results"]["eulerian"]
    lag = both["results"]["lagrangian"]
    assert eul["stop_reason"] == "empty"
    assert eul["discharged_fraction"] > 0.90
    assert eul["mass_balance_error"] < 1e-6
    assert eul["discharge_time_s"] > 10 * lag["stop_time_s"]
    # same filled hopper: the initial masses agree (Lagrangian mesh vs cut cells)
    assert lag["initial_mass_kg"] == pytest.approx(eul["initial_mass_kg"], rel=0.01)


def test_discharge_rates_agree_before_the_lagrangian_run_stops(both):
    agree = both["results"]["agreement"]
    # mean rate over [t_stop / 2, t_stop] (past the start) and since opening
    assert abs(agree["rate_ratio_second_half"] - 1.0) < 0.15, agree
    assert abs(agree["rate_ratio_since_opening"] - 1.0) < 0.15, agree


def test_lagrangian_mode_conserves_mass_exactly(both):
    lag_model, rec, state = both["lagrangian"]
    fresh = LagrangianModel(lag_model.cfg)
    assert np.array_equal(lag_model.node_mass, fresh.node_mass)      # never changed
    total = 2 * math.pi * lag_model.node_mass.sum()
    assert rec.total_mass == total
    for m_in, m_out in zip(rec.mass_in_hopper, rec.discharged):
        assert abs(m_in + m_out - total) <= 1e-12 * total
    assert rec.discharged[-1] > 0
    # the mesh volume is the filled volume (one-point r-weighted quadrature of the trapezoids)
    _, _, A, r_c = element_gradients(fresh.mesh.x, fresh.mesh.conn)
    assert 2 * math.pi * np.sum(A * r_c) == pytest.approx(lag_model.cfg.hopper.fill_volume(),
                                                          rel=2e-3)


def test_filled_wall_pressure_matches_the_eulerian_fill(both, study):
    agree = both["results"]["agreement"]
    cfg = both["cfg"]
    s = np.asarray(agree["wall_s_m"])
    compared = np.asarray(agree["wall_compared"], bool)
    s_t = geometry.transition_arc_length(cfg.hopper)
    assert np.sum(compared & (s < s_t)) >= 3 and np.sum(compared & (s > s_t)) >= 2
    assert agree["wall_max_rel_difference"] < 0.10, agree


def test_study_writes_its_outputs(both, study, tmp_path):
    out = tmp_path / "lve"
    out.mkdir()
    study.write_tables(both, out)
    study.plot_mesh_vs_layers(both, out / "mesh_vs_layers.png")
    study.plot_rates(both, out / "discharge_rate.png")
    study.plot_wall_pressure(both, out / "wall_pressure_fill.png")
    study.write_study_json(both, out, argv=["--out", str(out)])
    for name in study.OUTPUTS:
        assert (out / name).stat().st_size > 0, name
    assert (out / "mesh_vs_layers.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    res = json.loads((out / "results.json").read_text())
    assert res["lagrangian"]["stop_kind"] in STOP_KINDS
    assert (out / "rates.csv").read_text().startswith("t_s,")
    report = json.loads((out / "study.json").read_text())   # what studies/make_report.py reads
    assert report["study"] == study.NAME and report["setting"] == "custom"
    assert len(report["findings"]) >= 4 and report["headline"]
    assert all((out / f["file"]).is_file() for f in report["figures"])
    with pytest.raises(SystemExit):  # refuses a non-empty output directory before running
        study.main(["--out", str(out)])
    with pytest.raises(TypeError):
        study.setup(cell=0.01)


# ------------------------------------------------------------------------ the element
def test_mesh_conforms_to_the_wall_and_starts_well_shaped():
    cfg = coarse_config()
    mesh = build_mesh(cfg.boundary, cfg.numerics.cell_size)
    x = mesh.x.reshape(mesh.n_rows + 1, mesh.n_cols + 1, 2)
    d_wall = geometry.signed_distance(x[:, -1, 0], x[:, -1, 1], cfg.hopper)
    assert np.allclose(d_wall, 0.0, atol=1e-12)
    assert np.all(x[:, 0, 0] == 0.0)
    assert np.any(np.isclose(mesh.z_rows, cfg.hopper.cone_height, atol=1e-12))
    assert mesh.z_rows[0] == 0.0 and mesh.z_rows[-1] == pytest.approx(cfg.hopper.fill_level)
    jac, aspect, angle, length = element_quality(mesh.x, mesh.conn)
    assert jac.min() > 0 and aspect.max() < 1.5 and angle.min() > 60.0
    # flat-bottomed bin: a node column at the outlet radius
    flat = coarse_config().replace(hopper={"half_angle_deg": 90.0})
    fm = build_mesh(flat.boundary, 0.01)
    assert np.any(np.isclose(fm.x[:, 0], flat.hopper.outlet_radius))
    assert element_quality(fm.x, fm.conn)[0].min() > 0


def test_on_rectangles_the_element_is_the_eulerian_q1_kernel():
    h, nz, nr = 0.01, 5, 7
    rng = np.random.default_rng(1)
    r_nodes, z_nodes = h * np.arange(nr + 1), 0.3 + h * np.arange(nz + 1)
    R, Z = np.meshgrid(r_nodes, z_nodes)
    x = np.stack([R.ravel(), Z.ravel()], axis=1)
    j, i = np.meshgrid(np.arange(nz), np.arange(nr), indexing="ij")
    sw = (j * (nr + 1) + i).ravel()
    conn = np.stack([sw, sw + 1, sw + nr + 2, sw + nr + 1], axis=1)
    sigma = rng.normal(size=(nz * nr, 4)) * 1e3
    v = rng.normal(size=(len(x), 2))
    r_c = 0.5 * (r_nodes[1:] + r_nodes[:-1])
    volume = r_c[None, :] * h * h * np.ones((nz, 1))
    f_eul = momentum.internal_force(sigma.reshape(nz, nr, 4), volume, r_c, h)
    f_lag = internal_force(x, conn, sigma)
    assert np.allclose(f_lag[:, 0], f_eul[0].ravel(), rtol=1e-12, atol=1e-12)
    assert np.allclose(f_lag[:, 1], f_eul[1].ravel(), rtol=1e-12, atol=1e-12)
    v_grid = np.stack([v[:, 0].reshape(nz + 1, nr + 1), v[:, 1].reshape(nz + 1, nr + 1)])
    D_eul, w_eul = momentum.strain_rate(v_grid, r_c, h)
    D_lag, w_lag = strain_rate(x, conn, v)
    assert np.allclose(D_lag, D_eul.reshape(-1, 4), rtol=1e-12, atol=1e-9)
    assert np.allclose(w_lag, w_eul.ravel(), rtol=1e-12, atol=1e-9)
    # compiled force = -f_int + f_hg with the Eulerian hourglass coefficient kappa rho sqrt(g h) w/h
    scale = 0.1 * 1500.0 * math.sqrt(9.81)
    force = np.zeros_like(x)
    _force_kernel(x, v, conn, sigma, np.ones(len(conn), bool), scale, force)
    coef = 0.1 * 1500.0 * math.sqrt(9.81 * h) * volume / h
    f_hg = momentum.hourglass_force(v_grid, coef)
    expected = -f_eul + f_hg
    assert np.allclose(force[:, 0], expected[0].ravel(), rtol=1e-10, atol=1e-10)
    assert np.allclose(force[:, 1], expected[1].ravel(), rtol=1e-10, atol=1e-10)


def distorted_mesh(seed=2):
    cfg = coarse_config()
    mesh = build_mesh(cfg.boundary, 0.01)
    rng = np.random.default_rng(seed)
    x = mesh.x.copy()
    inner = x[:, 0] > 0
    x[inner] += rng.uniform(-1.5e-3, 1.5e-3, size=(inner.sum(), 2))
    return mesh, x, rng


def test_compiled_kernels_equal_the_numpy_reference_on_distorted_quads():
    mesh, x, rng = distorted_mesh()
    conn = mesh.conn
    ne = len(conn)
    active = np.ones(ne, bool)
    sigma = rng.normal(size=(ne, 4)) * 1e3
    v = rng.normal(size=(len(x), 2))
    force = np.zeros_like(x)
    _force_kernel(x, np.zeros_like(v), conn, sigma, active, 0.0, force)
    assert np.allclose(force, -internal_force(x, conn, sigma), rtol=1e-11, atol=1e-12)
    _force_kernel(x, v, conn, sigma, active, 1e3, force)
    expected = -internal_force(x, conn, sigma) + hourglass_force(x, conn, v, 1e3)
    assert np.allclose(force, expected, rtol=1e-10, atol=1e-10)
    dt = 1e-5
    d_eps, s_rot = np.zeros((ne, 4)), np.zeros((ne, 4))
    _strain_kernel(x, v, dt, conn, sigma, active, d_eps, s_rot)
    D, omega = strain_rate(x, conn, v)
    assert np.allclose(d_eps, D * dt, rtol=1e-11, atol=1e-15)
    assert np.allclose(s_rot, momentum.jaumann_rotate(sigma, omega, dt), rtol=1e-12)
    q = np.zeros((ne, 4))
    _quality_kernel(x, conn, active, q)
    assert np.allclose(q, np.stack(element_quality(x, conn), axis=1), rtol=1e-12)


def test_hourglass_force_vanishes_for_linear_velocity_on_any_quad():
    mesh, x, rng = distorted_mesh(3)
    conn = mesh.conn
    a, B = rng.normal(size=2), rng.normal(size=(2, 2))
    v = a[None, :] + x @ B.T
    force = np.zeros_like(x)
    _force_kernel(x, v, conn, np.zeros((len(conn), 4)), np.ones(len(conn), bool), 1e3, force)
    assert np.abs(force).max() < 1e-9
    # ...but resists the checkerboard mode
    chk = np.where((np.arange(len(x)) // (mesh.n_cols + 1) + np.arange(len(x)) %
                    (mesh.n_cols + 1)) % 2 == 0, 1.0, -1.0)
    v = np.stack([chk, chk], axis=1)
    _force_kernel(x, v, conn, np.zeros((len(conn), 4)), np.ones(len(conn), bool), 1e3, force)
    assert np.sum(force * v) < 0


def test_distortion_check_names_the_limit_and_the_element():
    cfg = coarse_config()
    model = LagrangianModel(cfg, limits=DistortionLimits(max_aspect=10.0, min_angle_deg=10.0))
    st = model.initial_state()
    assert model.check_distortion(st) is None
    e = 57
    n_sw, n_se, n_ne, n_nw = model.mesh.conn[e]
    bad = st.copy()
    bad.x[n_ne] = bad.x[n_sw] + 0.1 * (bad.x[n_ne] - bad.x[n_sw])   # reflex corner: inverted
    kind, elem, text = model.check_distortion(bad)
    assert kind == "inverted" and elem in (e, e + 1, e + model.mesh.n_cols,
                                           e + model.mesh.n_cols + 1) and "Jacobian" in text
    tall = st.copy()
    top = model.mesh.conn[:, 2:]
    tall.x[np.unique(top[-model.mesh.n_cols:])] += np.array([0.0, 0.5])  # stretch the top row
    kind, elem, text = model.check_distortion(tall)
    assert kind == "aspect_ratio" and elem >= model.mesh.n_elements - model.mesh.n_cols
    assert "> 10" in text


def test_without_shape_limits_an_element_inverts_soon_after():
    """The stop is not an artefact of the 10 / 10 deg limits: with none, an element inverts
    (non-positive Jacobian) before 30% of the mass has left."""
    model = LagrangianModel(coarse_config(), limits=DistortionLimits(max_aspect=math.inf,
                                                                     min_angle_deg=0.0))
    sim = Simulation(model, progress=False)
    sim.run()
    state = sim.state
    assert sim.record.stop_reason == "mesh_distorted"
    assert state.halt_kind == "inverted", state.halt_detail
    assert state.discharged / sim.record.initial_mass < 0.30
    assert model.check_distortion(state) is None


def test_frictionless_flat_bin_fills_hydrostatic():
    H, RHO, G = 0.2, 1500.0, 9.81
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cfg = HopperConfig.from_dict({
            "hopper": {"bin_diameter": 0.2, "outlet_diameter": 0.06, "half_angle_deg": 90.0,
                       "bin_height": H + 0.02, "fill_height": H},
            "wall": {"friction_angle_deg": 0.0}, "numerics": {"cell_size": 0.01}})
    model = LagrangianModel(cfg)
    sim = Simulation(model, progress=False)
    assert sim.fill()
    state = sim.state
    conn = model.mesh.conn
    z0 = model.mesh.x[conn, 1].mean(axis=1)       # the weight above is rho g (H - z0)
    _, _, A, r_c = element_gradients(state.x, conn)
    w = A * r_c
    rows = z0.reshape(model.mesh.n_rows, model.mesh.n_cols)[:, 0]
    mean = lambda k: (state.sigma[:, k] * w).reshape(model.mesh.n_rows, -1).sum(1) / \
        w.reshape(model.mesh.n_rows, -1).sum(1)  # noqa: E731
    deep = rows < H - 0.03
    assert np.allclose(mean(1)[deep] / (-RHO * G * (H - rows[deep])), 1.0, atol=0.02)
    assert np.allclose(mean(0)[deep] / mean(1)[deep], 0.3 / 0.7, rtol=0.02)
    assert np.abs(state.x[:, 1] - model.mesh.x[:, 1]).max() < 1e-3   # elastic settlement only


def test_contact_and_projection_kernels_equal_the_numpy_reference():
    from fipy_hopper.lagrangian import (_contact_kernel, _project_kernel, contact_reference,
                                        project_reference)
    for angle in (20.0, 90.0):
        cfg = coarse_config().replace(hopper={"half_angle_deg": angle})
        model = LagrangianModel(cfg)
        rng = np.random.default_rng(4)
        x = model.mesh.x + rng.uniform(-2e-3, 2e-3, model.mesh.x.shape)   # some inside the wall
        x[:, 0] = np.abs(x[:, 0])
        v = rng.normal(size=x.shape)
        dt = 2e-3
        for segments, plate in ((model.wall_segments, -1),
                                (model.segments_closed, len(model.segments_closed) - 1)):
            v_k, dv_k = v.copy(), np.zeros_like(v)
            _contact_kernel(x, v_k, dt, segments, len(segments), 2, plate, dv_k)
            v_ref, dv_ref = contact_reference(x, v, dt, segments, passes=2, plate_segment=plate)
            assert np.allclose(v_k, v_ref, rtol=1e-12, atol=1e-14)
            assert np.allclose(dv_k, dv_ref, rtol=1e-12, atol=1e-14)
            assert not np.array_equal(v_k, v)                       # contact acted
            assert (plate < 0) == (not np.any(dv_k))                # the plate's share apart
        for closed in (True, False):
            x_k = x.copy()
            a, b, rows = cfg.boundary.kernel_arrays()[:3]
            moved = _project_kernel(x_k, a, b, rows, cfg.hopper.outlet_radius, closed)
            assert moved > 0
            assert np.allclose(x_k, project_reference(x, cfg.boundary, closed), atol=1e-14)
            d = geometry.signed_distance(x_k[:, 0], x_k[:, 1], cfg.hopper)
            assert d.min() > -1e-12


# ------------------------------------------------------------------------ one loop, one API
def test_the_lagrangian_mode_runs_through_the_api_and_the_same_simulation(tmp_path):
    """``numerics.formulation = "lagrangian"`` runs through :func:`fipy_hopper.run` and the
    same :class:`Simulation` as the Eulerian model: its fill comes to rest by the same rule,
    the wall's and the plate's reactions carry the weight (0.5 %, the bar of the Eulerian
    fill), the vertical momentum balance closes to round-off in every row of loads.csv (every
    impulse is counted: gravity, damping, wall, plate), the wall friction is within Coulomb's
    limit in every bin, and the discharge stops by the ``halt`` rule when the mesh distorts."""
    from fipy_hopper import api

    cfg = coarse_config(formulation="lagrangian")
    seen = []
    summary = api.run(cfg, tmp_path / "run", setup=lambda sim: seen.append(sim))
    sim = seen[0]
    assert type(sim) is Simulation and isinstance(sim.model, LagrangianModel)
    assert summary["formulation"] == "lagrangian" and summary["fill_at_rest"]
    assert summary["stop_reason"] == "mesh_distorted"
    assert summary["distortion_kind"] in STOP_KINDS and "element" in summary["distortion"]
    assert summary["fill_equilibrium_residual"] < 0.005
    assert summary["load_balance_residual_max"] < 1e-9
    assert summary["mass_balance_error"] < 1e-12
    assert 0.0 < summary["discharged_kg"] < 0.3 * summary["initial_mass_kg"]
    res = api.read_results(tmp_path / "run")
    fill = res.wall_stage("filling")
    mu = math.tan(math.radians(cfg.wall.friction_angle_deg))
    loaded = fill["p_n_Pa"] > 0
    assert loaded.sum() >= 8
    assert np.all(np.abs(fill["tau_Pa"][loaded]) <= mu * fill["p_n_Pa"][loaded] * (1 + 1e-9))
    assert (tmp_path / "run" / "lagrangian_mesh.png").stat().st_size > 0
    assert len(res.snapshots) >= 2 and res.field(-1).cells_dict["quad"].shape[0] == \
        sim.model.mesh.n_elements


def test_a_lagrangian_wedge_is_refused_naming_the_key():
    from fipy_hopper.config import ConfigError

    with pytest.raises(ConfigError, match="numerics.formulation"):
        HopperConfig.from_dict({"hopper": {"shape": "wedge", "bin_width": 0.2,
                                           "outlet_width": 0.06},
                                "numerics": {"cell_size": 0.01, "formulation": "lagrangian"}})
    with pytest.raises(ConfigError, match="numerics.formulation"):
        coarse_config(formulation="lagrange")


def test_validate_describes_the_lagrangian_mesh(tmp_path, capsys):
    """``fipy-hopper validate`` of a Lagrangian configuration prints its mesh (not the grid)
    and the model's own first time step."""
    from fipy_hopper.cli import main

    cfg = coarse_config(formulation="lagrangian")
    path = tmp_path / "lagrangian.toml"
    path.write_text(cfg.to_toml())
    assert main(["validate", str(path)]) == 0
    out = capsys.readouterr().out
    model = LagrangianModel(cfg)
    assert f"{model.mesh.n_elements} elements in {model.mesh.n_cols} columns" in out
    assert f"time step          {model.dt0:.4g} s at the start" in out
    assert "cells of" not in out


def test_a_lagrangian_run_is_not_resumed(tmp_path):
    """A Lagrangian run writes no checkpoint (it lasts seconds), so ``resume`` is refused with
    a one-line reason before anything is written."""
    from fipy_hopper import api
    from fipy_hopper.config import ConfigError

    with pytest.raises(ConfigError, match="not checkpointed"):
        api.run(coarse_config(formulation="lagrangian"), tmp_path / "run", resume=True)
    assert not (tmp_path / "run").exists()
