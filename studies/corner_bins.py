"""The wall-pressure bins beside the cone-bin transition of the reference hopper at rest, per
cell size, and Coulomb's ratio in every bin (docs/physics_and_numerics.md, section 4, "Wall
contact"): the bin wall's first bin above the transition against the next, the cone's last
bin, and the largest |tau| / (tan phi_w p_n) on the cone and on the bin wall, at rest and,
with ``--discharge T``, in every stage of T seconds of discharge.

    python studies/corner_bins.py                       # 7.5, 5, 3.75 and 2.5 mm at rest
    python studies/corner_bins.py --cells 0.005 --discharge 1.6

It prints; it writes nothing.  About 2 minutes of CPU for the four fills.
"""

from __future__ import annotations

import argparse
import math
import warnings

import numpy as np

from fipy_hopper import geometry
from fipy_hopper.config import HopperConfig
from fipy_hopper.model import HopperModel
from fipy_hopper.simulation import Simulation


def reference(cell_size: float, end_time: float) -> HopperConfig:
    raw = HopperConfig().to_dict()
    raw["numerics"]["cell_size"] = cell_size
    raw["run"].update({"end_time": end_time, "markers_per_side": 0})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return HopperConfig.from_dict(raw)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cells", type=float, nargs="+",
                        default=[0.0075, 0.005, 0.00375, 0.0025], help="cell sizes (m)")
    parser.add_argument("--discharge", type=float, default=0.0,
                        help="seconds of discharge after the fill (0: the fill only)")
    args = parser.parse_args()
    first = {}
    for h in args.cells:
        cfg = reference(h, args.discharge)
        sim = Simulation(HopperModel(cfg, threads=1), progress=False)
        sim.run()
        mu = math.tan(math.radians(cfg.wall.friction_angle_deg))
        s_t = float(geometry.transition_arc_length(cfg.hopper))
        for stage, (_, s, _, _, p, tau) in sim.record.wall.items():
            if stage == "discharge_envelope":
                continue
            k = int(np.flatnonzero(s > s_t)[0])
            loaded = p > 0
            ratio = np.abs(tau) / (mu * np.where(loaded, p, 1.0))
            cone = loaded & (s < s_t)
            bin_wall = loaded & (s > s_t)
            print(f"{h * 1000:g} mm {stage}: bin wall's first bin {p[k]:.1f} Pa, next "
                  f"{p[k + 1]:.1f} Pa ({p[k] / p[k + 1] - 1:+.2%}); cone's last bin "
                  f"{p[k - 1]:.1f} Pa; max |tau|/(tan phi_w p_n) cone "
                  f"{ratio[cone].max():.6f}, bin wall {ratio[bin_wall].max():.6f}")
            if stage == "filling":
                first[h] = p[k]
    sizes = sorted(first, reverse=True)
    for a, b in zip(sizes[:-1], sizes[1:]):
        print(f"first bin {a * 1000:g} -> {b * 1000:g} mm: {first[a] / first[b] - 1:+.2%}")


if __name__ == "__main__":
    main()
