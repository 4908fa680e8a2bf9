"""Element tests of the Mohr–Coulomb material: stress paths, yield surface, failure deviators.

Runs drained triaxial compression and extension, simple shear and oedometric loading on one
material point (:func:`fipy_hopper.material.element_test`) for several confinements and writes

* ``meridional.png``: the paths in the (p, q) plane with the compression and extension meridians
  of the yield surface, q = 6 sin(phi)(p + c cot(phi))/(3 -+ sin(phi)), and the flow potential's
  hyperbola through the first compression failure point;
* ``deviatoric.png``: the Mohr–Coulomb hexagon and the Menetrey–Willam section of G in the
  deviatoric plane (normalised by p + c cot(phi)), with the failure states;
* ``stress_strain.png``: q and the volumetric strain against the controlled strain;
* ``failure_deviators.csv``: the failure deviator of every triaxial test against its closed form.

Usage: ``python studies/element_tests.py --out DIR`` (refuses a non-empty DIR unless --overwrite).
"""

from __future__ import annotations

import argparse
import csv
import math
import pathlib
import sys

import numpy as np

from fipy_hopper.material import PATHS, MohrCoulomb, R_mc, R_mw, element_test

DEFAULTS = {
    "E": 10e6,  # Pa
    "nu": 0.3,
    "rho": 1500.0,  # kg/m3
    "phi": 30.0,  # deg
    "psi": 5.0,  # deg
    "c": 0.0,  # Pa
    "confinements": (50e3, 100e3, 200e3),  # initial isotropic pressures p0 (Pa)
    "strain": 0.05,  # axial strain magnitude; the engineering shear strain in simple shear is 4x
    "n_steps": 100,
}
OUTPUTS = ("meridional.png", "deviatoric.png", "stress_strain.png", "failure_deviators.csv")
CLOSED_FORM_SIGN = {"triaxial_compression": -1.0, "triaxial_extension": +1.0}  # 3 -+ sin(phi)


def failure_deviator(mat: MohrCoulomb, p, path):
    """Closed-form q at failure: 6 sin(phi) (p + c cot(phi)) / (3 -+ sin(phi)) (Pa)."""
    s = math.sin(mat.phi_rad)
    return 6.0 * s * (p + mat.apex_stress) / (3.0 + CLOSED_FORM_SIGN[path] * s)


def setup(**options):
    """Run every path at every confinement; returns a dict with the options, the material, the
    results keyed by (path, p0) and the failure table (a list of dicts)."""
    unknown = set(options) - set(DEFAULTS)
    if unknown:
        raise TypeError(f"unknown options {sorted(unknown)}; known: {sorted(DEFAULTS)}")
    opts = {**DEFAULTS, **options}
    mat = MohrCoulomb(**{k: opts[k] for k in ("E", "nu", "rho", "phi", "psi", "c")})
    results, failure = {}, []
    for p0 in opts["confinements"]:
        for path in PATHS:
            strain = opts["strain"] * (4.0 if path == "simple_shear" else 1.0)
            res = element_test(mat, path, -p0, strain, opts["n_steps"])
            results[(path, p0)] = res
            if path in CLOSED_FORM_SIGN:
                p, q, _, _ = res.invariants
                q_cf = failure_deviator(mat, p[-1], path)
                failure.append({"path": path, "p0_Pa": p0, "p_f_Pa": p[-1], "q_f_Pa": q[-1],
                                "q_closed_form_Pa": q_cf, "rel_error": abs(q[-1] - q_cf) / q_cf,
                                "failed": bool(res.status[-1] > 0)})
    return {"options": opts, "material": mat, "results": results, "failure": failure}


