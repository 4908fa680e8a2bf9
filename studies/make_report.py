"""Generate ``studies/REPORT.md`` from the outputs of the studies (never written by hand).

Reads ``ROOT/<study>/study.json`` of each validation study (``flow_mode_map``, ``plane_flow``,
``discharge_rate``, ``wall_pressure``, ``discharge_dynamics``, ``stiffness_spread``,
``convergence``, ``robustness``, ``funnel_channel``, ``grain_size``, ``shear_band``,
``wall_zone``, ``lagrangian_vs_eulerian``, ``arching``, ``geometries``, ``three_d``, ``envelope``) and the
outputs of
``element_tests`` (``failure_deviators.csv`` and its pictures), and writes one Markdown report:
an overview, then per study its setting, findings (the comparisons as numbers), tables, figures
and settings.  Studies without outputs are listed as missing, with the command that makes them.
A study run on its ``--quick`` setting is flagged as such: those are test-sized runs, not
validation results.

The figures are copied next to the report (``report_figures/<study>/``) so that the report and
its pictures travel together; ``--no-copy`` links the study outputs in place instead.

``--only STUDY ...`` rewrites those studies' sections, overview rows and figures in the
existing report and keeps every other section as it is (for a study rerun on a machine that
does not hold the other studies' outputs).

Written to the default ``studies/REPORT.md``, the report is then read by
``studies/headline.py``, which writes ``studies/headline.json`` (the numbers the front door
publishes, with their studies' commits) and fills the generated regions of ``README.md`` and
``docs/validation.md`` from it (``--no-headline``: the report alone).

Usage::

    python studies/make_report.py [--root studies/output] [--out studies/REPORT.md] [--no-copy]
                                  [--no-headline] [--only STUDY ...]
"""

from __future__ import annotations

import argparse
import csv
import datetime
import json
import math
import os
import re
import shutil
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
DEFAULT_ROOT = HERE / "output"
DEFAULT_OUT = HERE / "REPORT.md"
STUDIES = ("flow_mode_map", "plane_flow", "discharge_rate", "wall_pressure",
           "discharge_dynamics", "stiffness_spread", "convergence", "robustness",
           "funnel_channel", "grain_size", "shear_band", "wall_zone", "lagrangian_vs_eulerian",
           "arching", "geometries", "three_d", "envelope", "eccentric")
ELEMENT_TESTS = "element_tests"
ELEMENT_FIGURES = (("meridional.png", "Stress paths in the meridional (p, q) plane with the "
                    "yield surface's meridians and the flow potential."),
                   ("deviatoric.png", "The Mohr-Coulomb hexagon and the Menetrey-Willam flow "
                    "potential in the deviatoric plane, with the failure states."),
                   ("stress_strain.png", "Deviatoric stress and volumetric strain against the "
                    "controlled strain."))


def _fmt(v) -> str:
    if v is None:
        return ""
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, float):
        if math.isnan(v):
            return ""
        return f"{v:.4g}"
    if isinstance(v, (list, tuple)):
        return ", ".join(f"({_fmt(x)})" if isinstance(x, (list, tuple)) else _fmt(x)
                         for x in v)
    if isinstance(v, dict):
        return "; ".join(f"{k}: {_fmt(x)}" for k, x in v.items())
    return str(v).replace("|", "\\|").replace("\n", " ")


def table(columns, rows) -> list:
    lines = ["| " + " | ".join(_fmt(c) for c in columns) + " |",
             "|" + "---|" * len(columns)]
    lines += ["| " + " | ".join(_fmt(c) for c in r) + " |" for r in rows]
    return lines


class Figures:
    """Copies (or links) figures and returns their Markdown paths relative to the report;
    the copies of the studies ``studies`` (all: ``None``) are removed first."""

    def __init__(self, report: Path, copy: bool, studies=None):
        self.report = report
        self.copy = copy
        self.folder = report.parent / "report_figures"
        for folder in ([self.folder] if studies is None
                       else [self.folder / name for name in studies]):
            if copy and folder.is_dir():
                shutil.rmtree(folder)

    def link(self, study: str, path: Path) -> str:
        if self.copy:
            target = self.folder / study / path.name
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(path, target)
            path = target
        return Path(os.path.relpath(path, self.report.parent)).as_posix()


