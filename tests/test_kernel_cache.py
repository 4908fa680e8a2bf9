"""The numba kernel cache follows the package's sources: a change in any module (one a
cached kernel calls, not only the kernel's own) removes the cached kernels."""

from fipy_hopper import kernel_cache


def _package(tmp_path):
    pkg = tmp_path / "pkg"
    (pkg / "sub" / "__pycache__").mkdir(parents=True)
    (pkg / "__pycache__").mkdir()
    (pkg / "a.py").write_text("x = 1\n")
    (pkg / "sub" / "b.py").write_text("y = 2\n")
    return pkg


def _cache(pkg):
    files = [pkg / "__pycache__" / "a.kernel-1.py311.nbi", pkg / "__pycache__" /
             "a.kernel-1.py311.1.nbc", pkg / "sub" / "__pycache__" / "b.step-3.py311.nbi"]
    for f in files:
        f.write_bytes(b"compiled")
    return files


def test_a_changed_source_removes_the_cached_kernels_and_only_them(tmp_path):
    pkg = _package(tmp_path)
    stamp = pkg / "__pycache__" / "kernel_sources.sha256"
    files = _cache(pkg)
    other = pkg / "__pycache__" / "a.cpython-311.pyc"
    other.write_bytes(b"bytecode")
    assert kernel_cache.refresh(pkg, stamp) == 3          # no stamp yet: recompile
    assert not any(f.exists() for f in files) and other.exists()
    files = _cache(pkg)
    assert kernel_cache.refresh(pkg, stamp) == 0          # same sources: kept
    assert all(f.exists() for f in files)
    (pkg / "sub" / "b.py").write_text("y = 3\n")           # a dependency changes
    assert kernel_cache.refresh(pkg, stamp) == 3
    assert not any(f.exists() for f in files)
    assert stamp.read_text().strip() == kernel_cache.source_digest(pkg)


def test_the_digest_sees_contents_and_names():
    digest = kernel_cache.source_digest()
    assert len(digest) == 64 and digest == kernel_cache.source_digest()
