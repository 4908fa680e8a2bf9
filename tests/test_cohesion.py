"""Cohesive powders on a coarse grid: a cohesion well above Jenike's critical value arches over
the outlet (``no_flow``), one well below it discharges, the tension and separation states that
cohesion brings stay bounded, and ``c = 0`` is the cohesionless model itself (no special case).

The hopper: a 0.2 m bin on a 20 deg cone with a 0.06 m outlet, filled 0.15 m above the
transition, phi = 30 deg, phi_w = 15 deg, 1 cm cells (3 across the outlet radius).  The
cohesions are multiples of the critical one by Jenike's rule,
``c_crit = D0 rho g (1 - sin phi) / (2 H(theta) cos phi)`` (``D0 = H(theta) sigma_c / (rho g)``,
``sigma_c = 2 c cos phi / (1 - sin phi)``): 109.2 Pa here.  Measured with this hopper (1 s of
discharge): 0.3, 1, 1.6 x c_crit flow at nearly the cohesionless rate, 1.8 x holds 0.3 s and
then flows, 1.9, 2 and 5 x hold (the outlet opens, about 2 g falls, nothing more; also at
5 mm and for E = 2 and 20 MPa): the simulated critical cohesion is 1.8-1.9 x Jenike's, whose
rule is known to be conservative.  The whole file runs in about 8 s (kernels compiled).
"""

import math
import warnings

import numpy as np
import pytest

from fipy_hopper import diagnostics, theory
from fipy_hopper.cli import main
from fipy_hopper.config import HopperConfig
from fipy_hopper.model import HopperModel
from fipy_hopper.simulation import Simulation

D0, THETA, PHI, RHO = 0.06, 20.0, 30.0, 1500.0


def critical_cohesion() -> float:
    """The cohesion whose unconfined yield strength makes Jenike's critical outlet ``D0``."""
    sigma_c = D0 * RHO * theory.G / float(theory.jenike_arching_H(THETA))
    return sigma_c * (1.0 - math.sin(math.radians(PHI))) / (2.0 * math.cos(math.radians(PHI)))


def config(cohesion: float, **run) -> HopperConfig:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")         # 3 cells across the outlet radius
        return HopperConfig.from_dict({
            "hopper": {"bin_diameter": 0.2, "outlet_diameter": D0, "half_angle_deg": THETA,
                       "bin_height": 0.25, "fill_height": 0.15},
            "material": {"density": RHO, "friction_angle_deg": PHI, "cohesion": cohesion},
            "wall": {"friction_angle_deg": 15.0},
            "numerics": {"cell_size": 0.01},
            "run": {"output_interval": 0.05, "markers_per_side": 0, **run}})


class Watch:
    """Every check of the run (filling and discharge): the extremes of alpha, and whether
    every field is finite."""

    def __init__(self):
        self.alpha_min, self.alpha_max, self.finite, self.checks = np.inf, -np.inf, True, 0

    def __call__(self, sim, state):
        self.checks += 1
        self.alpha_min = min(self.alpha_min, float(state.alpha.min()))
        self.alpha_max = max(self.alpha_max, float(state.alpha.max()))
        self.finite &= bool(all(np.isfinite(a).all() for a in (
            state.alpha, state.sigma, state.v, state.loose, state.eps_p)))


def run(cohesion: float, **run_section):
    sim = Simulation(HopperModel(config(cohesion, **run_section), threads=1), progress=False)
    watch = Watch()
    sim.add_callback(watch, 0.0)
    sim.run()
    return sim, sim.summary(), watch


@pytest.fixture(scope="module")
def arching():
    """2 x Jenike's critical cohesion, run until empty: the run stops by itself."""
    return run(2.0 * critical_cohesion(), end_time="empty", max_time=5.0)


@pytest.fixture(scope="module")
def flowing():
    """0.3 x Jenike's critical cohesion, 1 s of discharge."""
    return run(0.3 * critical_cohesion(), end_time=1.0)


def test_twice_the_critical_cohesion_arches(arching):
    """The outlet opens and the flow stops at once with more than 90 % of the mass left (a
    no-flow call's bar; measured: 99.98 %, 2 g fell out of 11.26 kg); the at-rest rule ends the run
    after its 0.5 s wait plus one 0.25 s window at most, well before ``max_time``."""
    sim, s, _ = arching
    assert s["flow_mode"] == "no_flow"
    assert s["stop_reason"] == "at_rest"
    assert s["remaining_mass_fraction"] > 0.9
    assert s["remaining_mass_kg"] == pytest.approx(s["remaining_mass_fraction"]
                                                   * s["initial_mass_kg"], rel=1e-12)
    assert 0.0 <= s["flow_stopped_time_s"] <= 0.25
    assert s["discharge_time_s"] < 0.5 + 0.25 + 0.01
    assert math.isnan(s["rathole_diameter_m"])
    # the arch stands over the outlet: the cells just above the outlet plane are full
    g, st = sim.model.grid, sim.state
    j = int(np.searchsorted(g.z_cells, 0.0))
    over_outlet = g.r_cells < 0.5 * D0
    assert np.all(st.alpha[j + 1, over_outlet] > 0.99)


