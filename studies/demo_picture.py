"""The README's picture: ``docs/images/demo.png``, made from a run of the demo.

Puts the run's ``flow_pattern.png`` (the layers and the speed in discharge) above its
``wall_pressure.png`` (the wall pressure at rest and in discharge against the theories),
scaled to a small width, and writes into the PNG's own text fields what made it: the commit of
the code that ran (the run's ``manifest.json``, ``code_commit``), the run's end date and its
command.  The README's caption (region ``picture``) is filled from those fields, so the
commit is written once, by the run; ``tests/test_headline.py`` holds the caption to the PNG.

Usage::

    fipy-hopper demo --out hopper_run --force
    python studies/demo_picture.py hopper_run         # write the PNG and the README's caption
    python studies/demo_picture.py --check            # exit 1 if the caption is not the PNG's,
                                                      # or the PNG is older than the code it draws

The picture is stale when a commit after the one recorded in it changed what it draws: the
plotting or the wall loads (:data:`DRAWN_BY`); ``--check`` then says which commit, in one
line, so that the picture is regenerated with the change that alters it.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))
import _docs  # noqa: E402

PICTURE = ROOT / "docs" / "images" / "demo.png"
README = ROOT / "README.md"
COMMAND = "python studies/demo_picture.py"
WIDTH = 1000          # px: the width of the picture, the two drawings one above the other
KEYS = ("fipy_hopper:commit", "fipy_hopper:date", "fipy_hopper:command")
#: The code the picture draws with: a commit that changes one of these after the picture's
#: commit makes it stale (the pictures themselves; the wall loads and their recovery).
DRAWN_BY = ("fipy_hopper/plotting.py", "fipy_hopper/wall_traction.py",
            "fipy_hopper/diagnostics.py")


def compose(run_dir: Path, out: Path = PICTURE, width: int = WIDTH) -> dict:
    """Write the picture of ``run_dir`` to ``out``; returns its text fields."""
    from PIL import Image, PngImagePlugin

    from fipy_hopper.io import atomic_path

    run_dir = Path(run_dir)
    manifest = json.loads((run_dir / "manifest.json").read_text(encoding="utf-8"))
    images = [Image.open(run_dir / name).convert("RGB")
              for name in ("flow_pattern.png", "wall_pressure.png")]
    images = [im.resize((width, round(im.height * width / im.width)), Image.LANCZOS)
              for im in images]
    whole = Image.new("RGB", (width, sum(im.height for im in images)), "white")
    y = 0
    for im in images:                     # the flow pattern above the wall pressure
        whole.paste(im, (0, y))
        y += im.height
    whole = whole.quantize(colors=128, method=Image.Quantize.MEDIANCUT)
    fields = {"fipy_hopper:commit": str(manifest.get("code_commit") or "not recorded"),
              "fipy_hopper:date": str(manifest.get("end_time") or manifest.get("start_time")
                                      or "")[:10],
              "fipy_hopper:command": str(manifest.get("command") or "fipy-hopper demo")}
    info = PngImagePlugin.PngInfo()
    for key, value in fields.items():
        info.add_text(key, value)
    out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(out) as tmp:
        whole.save(tmp, format="PNG", pnginfo=info, optimize=True)
    return fields


def fields_of(path: Path = PICTURE) -> dict:
    """The text fields :func:`compose` wrote into the picture."""
    from PIL import Image

    with Image.open(path) as im:
        text = dict(getattr(im, "text", {}) or im.info)
    return {k: text.get(k, "not recorded") for k in KEYS}


def caption(fields: dict) -> str:
    """The README's picture and its caption, from the picture's text fields."""
    return ("![The demo: the layers and the speed in discharge, and the wall pressure against "
            "Janssen and Walker](docs/images/demo.png)\n\n"
            "*The demo: the layers and the speed in the discharge (above), and the wall pressure "
            "at rest and in discharge against Janssen and Walker (below); its `flow_pattern.png` "
            f"and `wall_pressure.png`, run by `{fields['fipy_hopper:command']}` on "
            f"{fields['fipy_hopper:date']} at git {fields['fipy_hopper:commit']} "
            f"(`{COMMAND}`).*")


def readme_text(root: Path = ROOT) -> str:
    """README.md with its picture region made from the committed picture."""
    readme = root / README.relative_to(ROOT)
    return _docs.fill(readme.read_text(encoding="utf-8"), "picture",
                      caption(fields_of(root / PICTURE.relative_to(ROOT))), COMMAND)


def stale_reason(root: Path = ROOT, picture: Path = PICTURE, paths=DRAWN_BY):
    """Why the picture is older than the code it draws, in one line, or None: the last commit
    after the one recorded in the picture (``fipy_hopper:commit``) that changed one of
    ``paths``; an unrecorded or unknown commit, or no git, is a reason too (it cannot be
    told)."""
    import subprocess

    recorded = fields_of(picture)["fipy_hopper:commit"]
    name = picture.relative_to(root) if picture.is_relative_to(root) else picture

    def git(*args):
        return subprocess.run(["git", "-C", str(root), *args], capture_output=True,
                              text=True, check=False)

    if recorded in ("", "not recorded"):
        return f"{name} records no commit: regenerate it"
    try:
        known = git("rev-parse", "--verify", "--quiet", f"{recorded}^{{commit}}")
    except OSError:
        return f"cannot tell whether {name} is up to date: git is not available"
    if known.returncode != 0:
        return f"{name} was made at git {recorded}, which this checkout does not hold"
    log = git("log", "-1", "--format=%h %s", f"{recorded}..HEAD", "--", *paths)
    if log.returncode != 0:
        return f"cannot tell whether {name} is up to date: git log failed"
    if not log.stdout.strip():
        return None
    changed = git("log", "-1", "--format=", "--name-only", f"{recorded}..HEAD", "--", *paths)
    files = ", ".join(f for f in changed.stdout.split() if f in paths)
    commit, subject = (log.stdout.strip().split(" ", 1) + [""])[:2]
    return (f"{name} (git {recorded}) is older than git {commit}, which changed {files} "
            f"(\"{subject[:60]}\"): run fipy-hopper demo --out hopper_run --force and "
            f"{COMMAND} hopper_run")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run_dir", nargs="?", type=Path,
                        help="a finished run of the demo (default: only refill the caption)")
    parser.add_argument("--check", action="store_true",
                        help="write nothing; exit 1 if the caption is not the picture's or "
                             "the picture is older than the code that draws it")
    args = parser.parse_args(argv)
    if args.check:
        reason = (None if README.read_text(encoding="utf-8") == readme_text() else
                  f"README.md's caption is not the picture's: run {COMMAND}")
        reason = reason or stale_reason()
        print(reason or "up to date")
        return 1 if reason else 0
    if args.run_dir is not None:
        fields = compose(args.run_dir)
        print(f"written {PICTURE.relative_to(ROOT)} ({PICTURE.stat().st_size // 1024} KB, "
              f"git {fields['fipy_hopper:commit']})")
    from fipy_hopper.io import atomic_write_text

    atomic_write_text(README, readme_text())
    return 0


if __name__ == "__main__":
    sys.exit(main())
