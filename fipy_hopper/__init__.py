"""fipy_hopper: Eulerian Mohr-Coulomb simulation of granular discharge from conical hoppers.

Units are SI throughout (m, s, kg, Pa); angles are given in degrees at the configuration
boundary and used in radians inside.  Stress arrays have shape ``(..., 4)`` in the order
``(rr, zz, tt, rz)``, tension positive.
"""

__version__ = "0.1.0"

from .config import ConfigError, HopperConfig, ResolutionWarning  # noqa: E402
from .api import Results, load_config, read_results, run  # noqa: E402
