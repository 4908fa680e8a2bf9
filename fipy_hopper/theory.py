"""Closed-form theory that simulations of silo and hopper discharge are compared with.

Every function here is pure and vectorised: array arguments broadcast against each other
with numpy's rules, and a call with scalar arguments returns a numpy scalar.  Units are SI
(kg, m, s, Pa, kg/s).  **All angles at this public interface are in degrees.**  Friction
*coefficients* (``mu``, ``mu_h``) are plain numbers (tan of a friction angle), not angles.

Hopper half-angles (``theta`` in the flow-rate literature, ``beta`` in EN 1991-4) are measured
from the vertical.  Pressures are positive in compression.

What is verified
----------------
Each docstring carries a tag; ``docs/correlations.md`` lists every formula with its tag, source
and a worked value:

* **[V]** checked against the source that is named (``[V: X]`` names where it was read
  when that is a transcription or a quotation rather than the original);
* **[D]** re-derived (slice equilibrium, a Mohr circle, dimensional analysis, or a
  numerical check);
* **[M]** quoted from memory and not verified against a source; treat as provisional.

Contents
--------
Discharge rate
    :func:`beverloo_rate`, :func:`rose_tanaka_factor`, :func:`johanson_rate`,
    :func:`brown_coefficient`, :func:`brown_rate`; plane flow (slots):
    :func:`beverloo_slot_rate` (and :func:`johanson_rate` with ``m = 0``).
Flow mode
    :func:`jenike_critical_half_angle`, :func:`jenike_critical_half_angle_plane`,
    :func:`jenike_flow_mode`.
Vertical-walled section (Janssen)
    :func:`janssen_z0`, :func:`janssen_vertical_stress`, :func:`janssen_wall_pressure`,
    :func:`janssen_wall_shear`, :func:`janssen_asymptotic_wall_pressure`,
    :func:`janssen_wall_axial_force`; long rectangular (plane) bins: :func:`janssen_plane_z0`,
    :func:`janssen_plane_vertical_stress`, :func:`janssen_plane_wall_pressure`,
    :func:`janssen_plane_asymptotic_wall_pressure`, :func:`janssen_plane_wall_axial_force`.
Lateral pressure ratios
    :func:`k_jaky`, :func:`k_en1991`, :func:`k_rankine_active`, :func:`k_walker_wall`.
Hopper slice method (Walker 1966 / Walters 1973 with distribution factor D = 1)
    :func:`hopper_n`, :func:`hopper_vertical_stress`, :func:`walker_discharge_ratio`,
    :func:`walker_hopper_wall_pressure`, :func:`walker_switch_pressure`; ``S = 1`` gives the
    plane-flow (wedge) slice.
Cohesive powders: arching and ratholing (Jenike's method)
    :func:`unconfined_yield_strength`, :func:`jenike_arching_H`,
    :func:`jenike_critical_outlet`, :func:`critical_outlet_simplified`,
    :func:`jenike_rathole_G`, :func:`jenike_rathole_diameter`.
EN 1991-4:2006 (Eurocode 1, part 4)
    :func:`en1991_filling_vertical_walls`, :func:`en1991_h0`, :func:`en1991_intermediate_n`,
    :func:`en1991_intermediate_zV`, :func:`en1991_filling_intermediate`,
    :func:`en1991_discharge_factors`, :func:`en1991_discharge_vertical_walls`,
    :func:`en1991_hopper_class`, :func:`en1991_steep_filling_F`, :func:`en1991_steep_filling_n`,
    :func:`en1991_steep_discharge_F`, :func:`en1991_steep_discharge_n`,
    :func:`en1991_shallow_mu_heff`, :func:`en1991_shallow_F`, :func:`en1991_shallow_n`,
    :func:`en1991_hopper_vertical_stress`, :func:`en1991_hopper_pressures`.
Eccentric discharge (EN 1991-4's flow channel against the wall; AS 3774's eccentric outlets)
    :func:`eccentric_channel_geometry`, :func:`en1991_eccentric_channel`,
    :func:`en1991_eccentric_z0`, :func:`en1991_eccentric_pressures`,
    :func:`en1991_eccentric_wall_pressure`; :func:`as3774_eccentricity`,
    :func:`as3774_eccentric_increment`.

References
----------
* W.A. Beverloo, H.A. Leniger, J. van de Velde (1961), Chem. Eng. Sci. 15:260-269.
* C. Mankoc et al. (2007), Granular Matter 9:407, doi:10.1007/s10035-007-0062-2.
* H.E. Rose, T. Tanaka (1956), as used by R.M. Nedderman et al. (1982), Chem. Eng. Sci. 37:1597.
* J.R. Johanson (1965), mass-flow hopper discharge.
* R.L. Brown (1961); R.L. Brown, J.C. Richards (1970), *Principles of Powder Mechanics*.
* L.Y. Leung et al. (2019), A proposed complete methodology to predict gravity flow
  obstruction of pharmaceutical powders in drug product manufacturing, J. Pharm. Sci.
  108:464-475, eqs. 5-6 (closed fit of Jenike's chart), 2-3 (arching), 22 (ratholing).
* H.A. Janssen (1895); EN 1991-4:2006 eq. (5.75) for z0 = A/(U K mu).
* A.W. Jenike (1964), Storage and flow of solids, Bulletin 123, Utah Engineering Experiment
  Station (H(theta), G(phi)); M. Rhodes, Introduction to Particle Technology, hopper-design
  worked example (as reproduced in public lecture slides); D. Schulze, Powders and Bulk
  Solids, ch. 10 (simplified outlet rules, f(phi_i)).
* G.I. Tardos (1999), Stresses in bins and hoppers, Educational Resources for Particle
  Technology 992Q (slice method with m = 1 plane, m = 2 conical).
* J. Jaky (1944) for K0 = 1 - sin(phi).
* D.M. Walker (1966), Chem. Eng. Sci. 21:975-997; J.K. Walters (1973).
* EN 1991-4:2006, Eurocode 1: Actions on structures, Part 4: Silos and tanks; worked example
  in the Dlubal knowledge base (cement silo).
* EN 1991-4:2006 §5.2.4.3 (large-eccentricity discharge) as coded by A.J. Sadowski in
  SadowskiAJ/AJSABQ_Input_File_Generator (AJSABQ_fwrite_load.m).
* AS 3774-1996, Loads on bulk solids containers, Cl 6.5 (eccentric discharge), as transcribed
  in a public engineering-notes file.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

__all__ = [
    "G",
    "beverloo_rate",
    "rose_tanaka_factor",
    "johanson_rate",
    "brown_coefficient",
    "brown_rate",
    "beverloo_slot_rate",
    "jenike_critical_half_angle",
    "jenike_critical_half_angle_plane",
    "jenike_flow_mode",
    "janssen_z0",
    "janssen_vertical_stress",
    "janssen_wall_pressure",
    "janssen_wall_shear",
    "janssen_asymptotic_wall_pressure",
    "janssen_wall_axial_force",
    "janssen_plane_z0",
    "janssen_plane_vertical_stress",
    "janssen_plane_wall_pressure",
    "janssen_plane_asymptotic_wall_pressure",
    "janssen_plane_wall_axial_force",
    "k_jaky",
    "k_en1991",
    "k_rankine_active",
    "k_walker_wall",
    "hopper_n",
    "hopper_vertical_stress",
    "walker_discharge_ratio",
    "walker_hopper_wall_pressure",
    "SwitchPressure",
    "walker_switch_pressure",
    "WallPressures",
    "HopperPressures",
    "EN1991_B",
    "en1991_filling_vertical_walls",
    "en1991_h0",
    "en1991_intermediate_n",
    "en1991_intermediate_zV",
    "en1991_filling_intermediate",
    "en1991_discharge_factors",
    "en1991_discharge_vertical_walls",
    "en1991_hopper_class",
    "en1991_steep_filling_F",
    "en1991_steep_filling_n",
    "en1991_steep_discharge_F",
    "en1991_steep_discharge_n",
    "en1991_shallow_mu_heff",
    "en1991_shallow_F",
    "en1991_shallow_n",
    "en1991_hopper_vertical_stress",
    "en1991_hopper_pressures",
    "EN1991_ECCENTRIC_G",
    "ChannelGeometry",
    "eccentric_channel_geometry",
    "EccentricChannel",
    "en1991_eccentric_channel",
    "en1991_eccentric_z0",
    "EccentricPressures",
    "en1991_eccentric_pressures",
    "EccentricPattern",
    "en1991_eccentric_wall_pressure",
    "en1991_large_eccentricity",
    "AS3774Eccentricity",
    "as3774_eccentricity",
    "as3774_eccentric_increment",
    "unconfined_yield_strength",
    "jenike_arching_H",
    "jenike_critical_outlet",
    "critical_outlet_simplified",
    "jenike_rathole_G",
    "jenike_rathole_diameter",
]

#: Standard gravity used as the default ``g`` (m/s^2).
G = 9.81

#: EN 1991-4 hopper wall-friction reduction constant ``b`` (used in F_f and F_s).
EN1991_B = 0.2

# Smallest effective angle of internal friction for which the Jenike fit is defined:
# arccos((1 - sin d) / (2 sin d)) needs sin d >= 1/3.
_JENIKE_DELTA_MIN_DEG = float(np.degrees(np.arcsin(1.0 / 3.0)))


# ---------------------------------------------------------------------------------------
# conversion and validation of the arguments
# ---------------------------------------------------------------------------------------


def _arr(value) -> np.ndarray:
    return np.asarray(value, dtype=float)


def _out(value):
    """Numpy scalar for 0-d results, the array otherwise."""
    return np.asarray(value)[()]


def _fmt(bad: np.ndarray) -> str:
    bad = np.atleast_1d(bad)
    if bad.size == 1:
        return f"{bad[0]:g}"
    return f"{bad.size} values, e.g. {bad[0]:g}"


def _check(name: str, value, lo=None, hi=None, lo_open=False, hi_open=False, unit="") -> np.ndarray:
    """Return ``value`` as a float array after checking it lies in [lo, hi] (or open ends).

    NaN passes unchecked (it propagates to the result).  The error message names the
    parameter, the allowed range and the offending value.
    """
    a = _arr(value)
    bad = np.zeros(a.shape, dtype=bool)
    if lo is not None:
        bad |= (a <= lo) if lo_open else (a < lo)
    if hi is not None:
        bad |= (a >= hi) if hi_open else (a > hi)
    if np.any(bad):
        lb = "(" if (lo_open or lo is None) else "["
        rb = ")" if (hi_open or hi is None) else "]"
        lo_s = "-inf" if lo is None else f"{lo:g}"
        hi_s = "inf" if hi is None else f"{hi:g}"
        raise ValueError(
            f"{name} must lie in {lb}{lo_s}, {hi_s}{rb}{unit}; got {_fmt(a[bad])}{unit}"
        )
    return a


def _positive(name, value, unit=""):
    return _check(name, value, lo=0.0, lo_open=True, unit=unit)


def _nonneg(name, value, unit=""):
    return _check(name, value, lo=0.0, unit=unit)


def _deg(name, value, lo, hi, lo_open=False, hi_open=False):
    return np.radians(_check(name, value, lo, hi, lo_open, hi_open, unit=" deg"))


def _ratio_over_expm1(a, log_x):
    """``expm1(a*log_x)/a``, continuous through ``a = 0`` (where it is ``log_x``)."""
    a, log_x = np.broadcast_arrays(_arr(a), _arr(log_x))
    small = np.abs(a) < 1e-12
    safe_a = np.where(small, 1.0, a)
    with np.errstate(invalid="ignore", over="ignore"):
        general = np.expm1(a * log_x) / safe_a
    return np.where(small, log_x, general)


def _label(mask_values: np.ndarray, labels):
    """Choose string labels by integer code; a str for 0-d input, a str array otherwise."""
    code = np.asarray(mask_values)
    if code.ndim == 0:
        return str(labels[int(code)])
    return np.asarray(labels)[code]


# ---------------------------------------------------------------------------------------
# b. discharge rate
# ---------------------------------------------------------------------------------------


def beverloo_rate(rho_b, D0, C=0.58, k=1.5, d=0.0, g=G):
    """Beverloo mass discharge rate (kg/s) through a circular orifice in a flat bottom.

    ``W = C rho_b sqrt(g) (D0 - k d)^(5/2)``.

    Parameters
    ----------
    rho_b : bulk density (kg/m^3), > 0.
    D0 : orifice diameter (m), > 0.
    C : discharge coefficient, > 0; default 0.58 (literature range about 0.55-0.65).
    k : particle-size correction, >= 0; default 1.5 (range about 1.3-2.9).
    d : particle diameter (m), >= 0.  The continuum model has no particle size, so its
        comparison uses the default ``d = 0``; a fitted ``k d`` then reflects mesh size.
    g : gravitational acceleration (m/s^2), > 0.

    No angles are involved.

    Source: Beverloo, Leniger & van de Velde (1961), Chem. Eng. Sci. 15:260-269.
    Tag: form [V: as quoted by Mankoc et al. 2007]; default C and k [M, standard values].
    Valid for a bed deeper than about 1.2 silo diameters and silo diameter larger than
    2.5 D0 and D0 + 30 d (Nedderman, quoted by Mankoc et al. 2007) [V].

    Raises ValueError if ``D0 <= k d`` (the correlation has no meaning there).
    """
    rho_b = _positive("rho_b", rho_b, " kg/m^3")
    D0 = _positive("D0", D0, " m")
    C = _positive("C", C)
    k = _nonneg("k", k)
    d = _nonneg("d", d, " m")
    g = _positive("g", g, " m/s^2")
    D_eff = D0 - k * d
    if np.any(D_eff <= 0):
        raise ValueError("D0 must exceed k*d (effective orifice D0 - k d is not positive)")
    return _out(C * rho_b * np.sqrt(g) * D_eff**2.5)


def beverloo_rectangular_rate(rho_b, b, l, C=0.58, k=1.5, d=0.0, g=G):
    """Beverloo's rate (kg/s) through a rectangular orifice ``b`` by ``l`` in a flat bottom,
    by the hydraulic-diameter generalisation of the circular form.

    ``W = C (4/pi) rho_b sqrt(g) A_k sqrt(D_h,k)``, ``A_k = (b - k d)(l - k d)`` and ``D_h,k =
    4 A_k / U_k = 2 (b - k d)(l - k d) / (b + l - 2 k d)``: for a circle of diameter ``D`` it
    is Beverloo's ``C rho_b sqrt(g) (D - k d)^(5/2)``; a square of side ``b`` gives ``0.738
    rho_b sqrt(g) b^(5/2)`` (``d = 0``).

    Parameters as :func:`beverloo_rate`; ``b``, ``l``: the orifice's sides (m), > 0.

    Source: the circular form of Beverloo, Leniger & van de Velde (1961) with the area and
    hydraulic diameter of the orifice (a generalisation used for non-circular orifices;
    recalled, not checked against a source).  Tag: [D: reduces to Beverloo for a circle;
    the generalisation unverified].

    Raises ValueError if ``min(b, l) <= k d``.
    """
    rho_b = _positive("rho_b", rho_b, " kg/m^3")
    b = _positive("b", b, " m")
    l = _positive("l", l, " m")
    C = _positive("C", C)
    k = _nonneg("k", k)
    d = _nonneg("d", d, " m")
    g = _positive("g", g, " m/s^2")
    b_eff, l_eff = b - k * d, l - k * d
    if np.any(b_eff <= 0) or np.any(l_eff <= 0):
        raise ValueError("b and l must exceed k*d (the effective orifice is not positive)")
    area = b_eff * l_eff
    d_h = 2.0 * area / (b_eff + l_eff)
    return _out(C * 4.0 / np.pi * rho_b * np.sqrt(g) * area * np.sqrt(d_h))


def hydraulic_diameter(b, l):
    """``4 A / U = 2 b l / (b + l)`` (m) of a rectangular section ``b`` by ``l``: the diameter
    whose circle has the same hydraulic radius ``A / U``, so that Janssen's formulas of a
    circular bin (:func:`janssen_vertical_stress` and the others, ``z0 = D / (4 K mu)``) give
    a rectangular bin's with ``D`` this (EN 1991-4's ``z0 = A / (U K mu)``).

    Tag: [D: A/U of a rectangle]."""
    b = _positive("b", b, " m")
    l = _positive("l", l, " m")
    return _out(2.0 * b * l / (b + l))


def rose_tanaka_factor(theta_deg, beta_deg=45.0):
    """Rose-Tanaka hopper factor F multiplying the flat-bottom (Beverloo) rate.

    ``F = (tan(theta) tan(beta))^(-0.35)`` for ``theta < 90 - beta``, otherwise ``F = 1``.

    Parameters
    ----------
    theta_deg : hopper half-angle from the vertical, **degrees**, in (0, 90]
        (90 is a flat bottom).
    beta_deg : angle to the *horizontal* of the stagnant-zone boundary that the same
        material forms in a flat-bottomed bin, **degrees**, in (0, 90); default 45.

    With the default ``beta = 45`` the factor is ``tan(theta)^(-0.35)`` for theta < 45 deg
    (1.424 at the reference hopper's 20 deg): the default is a choice of this package, not
    a measured stagnant-zone angle [M].

    Source: H.E. Rose, T. Tanaka (1956), *The Engineer* 202:465-469, in the form used by
    R.M. Nedderman, U. Tuzun, S.B. Savage, G.T. Houlsby (1982), Chem. Eng. Sci. 37:1597, and
    R.M. Nedderman (1992), *Statics and kinematics of granular materials*, ch. 10.
    Tag: **[M]**, re-checked 2026-11 and still unverified: no readable copy of any of the
    three sources (nor of a paper quoting the formula) was found, so the exponent -0.35, the
    switch at ``theta = 90 - beta`` and beta being measured from the *horizontal* rest on
    memory.  What is checked [D]: the implementation is the formula above; the two branches
    join continuously at ``theta = 90 - beta`` (``tan(theta) tan(beta) = 1``); and the
    switch is the geometric condition for beta measured from the horizontal (a hopper wall
    at more than ``90 - beta`` from the vertical lies outside the flat-bottom stagnant zone,
    so the flat-bottom rate applies).  Comparisons of a simulated rate with
    Beverloo x Rose-Tanaka therefore inherit an unverified factor (+42 % at 20 deg).
    """
    th_d = _check("theta_deg", theta_deg, 0.0, 90.0, lo_open=True, unit=" deg")
    be_d = _check("beta_deg", beta_deg, 0.0, 90.0, lo_open=True, hi_open=True, unit=" deg")
    th_d, be_d = np.broadcast_arrays(th_d, be_d)
    hopper = th_d < 90.0 - be_d  # compared in degrees so the switch is exact
    th, be = np.radians(th_d), np.radians(be_d)
    with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
        f = (np.tan(th) * np.tan(be)) ** -0.35
    return _out(np.where(hopper, f, 1.0))


def johanson_rate(rho_b, D0, theta_deg, g=G, m=1):
    """Johanson mass-flow hopper discharge rate for a coarse, cohesionless solid.

    ``W = rho_b A sqrt(B g / (2 (1 + m) tan(theta)))``.

    * ``m = 1`` (default), conical hopper: ``B = D0`` the outlet diameter,
      ``A = pi D0^2 / 4``; returns kg/s.  The often-quoted form
      ``rho_b (pi D0^2/4) sqrt(D0 g / (4 tan(theta)))`` is the same equation [D].
    * ``m = 0``, plane (wedge) hopper: ``D0`` is the slot width B, ``A = B`` per unit slot
      length; returns kg/(s m).

    Parameters
    ----------
    rho_b : bulk density (kg/m^3), > 0.
    D0 : outlet diameter (cone) or slot width (plane), m, > 0.
    theta_deg : hopper half-angle from the vertical, **degrees**, in (0, 90).  The formula
        diverges as theta -> 0; use it only inside the mass-flow region.
    g : gravitational acceleration (m/s^2).
    m : 1 (cone) or 0 (plane).

    Source: Johanson (1965).  Tag: [M] (general form, and the dropped cohesion factor
    sqrt(1 - ff/ff_a)); the m = 1 identity is [D].  No air effects.
    """
    if m not in (0, 1):
        raise ValueError(f"m must be 1 (conical) or 0 (plane); got {m!r}")
    rho_b = _positive("rho_b", rho_b, " kg/m^3")
    B = _positive("D0", D0, " m")
    th = _deg("theta_deg", theta_deg, 0.0, 90.0, lo_open=True, hi_open=True)
    g = _positive("g", g, " m/s^2")
    area = np.pi * B**2 / 4.0 if m == 1 else B
    return _out(rho_b * area * np.sqrt(B * g / (2.0 * (1.0 + m) * np.tan(th))))


def brown_coefficient(alpha_deg):
    """Dimensionless Brown minimum-energy coefficient ``W / (rho_b sqrt(g) D0^(5/2))``.

    ``(pi/4) sqrt((1 - cos(alpha)^(3/2)) / (2 sin(alpha)^(5/2)))``.

    ``alpha_deg`` is the cone (or flow-channel) half-angle from the vertical in **degrees**,
    in (0, 90]; at 90 (flat bottom) the coefficient is ``pi/(4 sqrt 2) = 0.555`` [D], close
    to Beverloo's C = 0.58.  Note that this closed form is not monotone: it falls to a
    minimum of about 0.534 near alpha = 61 deg and rises again to 0.555 at 90 deg.

    Source: Brown (1961); Brown & Richards (1970).  Tag: [M] closed form (only the
    minimum-energy origin is confirmed, by Nguyen, Brennen & Sabersky 1979).
    """
    a = _deg("alpha_deg", alpha_deg, 0.0, 90.0, lo_open=True)
    return _out(np.pi / 4.0 * np.sqrt((1.0 - np.cos(a) ** 1.5) / (2.0 * np.sin(a) ** 2.5)))


def brown_rate(rho_b, D0, alpha_deg, g=G):
    """Brown / Brown & Richards minimum-energy discharge rate (kg/s) of a conical hopper.

    ``W = (pi/4) rho_b sqrt(g) D0^(5/2) sqrt((1 - cos(alpha)^(3/2)) / (2 sin(alpha)^(5/2)))``.

    Parameters
    ----------
    rho_b : bulk density (kg/m^3), > 0.
    D0 : outlet diameter (m), > 0.
    alpha_deg : cone or flow-channel half-angle from the vertical, **degrees**, in (0, 90].
    g : gravitational acceleration (m/s^2).

    Source: Brown (1961); Brown & Richards (1970).  Tag: [M] (see :func:`brown_coefficient`).
    """
    rho_b = _positive("rho_b", rho_b, " kg/m^3")
    D0 = _positive("D0", D0, " m")
    g = _positive("g", g, " m/s^2")
    return _out(brown_coefficient(alpha_deg) * rho_b * np.sqrt(g) * D0**2.5)


def beverloo_slot_rate(rho_b, B, C=1.03, k=1.5, d=0.0, g=G):
    """Beverloo-type discharge rate per unit slot length, kg/(s m), through a long slot.

    ``W' = C' rho_b sqrt(g) (B - k d)^(3/2)`` for a slot of width B in a flat bottom, much
    longer than it is wide (plane flow; end effects neglected).  For a continuum with no
    particle size (d = 0) the rate per unit length scales exactly as ``B^(3/2)`` [D:
    dimensional analysis: ``W' / (rho_b sqrt(g) B^(3/2))`` can depend only on angles and
    ratios].

    Parameters
    ----------
    rho_b : bulk density (kg/m^3), > 0.
    B : slot width (m), > 0.
    C : slot discharge coefficient C', > 0; default 1.03 (the value attributed to Myers &
        Sellers for slots [M]).  Per unit length the plane coefficient is of a different size
        from the circular C = 0.58 because the geometry differs (W' ~ B^1.5, not D^2.5).
    k : particle-size correction, >= 0; default 1.5 [M] (as for circular orifices).
    d : particle diameter (m), >= 0; default 0 (continuum).
    g : gravitational acceleration (m/s^2), > 0.

    No angles are involved.  No hopper (converging-wall) factor for plane flow is offered:
    none was found in a source that could be read.  For a plane mass-flow hopper use
    :func:`johanson_rate` with ``m = 0``.

    Source: the plane (slot) analogue of Beverloo, Leniger & van de Velde (1961); C' after
    Myers & Sellers (quoted from memory, citation not checked).  Tag: the 3/2 power [D:
    dimensional analysis]; C' = 1.03 and k = 1.5 [M].

    Raises ValueError if ``B <= k d``.
    """
    rho_b = _positive("rho_b", rho_b, " kg/m^3")
    B = _positive("B", B, " m")
    C = _positive("C", C)
    k = _nonneg("k", k)
    d = _nonneg("d", d, " m")
    g = _positive("g", g, " m/s^2")
    B_eff = B - k * d
    if np.any(B_eff <= 0):
        raise ValueError("B must exceed k*d (effective slot width B - k d is not positive)")
    return _out(C * rho_b * np.sqrt(g) * B_eff**1.5)


# ---------------------------------------------------------------------------------------
# c. flow mode
# ---------------------------------------------------------------------------------------


def jenike_critical_half_angle(delta_deg, phi_w_deg):
    """Critical conical-hopper half-angle theta_c (degrees) of Jenike's mass-flow boundary.

    ``theta_c = 90 - arccos((1 - sin delta) / (2 sin delta)) / 2 - beta_w`` with
    ``beta_w = (phi_w + arcsin(sin phi_w / sin delta)) / 2``.  Mass flow for
    ``theta < theta_c``; designers subtract a margin of 3-5 deg [M].

    Parameters
    ----------
    delta_deg : effective angle of internal friction, **degrees**, in [19.47, 90)
        (the fit needs sin(delta) >= 1/3).  For a cohesionless Mohr-Coulomb material use
        delta = phi, and the steady-flow phi rather than a peak value.
    phi_w_deg : wall friction angle, **degrees**, in [0, 90).

    Returns NaN where ``phi_w >= delta``: no mass flow by this criterion.

    Source: closed fit of Jenike's chart, Leung et al. (2019), J. Pharm. Sci. 108:464,
    eqs. 5-6.  Tag: [V] for the fit (as implemented in Tornado128/hoppers_performance_checking,
    MassFlow_or_FunnelFlow.py).  Accuracy against Jenike's chart: one chart point only
    [V: the Rhodes hopper-design worked example reads theta_c = 30.5 deg from Jenike's
    conical chart at delta = 30, phi_w = 19 deg; the fit gives 30.2 deg].  Elsewhere not
    verified; the same expression is attributed to Schulze's textbook [M].
    """
    de = _deg("delta_deg", delta_deg, _JENIKE_DELTA_MIN_DEG, 90.0, hi_open=True)
    pw = _deg("phi_w_deg", phi_w_deg, 0.0, 90.0, hi_open=True)
    de, pw = np.broadcast_arrays(de, pw)
    no_mass = pw >= de
    s = np.sin(de)
    with np.errstate(invalid="ignore"):
        beta_w = 0.5 * (pw + np.arcsin(np.sin(pw) / s))
        theta_c = np.pi / 2 - 0.5 * np.arccos((1.0 - s) / (2.0 * s)) - beta_w
    return _out(np.where(no_mass, np.nan, np.degrees(theta_c)))


def jenike_critical_half_angle_plane(delta_deg, phi_w_deg, offset_deg=10.0):
    """Critical half-angle (degrees) of a plane-flow (wedge) hopper, by the rule of thumb.

    ``theta_c,plane = theta_c,cone + offset`` with theta_c,cone from
    :func:`jenike_critical_half_angle` and ``offset = 10 deg`` by default: Jenike's
    plane-flow mass-flow boundary is commonly said to be about 8-12 deg more generous than
    the conical one.  Mass flow for ``theta < theta_c,plane`` (theta the angle of the
    inclined walls from the vertical).  NaN where ``phi_w >= delta``, as for the cone.

    **This is not a closed form of Jenike's plane-flow chart.**  No documented closed form
    or fit of that chart boundary could be found and read (2026-11), and no plane-flow chart
    point was available to test this rule against; use it to place a plane-flow study, not
    to decide a design.

    Parameters
    ----------
    delta_deg : effective angle of internal friction, **degrees**, in [30, 70] (the range
        for which Jenike published charts: delta = 30, 40, ..., 70 deg [V: as listed in the
        Rhodes hopper-design worked example]).
    phi_w_deg : wall friction angle, **degrees**, in [0, 90).
    offset_deg : the plane-flow allowance, **degrees**, in [0, 20]; default 10.

    Source: Jenike (1964), Bulletin 123 (plane-flow charts); the offset rule of thumb.
    Tag: **[M]** (the 8-12 deg allowance is quoted from memory; the conical part is as
    :func:`jenike_critical_half_angle`).
    """
    _check("delta_deg", delta_deg, 30.0, 70.0, unit=" deg")
    off = _check("offset_deg", offset_deg, 0.0, 20.0, unit=" deg")
    return _out(_arr(jenike_critical_half_angle(delta_deg, phi_w_deg)) + off)


_GEOMETRIES = ("conical", "plane")


def _geometry(geometry):
    if geometry not in _GEOMETRIES:
        raise ValueError(f"geometry must be 'conical' or 'plane'; got {geometry!r}")
    return geometry


def jenike_flow_mode(theta_deg, delta_deg, phi_w_deg, margin_deg=0.0, geometry="conical"):
    """Classify a hopper as ``"mass"`` or ``"funnel"`` flow by Jenike's boundary.

    ``"mass"`` where ``theta < theta_c - margin``, ``"funnel"`` otherwise (including where
    theta_c is NaN, i.e. ``phi_w >= delta``).  See :func:`jenike_critical_half_angle`.

    Parameters
    ----------
    theta_deg : hopper half-angle from the vertical, **degrees**, in (0, 90].
    delta_deg, phi_w_deg : as in :func:`jenike_critical_half_angle`, **degrees**.
    margin_deg : design margin subtracted from theta_c, **degrees**, >= 0 (default 0).
    geometry : ``"conical"`` (default; :func:`jenike_critical_half_angle`) or ``"plane"``
        (:func:`jenike_critical_half_angle_plane` with its default offset, [M]).

    Returns a str for scalar input, an array of str otherwise.

    Source and tag as the critical-angle function used.
    """
    _geometry(geometry)
    th = _check("theta_deg", theta_deg, 0.0, 90.0, lo_open=True, unit=" deg")
    margin = _nonneg("margin_deg", margin_deg, " deg")
    if geometry == "conical":
        tc = _arr(jenike_critical_half_angle(delta_deg, phi_w_deg))
    else:
        tc = _arr(jenike_critical_half_angle_plane(delta_deg, phi_w_deg))
    with np.errstate(invalid="ignore"):
        mass = th < tc - margin  # NaN compares False -> funnel
    return _label(np.where(mass, 0, 1), ["mass", "funnel"])


# ---------------------------------------------------------------------------------------
# d. wall pressure: vertical section (Janssen)
# ---------------------------------------------------------------------------------------


def janssen_z0(D, K, mu):
    """Janssen characteristic depth ``z0 = A/(U K mu) = D/(4 K mu)`` (m), circular section.

    Parameters
    ----------
    D : cylinder diameter (m), > 0.
    K : lateral pressure ratio (wall-normal / vertical stress), > 0.
    mu : wall friction coefficient ``tan(phi_w)`` (a number, not an angle), > 0.

    Source: Janssen (1895); the A/(U K mu) form is EN 1991-4:2006 eq. (5.75).
    Tag: [V: EN 1991-4 eq. (5.75), quoted by Dlubal].
    """
    D = _positive("D", D, " m")
    K = _positive("K", K)
    mu = _positive("mu", mu)
    return _out(D / (4.0 * K * mu))


def janssen_vertical_stress(z, rho_b, D, K, mu, q0=0.0, g=G):
    """Janssen mean vertical stress (Pa) at depth z below a levelled surface.

    ``sigma_v = rho_b g z0 (1 - exp(-z/z0)) + q0 exp(-z/z0)``, ``z0 = D/(4 K mu)``.

    Parameters
    ----------
    z : depth below the levelled surface (m), >= 0.
    rho_b : bulk density (kg/m^3), > 0.
    D : cylinder diameter (m), > 0.
    K : lateral pressure ratio, > 0.
    mu : wall friction coefficient tan(phi_w) (not an angle), > 0.
    q0 : surcharge on the surface (Pa), >= 0.
    g : gravitational acceleration (m/s^2).

    No angles are involved.  For z << z0 it tends to the hydrostatic ``rho_b g z + q0``.

    Source: Janssen (1895).  Tag: [V form; D: slice equilibrium].
    """
    z = _nonneg("z", z, " m")
    rho_b = _positive("rho_b", rho_b, " kg/m^3")
    q0 = _nonneg("q0", q0, " Pa")
    g = _positive("g", g, " m/s^2")
    z0 = _arr(janssen_z0(D, K, mu))
    x = z / z0
    return _out(-rho_b * g * z0 * np.expm1(-x) + q0 * np.exp(-x))


def janssen_wall_pressure(z, rho_b, D, K, mu, q0=0.0, g=G):
    """Janssen normal wall pressure ``p_n = K sigma_v`` (Pa).

    Arguments as :func:`janssen_vertical_stress` (no angles; ``mu`` is a coefficient).
    Tends to ``rho_b g D / (4 mu)`` at depth, independent of K
    (:func:`janssen_asymptotic_wall_pressure`).

    Source: Janssen (1895).  Tag: [V form; D].
    """
    return _out(_arr(K) * _arr(janssen_vertical_stress(z, rho_b, D, K, mu, q0, g)))


def janssen_wall_shear(z, rho_b, D, K, mu, q0=0.0, g=G):
    """Janssen wall shear (friction) stress ``tau_w = mu K sigma_v`` (Pa).

    Arguments as :func:`janssen_vertical_stress`.  Source: Janssen (1895).  Tag: [V form; D].
    """
    return _out(_arr(mu) * _arr(janssen_wall_pressure(z, rho_b, D, K, mu, q0, g)))


def janssen_asymptotic_wall_pressure(rho_b, D, mu, g=G):
    """Deep-bed Janssen wall pressure ``rho_b g D / (4 mu)`` (Pa); does not depend on K.

    Parameters: bulk density rho_b (kg/m^3), diameter D (m), wall friction coefficient
    mu = tan(phi_w) (not an angle), g (m/s^2).

    Source: limit z -> infinity of Janssen (1895).  Tag: [D] (test invariant).
    """
    rho_b = _positive("rho_b", rho_b, " kg/m^3")
    D = _positive("D", D, " m")
    mu = _positive("mu", mu)
    g = _positive("g", g, " m/s^2")
    return _out(rho_b * g * D / (4.0 * mu))


def janssen_wall_axial_force(z, rho_b, D, K, mu, q0=0.0, g=G):
    """Janssen vertical force in the wall per unit length of its perimeter (N/m, compression
    positive) at depth z: the wall friction above z, ``n_z = int_0^z mu K sigma_v dz``.

    From the equilibrium of the column above z, weight and surcharge ``(rho_b g z + q0) A``
    = ``sigma_v A + n_z U``: ``n_z = (D/4) (rho_b g z + q0 - sigma_v(z))`` [D]; with
    ``q0 = 0`` this is ``mu K rho_b g z0 (z - z0 (1 - exp(-z/z0)))``, the form of
    EN 1991-4's characteristic vertical wall force ``n_zSk`` (section 5.2.1.1).  Arguments as
    :func:`janssen_vertical_stress` (no angles).  Tends to ``z^2 rho_b g K mu / 2`` near the
    surface and grows as ``rho_b g D/4`` per metre of depth below ``z0``.

    Source: Janssen (1895).  Tag: [D].
    """
    D = _positive("D", D, " m")
    return _wall_axial_force(z, rho_b, janssen_z0(D, K, mu), D / 4.0, q0, g)


def _wall_axial_force(z, rho_b, z0, area_per_perimeter, q0, g):
    """``(A/U) (rho_b g z + q0 - sigma_v(z))`` for Janssen's ``sigma_v`` of depth ``z0``."""
    z = _nonneg("z", z, " m")
    rho_b = _positive("rho_b", rho_b, " kg/m^3")
    q0 = _nonneg("q0", q0, " Pa")
    g = _positive("g", g, " m/s^2")
    x = z / _arr(z0)
    # rho g z + q0 - sigma_v = rho g (z - z0 (1 - e^-x)) + q0 (1 - e^-x), without cancellation
    excess = rho_b * g * _arr(z0) * (x + np.expm1(-x)) - q0 * np.expm1(-x)
    return _out(area_per_perimeter * excess)


def janssen_plane_z0(B, K, mu):
    """Janssen characteristic depth of a long rectangular (plane) bin, ``z0 = B/(2 K mu)`` (m).

    The bin is B wide between two parallel walls and much longer than wide: per unit length
    the section has area B and wetted perimeter 2, so ``A/U = B/2`` (the limit of
    ``A/U = B L / (2 (B + L))`` as the length L grows) and ``z0 = A/(U K mu) = B/(2 K mu)``.

    Parameters: width B (m), > 0; lateral pressure ratio K, > 0; wall friction coefficient
    mu = tan(phi_w) (not an angle), > 0.

    Source: Janssen (1895) with the A/U form of EN 1991-4 eq. (5.75).  Tag: A/U form
    [V: EN 1991-4 as quoted by Dlubal; as coded for rectangular silos in
    arturopala/encalmo RectangularSilos.scala]; A/U = B/2 [D].
    """
    B = _positive("B", B, " m")
    K = _positive("K", K)
    mu = _positive("mu", mu)
    return _out(B / (2.0 * K * mu))


def janssen_plane_vertical_stress(z, rho_b, B, K, mu, q0=0.0, g=G):
    """Janssen mean vertical stress (Pa) in a long rectangular (plane) bin of width B.

    ``sigma_v = rho_b g z0 (1 - exp(-z/z0)) + q0 exp(-z/z0)``, ``z0 = B/(2 K mu)``
    (:func:`janssen_plane_z0`); it solves the slice equilibrium per unit length
    ``B dsigma_v/dz = rho_b g B - 2 mu K sigma_v`` [D].

    Parameters: depth z (m) below the levelled surface, >= 0; rho_b (kg/m^3); width B (m);
    K; mu = tan(phi_w) (a coefficient); surcharge q0 (Pa), >= 0; g (m/s^2).  No angles.

    Source: Janssen (1895).  Tag: [D] (same solution as :func:`janssen_vertical_stress`
    with ``D/4`` replaced by ``B/2``).
    """
    z = _nonneg("z", z, " m")
    rho_b = _positive("rho_b", rho_b, " kg/m^3")
    q0 = _nonneg("q0", q0, " Pa")
    g = _positive("g", g, " m/s^2")
    z0 = _arr(janssen_plane_z0(B, K, mu))
    x = z / z0
    return _out(-rho_b * g * z0 * np.expm1(-x) + q0 * np.exp(-x))


def janssen_plane_wall_pressure(z, rho_b, B, K, mu, q0=0.0, g=G):
    """Janssen normal wall pressure ``p_h = K sigma_v`` (Pa) in a long rectangular bin.

    Arguments as :func:`janssen_plane_vertical_stress`.  Tends to ``rho_b g B / (2 mu)``
    at depth, independent of K (:func:`janssen_plane_asymptotic_wall_pressure`).  The wall
    shear is ``mu p_h``.

    Source: Janssen (1895).  Tag: [D].
    """
    return _out(_arr(K) * _arr(janssen_plane_vertical_stress(z, rho_b, B, K, mu, q0, g)))


def janssen_plane_asymptotic_wall_pressure(rho_b, B, mu, g=G):
    """Deep-bed wall pressure of a long rectangular (plane) bin, ``rho_b g B / (2 mu)`` (Pa).

    Independent of K: at depth the wall friction on the two walls, ``2 mu p_h`` per unit
    length, carries the whole weight ``rho_b g B`` of each further metre of depth [D].
    Parameters: rho_b (kg/m^3), width B (m), mu = tan(phi_w) (not an angle), g (m/s^2).

    Source: limit z -> infinity of Janssen (1895).  Tag: [D].
    """
    rho_b = _positive("rho_b", rho_b, " kg/m^3")
    B = _positive("B", B, " m")
    mu = _positive("mu", mu)
    g = _positive("g", g, " m/s^2")
    return _out(rho_b * g * B / (2.0 * mu))


def janssen_plane_wall_axial_force(z, rho_b, B, K, mu, q0=0.0, g=G):
    """Janssen vertical force in each wall of a long rectangular (plane) bin per metre of its
    length (N/m, compression positive) at depth z: ``n_z = (B/2) (rho_b g z + q0 - sigma_v)``,
    the two walls' friction carrying what the vertical stress does not [D].  Arguments as
    :func:`janssen_plane_vertical_stress` (no angles).

    Source: Janssen (1895).  Tag: [D] (:func:`janssen_wall_axial_force` with ``D/4`` replaced
    by ``B/2``).
    """
    B = _positive("B", B, " m")
    return _wall_axial_force(z, rho_b, janssen_plane_z0(B, K, mu), B / 2.0, q0, g)


# ---------------------------------------------------------------------------------------
# lateral pressure ratios
# ---------------------------------------------------------------------------------------


def k_jaky(phi):
    """At-rest lateral pressure ratio ``K0 = 1 - sin(phi)``.

    ``phi``: internal friction angle in **degrees**, in [0, 90).

    Source: Jaky (1944).  Tag: standard.
    """
    ph = _deg("phi", phi, 0.0, 90.0, hi_open=True)
    return _out(1.0 - np.sin(ph))


def k_en1991(phi_im):
    """EN 1991-4 mean lateral pressure ratio ``K_m = 1.1 (1 - sin(phi_im))``.

    ``phi_im``: mean angle of internal friction in **degrees**, in [0, 90).  The code's
    characteristic values are ``K_m a_K`` (upper) and ``K_m / a_K`` (lower).

    Source: EN 1991-4:2006.  Tag: formula text [M]; [D: reproduces the Table E.1 K_m column
    from its phi_im column within +-0.02 for 24 of 25 solids].
    """
    ph = _deg("phi_im", phi_im, 0.0, 90.0, hi_open=True)
    return _out(1.1 * (1.0 - np.sin(ph)))


def k_rankine_active(phi):
    """Rankine active lateral pressure ratio ``(1 - sin phi) / (1 + sin phi)``.

    ``phi``: internal friction angle in **degrees**, in [0, 90).  Source: Rankine.
    Tag: standard.
    """
    ph = _deg("phi", phi, 0.0, 90.0, hi_open=True)
    s = np.sin(ph)
    return _out((1.0 - s) / (1.0 + s))


def k_walker_wall(phi, phi_w):
    """Walker/Walters wall value of K for an actively yielding solid with wall friction.

    ``K = (1 + sin^2 phi - 2 sqrt(sin^2 phi - mu^2 cos^2 phi)) / (4 mu^2 + cos^2 phi)``,
    ``mu = tan(phi_w)``.

    Parameters
    ----------
    phi : internal friction angle, **degrees**, in (0, 90).
    phi_w : wall friction angle, **degrees**, in [0, phi] (the square root needs
        ``phi_w <= phi``).  At ``phi_w = 0`` this is the Rankine active ratio.

    Source: Walker (1966); Walters (1973).  Tag: closed form [M]; value [D: brute-force
    Mohr circle].
    """
    ph = _deg("phi", phi, 0.0, 90.0, lo_open=True, hi_open=True)
    pw = _deg("phi_w", phi_w, 0.0, 90.0, hi_open=True)
    if np.any(pw > ph):
        raise ValueError("phi_w must not exceed phi (the wall would be rougher than the solid)")
    s2 = np.sin(ph) ** 2
    c2 = np.cos(ph) ** 2
    mu2 = np.tan(pw) ** 2
    root = np.sqrt(np.maximum(s2 - mu2 * c2, 0.0))
    return _out((1.0 + s2 - 2.0 * root) / (4.0 * mu2 + c2))


# ---------------------------------------------------------------------------------------
# hopper slice method (Walker 1966 / Walters 1973, D = 1; EN 1991-4)
# ---------------------------------------------------------------------------------------


def hopper_n(F, mu, beta_deg, S=2):
    """Exponent of the hopper slice solution ``n = S (F mu cot(beta) + F - 1)``.

    For a cone (S = 2) this is the EN 1991-4 form ``S (F mu cot(beta) + F) - 2``.  For a
    wedge (plane, S = 1) it is ``F mu cot(beta) + F - 1``, which is what vertical
    equilibrium of a wedge slice gives; the form with ``- 2`` for every S is *not*: it
    fails the hydrostatic check (F = 1, mu = 0 must give n = 0, a fluid) for S = 1.

    Derivation [D]: a slice of cross-section ``A ~ x^S`` (x up from the apex; S = 2 cone,
    S = 1 wedge per unit length), wall pressure ``p_n = F sigma_v`` and friction
    ``mu p_n`` acting up the wall, gives ``A' = S A / x`` and
    ``d(sigma_v A)/dx = -gamma A + (S A / x) F (1 + mu cot(beta)) sigma_v``, i.e.
    ``d sigma_v/dx = -gamma + n sigma_v / x`` with n above (the plane form is Walker's
    slice with m = 1 as written by G.I. Tardos, *Stresses in bins and hoppers*, ERPT 1999,
    eqs. 11-12 [V]).

    Parameters
    ----------
    F : wall-normal / mean vertical stress ratio (p_n / sigma_v), > 0.
    mu : wall friction coefficient (not an angle), >= 0.
    beta_deg : hopper half-angle from the vertical, **degrees**, in (0, 90).
    S : 2 for a cone, 1 for a wedge (plane) hopper, per unit length of the wedge.

    Source: vertical equilibrium of a slice, Walker (1966) with distribution factor D = 1 as
    in EN 1991-4 (general hopper n, cone); the same ODE as the Motzkus/Schulze form in
    Tornado128/hoppers_performance_checking.  Tag: [D].  (Before 2026-11 this function
    returned ``S (F mu cot(beta) + F) - 2`` for every S: 1 too low for S = 1; unchanged
    for cones.)
    """
    F = _positive("F", F)
    mu = _nonneg("mu", mu)
    be = _deg("beta_deg", beta_deg, 0.0, 90.0, lo_open=True, hi_open=True)
    S = _positive("S", S)
    return _out(S * (F * mu / np.tan(be) + F - 1.0))


def hopper_vertical_stress(x, h, gamma, n, sigma_vt):
    """Mean vertical stress in a hopper by the slice method (Pa).

    Solves ``d sigma_v/dx = -gamma + n sigma_v / x`` with ``sigma_v(h) = sigma_vt``:
    ``sigma_v = gamma h/(n-1) [(x/h) - (x/h)^n] + sigma_vt (x/h)^n``, continuous through
    n = 1 (where the bracket term becomes ``-gamma x ln(x/h)``).

    Parameters
    ----------
    x : height above the (virtual) cone apex (m), in [0, h].
    h : apex-to-transition height (m), > 0.
    gamma : unit weight rho_b g (N/m^3), >= 0.
    n : exponent, e.g. from :func:`hopper_n`.  For ``n <= 0`` the stress is unbounded at
        the apex (returned as inf at x = 0 for n < 0).
    sigma_vt : mean vertical stress at the transition x = h (Pa), >= 0.

    No angles are involved.

    Source: Walker (1966) slice method, D = 1; EN 1991-4 hopper p_v.  Tag: [D].
    """
    h = _positive("h", h, " m")
    x = _arr(x)
    if np.any((x < 0) | (x > h)):
        raise ValueError("x must lie in [0, h] (height above the cone apex)")
    gamma = _nonneg("gamma", gamma, " N/m^3")
    sigma_vt = _nonneg("sigma_vt", sigma_vt, " Pa")
    n = _arr(n)
    xi, n, h, gamma, sigma_vt = np.broadcast_arrays(x / h, n, h, gamma, sigma_vt)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        xin = np.where(xi > 0, xi**n, np.where(n > 0, 0.0, np.where(n == 0, 1.0, np.inf)))
        log_xi = np.log(np.where(xi > 0, xi, 1.0))
        # (xi - xi^n)/(n - 1) = -xi * expm1((n-1) ln xi)/(n-1); stable through n = 1.
        bracket_pos = -xi * _ratio_over_expm1(n - 1.0, log_xi)
        bracket = np.where(xi > 0, bracket_pos, -xin / (n - 1.0))
        # xi = 0 and n == 1: bracket -> 0
        bracket = np.where((xi == 0) & (n == 1.0), 0.0, bracket)
        sv = gamma * h * bracket + sigma_vt * xin
    return _out(sv)


def walker_discharge_ratio(phi, phi_w, beta_deg):
    """Passive (discharge) wall ratio F_e = p_n / sigma_v of a Walker-type hopper, D = 1.

    ``F_e = (1 + sin(phi) cos(eps)) / (1 - sin(phi) cos(2 beta + eps))``,
    ``eps = phi_w + arcsin(sin(phi_w) / sin(phi))``.

    Parameters
    ----------
    phi : (effective) internal friction angle, **degrees**, in (0, 90).
    phi_w : wall friction angle, **degrees**, in [0, phi].
    beta_deg : hopper half-angle from the vertical, **degrees**, in [0, 90).

    At ``phi_w = 0`` and ``beta = 0`` this is the Rankine passive ratio.

    Source: Walker (1966); EN 1991-4 steep-hopper discharge F_e (as transcribed in
    kei-mp/blog silo.md, which uses cos(2 beta + eps); the arturopala/encalmo cos(beta + eps)
    disagrees with the Mohr circle).  Tag: [D: brute-force Mohr circle at yield with wall
    friction acting up the wall].
    """
    ph = _deg("phi", phi, 0.0, 90.0, lo_open=True, hi_open=True)
    pw = _deg("phi_w", phi_w, 0.0, 90.0, hi_open=True)
    be = _deg("beta_deg", beta_deg, 0.0, 90.0, hi_open=True)
    if np.any(pw > ph):
        raise ValueError("phi_w must not exceed phi (the wall would be rougher than the solid)")
    s = np.sin(ph)
    eps = pw + np.arcsin(np.minimum(np.sin(pw) / s, 1.0))
    return _out((1.0 + s * np.cos(eps)) / (1.0 - s * np.cos(2.0 * be + eps)))


def walker_hopper_wall_pressure(
    x, h, beta_deg, rho_b, phi, phi_w, sigma_vt, mode="filling", g=G, S=2, b=EN1991_B
):
    """Normal wall pressure p_n (Pa) in a hopper by the slice method (Walker, D = 1).

    ``p_n = F sigma_v(x)`` with ``sigma_v`` from :func:`hopper_vertical_stress`,
    ``n = S (F mu cot(beta) + F - 1)`` (:func:`hopper_n`), ``mu = tan(phi_w)``,
    ``gamma = rho_b g`` and

    * ``mode="filling"``: ``F = F_f = 1 - b / (1 + tan(beta)/mu)`` (EN 1991-4, b = 0.2);
    * ``mode="discharge"``: ``F = F_e`` from :func:`walker_discharge_ratio`.

    Parameters
    ----------
    x : height above the cone apex (m), in [0, h].
    h : apex-to-transition height (m), > 0; for a cone running to its apex from a cylinder
        of diameter D, ``h = D / (2 tan(beta))``; for a wedge (S = 1) from a bin of width B,
        ``h = B / (2 tan(beta))``.
    beta_deg : hopper half-angle from the vertical, **degrees**, in (0, 90).
    rho_b : bulk density (kg/m^3).
    phi : internal friction angle, **degrees** (used by the discharge ratio).
    phi_w : wall friction angle, **degrees**.
    sigma_vt : mean vertical stress at the transition (Pa), e.g. from Janssen.
    mode : "filling" or "discharge".
    g : gravitational acceleration (m/s^2).
    S : 2 cone, 1 wedge (plane flow, per unit length; the plane-flow Walker slice).
    b : EN wall-friction reduction constant for F_f (default 0.2).

    Sources: Walker (1966); EN 1991-4:2006 (F_f [V: kei-mp/blog silo.md, arturopala/encalmo];
    F_e [D]).  Tag: [D] slice solution.
    """
    if mode not in ("filling", "discharge"):
        raise ValueError(f"mode must be 'filling' or 'discharge'; got {mode!r}")
    _check("phi", phi, 0.0, 90.0, lo_open=True, hi_open=True, unit=" deg")
    pw = _deg("phi_w", phi_w, 0.0, 90.0, hi_open=True)
    mu = np.tan(pw)
    rho_b = _positive("rho_b", rho_b, " kg/m^3")
    g = _positive("g", g, " m/s^2")
    if mode == "filling":
        F = _arr(en1991_steep_filling_F(beta_deg, mu, b=b))
    else:
        F = _arr(walker_discharge_ratio(phi, phi_w, beta_deg))
    n = hopper_n(F, mu, beta_deg, S=S)
    sv = _arr(hopper_vertical_stress(x, h, rho_b * g, n, sigma_vt))
    return _out(F * sv)


class SwitchPressure(NamedTuple):
    """Wall pressure just above (cylinder, active) and just below (hopper, passive) the
    transition during mass-flow discharge, and their ratio."""

    cylinder: np.ndarray
    hopper: np.ndarray
    ratio: np.ndarray


def walker_switch_pressure(sigma_vt, K, phi, phi_w, beta_deg):
    """Simple switch-pressure estimate at the cylinder/hopper transition during discharge.

    Above the transition the wall pressure is active, ``K sigma_vt``; just below it, passive,
    ``F_e sigma_vt`` (:func:`walker_discharge_ratio`).  Returns
    ``SwitchPressure(cylinder, hopper, ratio=F_e/K)``; the ratio is typically about 2.

    Parameters
    ----------
    sigma_vt : mean vertical stress at the transition (Pa), >= 0, e.g. Janssen.
    K : lateral pressure ratio in the cylinder, > 0.
    phi, phi_w : internal and wall friction angles, **degrees**.
    beta_deg : hopper half-angle from the vertical, **degrees**.

    Source: Walker (1966) / Walters (1973) (Walters derives the true peak with a distribution
    factor D != 1, not implemented).  Tag: [D] simple estimate.
    """
    svt = _nonneg("sigma_vt", sigma_vt, " Pa")
    K = _positive("K", K)
    Fe = _arr(walker_discharge_ratio(phi, phi_w, beta_deg))
    return SwitchPressure(_out(K * svt), _out(Fe * svt), _out(Fe / K))


# ---------------------------------------------------------------------------------------
# EN 1991-4:2006
# ---------------------------------------------------------------------------------------


class WallPressures(NamedTuple):
    """Vertical-wall loads (Pa): horizontal (normal) p_h, wall friction p_w, vertical p_v."""

    p_h: np.ndarray
    p_w: np.ndarray
    p_v: np.ndarray


class HopperPressures(NamedTuple):
    """Hopper loads (Pa): normal p_n, friction p_t, mean vertical p_v; and the hopper class."""

    p_n: np.ndarray
    p_t: np.ndarray
    p_v: np.ndarray
    hopper_class: object


def en1991_filling_vertical_walls(z, gamma, d_c, K, mu):
    """EN 1991-4 filling loads on the vertical walls of a *slender* circular silo.

    ``p_hf = p_ho Y_J(z)``, ``p_ho = gamma K z0``, ``Y_J = 1 - exp(-z/z0)``,
    ``p_wf = mu p_hf``, ``p_vf = p_hf / K``, ``z0 = d_c / (4 K mu)``.

    Parameters
    ----------
    z : depth below the equivalent surface (m), >= 0.
    gamma : unit weight (N/m^3), > 0.
    d_c : silo inner diameter (m), > 0.
    K, mu : lateral pressure ratio and wall friction coefficient (not an angle), > 0; the
        code's characteristic combination for the load case in question.

    No angles are involved.  Returns ``WallPressures(p_h, p_w, p_v)``.

    Source: EN 1991-4:2006 §5.2.1.  Tag: z0 [V]; the rest [M] (it is Janssen's solution).
    """
    z = _nonneg("z", z, " m")
    gamma = _positive("gamma", gamma, " N/m^3")
    z0 = _arr(janssen_z0(d_c, K, mu))
    K = _arr(K)
    mu = _arr(mu)
    p_h = gamma * K * z0 * (-np.expm1(-z / z0))
    return WallPressures(_out(p_h), _out(mu * p_h), _out(p_h / K))


def en1991_h0(d_c, phi_r):
    """EN 1991-4 depth h0 (m) of the highest solid-wall contact below the equivalent surface,
    circular silo with symmetric filling: ``h0 = d_c tan(phi_r) / 6``.

    ``d_c``: silo diameter (m), > 0.  ``phi_r``: angle of repose, **degrees**, in [0, 90).

    Source: EN 1991-4:2006 §5.3 (intermediate slenderness).  Tag: [V: Dlubal].
    """
    d_c = _positive("d_c", d_c, " m")
    pr = _deg("phi_r", phi_r, 0.0, 90.0, hi_open=True)
    return _out(d_c * np.tan(pr) / 6.0)


def en1991_intermediate_n(d_c, K, mu, phi_r):
    """EN 1991-4 exponent ``n = -(1 + tan(phi_r)) (1 - h0/z0)`` (intermediate slenderness).

    Parameters: d_c (m), K, mu (coefficient), phi_r the angle of repose in **degrees**.

    Source: EN 1991-4:2006 §5.3.  Tag: [V: Dlubal].
    """
    z0 = _arr(janssen_z0(d_c, K, mu))
    h0 = _arr(en1991_h0(d_c, phi_r))
    tr = np.tan(np.radians(_arr(phi_r)))
    return _out(-(1.0 + tr) * (1.0 - h0 / z0))


def en1991_intermediate_zV(z, d_c, K, mu, phi_r):
    """EN 1991-4 equivalent depth z_V (m) for silos of intermediate slenderness.

    ``z_V = h0 - [z0 - h0 - (z + z0 - 2 h0)^(n+1) / (z0 - h0)^n] / (n + 1)`` for z >= h0,
    evaluated stably through ``n = -1``; for ``0 <= z < h0`` (above the highest wall contact)
    ``z_V = z`` (no wall friction) [D], which is continuous at ``z = h0``.

    Parameters
    ----------
    z : depth below the equivalent surface (m), >= 0.
    d_c : silo diameter (m).  K, mu : ratio and wall friction coefficient (not an angle).
    phi_r : angle of repose, **degrees**, in [0, 90); requires ``h0 < z0``.

    Source: EN 1991-4:2006 §5.3.  Tag: [M] (reproduces the Dlubal cement-silo example:
    p_vf(z = 8 m) = 69.24 kN/m^2 against the published 69.27).
    """
    z = _nonneg("z", z, " m")
    z0 = _arr(janssen_z0(d_c, K, mu))
    h0 = _arr(en1991_h0(d_c, phi_r))
    if np.any(h0 >= z0):
        raise ValueError("phi_r too large for this silo: h0 = d_c tan(phi_r)/6 must be below z0")
    n = _arr(en1991_intermediate_n(d_c, K, mu, phi_r))
    c = z0 - h0
    u = np.maximum(z + z0 - 2.0 * h0, 0.0) / c  # > 0 for z >= h0
    with np.errstate(divide="ignore", invalid="ignore"):
        # [c - u^(n+1) c] / (n+1) = -c expm1((n+1) ln u)/(n+1)
        bracket = -c * _ratio_over_expm1(n + 1.0, np.log(np.where(u > 0, u, 1.0)))
    zV = np.where(z >= h0, h0 - bracket, z)
    return _out(zV)


def en1991_filling_intermediate(z, gamma, d_c, K, mu, phi_r):
    """EN 1991-4 filling loads for a circular silo of intermediate slenderness.

    ``p_vf = gamma z_V`` (:func:`en1991_intermediate_zV`);
    ``p_hf = gamma K z0 Y_R`` with ``Y_R = 1 - ((z - h0)/(z0 - h0) + 1)^n`` for z >= h0
    and 0 above; ``p_wf = mu p_hf``.  Y_R follows from z_V by vertical equilibrium of a slice
    (``dp_v/dz = gamma - (4 mu / d_c) p_h``) [D].

    Parameters: z (m) below the equivalent surface, gamma (N/m^3), d_c (m), K, mu (not an
    angle), phi_r angle of repose in **degrees**.  Returns ``WallPressures(p_h, p_w, p_v)``.

    Source: EN 1991-4:2006 §5.3.  Tag: h0, n [V: Dlubal]; z_V [M]; Y_R [D] from z_V.
    """
    z = _nonneg("z", z, " m")
    gamma = _positive("gamma", gamma, " N/m^3")
    zV = _arr(en1991_intermediate_zV(z, d_c, K, mu, phi_r))
    z0 = _arr(janssen_z0(d_c, K, mu))
    h0 = _arr(en1991_h0(d_c, phi_r))
    n = _arr(en1991_intermediate_n(d_c, K, mu, phi_r))
    K = _arr(K)
    mu = _arr(mu)
    base = np.maximum((z - h0) / (z0 - h0) + 1.0, 1.0)
    Y_R = np.where(z >= h0, 1.0 - base**n, 0.0)
    p_h = gamma * K * z0 * Y_R
    return WallPressures(_out(p_h), _out(mu * p_h), _out(gamma * zV))


def en1991_discharge_factors(top_emptied=False):
    """EN 1991-4 discharge factors ``(C_h, C_w)`` for the vertical walls of slender silos.

    ``(1.15, 1.10)`` in general; ``(1.0, 1.0)`` for silos emptied from the top.
    Patch loads are not included.

    Source: EN 1991-4:2006 eqs. (5.21)/(5.22).  Tag: 1.15 / 1.10 [V: kei-mp/blog silo.md;
    arturopala/encalmo CircularSilos.scala]; the top-emptied 1.0 [M].
    """
    return (1.0, 1.0) if top_emptied else (1.15, 1.10)


def en1991_discharge_vertical_walls(p_hf, p_wf, top_emptied=False):
    """EN 1991-4 discharge loads on vertical walls: ``p_he = C_h p_hf``, ``p_we = C_w p_wf``.

    ``p_hf``, ``p_wf``: filling loads (Pa), >= 0.  No angles.  Returns ``(p_he, p_we)``.

    Source and tag: see :func:`en1991_discharge_factors`.
    """
    p_hf = _nonneg("p_hf", p_hf, " Pa")
    p_wf = _nonneg("p_wf", p_wf, " Pa")
    C_h, C_w = en1991_discharge_factors(top_emptied)
    return _out(C_h * p_hf), _out(C_w * p_wf)


def en1991_hopper_class(beta_deg, K, mu_h):
    """EN 1991-4 hopper class: ``"flat"``, ``"steep"`` or ``"shallow"``.

    * flat if the bottom is inclined less than 5 deg to the horizontal (``beta > 85``);
    * steep if ``tan(beta) < (1 - K) / (2 mu_h)``;
    * shallow otherwise.

    Parameters
    ----------
    beta_deg : hopper half-angle from the vertical, **degrees**, in (0, 90].
    K : lower characteristic lateral pressure ratio, > 0.
    mu_h : lower characteristic hopper wall friction coefficient (not an angle), > 0.

    Returns a str for scalar input, an array of str otherwise.

    Source: EN 1991-4:2006 §6.1.  Tag: [V: Dlubal].
    """
    be = _deg("beta_deg", beta_deg, 0.0, 90.0, lo_open=True)
    K = _positive("K", K)
    mu_h = _positive("mu_h", mu_h)
    flat = be > np.radians(85.0)
    with np.errstate(over="ignore"):
        steep = np.tan(be) < (1.0 - K) / (2.0 * mu_h)
    code = np.where(flat, 0, np.where(steep, 1, 2))
    return _label(code, ["flat", "steep", "shallow"])


def en1991_steep_filling_F(beta_deg, mu_h, b=EN1991_B):
    """EN 1991-4 steep-hopper filling ratio ``F_f = 1 - b / (1 + tan(beta)/mu_h)``.

    ``beta_deg`` half-angle from the vertical in **degrees**, in (0, 90); ``mu_h`` hopper wall
    friction coefficient (not an angle), > 0; ``b`` = 0.2 by default.

    Source: EN 1991-4:2006 §6.3.2.  Tag: [V: kei-mp/blog silo.md; arturopala/encalmo].
    """
    be = _deg("beta_deg", beta_deg, 0.0, 90.0, lo_open=True, hi_open=True)
    mu_h = _positive("mu_h", mu_h)
    b = _nonneg("b", b)
    return _out(1.0 - b / (1.0 + np.tan(be) / mu_h))


def en1991_steep_filling_n(beta_deg, mu_h, b=EN1991_B, S=2):
    """EN 1991-4 steep-hopper filling exponent ``n = S (1 - b) mu_h cot(beta)``.

    With ``F = F_f`` the slice exponent ``S (F mu_h cot(beta) + F - 1)`` of
    :func:`hopper_n` equals ``S (1 - b) mu_h cot(beta)`` exactly, for a cone and a wedge
    alike [D], since ``F_f (1 + mu_h cot(beta)) = 1 + (1 - b) mu_h cot(beta)``.

    ``beta_deg`` in **degrees**, in (0, 90); ``mu_h`` coefficient; ``S`` 2 cone / 1 wedge.

    Source: EN 1991-4:2006 §6.3.2.  Tag: [V: kei-mp/blog silo.md; arturopala/encalmo].
    """
    be = _deg("beta_deg", beta_deg, 0.0, 90.0, lo_open=True, hi_open=True)
    mu_h = _positive("mu_h", mu_h)
    b = _nonneg("b", b)
    S = _positive("S", S)
    return _out(S * (1.0 - b) * mu_h / np.tan(be))


def en1991_steep_discharge_F(beta_deg, mu_h, phi_i):
    """EN 1991-4 steep-hopper discharge ratio F_e, with ``phi_wh = arctan(mu_h)``.

    ``F_e = (1 + sin(phi_i) cos(eps)) / (1 - sin(phi_i) cos(2 beta + eps))``,
    ``eps = phi_wh + arcsin(sin(phi_wh) / sin(phi_i))``; see :func:`walker_discharge_ratio`.

    ``beta_deg`` and ``phi_i`` (the solid's angle of internal friction) in **degrees**;
    ``mu_h`` a coefficient (not an angle) with ``arctan(mu_h) <= phi_i``.

    Source: EN 1991-4:2006 §6.3.3.  Tag: [V: kei-mp/blog silo.md; D: brute-force Mohr circle].
    """
    mu_h = _nonneg("mu_h", mu_h)
    return walker_discharge_ratio(phi_i, np.degrees(np.arctan(mu_h)), beta_deg)


def en1991_steep_discharge_n(beta_deg, mu_h, phi_i, S=2):
    """EN 1991-4 steep-hopper discharge exponent ``n = S (F_e mu_h cot(beta) + F_e - 1)``.

    For a cone (S = 2) this is the code's ``2 (F_e mu_h cot(beta) + F_e) - 2``; for a wedge
    (S = 1) it is the slice-equilibrium form of :func:`hopper_n`.
    Angles in **degrees**; ``mu_h`` a coefficient.  Source: EN 1991-4:2006 §6.3.3.
    Tag: cone [V: kei-mp/blog silo.md]; wedge [D] (see :func:`hopper_n`).
    """
    Fe = en1991_steep_discharge_F(beta_deg, mu_h, phi_i)
    return hopper_n(Fe, mu_h, beta_deg, S=S)


def en1991_shallow_mu_heff(beta_deg, K):
    """EN 1991-4 mobilised wall friction of a shallow hopper ``mu_heff = (1 - K)/(2 tan beta)``.

    ``beta_deg`` half-angle from the vertical in **degrees**, in (0, 90); ``K`` lower
    characteristic lateral pressure ratio, in (0, 1].

    Source: EN 1991-4:2006 eq. (6.28).  Tag: [V: Dlubal] (friction not fully mobilised).
    """
    be = _deg("beta_deg", beta_deg, 0.0, 90.0, lo_open=True, hi_open=True)
    K = _check("K", K, 0.0, 1.0, lo_open=True)
    return _out((1.0 - K) / (2.0 * np.tan(be)))


def en1991_shallow_F(beta_deg, K, b=EN1991_B):
    """EN 1991-4 shallow-hopper ratio ``F_s = 1 - b / (1 + tan(beta)/mu_heff)``.

    Angles in **degrees**; K as in :func:`en1991_shallow_mu_heff`; b = 0.2.
    Discharge loads in a shallow hopper equal the filling loads.

    Source: EN 1991-4:2006 §6.3.  Tag: [M].
    """
    be = _deg("beta_deg", beta_deg, 0.0, 90.0, lo_open=True, hi_open=True)
    b = _nonneg("b", b)
    mue = _arr(en1991_shallow_mu_heff(beta_deg, K))
    with np.errstate(divide="ignore"):
        return _out(1.0 - b / (1.0 + np.tan(be) / mue))


def en1991_shallow_n(beta_deg, K, b=EN1991_B, S=2):
    """EN 1991-4 shallow-hopper exponent ``n = S (1 - b) mu_heff cot(beta)``.

    Angles in **degrees**; K the lower characteristic ratio; S 2 cone / 1 wedge.

    Source: EN 1991-4:2006 §6.3.  Tag: [M].
    """
    be = _deg("beta_deg", beta_deg, 0.0, 90.0, lo_open=True, hi_open=True)
    b = _nonneg("b", b)
    S = _positive("S", S)
    mue = _arr(en1991_shallow_mu_heff(beta_deg, K))
    return _out(S * (1.0 - b) * mue / np.tan(be))


def en1991_hopper_vertical_stress(x, h_h, gamma, n, p_vft):
    """EN 1991-4 mean vertical stress in a hopper (every hopper class), Pa.

    ``p_v = gamma h_h/(n-1) [(x/h_h) - (x/h_h)^n] + p_vft (x/h_h)^n``.

    x (m) above the apex in [0, h_h]; h_h hopper height (m); gamma (N/m^3); n from the class
    functions; ``p_vft = C_b p_vf(h_c)`` the transition vertical stress (C_b = 1.0 for Action
    Assessment Class 2 without dynamic solids [V: Dlubal]).  No angles.

    Source: EN 1991-4:2006 §6.3.  Tag: [D] (same as :func:`hopper_vertical_stress`).
    """
    return hopper_vertical_stress(x, h_h, gamma, n, p_vft)


def en1991_hopper_pressures(
    x, h_h, beta_deg, gamma, K, mu_h, p_vft, mode="filling", phi_i=None, b=EN1991_B, S=2
):
    """EN 1991-4 hopper wall loads ``HopperPressures(p_n, p_t, p_v, hopper_class)`` (Pa).

    The class (:func:`en1991_hopper_class`) picks the formulas:

    * steep, filling: ``F = F_f``, ``n = S (1 - b) mu_h cot(beta)``, ``p_t = mu_h p_n``;
    * steep, discharge: ``F = F_e`` (needs ``phi_i``), ``n = S (F_e mu_h cot beta + F_e - 1)``,
      ``p_t = mu_h p_n``;
    * shallow (filling and discharge alike): ``F = F_s``, ``n = S (1 - b) mu_heff cot(beta)``,
      ``p_t = mu_heff p_n`` [M];
    * flat bottoms (beta > 85 deg) are not implemented (ValueError).

    Parameters
    ----------
    x : height above the apex (m), in [0, h_h].
    h_h : hopper height (m), > 0.
    beta_deg : hopper half-angle from the vertical, **degrees** (scalar or array).
    gamma : unit weight (N/m^3).
    K, mu_h : lower characteristic K and hopper wall friction coefficient (not an angle).
    p_vft : vertical stress at the transition, ``C_b p_vf(h_c)`` (Pa).
    mode : "filling" or "discharge".
    phi_i : the solid's angle of internal friction, **degrees**; required for steep discharge.
    b : 0.2.  S : 2 cone, 1 wedge.

    Source: EN 1991-4:2006 §6.  Tags as the component functions.
    """
    if mode not in ("filling", "discharge"):
        raise ValueError(f"mode must be 'filling' or 'discharge'; got {mode!r}")
    cls = en1991_hopper_class(beta_deg, K, mu_h)
    cls_arr = np.asarray(cls)
    if np.any(cls_arr == "flat"):
        raise ValueError("beta_deg > 85: flat-bottom loads are not implemented")
    steep = cls_arr == "steep"
    mu_h_a = _arr(mu_h)
    if mode == "discharge" and np.any(steep):
        if phi_i is None:
            raise ValueError("phi_i is required for steep-hopper discharge loads")
        F_steep = _arr(en1991_steep_discharge_F(beta_deg, mu_h, phi_i))
        n_steep = _arr(hopper_n(F_steep, mu_h, beta_deg, S=S))
    else:
        F_steep = _arr(en1991_steep_filling_F(beta_deg, mu_h, b=b))
        n_steep = _arr(en1991_steep_filling_n(beta_deg, mu_h, b=b, S=S))
    K_sh = np.minimum(_arr(K), 1.0)  # K > 1 is always steep; keep the unused branch finite
    F_shallow = _arr(en1991_shallow_F(beta_deg, K_sh, b=b))
    n_shallow = _arr(en1991_shallow_n(beta_deg, K_sh, b=b, S=S))
    mu_eff = np.where(steep, mu_h_a, _arr(en1991_shallow_mu_heff(beta_deg, K_sh)))
    F = np.where(steep, F_steep, F_shallow)
    n = np.where(steep, n_steep, n_shallow)
    p_v = _arr(hopper_vertical_stress(x, h_h, gamma, n, p_vft))
    p_n = F * p_v
    return HopperPressures(_out(p_n), _out(mu_eff * p_n), _out(p_v), cls)


# ---------------------------------------------------------------------------------------
# e. eccentric discharge: EN 1991-4's flow channel against the wall, AS 3774's rules
# ---------------------------------------------------------------------------------------

#: EN 1991-4's three flow-channel radii ``G = r_c / r`` for large-eccentricity discharge [M].
EN1991_ECCENTRIC_G = (0.25, 0.4, 0.6)


class ChannelGeometry(NamedTuple):
    """A circular flow channel in a circular silo: the contact half-angle ``theta_c`` and the
    angle ``psi`` (degrees), the wall contact ``U_wc`` and the channel's boundary with the
    stationary solid ``U_sc`` (m), the channel's area inside the silo ``A_c`` (m^2)."""

    theta_c: np.ndarray
    psi: np.ndarray
    U_wc: np.ndarray
    U_sc: np.ndarray
    A_c: np.ndarray


def eccentric_channel_geometry(r, r_c, e_c):
    """The geometry of a circular flow channel (radius ``r_c``, centre ``e_c`` off the axis)
    in a circular silo of radius ``r``: ``ChannelGeometry(theta_c, psi, U_wc, U_sc, A_c)``.

    With O the silo's axis, C the channel's centre and P a point where the two circles cross,
    ``theta_c`` is the angle at O between OC and OP (half the wall arc the channel covers) and
    ``psi = 180 deg - angle OCP``, so that

    * ``cos theta_c = (r^2 + e_c^2 - r_c^2) / (2 r e_c)``,
    * ``cos(180 deg - psi) = (e_c^2 + r_c^2 - r^2) / (2 e_c r_c)``,
    * ``U_wc = 2 theta_c r``, ``U_sc = 2 r_c (pi - psi)`` (angles in radians there),
    * ``A_c = (pi - psi) r_c^2 + theta_c r^2 - r r_c sin(psi - theta_c)``, the area of the
      overlap of the two discs (``r r_c sin(psi - theta_c) = r e_c sin(theta_c)`` is twice
      the area of the triangle OCP).

    EN 1991-4 writes ``psi`` as ``arcsin((r / r_c) sin theta_c)`` (the law of sines in OCP),
    which is the same angle when ``e_c^2 + r_c^2 <= r^2`` (angle OCP obtuse), always so for the
    standard's channel (:func:`en1991_eccentric_channel`); the cosine form here holds for any
    channel that meets the silo.  A channel inside the silo without touching its wall
    (``e_c <= r - r_c``) gives ``theta_c = psi = 0``, ``U_wc = 0``, ``U_sc = 2 pi r_c``,
    ``A_c = pi r_c^2``; one containing the silo (``e_c <= r_c - r``) gives 180 deg, the wall's
    perimeter and ``pi r^2``: the formulas run continuously into both.

    Parameters
    ----------
    r : the silo's radius (m), > 0.
    r_c : the channel's radius (m), > 0.
    e_c : the distance of the channel's centre from the silo's axis (m), >= 0, less than
        ``r + r_c`` (the channel must overlap the silo).

    Returns angles in **degrees**.

    Source: the geometry of EN 1991-4:2006 §5.2.4.3 (its equations for theta_c, psi, U_wc,
    U_sc and A_c, as coded in SadowskiAJ/AJSABQ_Input_File_Generator, AJSABQ_fwrite_load.m,
    which also codes the same A_c with ``R e_c sin theta_c`` for its own channel model in
    AJSABQ_silo_pressures.m).  Tag: [D] (the laws of cosines and sines in the triangle OCP;
    tested: the two circles cross at ``+-theta_c``, ``A_c`` equals a numerical integration
    of the overlap to 1e-6, the limits above).
    """
    r = _positive("r", r, " m")
    r_c = _positive("r_c", r_c, " m")
    e_c = _nonneg("e_c", e_c, " m")
    r, r_c, e_c = np.broadcast_arrays(r, r_c, e_c)
    if np.any(e_c >= r + r_c):
        bad = (e_c >= r + r_c)
        raise ValueError("e_c must be less than r + r_c (the channel must overlap the silo); "
                         f"got e_c = {_fmt(e_c[bad])} m")
    centred = e_c == 0.0
    safe_e = np.where(centred, 1.0, e_c)
    # half-angle forms of the two cosines (no digits lost near tangency):
    # 1 - cos theta_c = (r_c - r + e_c)(r_c + r - e_c) / (2 r e_c),
    # 1 - cos psi = (e_c + r_c - r)(e_c + r_c + r) / (2 e_c r_c)
    big = np.where(r_c < r, 0.0, 2.0)
    vers_t = np.where(centred, big, (r_c - r + e_c) * (r_c + r - e_c) / (2.0 * r * safe_e))
    vers_p = np.where(centred, big, (e_c + r_c - r) * (e_c + r_c + r) / (2.0 * safe_e * r_c))
    theta = 2.0 * np.arcsin(np.sqrt(np.clip(0.5 * vers_t, 0.0, 1.0)))
    psi = 2.0 * np.arcsin(np.sqrt(np.clip(0.5 * vers_p, 0.0, 1.0)))
    U_wc = 2.0 * theta * r
    U_sc = 2.0 * r_c * (np.pi - psi)
    A_c = (np.pi - psi) * r_c * r_c + theta * r * r - r * r_c * np.sin(psi - theta)
    return ChannelGeometry(_out(np.degrees(theta)), _out(np.degrees(psi)), _out(U_wc),
                           _out(U_sc), _out(A_c))


class EccentricChannel(NamedTuple):
    """EN 1991-4's eccentric flow channel: ``eta = mu / tan(phi_i)``, the eccentricity of the
    channel's centre ``e_c`` (m), and its geometry (:class:`ChannelGeometry`: ``theta_c``,
    ``psi`` in degrees, ``U_wc``, ``U_sc`` in m, ``A_c`` in m^2)."""

    eta: np.ndarray
    e_c: np.ndarray
    theta_c: np.ndarray
    psi: np.ndarray
    U_wc: np.ndarray
    U_sc: np.ndarray
    A_c: np.ndarray


def _eta(mu, phi_i):
    mu = _positive("mu", mu)
    ph = _deg("phi_i", phi_i, 0.0, 90.0, lo_open=True, hi_open=True)
    eta = mu / np.tan(ph)
    if np.any(eta > 1.0 + 1e-12):
        raise ValueError("mu must not exceed tan(phi_i) (eta = mu / tan(phi_i) <= 1: with a "
                         f"rougher wall no flow channel slides on it); got eta = "
                         f"{_fmt(eta[eta > 1.0 + 1e-12])}")
    return np.minimum(eta, 1.0)


def en1991_eccentric_channel(r, G, mu, phi_i):
    """EN 1991-4's flow channel for large-eccentricity discharge from a circular silo.

    For a channel of radius ``r_c = G r``:

    * ``eta = mu / tan(phi_i)``,
    * ``e_c = r [eta (1 - G) + (1 - eta) sqrt(1 - G)]``, the eccentricity of its centre,
    * ``cos theta_c = (1 - G^2 + eps^2) / (2 eps)``, ``eps = e_c / r``: the contact
      half-angle (the channel covers the wall over ``2 theta_c``),
    * ``sin psi = (r / r_c) sin theta_c``,
    * ``U_wc = 2 theta_c r``, ``U_sc = 2 r_c (pi - psi)``,
    * ``A_c = (pi - psi) r_c^2 + theta_c r^2 - r r_c sin(psi - theta_c)``
      (:func:`eccentric_channel_geometry`).

    ``eta`` lies in (0, 1], so ``1 - G <= e_c / r <= sqrt(1 - G)``: the channel always reaches
    the wall (``eta = 1`` just touches it, ``theta_c = 0``), its centre lies inside the silo
    and ``psi`` is the principal arcsine [D].  The two angles are computed in half-angle forms
    of the same equations (``1 - cos theta_c = (G^2 - (1 - eps)^2) / (2 eps)``, with
    ``1 - eps`` summed without cancellation), which keep their digits as ``G -> 0``.

    Parameters
    ----------
    r : the silo's radius (m), > 0.
    G : ``r_c / r``, in (0, 1); the standard takes 0.25, 0.4 and 0.6
        (:data:`EN1991_ECCENTRIC_G`).
    mu : wall friction coefficient (not an angle), the **lower** characteristic value, > 0,
        at most ``tan(phi_i)``.
    phi_i : the solid's angle of internal friction, **degrees**, the **upper** characteristic
        value, in (0, 90).

    Returns :class:`EccentricChannel` (angles in degrees).

    Source: EN 1991-4:2006 §5.2.4.3 (large-eccentricity discharge), eqs. (5.55)-(5.62) by the
    numbering quoted in the coding below.
    Tag: the formulas [V: as coded in SadowskiAJ/AJSABQ_Input_File_Generator,
    AJSABQ_fwrite_load.m, with the standard's equation numbers in its comments; they agree with
    the text as recalled here, the standard itself was not read]; worked values [V: a published
    worked example (mu = 0.491, phi_i = 33.6 deg, eta = 0.739) as reproduced for this project:
    e_c/r = 0.780, 0.646, 0.461 and theta_c = 7.74, 13.25, 22.33 deg at G = 0.25, 0.40, 0.60,
    held to 3 digits; the example's own text not read]; the geometry [D] (see
    :func:`eccentric_channel_geometry`); lower mu with upper phi_i [V: the coding uses the
    lower mu; M: upper phi_i, the coding has one phi_i]; the three G [M].
    """
    r = _positive("r", r, " m")
    G = _check("G", G, 0.0, 1.0, lo_open=True, hi_open=True)
    eta = _eta(mu, phi_i)
    # delta = 1 - e_c/r without cancellation (1 - sqrt(1 - G) = G / (1 + sqrt(1 - G)))
    delta = eta * G + (1.0 - eta) * G / (1.0 + np.sqrt(1.0 - G))
    eps = 1.0 - delta
    r, G, eps, eta, delta = np.broadcast_arrays(r, G, eps, eta, delta)
    # the standard's cos theta_c and arcsin psi in their half-angle forms, which keep their
    # digits as G -> 0: 1 - cos theta_c = (G^2 - delta^2) / (2 eps),
    # 1 - cos psi = (G - delta)(2 + G - delta) / (2 eps G)  (psi <= 90 deg here)
    vers_t = (G - delta) * (G + delta) / (2.0 * eps)
    vers_p = (G - delta) * (2.0 + G - delta) / (2.0 * eps * G)
    theta = 2.0 * np.arcsin(np.sqrt(np.clip(0.5 * vers_t, 0.0, 1.0)))
    psi = 2.0 * np.arcsin(np.sqrt(np.clip(0.5 * vers_p, 0.0, 1.0)))
    r_c = G * r
    A_c = (np.pi - psi) * r_c * r_c + theta * r * r - r * r_c * np.sin(psi - theta)
    return EccentricChannel(_out(eta), _out(eps * r), _out(np.degrees(theta)),
                            _out(np.degrees(psi)), _out(2.0 * theta * r),
                            _out(2.0 * r_c * (np.pi - psi)), _out(A_c))


def en1991_eccentric_z0(r, G, K, mu, phi_i):
    """EN 1991-4's characteristic depth of the eccentric flow channel (m):
    ``z_oc = (1/K) A_c / (U_wc mu + U_sc tan(phi_i))``.

    The channel's own Janssen depth: its wall contact ``U_wc`` carries ``mu`` and its boundary
    with the stationary solid ``U_sc`` carries ``tan(phi_i)``.  Parameters as
    :func:`en1991_eccentric_channel`, and ``K`` the lateral pressure ratio (> 0).

    Source: EN 1991-4:2006 §5.2.4.3, eq. (5.65) by the numbering quoted in
    SadowskiAJ/AJSABQ_Input_File_Generator.  Tag: [V: as coded there].  ``z_oc`` is below the
    silo's own ``z0 = r/(2 K mu)`` for every channel [D: ``tan phi_i >= mu`` and a region of
    a disc has ``A/U < r/2``], so the channel's pressure is below the filling pressure.
    """
    K = _positive("K", K)
    ch = en1991_eccentric_channel(r, G, mu, phi_i)
    tp = np.tan(np.radians(_arr(phi_i)))
    return _out(_arr(ch.A_c) / (K * (_arr(ch.U_wc) * _arr(mu) + _arr(ch.U_sc) * tp)))


class EccentricPressures(NamedTuple):
    """EN 1991-4's eccentric-discharge loads (Pa): in the channel's contact ``p_hce``,
    ``p_wce``; beside it ``p_hae``, ``p_wae``; and the filling pressure ``p_hf`` used."""

    p_hce: np.ndarray
    p_hae: np.ndarray
    p_wce: np.ndarray
    p_wae: np.ndarray
    p_hf: np.ndarray


def en1991_eccentric_pressures(z, gamma, r, G, K, mu, phi_i, p_hf=None):
    """EN 1991-4's wall loads for large-eccentricity discharge (Pa):
    ``EccentricPressures(p_hce, p_hae, p_wce, p_wae, p_hf)``.

    * ``p_hco = gamma K z_oc`` (:func:`en1991_eccentric_z0`),
    * in the channel's contact: ``p_hce = p_hco (1 - exp(-z / z_oc))``, ``p_wce = mu p_hce``,
    * beside it: ``p_hae = 2 p_hf - p_hce``, ``p_wae = mu p_hae``,

    so the mean of the two is the filling pressure ``p_hf`` at that depth, and ``p_hce <
    p_hf < p_hae`` [D].

    Parameters
    ----------
    z : depth below the equivalent surface (m), >= 0.
    gamma : unit weight (N/m^3), > 0.
    r, G, mu, phi_i : as :func:`en1991_eccentric_channel` (``phi_i`` in **degrees**).
    K : lateral pressure ratio, > 0.
    p_hf : the filling pressure on the wall at depth ``z`` (Pa, broadcast against ``z``); by
        default the slender silo's ``gamma K z0 (1 - exp(-z/z0))``, ``z0 = r/(2 K mu)``
        (:func:`en1991_filling_vertical_walls` with the same K and mu).  Pass the value of the
        code's own load combination (or of the intermediate-slenderness form) to use it.

    Source: EN 1991-4:2006 §5.2.4.3 (of these equations the coding below numbers only z_oc and
    p_hco, (5.65)-(5.66)).  Tag: [V: as coded in SadowskiAJ/AJSABQ_Input_File_Generator,
    AJSABQ_fwrite_load.m: ``phce = phco (1 - exp(-z/zoc))``, ``phae = 2 ph - phce``, the
    friction the lower mu times each]; the default ``p_hf`` [M: the standard's combination of
    characteristic values for it was not read].
    """
    z = _nonneg("z", z, " m")
    gamma = _positive("gamma", gamma, " N/m^3")
    K = _positive("K", K)
    z_oc = _arr(en1991_eccentric_z0(r, G, K, mu, phi_i))
    p_hce = gamma * K * z_oc * (-np.expm1(-z / z_oc))
    if p_hf is None:
        p_hf = _arr(en1991_filling_vertical_walls(z, gamma, 2.0 * _arr(r), K, mu).p_h)
    else:
        p_hf = _nonneg("p_hf", p_hf, " Pa")
    p_hae = 2.0 * p_hf - p_hce
    mu = _arr(mu)
    p_hce, p_hae, p_hf = np.broadcast_arrays(p_hce, p_hae, p_hf)
    return EccentricPressures(_out(p_hce), _out(p_hae), _out(mu * p_hce), _out(mu * p_hae),
                              _out(p_hf))


class EccentricPattern(NamedTuple):
    """The circumferential pattern of EN 1991-4's eccentric discharge: the normal pressure
    ``p_h`` and the friction ``p_w`` (Pa), and the ``zone`` (0 away from the channel, 1 the
    channel's contact, 2 the adjacent zones)."""

    p_h: np.ndarray
    p_w: np.ndarray
    zone: np.ndarray


#: EN 1991-4's critical eccentricities of the outlet and of the filling over the silo's
#: diameter, ``e_o,cr / d_c = e_f,cr / d_c`` [M].
EN1991_CRITICAL_ECCENTRICITY = 0.25


def en1991_large_eccentricity(e_o, d_c, e_f=0.0):
    """Whether EN 1991-4 calls for its large-eccentricity procedures (the eccentric flow
    channel of :func:`en1991_eccentric_channel` for discharge): the outlet's eccentricity
    ``e_o`` or the filling's ``e_f`` (m, >= 0) above ``0.25 d_c`` (``d_c`` the silo's diameter,
    m, > 0), :data:`EN1991_CRITICAL_ECCENTRICITY`.  Below it, the standard's symmetrical loads
    with their patch loads cover the eccentricity.  Returns a boolean array (numpy scalar).

    Source: EN 1991-4:2006 §5.2.4.1 (the critical eccentricities ``e_o,cr = e_f,cr =
    0.25 d_c`` for slender silos).  Tag: **[M]** the threshold as recalled, the standard's text
    not read; consistent with ENV 1991-4's scope, whose rules stop at ``e_o < 0.25 d_c``
    [V: as quoted on eurocode.us], and with EN 1991-4's Action Assessment Class 3 for an
    eccentric discharge beyond 25 % of the diameter [V: as tabulated by J. Carson and D.
    Craig (2015), Procedia Engineering 102, 647-656, Table 1]; which silos (slender, which
    classes) the procedure is required for is not encoded here.
    """
    d_c = _positive("d_c", d_c, " m")
    e_o, e_f = _nonneg("e_o", e_o, " m"), _nonneg("e_f", e_f, " m")
    limit = EN1991_CRITICAL_ECCENTRICITY * d_c
    return _out((e_o > limit) | (e_f > limit))


def en1991_eccentric_wall_pressure(theta_deg, z, gamma, r, G, K, mu, phi_i, p_hf=None,
                                   theta_0=0.0):
    """EN 1991-4's wall pressure around a circular silo in large-eccentricity discharge,
    ``EccentricPattern(p_h, p_w, zone)`` at the angles ``theta_deg`` and depths ``z``.

    With ``d = |theta - theta_0|`` (wrapped to [0, 180] deg) and ``theta_c`` of
    :func:`en1991_eccentric_channel`:

    * ``d <= theta_c``: the channel's contact (zone 1), ``p_hce`` and ``p_wce``;
    * ``theta_c < d <= 2 theta_c``: the adjacent zones (zone 2), each of the width
      ``theta_c`` of half the channel's contact, ``p_hae`` and ``p_wae``;
    * elsewhere (zone 0): the filling pressure ``p_hf`` and ``mu p_hf``.

    Parameters
    ----------
    theta_deg : angle around the silo, **degrees** (any real; wrapped).
    z : depth below the equivalent surface (m), >= 0; broadcast against ``theta_deg``.
    gamma, r, G, K, mu, phi_i, p_hf : as :func:`en1991_eccentric_pressures`.
    theta_0 : the angle of the channel's centre (the outlet's side), **degrees**; default 0
        (the package's wall angle is 0 towards the outlet's offset).

    The wall friction away from the channel is ``mu p_hf`` with this function's ``mu`` (the
    filling case's own friction is :func:`en1991_filling_vertical_walls`'s).

    Source: EN 1991-4:2006 §5.2.4.3 and its figure of the pressure pattern.  Tag: the zones and
    the adjacent zones' width ``theta_c`` [V: as coded in SadowskiAJ/AJSABQ_Input_File_Generator,
    AJSABQ_fwrite_load.m, channel within ``+-theta_c`` of its centre and "ears" from
    ``theta_c`` to ``2 theta_c`` either side; the standard's figure was not read]; the
    pressures as :func:`en1991_eccentric_pressures`.
    """
    d = _angle_from(_arr(theta_deg) - _arr(theta_0))
    ch = en1991_eccentric_channel(r, G, mu, phi_i)
    p = en1991_eccentric_pressures(z, gamma, r, G, K, mu, phi_i, p_hf=p_hf)
    tc = _arr(ch.theta_c)
    d, tc, p_hce, p_hae, p_hf_ = np.broadcast_arrays(d, tc, _arr(p.p_hce), _arr(p.p_hae),
                                                     _arr(p.p_hf))
    zone = np.where(d <= tc, 1, np.where(d <= 2.0 * tc, 2, 0))
    p_h = np.choose(zone, [p_hf_, p_hce, p_hae])
    return EccentricPattern(_out(p_h), _out(_arr(mu) * p_h), _out(zone))


def _angle_from(delta_deg):
    """``|delta|`` wrapped to [0, 180] degrees (values already in [-180, 180] untouched, so a
    zone's edge is exact)."""
    x = np.abs(delta_deg)
    return np.where(x <= 180.0, x, np.abs((delta_deg + 180.0) % 360.0 - 180.0))


class AS3774Eccentricity(NamedTuple):
    """AS 3774's eccentric-outlet constants: ``ratio = e_o / d_c``, the pressure factor
    ``f = max(ratio - 0.1, 0)`` (the far side's increase is ``f p_nf``, the near side's
    reduction ``1.5 f p_nf``), the height ``h_D`` (m) above the outlet at which the far side's
    band is centred, and the near side's half-width ``beta_e`` (degrees)."""

    ratio: np.ndarray
    factor: np.ndarray
    h_D: np.ndarray
    beta_e: np.ndarray


def as3774_eccentricity(e_o, d_c, phi_i):
    """AS 3774's constants for an eccentric outlet: ``AS3774Eccentricity(ratio, factor, h_D,
    beta_e)``.

    * no eccentricity effect below ``e_o = 0.1 d_c``: ``factor = max(e_o/d_c - 0.1, 0)``;
    * the far side's band is centred ``h_D = (0.5 d_c + e_o) tan(phi_i)`` above the outlet;
    * the near side's reduction spans ``beta_e = 105 - 150 e_o/d_c`` degrees either side of the
      near side (the angular form of a distance ``d_e / 2`` along the wall either side,
      ``d_e = 1.83 d_c (1 - 1.43 e_o/d_c)``: the two agree within 0.4 % (0.0013 d_c along
      the wall) for ``0.1 <= e_o/d_c <= 0.5`` when ``beta_e`` is each side's angle [D]).

    Parameters
    ----------
    e_o : the outlet's eccentricity (m), >= 0, at most ``d_c / 2``.
    d_c : the silo's diameter (m), > 0.
    phi_i : the solid's angle of internal friction, **degrees**, the upper characteristic
        value, in (0, 90).

    Source: AS 3774-1996 (with amendments 1 and 2), Cl 6.5 (eccentric discharge), eqs.
    6.5.2.2(2), 6.5.2.3(1)-(3).  Tag: [V: transcribed in a public engineering-notes file that
    summarises AS 3774-1996 Cl 6.5 from the standard (the repository was not identified by the
    search index); not checked against the standard's text]; the reading of ``beta_e`` as each
    side's angle [D: the agreement with ``d_e`` above].
    """
    d_c = _positive("d_c", d_c, " m")
    e_o = _nonneg("e_o", e_o, " m")
    ph = _deg("phi_i", phi_i, 0.0, 90.0, lo_open=True, hi_open=True)
    e_o, d_c = np.broadcast_arrays(e_o, d_c)
    if np.any(e_o > 0.5 * d_c):
        raise ValueError("e_o must lie in [0, d_c/2] (the outlet's centre inside the silo); "
                         f"got e_o = {_fmt(e_o[e_o > 0.5 * d_c])} m")
    ratio = e_o / d_c
    return AS3774Eccentricity(_out(ratio), _out(np.maximum(ratio - 0.1, 0.0)),
                              _out((0.5 * d_c + e_o) * np.tan(ph)),
                              _out(105.0 - 150.0 * ratio))


def as3774_eccentric_increment(theta_deg, h, p_nf, e_o, d_c, phi_i):
    """AS 3774's increment to the wall's normal flow pressure for an eccentric outlet (Pa;
    positive an increase), at angle ``theta_deg`` from the near side and height ``h`` above the
    outlet.

    With ``f = max(e_o/d_c - 0.1, 0)``, ``h_D`` and ``beta_e`` of :func:`as3774_eccentricity`:

    * far side, ``90 <= |theta| <= 180`` deg and ``|h - h_D| <= d_c/2`` (a band of height
      ``d_c`` centred at ``h_D``): ``+ f p_nf (-cos theta)``, largest, ``f p_nf``, opposite the
      outlet;
    * near side, ``|theta| <= beta_e`` and ``0 <= h <= d_c`` (from the outlet up over
      ``d_c``): ``- 1.5 f p_nf``, uniform;
    * zero elsewhere, and everywhere for ``e_o <= 0.1 d_c``.

    Parameters
    ----------
    theta_deg : angle around the silo from the near side (the outlet's side), **degrees**
        (any real; wrapped): the package's wall angle.
    h : height above the outlet (m).
    p_nf : the symmetric flow pressure on the wall (Pa, >= 0), broadcast against ``h`` (a
        value per height, or one value).
    e_o, d_c, phi_i : as :func:`as3774_eccentricity` (``phi_i`` in **degrees**).

    Source: AS 3774-1996 Cl 6.5.2.2 (far side) and 6.5.2.3 (near side), Fig. 6.12.
    Tag: the rules [V: as transcribed in the notes file of :func:`as3774_eccentricity`, not
    checked against the standard's text]; uniform in height over each band, and ``p_nf`` taken
    at the height considered [M: the figure's height variation and which height's ``p_nf`` is
    meant were not read].
    """
    p_nf = _nonneg("p_nf", p_nf, " Pa")
    c = as3774_eccentricity(e_o, d_c, phi_i)
    h = _arr(h)
    d = _angle_from(_arr(theta_deg))
    minus_cos = np.maximum(-np.cos(np.radians(d)), 0.0)    # exactly 0 at 90 deg
    f = _arr(c.factor)
    far = (d >= 90.0) & (np.abs(h - _arr(c.h_D)) <= 0.5 * _arr(d_c))
    near = (d <= _arr(c.beta_e)) & (h >= 0.0) & (h <= _arr(d_c))
    inc = np.where(far, f * p_nf * minus_cos, 0.0) - np.where(near, 1.5 * f * p_nf, 0.0)
    return _out(inc + 0.0)


# ---------------------------------------------------------------------------------------
# g. cohesive powders: arching and ratholing (Jenike's method)
# ---------------------------------------------------------------------------------------


def unconfined_yield_strength(c, phi_deg):
    """Unconfined yield strength ``sigma_c = 2 c cos(phi) / (1 - sin(phi))`` (Pa).

    The uniaxial compressive strength of a Mohr-Coulomb material with cohesion c and
    friction angle phi; the same as ``2 c tan(45 + phi/2)``.

    Parameters
    ----------
    c : cohesion (Pa), >= 0.
    phi_deg : friction angle, **degrees**, in [0, 90).

    Source: the Mohr-Coulomb criterion ``sigma_1 - sigma_3 = (sigma_1 + sigma_3) sin(phi)
    + 2 c cos(phi)`` at ``sigma_3 = 0``.  Tag: [D] (also the uniaxial-compression point,
    Theta = pi/3, of the Abaqus form ``R_mc q - p tan(phi) - c = 0`` that the simulation
    uses: a test checks both).
    """
    c = _nonneg("c", c, " Pa")
    ph = _deg("phi_deg", phi_deg, 0.0, 90.0, hi_open=True)
    return _out(2.0 * c * np.cos(ph) / (1.0 - np.sin(ph)))


def jenike_arching_H(theta_deg, geometry="conical"):
    """Jenike's arching function H(theta) in ``D_crit = H(theta) sigma_c / (rho_b g)``.

    * ``geometry="conical"`` (circular outlet): ``H = 2 + theta/60`` (theta in degrees).
    * ``geometry="plane"`` (slot outlet, B the slot width): ``H = 1 + theta/180``.

    Parameters
    ----------
    theta_deg : hopper half-angle from the vertical, **degrees**, in [0, 90).  Jenike's
        function is drawn for mass-flow hopper angles (up to about 60 deg for plane flow,
        less for cones); the linear fits are not checked beyond that [M].
    geometry : ``"conical"`` or ``"plane"``.

    Source: Jenike (1964), Bulletin 123 (the H(theta) chart).  Tag: conical fit
    [V: the Rhodes hopper-design worked example, "H(theta) = 2.0 + theta/60 = 2.46" at
    theta = 27.5 deg; also as coded in Tornado128/hoppers_performance_checking,
    D_arch_passive_estimation.py, after Leung et al. 2019; another file of that repository
    uses (130 + theta)/65 = 2 + theta/65, within 1.6 % of it for theta <= 30 deg];
    plane fit [M] (its end value H(0) = 1 matches Schulze's simplified slot rule, see
    :func:`critical_outlet_simplified`; the slope is unverified).
    """
    _geometry(geometry)
    th = _check("theta_deg", theta_deg, 0.0, 90.0, hi_open=True, unit=" deg")
    if geometry == "conical":
        return _out(2.0 + th / 60.0)
    return _out(1.0 + th / 180.0)


def jenike_critical_outlet(sigma_c, rho_b, theta_deg, geometry="conical", g=G):
    """Jenike's critical outlet size (m) against a cohesive arch in a mass-flow hopper.

    ``D_crit = H(theta) sigma_c / (rho_b g)`` (:func:`jenike_arching_H`): the outlet
    diameter (cone) or slot width (plane) above which no stable arch forms.  sigma_c is the
    unconfined yield strength *at the critical consolidation stress* (where the flow function
    meets the hopper flow factor); for a Mohr-Coulomb continuum with a constant cohesion it
    does not depend on the stress, and :func:`unconfined_yield_strength` gives it.

    Parameters
    ----------
    sigma_c : unconfined yield strength (Pa), >= 0.
    rho_b : bulk density (kg/m^3), > 0.
    theta_deg : hopper half-angle from the vertical, **degrees**, in [0, 90).
    geometry : ``"conical"`` or ``"plane"``.
    g : gravitational acceleration (m/s^2), > 0.

    Source: Jenike (1964), Bulletin 123.  Tag: the form [V: Rhodes worked example,
    ``B_min = H(theta) sigma_crit / (rho_b g) = 2.46 x 0.83 kPa / (1300 x 9.81) = 0.16 m``;
    Leung et al. 2019 as coded in Tornado128]; H as :func:`jenike_arching_H`.
    Jenike's arching criterion is known to be conservative.
    """
    sigma_c = _nonneg("sigma_c", sigma_c, " Pa")
    rho_b = _positive("rho_b", rho_b, " kg/m^3")
    g = _positive("g", g, " m/s^2")
    H = _arr(jenike_arching_H(theta_deg, geometry))
    return _out(H * sigma_c / (rho_b * g))


def critical_outlet_simplified(sigma_c, rho_b, geometry="conical", g=G):
    """Simplified critical outlet size (m): ``2 sigma_c/(rho_b g)`` (circular),
    ``sigma_c/(rho_b g)`` (slot width).

    Jenike's rule with H at its theta = 0 value (H = 2 for a circular outlet, 1 for a slot);
    no hopper angle enters, so it is the estimate for a flat-bottomed bin or a quick check.
    A frictionless cohesive solid (sigma_c = 2 tau_0) gives ``4 tau_0 / (rho_b g)`` for a
    circular outlet [D].

    Parameters
    ----------
    sigma_c : unconfined yield strength (Pa), >= 0.
    rho_b : bulk density (kg/m^3), > 0.
    geometry : ``"conical"`` (circular outlet) or ``"plane"`` (slot).
    g : gravitational acceleration (m/s^2), > 0.

    Source: D. Schulze, *Powders and Bulk Solids*, eqs. (10.6a) slot and (10.6b) circular.
    Tag: [V: as transcribed in tli2025/silo_design, pages/4_Results.py]; its use for
    flat-bottomed bins [M].
    """
    sigma_c = _nonneg("sigma_c", sigma_c, " Pa")
    rho_b = _positive("rho_b", rho_b, " kg/m^3")
    g = _positive("g", g, " m/s^2")
    H = 2.0 if _geometry(geometry) == "conical" else 1.0
    return _out(H * sigma_c / (rho_b * g))


#: Range of the friction angle (deg) over which the rathole G fit has been checked.
_RATHOLE_PHI_RANGE = (30.0, 70.0)


def jenike_rathole_G(phi_deg):
    """Jenike's rathole function G(phi) (cubic fit of the Bulletin 123 chart).

    ``G = -6.86712 + 0.58911 phi - 0.012966 phi^2 + 0.00011939 phi^3`` (phi in degrees).

    Parameters
    ----------
    phi_deg : static angle of internal friction (Jenike's phi_t; phi for a Mohr-Coulomb
        material), **degrees**, in [30, 70], the range over which the fit is checked.

    Source: Jenike (1964), Bulletin 123, p. 67 (chart).  Tag: the cubic [V: as coded in
    Tornado128/hoppers_performance_checking, rathole_diameter_estimation.py, after Leung et
    al. 2019]; [D: within 1.4 % of a digitisation of the same function in Schulze's
    *Powders and Bulk Solids* Fig. 10.19, f(phi_i), at phi = 30, 35, ..., 70 deg
    (tli2025/silo_design, app_utils.py)].  G(30) = 2.36, G(40) = 3.59.
    """
    ph = _check("phi_deg", phi_deg, *_RATHOLE_PHI_RANGE, unit=" deg")
    return _out(-6.86712 + ph * (0.58911 + ph * (-0.012966 + ph * 0.00011939)))


def jenike_rathole_diameter(sigma_c, rho_b, phi_deg, g=G):
    """Jenike's critical rathole diameter (m): ``D_f = G(phi) sigma_c / (rho_b g)``.

    A funnel-flow bin whose outlet (or flow channel) is smaller than D_f can leave a stable
    empty rathole; an outlet larger than D_f clears it.  sigma_c is the unconfined yield
    strength at the consolidation stress in the bin (constant for a Mohr-Coulomb continuum,
    :func:`unconfined_yield_strength`).

    Parameters
    ----------
    sigma_c : unconfined yield strength (Pa), >= 0.
    rho_b : bulk density (kg/m^3), > 0.
    phi_deg : static angle of internal friction, **degrees**, in [30, 70].
    g : gravitational acceleration (m/s^2), > 0.

    Source: Jenike (1964), Bulletin 123; Leung et al. (2019) eq. 22.  Tag: form
    [V: as coded in Tornado128/hoppers_performance_checking, and the same form with
    Schulze's f(phi_i) in tli2025/silo_design]; G as :func:`jenike_rathole_G`.  Jenike's
    rathole criterion is known to be conservative (more so than the arching one).
    """
    sigma_c = _nonneg("sigma_c", sigma_c, " Pa")
    rho_b = _positive("rho_b", rho_b, " kg/m^3")
    g = _positive("g", g, " m/s^2")
    return _out(_arr(jenike_rathole_G(phi_deg)) * sigma_c / (rho_b * g))