def test_five_times_the_critical_cohesion_arches_from_the_opening():
    """At 5 x nothing falls: no sample ever reaches the at-rest rate, so the flow stopped at
    0 s; the sample taken when the run stops (a few steps long, over which the arch's elastic
    sway moves more than the rule's rate) does not count."""
    sim, s, watch = run(5.0 * critical_cohesion(), end_time="empty", max_time=5.0)
    assert s["flow_mode"] == "no_flow" and s["stop_reason"] == "at_rest"
    assert s["flow_stopped_time_s"] == 0.0 and s["remaining_mass_fraction"] > 0.99
    assert s["mass_balance_error"] < 1e-9 and watch.finite
    assert watch.alpha_min >= -1e-12 and watch.alpha_max <= 1.0 + 1e-3


def test_a_third_of_the_critical_cohesion_discharges(flowing):
    """More than 20 % of the mass leaves in the first second (measured: 27 %, the
    cohesionless hopper 27 % too) and the flow has not stopped."""
    sim, s, _ = flowing
    assert s["flow_mode"] in ("mass", "funnel")
    assert s["remaining_mass_fraction"] < 0.8
    assert math.isnan(s["flow_stopped_time_s"])
    assert s["stop_reason"] == "end_time"


@pytest.mark.parametrize("case", ["arching", "flowing"])
def test_cohesive_runs_stay_bounded(case, request):
    """Mass balance to 1e-9 of the initial mass (the outlet books the transport's own face
    values: round-off, measured 3e-16); every field finite at every check; alpha in
    [0, 1 + 1e-3], the bound of the tension and separation states, less
    round-off traces below 0 (-1e-12, as in tests/test_compaction.py: redistribution leaves
    traces of a few 1e-17, measured -5.7e-17, which carry no stress)."""
    sim, s, watch = request.getfixturevalue(case)
    assert s["mass_balance_error"] < 1e-9
    assert watch.checks > 100 and watch.finite
    assert watch.alpha_min >= -1e-12 and watch.alpha_max <= 1.0 + 1e-3


def test_zero_cohesion_is_not_a_special_case():
    """The smallest positive cohesion (5e-324 Pa, so every ``c > 0`` branch would be taken)
    gives exactly the summary of ``c = 0`` and the same state to the bit, but for the stress
    of cells at the apex of the yield surface: ``c cot(phi)``, 1e-323 Pa instead of 0.  And the
    cohesionless run gets the new summary entries without an outcome of its own."""
    runs = [run(c, end_time=0.5) for c in (0.0, 5e-324)]
    (sim0, s0, _), (sim1, s1, _) = runs
    s0.pop("wall_time_s"), s1.pop("wall_time_s")
    assert s0.keys() == s1.keys()
    for key in s0:
        same = s0[key] == s1[key] or (s0[key] != s0[key] and s1[key] != s1[key])
        assert same, key
    for name in ("v", "alpha", "loose", "eps_p", "layer"):
        assert np.array_equal(getattr(sim0.state, name), getattr(sim1.state, name)), name
    assert np.max(np.abs(sim0.state.sigma - sim1.state.sigma)) <= 1e-323
    assert s0["flow_mode"] in ("mass", "funnel")
    assert math.isnan(s0["flow_stopped_time_s"]) and math.isnan(s0["rathole_diameter_m"])


