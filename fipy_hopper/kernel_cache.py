"""Keep numba's on-disk kernel cache in step with the package's sources.

Numba's ``cache=True`` keeps a compiled function until its *own* source file changes: a kernel
that inlines or calls a function of another module (the fused step calls the law's point
update and overstress, the 3D step the law's 3D update) keeps its old machine code when only
that other module changes, and runs the old physics without a word.  So, before any kernel is
loaded, :func:`refresh` compares a digest of every ``.py`` file of the package with the one
recorded beside the cache, and when they differ removes the package's cached kernels
(``__pycache__/*.nbi``, ``*.nbc``): they are compiled again on first use, as on a new machine.
Hashing the sources takes a few milliseconds.  A cache numba keeps outside the package
(``NUMBA_CACHE_DIR``, or a user-wide one when the package's folder cannot be written) is not
touched: clear it by hand after changing the package there.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent
#: the digest of the sources the cached kernels were compiled from
STAMP = PACKAGE / "__pycache__" / "kernel_sources.sha256"


def source_digest(package: Path = PACKAGE) -> str:
    """SHA-256 of the package's ``.py`` files (their paths and contents, in sorted order)."""
    h = hashlib.sha256()
    for path in sorted(package.rglob("*.py")):
        h.update(path.relative_to(package).as_posix().encode())
        h.update(b"\0")
        h.update(path.read_bytes())
        h.update(b"\0")
    return h.hexdigest()


def cached_kernels(package: Path = PACKAGE) -> list:
    """The package's numba cache files (index ``.nbi`` and data ``.nbc``)."""
    return [p for pattern in ("*.nbi", "*.nbc") for p in package.rglob(f"__pycache__/{pattern}")]


def refresh(package: Path = PACKAGE, stamp: Path = STAMP) -> int:
    """Remove the cached kernels when the sources differ from those they were compiled from;
    returns how many files were removed (0 when the cache is current or cannot be written)."""
    digest = source_digest(package)
    try:
        if stamp.is_file() and stamp.read_text().strip() == digest:
            return 0
    except OSError:
        return 0
    removed = 0
    for path in cached_kernels(package):
        try:
            path.unlink()
            removed += 1
        except OSError:
            pass
    try:
        stamp.parent.mkdir(exist_ok=True)
        tmp = stamp.with_name(f"{stamp.name}.{os.getpid()}.tmp")
        tmp.write_text(digest + "\n")
        os.replace(tmp, stamp)
    except OSError:
        pass
    return removed