def _git_commit() -> str:
    """The commit of the code (``_sweep._git_commit``: the package and the studies' scripts)."""
    if str(HERE) not in sys.path:
        sys.path.insert(0, str(HERE))
    import _sweep

    return _sweep._git_commit() or "unknown"


def _runs_made_by(data: dict) -> str:
    """" Its runs were made by git X (n cases), ..." when a case was run (or reused from a run)
    by other code than the study's own commit; "" when every case ran at that commit or the
    study does not say (a study.json from before it recorded its runs' commits)."""
    commits = data.get("run_commits") or {}
    if not commits or set(commits) == {data.get("commit")}:
        return ""
    parts = [f"{'git ' + c if c != 'not recorded' else 'code not recorded'} ({n} case"
             f"{'s' if n != 1 else ''})" for c, n in commits.items()]
    return " Its runs were made by " + ", ".join(parts) + "."


def study_section(name: str, data: dict, folder: Path, figures: Figures) -> list:
    lines = [f"## {data.get('title', name)}", ""]
    setting = data.get("setting", "?")
    minutes = data.get("case_wall_time_total_s", 0) / 60
    meta = (f"Study `{name}` — setting **{setting}**, {data.get('cases', '?')} case(s)"
            f" ({data.get('cases_failed', 0)} failed), {minutes:.1f} min of run wall time summed "
            f"over the cases, written {data.get('created', '?')} by fipy_hopper "
            f"{data.get('fipy_hopper_version', '?')}"
            + (f", git {data['commit']}" if data.get("commit") else "") + "."
            + _runs_made_by(data))
    lines += [meta, "", f"Command: `{data.get('command', '')}`", ""]
    if setting == "quick":
        lines += ["> **Quick setting**: tiny hoppers on coarse grids, the test-suite size. These "
                  "numbers show that the study runs; they are not validation results.", ""]
    if data.get("findings"):
        lines += ["### Findings", ""]
        lines += [f"- {f}" for f in data["findings"]]
        lines.append("")
    for fig in data.get("figures", []):
        path = folder / fig["file"]
        if path.is_file():
            lines += [f"![{fig['file']}]({figures.link(name, path)})", "",
                      f"*{fig.get('caption', '')}*", ""]
        else:
            lines += [f"*(figure {fig['file']} is missing)*", ""]
    for t in data.get("tables", []):
        if not t.get("rows"):
            continue
        lines += [f"### {t['title']}", ""]
        lines += table(t["columns"], t["rows"])
        lines.append("")
    if data.get("settings"):
        lines += ["<details><summary>Settings</summary>", ""]
        lines += table(["option", "value"], sorted(data["settings"].items()))
        lines += ["", "</details>", ""]
    return lines


