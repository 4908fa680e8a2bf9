"""A run directory is never touched outside itself, and ``--force`` replaces only a run's files.

``--force`` removes the files a run writes (its outputs, pictures, snapshots and their
writers' temporary files) and nothing else, never through a symbolic link, only in a
directory that an earlier run wrote (its ``manifest.json``), and only once the directory and
its ``fields/`` are known to be writable.  The lock file is never opened through a link.
No run here steps a model: the directory is opened as a run opens it.
"""

import json
import os
import tempfile
from pathlib import Path

import pytest

from fipy_hopper import io as fio
from fipy_hopper.cli import main
from fipy_hopper.config import HopperConfig
from fipy_hopper.io import RunDirectory, RunDirectoryError

MANIFEST = json.dumps({"package": "fipy_hopper", "status": "finished", "sessions": []})

#: the files an earlier run left, at the top and in fields/
OWN_TOP = ("config.toml", "summary.json", "summary.txt", "timeseries.csv", "discharge.png",
           "error.log", ".summary.abcd_123.tmp.json", ".summary.q1w2e3r4.tmp.txt",
           ".checkpoint-k2j4h5g6.npz")
OWN_FIELDS = ("fields_0000.vtu", "fields_0012.vtu", "markers_0012.vtu", "fields.pvd",
              "snapshots.csv", ".fields_0013.q1w2e3r4.tmp.vtu", ".snapshots.zzzzzzzz.tmp.csv")
#: files that look like them and that no run writes
FOREIGN_TOP = (".env.tmpl", "notes.txt", "summary.json.bak", "summary.txt.bak", ".my.tmp",
               "results.vtu")
FOREIGN_FIELDS = ("my.tmp.txt", "paraview_state.pvsm", "fields_final.vtu", "notes.vtu.txt",
                  ".hidden.tmp")


def earlier_run(folder: Path, foreign=True) -> Path:
    """A directory an earlier run wrote (with its manifest), and files of the user's."""
    out = folder / "run"
    (out / "fields").mkdir(parents=True)
    (out / "manifest.json").write_text(MANIFEST)
    for name in OWN_TOP:
        (out / name).write_text("old")
    for name in OWN_FIELDS:
        (out / "fields" / name).write_text("old")
    if foreign:
        for name in FOREIGN_TOP:
            (out / name).write_text("mine")
        for name in FOREIGN_FIELDS:
            (out / "fields" / name).write_text("mine")
    return out


def tree(folder: Path) -> dict:
    return {str(p.relative_to(folder)): (p.read_bytes() if p.is_file() and not p.is_symlink()
                                         else os.readlink(p) if p.is_symlink() else None)
            for p in sorted(folder.rglob("*"))}


def test_force_removes_only_the_files_a_run_writes(tmp_path):
    out = earlier_run(tmp_path)
    with RunDirectory(out, force=True):
        pass
    left = {str(p.relative_to(out)) for p in out.rglob("*")}
    assert left == {"fields", *FOREIGN_TOP, *(f"fields/{n}" for n in FOREIGN_FIELDS)}
    for name in FOREIGN_TOP:
        assert (out / name).read_text() == "mine"


@pytest.mark.parametrize("name, own, in_fields", [
    ("summary.json", True, False), ("summary.txt", True, False),
    (".summary.a1b2c3d4.tmp.txt", True, False), ("summary.txt", False, True),
    ("wall_forces.png", True, False),
    ("discharge.gif", True, False), (".discharge.a1b2c3d4.tmp.gif", True, False),
    (".checkpoint-abcdefgh.npz", True, False), (".probe.abcdefgh.tmp", True, False),
    (".env.tmpl", False, False), ("notes.txt", False, False), (".lock", False, False),
    (".summary.json.tmp", False, False), (".notes.abcdefgh.tmp.txt", False, False),
    ("fields_0001.vtu", True, True), ("markers_0001.vtu", True, True),
    (".fields_0001.abcdefgh.tmp.vtu", True, True), ("fields.pvd", True, True),
    ("my.tmp.txt", False, True), ("other.vtu", False, True), ("summary.json", False, True),
    ("fields_1.vtu", False, True),
])
def test_what_counts_as_a_runs_file(name, own, in_fields):
    assert RunDirectory.is_output(name, in_fields) is own


def test_a_fields_link_is_refused_and_its_target_untouched(tmp_path, capsys):
    out = earlier_run(tmp_path, foreign=False)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    for name in ("fields_0000.vtu", "results.vtu", "series.pvd", ".a.abcdefgh.tmp.vtu",
                 "snapshots.csv"):
        (elsewhere / name).write_text("precious")
    for name in OWN_FIELDS:
        (out / "fields" / name).unlink()
    (out / "fields").rmdir()
    (out / "fields").symlink_to(elsewhere)
    before, outside = tree(out), tree(elsewhere)
    for mode in ({"force": True}, {"resume": True}):
        with pytest.raises(RunDirectoryError, match="fields is a symbolic link"):
            RunDirectory(out, **mode)
    config = tmp_path / "c.toml"
    config.write_text(HopperConfig().to_toml())
    assert main(["run", str(config), "--out", str(out), "--force", "--quiet"]) == 2
    err = [line for line in capsys.readouterr().err.splitlines() if "warning" not in line]
    assert len(err) == 1 and "symbolic link" in err[0], err
    assert tree(out) == before and tree(elsewhere) == outside