def rathole_config(cohesion: float) -> HopperConfig:
    """A funnel-flow hopper with a wide outlet: a 0.24 m bin on a 60 deg cone, phi_w = 25 deg,
    D0 = 0.08 m, filled 0.15 m above the transition, 1 cm cells (4 across the outlet radius)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return config(cohesion, end_time="empty", max_time=4.0, output_interval=0.02).replace(
            hopper={"bin_diameter": 0.24, "outlet_diameter": 0.08, "half_angle_deg": 60.0,
                    "bin_height": 0.17},
            wall={"friction_angle_deg": 25.0})


def test_a_cohesive_funnel_flow_hopper_leaves_a_rathole():
    """sigma_c / (rho g) = 55 mm (c = 233.6 Pa): Jenike's rathole diameter G(phi) sigma_c /
    (rho g) = 130 mm is larger than the outlet, and his critical outlet for arching (165 mm)
    too, but the simulated critical outlet is about half of his (``studies/arching.py``): the
    outlet flows, the flow channel empties and stops with the rest standing around it.
    Measured: the flow stopped at 3.10 s with 29.1 % of the mass left, around an empty
    channel 76 mm wide and 90 mm high (from the outlet plane to the top of the material):
    narrower than Jenike's rathole diameter, as his theory requires of a stable rathole.  The
    bounds: a tenth to a half of the mass left (the rule's rathole bound, and below an arch's),
    the channel at most Jenike's diameter.  Without cohesion the same hopper discharges to a
    heel on the cone (3.4 % left at 4 s, still flowing)."""
    head = 0.055
    sigma_c = head * RHO * theory.G
    cohesion = sigma_c * (1.0 - math.sin(math.radians(PHI))) / (2.0 * math.cos(math.radians(PHI)))
    d_f = float(theory.jenike_rathole_diameter(sigma_c, RHO, PHI))
    sim = Simulation(HopperModel(rathole_config(cohesion), threads=1), progress=False)
    sim.run()
    s = sim.summary()
    assert s["flow_mode"] == "rathole" and s["stop_reason"] == "at_rest"
    assert 0.1 <= s["remaining_mass_fraction"] <= 0.5
    assert np.isfinite(s["flow_stopped_time_s"])
    assert 0.0 < s["rathole_diameter_m"] <= d_f
    assert s["mass_balance_error"] < 1e-9
    sim0 = Simulation(HopperModel(rathole_config(0.0), threads=1), progress=False)
    sim0.run()
    s0 = sim0.summary()
    assert s0["flow_mode"] == "funnel" and s0["remaining_mass_fraction"] < 0.1
    assert math.isnan(s0["rathole_diameter_m"])


class _Grid:
    def __init__(self, h, nr, nz, z0):
        self.r_cells = (np.arange(nr) + 0.5) * h
        self.z_nodes = z0 + np.arange(nz + 1) * h
        self.z_cells = 0.5 * (self.z_nodes[1:] + self.z_nodes[:-1])
        self.kappa = np.ones((nz, nr))            # every cell open: no wall, no insert


class _Model:
    def __init__(self, grid):
        self.grid = grid


class _State:
    def __init__(self, alpha):
        self.alpha = alpha


def test_outcome_rule_on_constructed_states():
    """The stated rule on hand-made fields (1 cm cells, outlet plane at z = 0, 3 rows of free
    fall below it): an empty channel through 20 rows of material, whose wall is the centre of
    the half-full third cell (alpha = 1/2 there), is 0.05 m wide and 0.2 m high: a rathole
    when the flow has stopped with at least a tenth of the mass around it, else the flow's
    own call; an arch over a one-row hollow is no_flow; a channel wider than high (a low
    ring) is not a rathole."""
    g = _Grid(0.01, 10, 23, -0.03)
    model = _Model(g)
    alpha = np.zeros((23, 10))
    alpha[3:, :] = 1.0
    alpha[3:, :2] = 0.0                       # empty out to r = 2 cells
    alpha[3:, 2] = 0.5                        # the third cell half full: the edge at its centre
    d, h = diagnostics.empty_channel(model, _State(alpha))
    assert d == pytest.approx(0.05) and h == pytest.approx(0.2)
    rule = diagnostics.OutcomeRule()
    assert diagnostics.classify_outcome("funnel", True, 0.85, d, h, rule) == "rathole"
    assert diagnostics.classify_outcome("funnel", False, 0.85, d, h, rule) == "funnel"
    assert diagnostics.classify_outcome("funnel", True, 0.3, d, h, rule) == "rathole"
    assert diagnostics.classify_outcome("funnel", True, 0.05, d, h, rule) == "funnel"
    arch = np.zeros((23, 10))
    arch[4:, :] = 1.0                          # the fallen first row leaves a hollow below
    d, h = diagnostics.empty_channel(model, _State(arch))
    assert math.isnan(d)
    assert diagnostics.classify_outcome("mass", True, 0.99, d, h, rule) == "no_flow"
    crater = np.zeros((23, 10))
    crater[3:5, 4:] = 1.0                      # a low ring: a channel wider than high
    d, h = diagnostics.empty_channel(model, _State(crater))
    assert d == pytest.approx(0.08) and h == pytest.approx(0.02)
    assert diagnostics.classify_outcome("mass", True, 0.6, d, h, rule) == "no_flow"
    assert diagnostics.classify_outcome("mass", True, 0.3, d, h, rule) == "mass"


def test_validate_prints_jenike_design_numbers(tmp_path, capsys):
    """``fipy-hopper validate`` of a cohesive configuration prints sigma_c, Jenike's critical
    outlet and the simplified one, and the critical rathole diameter (the theory functions'
    values, to the 4 digits printed); a negative cohesion is a one-line error (exit 2)."""
    c = 2.0 * critical_cohesion()
    path = tmp_path / "cohesive.toml"
    path.write_text(config(c).to_toml())
    assert main(["validate", str(path)]) == 0
    out = capsys.readouterr().out
    sigma_c = float(theory.unconfined_yield_strength(c, PHI))
    assert f"sigma_c = {sigma_c:.4g} Pa" in out
    assert f"= {float(theory.jenike_critical_outlet(sigma_c, RHO, THETA)):.4g} m" in out
    assert f"= {float(theory.critical_outlet_simplified(sigma_c, RHO)):.4g} m" in out
    assert f"= {float(theory.jenike_rathole_diameter(sigma_c, RHO, PHI)):.4g} m" in out
    assert "it may arch" in out
    bad = tmp_path / "negative.toml"
    bad.write_text("[material]\ncohesion = -5.0\n")
    assert main(["validate", str(bad)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "material.cohesion" in err[0]