def element_section(folder: Path, figures: Figures):
    csv_path = folder / "failure_deviators.csv"
    if not csv_path.is_file():
        return None
    with open(csv_path, newline="", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    worst = max((float(r["rel_error"]) for r in rows), default=math.nan)
    failed = sum(1 for r in rows if r.get("failed") == "True")
    headline = (f"{len(rows)} triaxial tests reached failure in {failed} cases; the largest "
                f"relative difference of the failure deviator q_f from the closed form "
                f"6 sin(phi)(p + c cot(phi))/(3 -+ sin(phi)) is {worst:.2e}.")
    lines = ["## Material element tests (Mohr-Coulomb)", "",
             "Study `element_tests` (`studies/element_tests.py`): drained triaxial compression "
             "and extension, simple shear and oedometric loading of one material point.", "",
             "### Findings", "", f"- {headline}", ""]
    for name, caption in ELEMENT_FIGURES:
        path = folder / name
        if path.is_file():
            lines += [f"![{name}]({figures.link(ELEMENT_TESTS, path)})", "", f"*{caption}*", ""]
    lines += ["### Failure deviators", ""]
    lines += table(["path", "p0 (Pa)", "p_f (Pa)", "q_f (Pa)", "closed form (Pa)", "rel. error"],
                   [[r["path"], float(r["p0_Pa"]), float(r["p_f_Pa"]), float(r["q_f_Pa"]),
                     float(r["q_closed_form_Pa"]), f"{float(r['rel_error']):.1e}"] for r in rows])
    lines.append("")
    return lines, headline


def report_parts(text: str) -> dict:
    """``{study: (overview row, section lines)}`` of a report this script wrote."""
    rows = {m[1]: m[0] for m in re.finditer(r"^\| `(\w+)` \|.*$", text, flags=re.M)}
    parts = {}
    for chunk in re.split(r"^(?=## )", text, flags=re.M):
        found = re.search(r"^Study `(\w+)`", chunk, flags=re.M)
        if found and found[1] in rows:
            parts[found[1]] = (rows[found[1]], chunk.rstrip("\n").split("\n") + [""])
    return parts


def build(root: Path, out: Path, copy: bool = True, only=None) -> dict:
    """Write the report; returns ``{"present": [...], "missing": [...], "path": out}``.
    ``only``: rewrite those studies and keep the other sections of the report at ``out``."""
    root, out = Path(root), Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    kept = {}
    if only is not None:
        unknown = set(only) - set(STUDIES) - {ELEMENT_TESTS}
        if unknown:
            raise ValueError(f"no such studies: {sorted(unknown)}")
        absent = [n for n in only if not (root / n / ("failure_deviators.csv" if n == ELEMENT_TESTS
                                                     else "study.json")).is_file()]
        if absent:
            raise FileNotFoundError(f"no outputs in {root} for {absent}")
        kept = {k: v for k, v in report_parts(out.read_text(encoding="utf-8")).items()
                if k not in only}
    figures = Figures(out, copy, only)
    present, missing, body, overview = [], [], [], []

    def keep(name) -> bool:
        if name not in kept:
            return False
        present.append(name)
        body.extend(kept[name][1])
        overview.append(kept[name][0])
        return True

    for name in STUDIES:
        path = root / name / "study.json"
        if keep(name):
            continue
        if not path.is_file():
            missing.append(name)
            continue
        with open(path, encoding="utf-8") as fh:
            data = json.load(fh)
        present.append(name)
        body += study_section(name, data, root / name, figures)
        head = data.get("headline") or (data.get("findings") or [""])[0]
        overview.append("| " + " | ".join(_fmt(c) for c in [
            f"`{name}`", data.get("setting", "?"), data.get("cases", ""), head]) + " |")
    element = None if keep(ELEMENT_TESTS) else element_section(root / ELEMENT_TESTS, figures)
    if element is not None:
        present.append(ELEMENT_TESTS)
        body += element[0]
        overview.append("| " + " | ".join(_fmt(c) for c in [
            f"`{ELEMENT_TESTS}`", "", "", element[1]]) + " |")
    elif ELEMENT_TESTS not in kept:
        missing.append(ELEMENT_TESTS)
    now = datetime.datetime.now().astimezone().isoformat(timespec="seconds")
    lines = ["# fipy_hopper validation report", "",
             f"*Generated by `python studies/make_report.py` from the study outputs in "
             f"`{_display(root, out)}` on {now} (git {_git_commit()}). Do not edit by hand: "
             "rerun the studies and this script."
             + (f" Rewritten: {', '.join(only)}; the other sections are kept from the report "
                "before." if only else "") + "*", "",
             "Each study is rerun with `python studies/<study>.py` (a Dask cluster on this "
             "machine's cores by default; `--scheduler ADDRESS` for an existing cluster, "
             "`--serial` without Dask); finished cases are not recomputed.  The correlations "
             "and their verification tags are those of `fipy_hopper.theory`.", ""]
    if overview:
        lines += ["## Overview", ""]
        lines += table(["study", "setting", "cases", "headline"], []) + overview
        lines.append("")
    if missing:
        lines += ["## Missing studies", "",
                  "No outputs were found for these studies (run them, then this script):", ""]
        for name in missing:
            cmd = (f"python studies/{name}.py --out {_display(root / name, out)}"
                   if name != ELEMENT_TESTS else
                   f"python studies/element_tests.py --out {_display(root / name, out)}")
            lines.append(f"- `{name}`: `{cmd}`")
        lines.append("")
    moved = moved_section("\n".join(lines + body))
    lines += moved + body
    from fipy_hopper.io import atomic_write_text

    atomic_write_text(out, "\n".join(lines).rstrip() + "\n")
    return {"present": present, "missing": missing, "path": out}


#: the published numbers before the last change of the defaults (a copy of the
#: ``headline.json`` of the report before it) and what explains each number that moved
PREVIOUS = HERE / "previous_headline.json"
MOVED = HERE / "moved.json"
MOVED_TITLE = "## What moved since the previous report"


def moved_section(report_text: str, previous=PREVIOUS, explanations=MOVED) -> list:
    """The section that sets every published claim (``studies/headline.py``) of this report
    beside the previous report's (``previous_headline.json``), with the explanation of each
    one that moved (``moved.json``: ``{"change": what changed, "claims": {key: why}}``);
    ``[]`` without a previous report.  A moved claim without an explanation says so; a claim
    whose study has the previous report's commit is marked not rerun, not unchanged."""
    previous, explanations = Path(previous), Path(explanations)
    if not previous.is_file():
        return []
    if str(HERE) not in sys.path:
        sys.path.insert(0, str(HERE))
    import headline

    before = {c["key"]: c for c in json.loads(previous.read_text(encoding="utf-8"))["claims"]}
    notes = (json.loads(explanations.read_text(encoding="utf-8"))
             if explanations.is_file() else {})
    try:
        now = {c["key"]: c for c in headline.build(report_text)["claims"]}
    except headline.HeadlineError as exc:       # a study still missing: no comparison yet
        return [MOVED_TITLE, "", f"Not compared: {exc}.", ""]
    rows = []
    for key, claim in now.items():
        old = before.get(key)
        if old is None:
            why, was = "a new claim", ""
        else:
            was = old["result"]
            rerun = old.get("study_commit") != claim.get("study_commit")
            why = ("unchanged" if rerun and old.get("values") == claim.get("values") else
                   "not rerun (the previous report's runs)" if not rerun else
                   notes.get("claims", {}).get(key, "**moved, not yet explained**"))
        rows.append([claim["claim"], was, claim["result"], why])
    made = before and next(iter(before.values())).get("study_commit", "")
    lines = [MOVED_TITLE, "", notes.get("change", ""), "",
             f"Each claim of the previous report (`studies/previous_headline.json`, its "
             f"studies' commits as there{', e.g. ' + made if made else ''}) beside this one's, "
             "and why it moved (`studies/moved.json`).", ""]
    lines += table(["claim", "previous", "now", "why"], rows)
    return lines + [""]


def _display(path: Path, out: Path) -> str:
    try:
        return Path(os.path.relpath(path, Path.cwd())).as_posix()
    except ValueError:
        return str(path)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--root", type=Path, default=DEFAULT_ROOT,
                        help="folder holding the study outputs (default studies/output)")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT,
                        help="the report (default studies/REPORT.md)")
    parser.add_argument("--no-copy", dest="copy", action="store_false",
                        help="link the figures in place instead of copying them next to the "
                             "report")
    parser.add_argument("--no-headline", dest="headline", action="store_false",
                        help="do not rewrite studies/headline.json and the README's and "
                             "docs' generated regions from the report (they are rewritten "
                             "only when the report is the default studies/REPORT.md)")
    parser.add_argument("--only", nargs="+", metavar="STUDY",
                        help="rewrite only these studies in the existing report, keeping the "
                             "other sections as they are")
    args = parser.parse_args(argv)
    result = build(args.root, args.out, args.copy, args.only)
    print(f"report written to {result['path']}: {len(result['present'])} studies "
          f"({', '.join(result['present']) or 'none'}); missing: "
          f"{', '.join(result['missing']) or 'none'}")
    if args.headline and Path(args.out).resolve() == DEFAULT_OUT:
        if str(HERE) not in sys.path:
            sys.path.insert(0, str(HERE))
        import headline

        return headline.main([])
    return 0


if __name__ == "__main__":
    sys.exit(main())