@pytest.mark.parametrize("force", [False, True])
def test_a_lock_link_is_never_written_through(tmp_path, force):
    out = earlier_run(tmp_path, foreign=False) if force else tmp_path / "fresh"
    out.mkdir(exist_ok=True)
    target = tmp_path / "precious.txt"
    target.write_text("precious\n")
    (out / ".lock").symlink_to(target)
    before = tree(out)
    with pytest.raises(RunDirectoryError, match=r"\.lock is a symbolic link"):
        RunDirectory(out, force=force)
    assert target.read_text() == "precious\n" and tree(out) == before


def test_a_lock_that_is_a_hard_link_is_never_written_through(tmp_path):
    out = tmp_path / "run"
    out.mkdir()
    target = tmp_path / "precious.txt"
    target.write_text("precious\n")
    os.link(target, out / ".lock")
    with pytest.raises(RunDirectoryError, match=r"\.lock is a hard link"):
        RunDirectory(out)
    assert target.read_text() == "precious\n"


def test_a_lock_that_is_not_a_file_is_refused(tmp_path):
    out = tmp_path / "run"
    (out / ".lock").mkdir(parents=True)
    with pytest.raises(RunDirectoryError, match=r"\.lock is not a regular file"):
        RunDirectory(out)


@pytest.mark.parametrize("files", [
    {"notes.txt": "mine"},
    {"summary.json": "{}", "timeseries.csv": "t_s\n"},          # a run's names, no manifest
    {"manifest.json": '{"name": "my web app", "version": 3}'},  # someone else's manifest
    {"manifest.json": "not json"},
])
def test_force_refuses_a_directory_that_no_run_wrote(tmp_path, capsys, files):
    out = tmp_path / "mine"
    out.mkdir()
    for name, text in files.items():
        (out / name).write_text(text)
    before = tree(out)
    with pytest.raises(RunDirectoryError, match="not a run directory of fipy-hopper"):
        RunDirectory(out, force=True)
    config = tmp_path / "c.toml"
    config.write_text(HopperConfig().to_toml())
    assert main(["run", str(config), "--out", str(out), "--force", "--quiet"]) == 2
    err = [line for line in capsys.readouterr().err.splitlines() if "warning" not in line]
    assert len(err) == 1 and "not a run directory" in err[0] and "new or empty" in err[0]
    assert main(["run", str(config), "--out", str(out), "--quiet"]) == 2    # no --force
    err = [line for line in capsys.readouterr().err.splitlines() if "warning" not in line]
    assert len(err) == 1 and "not a run directory" in err[0] and "--force" not in err[0]
    assert tree(out) == before


def test_force_takes_an_empty_directory_or_one_with_a_stale_lock(tmp_path):
    out = tmp_path / "empty"
    out.mkdir()
    RunDirectory(out, force=True).close()
    (out / ".lock").write_text("99999999\n")
    RunDirectory(out, force=True).close()


def test_an_output_name_that_is_a_folder_is_refused_before_anything_goes(tmp_path):
    out = earlier_run(tmp_path)
    (out / "discharge.png").unlink()
    (out / "discharge.png").mkdir()
    before = tree(out)
    with pytest.raises(RunDirectoryError, match="discharge.png is a folder"):
        RunDirectory(out, force=True)
    assert tree(out) == before


def test_nothing_is_removed_where_the_new_run_cannot_write(tmp_path, monkeypatch):
    """The probe of ``fields/`` fails (as in a read-only folder): the earlier run's files are
    all still there, and the message says so."""
    out = earlier_run(tmp_path)
    before = tree(out)
    real = tempfile.mkstemp

    def refuse_fields(*args, dir=None, **kwargs):
        if Path(dir).name == "fields":
            raise PermissionError(13, "Permission denied")
        return real(*args, dir=dir, **kwargs)

    monkeypatch.setattr(fio.tempfile, "mkstemp", refuse_fields)
    with pytest.raises(RunDirectoryError, match=r"cannot write in .*fields: Permission "
                                                 r"denied; nothing in .* was removed"):
        RunDirectory(out, force=True)
    assert tree(out) == before


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into a read-only folder")
def test_a_read_only_fields_folder_keeps_the_earlier_results(tmp_path, capsys):
    out = earlier_run(tmp_path)
    before = tree(out)
    (out / "fields").chmod(0o555)
    try:
        config = tmp_path / "c.toml"
        config.write_text(HopperConfig().to_toml())
        assert main(["run", str(config), "--out", str(out), "--force", "--quiet"]) == 2
        assert "cannot write in" in capsys.readouterr().err
        assert tree(out) == before
    finally:
        (out / "fields").chmod(0o755)