def write_csv(data, path):
    rows = data["failure"]
    with open(path, "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


def _figure(ncols=1):
    from matplotlib.figure import Figure  # Agg canvas, no display needed

    fig = Figure(figsize=(6.0 * ncols, 5.0), layout="constrained")
    return fig, [fig.add_subplot(1, ncols, i + 1) for i in range(ncols)]


COLOURS = {"triaxial_compression": "C0", "triaxial_extension": "C1", "simple_shear": "C2",
           "oedometric": "C3"}


def plot_meridional(data, path):
    mat, results = data["material"], data["results"]
    fig, (ax,) = _figure()
    p_max = max(res.invariants[0].max() for res in results.values()) * 1.1
    p = np.linspace(-mat.apex_stress, p_max, 200)
    for name, sign, style in (("compression", -1.0, "k-"), ("extension", 1.0, "k--")):
        ax.plot(p, [failure_deviator(mat, pi, f"triaxial_{name}") for pi in p], style,
                label=f"F = 0, {name} meridian")
    res = results[("triaxial_compression", data["options"]["confinements"][0])]
    pf, qf = res.invariants[0][-1], res.invariants[1][-1]
    rw = float(R_mw(math.pi / 3, mat.e, mat.phi_rad))
    a, tp = mat.flow_hyperbola, math.tan(mat.psi_rad)
    g0 = math.hypot(a, rw * qf) - pf * tp
    pg = p[(g0 + p * tp) >= a]
    ax.plot(pg, np.sqrt((g0 + pg * tp) ** 2 - a * a) / rw, ":", color="grey",
            label="G = const through a failure point (compression)")
    for (name, p0), res in results.items():
        pp, qq, _, _ = res.invariants
        ax.plot(pp, qq, color=COLOURS[name], lw=1.2,
                label=name.replace("_", " ") if p0 == data["options"]["confinements"][0] else None)
    ax.set(xlabel="p (Pa)", ylabel="q (Pa)", xlim=(min(0.0, -mat.apex_stress), p_max), ylim=(0, None),
           title=f"Meridional plane, phi = {mat.phi:g} deg, psi = {mat.psi:g} deg, c = {mat.c:g} Pa")
    ax.legend(fontsize=8)
    fig.savefig(path, dpi=120)


def plot_deviatoric(data, path):
    mat, results = data["material"], data["results"]
    fig, (ax,) = _figure()
    ang = np.linspace(0.0, 2.0 * np.pi, 721)
    fold = np.abs(np.mod(ang + np.pi / 3, 2 * np.pi / 3) - np.pi / 3)  # Lode angle, 0 = extension
    q_mc = math.tan(mat.phi_rad) / R_mc(fold, mat.phi_rad)  # q/(p + c cot phi) on F = 0
    q_mw = q_mc[0] * R_mw(0.0, mat.e, mat.phi_rad) / R_mw(fold, mat.e, mat.phi_rad)
    ax.plot(q_mc * np.cos(ang), q_mc * np.sin(ang), "k-", label="yield surface (MC hexagon)")
    ax.plot(q_mw * np.cos(ang), q_mw * np.sin(ang), "--", color="grey",
            label=f"flow potential (MW, e = {mat.e:.3f})")
    for (name, p0), res in results.items():
        pp, qq, _, th = res.invariants
        rr = qq / (pp + mat.apex_stress)
        ax.plot(rr * np.cos(th), rr * np.sin(th), ".", ms=3, color=COLOURS[name],
                label=name.replace("_", " ") if p0 == data["options"]["confinements"][0] else None)
    ax.set_aspect("equal")
    ax.set(xlabel="q cos(Theta) / (p + c cot phi)", ylabel="q sin(Theta) / (p + c cot phi)",
           title="Deviatoric plane (Theta = 0: extension, pi/3: compression)")
    ax.legend(fontsize=8, loc="lower left")
    fig.savefig(path, dpi=120)


def plot_stress_strain(data, path):
    results = data["results"]
    fig, (a1, a2) = _figure(2)
    for (name, p0), res in results.items():
        comp = 3 if name == "simple_shear" else 1
        x = np.abs(res.strain[:, comp]) * (2.0 if comp == 3 else 1.0)
        lab = name.replace("_", " ") if p0 == data["options"]["confinements"][0] else None
        a1.plot(x, res.invariants[1], color=COLOURS[name], label=lab)
        a2.plot(x, res.volumetric(res.strain), color=COLOURS[name], label=lab)
    a1.set(xlabel="|controlled strain| (axial, or gamma_rz)", ylabel="q (Pa)")
    a2.set(xlabel="|controlled strain| (axial, or gamma_rz)", ylabel="volumetric strain (+ = dilation)")
    a1.legend(fontsize=8)
    fig.savefig(path, dpi=120)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", required=True, type=pathlib.Path, help="output directory")
    parser.add_argument("--overwrite", action="store_true", help="allow a non-empty output directory")
    for key in ("phi", "psi", "c", "strain"):
        parser.add_argument(f"--{key}", type=float, default=DEFAULTS[key])
    parser.add_argument("--n-steps", type=int, default=DEFAULTS["n_steps"])
    args = parser.parse_args(argv)
    out = args.out
    if out.exists() and any(out.iterdir()) and not args.overwrite:
        parser.error(f"output directory {out} is not empty (use --overwrite)")
    out.mkdir(parents=True, exist_ok=True)
    data = setup(phi=args.phi, psi=args.psi, c=args.c, strain=args.strain, n_steps=args.n_steps)
    write_csv(data, out / "failure_deviators.csv")
    plot_meridional(data, out / "meridional.png")
    plot_deviatoric(data, out / "deviatoric.png")
    plot_stress_strain(data, out / "stress_strain.png")
    worst = max(row["rel_error"] for row in data["failure"])
    print(f"element tests written to {out}: {len(data['failure'])} triaxial failure deviators, "
          f"largest relative error against the closed form {worst:.1e}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
