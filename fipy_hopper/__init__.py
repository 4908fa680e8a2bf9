"""fipy_hopper: Eulerian Mohr-Coulomb simulation of granular flow in silos and hoppers.

Units are SI throughout (m, s, kg, Pa); angles are given in degrees at the configuration
boundary and used in radians inside.  Stress arrays have shape ``(..., 4)`` in the order
``(rr, zz, tt, rz)``, tension positive.
"""

__version__ = "0.1.0"

import os as _os
import sys as _sys
import tempfile as _tempfile


def _writable_dir(path: str) -> bool:
    """True if ``path`` is (or can be made) a directory this process can create files in
    (the test numba's cache locators make)."""
    try:
        _os.makedirs(path, exist_ok=True)
        _tempfile.TemporaryFile(dir=path).close()
        return True
    except OSError:
        return False


def _private_temp_dir(parent: str) -> str:
    """``parent/fipy_hopper-numba-<uid>``, a directory of this user only; a fresh one if that
    name is taken by someone else (or is a link)."""
    uid = _os.getuid() if hasattr(_os, "getuid") else 0
    path = _os.path.join(parent, f"fipy_hopper-numba-{uid}")
    try:
        _os.makedirs(path, mode=0o700, exist_ok=True)
        st = _os.lstat(path)
        import stat
        if stat.S_ISDIR(st.st_mode) and st.st_uid == uid and _writable_dir(path):
            return path
    except OSError:
        pass
    return _tempfile.mkdtemp(prefix="fipy_hopper-numba-", dir=parent)


def _numba_cache_dir(package_dir: str, environ, writable=_writable_dir,
                     temp_dir=None):
    """The ``NUMBA_CACHE_DIR`` to set so that the ``cache=True`` kernels can be imported, or
    ``None`` when numba finds a cache on its own.

    numba caches a kernel in the ``__pycache__`` folder next to its module, else in the
    user-wide cache (``$XDG_CACHE_HOME/numba`` or ``~/.cache/numba``), and refuses to compile
    it if neither is writable.  Only then (and when ``NUMBA_CACHE_DIR`` is not set) this
    returns a private directory under the temporary folder.
    """
    if environ.get("NUMBA_CACHE_DIR"):
        return None
    if writable(_os.path.join(package_dir, "__pycache__")):
        return None
    home = environ.get("HOME") or _os.path.expanduser("~")
    user_cache = environ.get("XDG_CACHE_HOME") or _os.path.join(home, ".cache")
    if writable(_os.path.join(user_cache, "numba")):
        return None
    return _private_temp_dir(temp_dir or _tempfile.gettempdir())


def _set_numba_cache_dir() -> None:
    """Point numba's cache at a writable directory if it has none (before numba is used)."""
    try:
        path = _numba_cache_dir(_os.path.dirname(_os.path.abspath(__file__)), _os.environ)
    except OSError:        # no temporary folder either: numba will say so if it must cache
        return
    if path is None:
        return
    _os.environ["NUMBA_CACHE_DIR"] = path
    numba_config = _sys.modules.get("numba.core.config")
    if numba_config is not None:      # numba imported before us: it read the environment
        numba_config.CACHE_DIR = path


_set_numba_cache_dir()

from . import kernel_cache as _kernel_cache  # noqa: E402

_kernel_cache.refresh()       # kernels compiled from other sources are compiled again

from .config import ConfigError, HopperConfig, ResolutionWarning  # noqa: E402
from .api import Results, load_config, read_results, run  # noqa: E402
