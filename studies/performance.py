"""What a run costs: ``docs/performance.md``, written from the benchmarks that measure it.

Runs the benchmarks of ``tests/benchmarks/`` (pytest-benchmark, ``--benchmark-json``), takes
from their JSON the figures the project publishes, each with the date, the machine (CPU
model and cores), the commit of the code and the benchmark that measured it, merges them into
``docs/performance.json`` (a figure measured again replaces the earlier one; the others are
kept) and writes from that store ``docs/performance.md`` and the timing sentence of
``README.md`` (region ``timings``), every file atomically and only when all of them could be
made.  So no timing is written by hand: ``tests/test_performance_doc.py`` fails when the page
or the README's sentence is not what the store makes.

The benchmarks (run them alone on the machine: what else runs changes the times):

* ``emptying``: ``tests/benchmarks/test_bench_emptying.py``, the reference hopper from filling
  to empty as ``fipy-hopper run`` runs it, at 5 mm (the demo) and 2.5 mm;
* ``emptying_3d``: ``tests/benchmarks/test_bench_emptying_3d.py``, the reference hopper in 3D
  (1 cm cubes, centred, the default mirror planes: a quarter) from filling to empty the same
  way, written beside the demo with their ratio;
* ``step``: ``tests/benchmarks/test_bench_step.py``, a discharge step and its phases;
* ``flow_mode_map``: ``tests/benchmarks/test_bench_flow_mode_map.py``, the whole map.

Usage::

    python studies/performance.py [--only emptying emptying_3d step flow_mode_map]
                                                                  # run, then write
    python studies/performance.py --from-json BENCH.json [...]            # write from saved runs
    python studies/performance.py --drop KEY [...]                        # forget figures
    python studies/performance.py --render    # rewrite the page and the README from the store
    python studies/performance.py --check     # exit 1 if a written file is not what the store
                                              # makes
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import textwrap
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))
import _docs  # noqa: E402

STORE = ROOT / "docs" / "performance.json"
PAGE = ROOT / "docs" / "performance.md"
README = ROOT / "README.md"
COMMAND = "python studies/performance.py"
BENCHMARKS = {"emptying": "tests/benchmarks/test_bench_emptying.py",
              "emptying_3d": "tests/benchmarks/test_bench_emptying_3d.py",
              "step": "tests/benchmarks/test_bench_step.py",
              "flow_mode_map": "tests/benchmarks/test_bench_flow_mode_map.py"}
PHASES = ("step", "forces", "nodes", "strain_predictor", "stress_update", "faces", "transport",
          "markers", "diagnostics", "output")
RUNS = {0.005: ("demo", "The demo: the reference hopper from filling to empty, 5 mm cells"),
        0.0025: ("fine_2p5mm", "The reference hopper at 2.5 mm cells "
                 "(`examples/fine_2p5mm.toml`)")}
RUN_VALUES = ("total_s", "simulation_s", "pictures_and_writing_s", "peak_rss_mb", "steps",
              "cells", "threads")
#: the 3D reference's record (``tests/benchmarks/test_bench_emptying_3d.py``)
RUN_3D = ("reference_3d_1cm", "The reference hopper in 3D, 1 cm cubes (centred; a quarter by "
          "the default mirror planes)")
RUN_3D_VALUES = RUN_VALUES + ("loaded_cells", "mirror_factor", "snapshots")


# ---------------------------------------------------------------------- from the benchmarks
def machine(bench: dict) -> str:
    """"CPU model, N cores" of a pytest-benchmark run (its ``machine_info``)."""
    info = bench.get("machine_info") or {}
    cpu = info.get("cpu") or {}
    model = cpu.get("brand_raw") or info.get("processor") or platform.processor() or "CPU"
    cores = cpu.get("count") or os.cpu_count()
    return f"{model}, {cores} cores"


def commit(bench: dict) -> str:
    """The short commit of a pytest-benchmark run (``+dirty`` with uncommitted changes)."""
    info = bench.get("commit_info") or {}
    ident = str(info.get("id") or "unknown")
    short = ident[:7] if len(ident) == 40 else ident
    return short + ("+dirty" if info.get("dirty") else "")


def records(bench: dict) -> list:
    """The published figures of one pytest-benchmark JSON run, as store records."""
    common = {"measured": str(bench.get("datetime", ""))[:16].replace("T", " "),
              "machine": machine(bench), "commit": commit(bench)}
    out, phases = [], {}
    for b in bench.get("benchmarks", []):
        name, params = b["fullname"], b.get("params") or {}
        extra, stats = b.get("extra_info") or {}, b.get("stats") or {}
        if "test_bench_reference_3d_run" in name:
            key, title = RUN_3D
            out.append({"key": key, "title": title, "source": name, **common,
                        "values": {k: extra[k] for k in RUN_3D_VALUES if k in extra}})
        elif "test_bench_reference_hopper_run" in name:
            key, title = RUNS[float(params["cell_size"])]
            out.append({"key": key, "title": title, "source": name, **common,
                        "values": {k: extra[k] for k in RUN_VALUES if k in extra}})
        elif "test_bench_discharge_step" in name:
            size = float(params["cell_size"])
            per_call = stats["median"] / (extra.get("steps_per_round") or 1)
            entry = phases.setdefault(size, {"values": {}, "source": name.split("[")[0]})
            entry["values"][params["phase"]] = per_call * 1e6
            for k in ("cells", "threads", "loaded_cells"):
                if k in extra:
                    entry["values"][k] = extra[k]
        elif "test_bench_flow_mode_map" in name:
            out.append({"key": "flow_mode_map", "title": "The flow-mode map study, default "
                        "setting (30 cases, a local Dask cluster)", "source": name, **common,
                        "values": {"total_s": stats["max"],
                                   **{k: extra[k] for k in ("cases", "cores",
                                                            "case_wall_time_total_s")
                                      if k in extra}}})
    for size, entry in sorted(phases.items(), reverse=True):
        label = f"{size * 1000:g}".replace(".", "p")
        out.append({"key": f"step_{label}mm", "title": f"A discharge step by phase, "
                    f"{size * 1000:g} mm cells (µs per call)", "source": entry["source"],
                    **common, "values": entry["values"]})
    return out


def merge(store: dict, new: list, drop=()) -> dict:
    """``store`` with the records of ``new`` in place of those of the same key, less
    ``drop``; the order: the known keys first, then the rest as they came."""
    figures = {r["key"]: r for r in store.get("figures", []) if r["key"] not in drop}
    for r in new:
        figures[r["key"]] = r
    order = ["demo", "fine_2p5mm", RUN_3D[0], "step_5mm", "step_2p5mm", "flow_mode_map"]
    keys = [k for k in order if k in figures] + [k for k in figures if k not in order]
    return {"figures": [figures[k] for k in keys]}


# ---------------------------------------------------------------------- writing
def _number(v, digits=3) -> str:
    if isinstance(v, (list, tuple)):
        return "–".join(_number(x, digits) for x in v)
    if isinstance(v, int):
        return f"{v:,}".replace(",", " ")
    return f"{v:.{digits}g}" if abs(v) < 10 ** digits else f"{v:.0f}"


def _memory(mb) -> str:
    top = max(mb) if isinstance(mb, (list, tuple)) else mb
    if top >= 1000:
        gb = [x / 1000 for x in mb] if isinstance(mb, (list, tuple)) else mb / 1000
        return f"{_number(gb, 2)} GB"
    return f"{_number(mb)} MB"


def _when(r) -> str:
    return f"{r['measured']}, {r['machine']}, git {r['commit']}"


def _source(r) -> str:
    """A benchmark's test id in code style; a quotation's origin as it is."""
    return f"`{r['source']}`" if r["source"].startswith("tests/") else r["source"]


def _wrap(text: str) -> list:
    return textwrap.wrap(text, 99, break_on_hyphens=False, break_long_words=False)


def page(store: dict) -> str:
    """The text of ``docs/performance.md``."""
    figures = {r["key"]: r for r in store["figures"]}
    lines = ["# Performance: what a run costs", "",
             f"<!-- generated by `{COMMAND}` from docs/performance.json; do not edit by hand, "
             "rerun it -->", ""]
    lines += _wrap("Every figure below was measured by the benchmark it names "
                   "(`tests/benchmarks/`) and carries its date, the machine (CPU model and "
                   "cores) and the commit of the code; a figure quoted from before this page "
                   "was generated says where it was published. On a shared machine the times "
                   "of one code drift by a fifth within an hour and by twice between hours: "
                   "compare speeds only in runs side by side, and measure alone on the "
                   "machine.") + [""]
    lines += _wrap(f"Regenerate with `{COMMAND}` (it runs the benchmarks; `--only emptying`, "
                   "`emptying_3d`, `step` or `flow_mode_map` for some of them), or from saved "
                   f"benchmark output with `{COMMAND} --from-json BENCH.json`.") + [""]
    runs = [figures[k] for k in ("demo", "fine_2p5mm") if k in figures]
    if runs:
        lines += ["## The demo and the 2.5 mm run", "",
                  "`fipy-hopper run` as a user runs it: markers, field snapshots, time series, "
                  "checkpoints and the pictures, in one process.", "",
                  "| run | cells | steps | threads | total | simulation | pictures and "
                  "writing | peak memory | measured | by |",
                  "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
        for r in runs:
            v = r["values"]
            cell = lambda k, unit="": (_number(v[k]) + unit) if k in v else "—"  # noqa: E731
            lines.append(f"| {r['title']} | {cell('cells')} | {cell('steps')} | "
                         f"{cell('threads')} | {cell('total_s', ' s')} | "
                         f"{cell('simulation_s', ' s')} | "
                         f"{cell('pictures_and_writing_s', ' s')} | "
                         f"{_memory(v['peak_rss_mb']) if 'peak_rss_mb' in v else '—'} | "
                         f"{_when(r)} | {_source(r)} |")
        notes = [x for r in runs if r.get("note")
                 for x in _wrap(f"- {r['title']}: {r['note']}")]
        lines += [""] + (notes + [""] if notes else [])
    if RUN_3D[0] in figures:
        lines += three_d_section(figures)
    steps = [figures[k] for k in ("step_5mm", "step_2p5mm") if k in figures]
    if steps:
        lines += ["## Where a discharge step goes", "",
                  "µs per call of each phase (`step`: one whole step, transports included; "
                  "the phases as `tests/benchmarks/test_bench_step.py` describes them).", "",
                  "| phase | " + " | ".join(r["title"].split(", ")[1].split(" (")[0]
                                           for r in steps) + " |",
                  "| --- |" + " --- |" * len(steps)]
        for phase in PHASES + ("cells", "loaded_cells", "threads"):
            if any(phase in r["values"] for r in steps):
                lines.append(f"| {phase.replace('_', ' ')} | " + " | ".join(
                    _number(r["values"][phase]) if phase in r["values"] else "—"
                    for r in steps) + " |")
        lines += [""] + [f"- {r['title']}: {_when(r)}, {_source(r)}." for r in steps] + [""]
    if "flow_mode_map" in figures:
        r = figures["flow_mode_map"]
        v = r["values"]
        lines += ["## The flow-mode map", "", "| study | cases | total | the cases' own wall "
                  "time | cores | measured | by |", "| --- | --- | --- | --- | --- | --- | --- |",
                  f"| {r['title']} | {_number(v['cases']) if 'cases' in v else '—'} | "
                  f"{_number(v['total_s'])} s | "
                  + (f"{_number(v['case_wall_time_total_s'])} s" if "case_wall_time_total_s"
                     in v else "—")
                  + f" | {v.get('cores', '—')} | {_when(r)} | {_source(r)} |", ""]
        if r.get("note"):
            lines += _wrap(r["note"][:1].upper() + r["note"][1:]) + [""]
    known = {"demo", "fine_2p5mm", RUN_3D[0], "step_5mm", "step_2p5mm", "flow_mode_map"}
    others = [r for r in store["figures"] if r["key"] not in known]
    if others:
        lines += ["## Other measurements", ""]
        for r in others:
            lines += [f"### {r['title']}", ""] + _wrap(r["text"]) + [""]
            lines += _wrap(f"*Measured {_when(r)}; {r['source']}.*") + [""]
    return "\n".join(lines).rstrip() + "\n"


def _run_row(r) -> str:
    """A row of a run table: cells, steps, threads, times, memory, when, by."""
    v = r["values"]
    cell = lambda k, unit="": (_number(v[k]) + unit) if k in v else "—"  # noqa: E731
    return (f"| {r['title']} | {cell('cells')} | {cell('steps')} | {cell('threads')} | "
            f"{cell('total_s', ' s')} | {cell('simulation_s', ' s')} | "
            f"{cell('pictures_and_writing_s', ' s')} | "
            f"{_memory(v['peak_rss_mb']) if 'peak_rss_mb' in v else '—'} | {_when(r)} | "
            f"{_source(r)} |")


def _ratio(a, b):
    """``a / b`` of two figures (a range where either is a range of measurements)."""
    lows = [x / y for x in (a if isinstance(a, (list, tuple)) else [a])
            for y in (b if isinstance(b, (list, tuple)) else [b])]
    return [min(lows), max(lows)] if min(lows) != max(lows) else lows[0]


def three_d_section(figures: dict) -> list:
    """The 3D reference beside the demo: both runs' rows and the ratio of their times."""
    r3 = figures[RUN_3D[0]]
    v3 = r3["values"]
    lines = ["## The reference in 3D beside the demo", "",
             "The same hopper, material and run settings computed whole in 3D (1 cm cubes; a "
             "quarter by the default mirror planes) and as the demo's axisymmetric section "
             "(5 mm squares), each from filling to empty by `fipy-hopper run`.", "",
             "| run | cells | steps | threads | total | simulation | pictures and writing | "
             "peak memory | measured | by |",
             "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    demo = figures.get("demo")
    lines += ([_run_row(demo)] if demo else []) + [_run_row(r3)]
    extra = [text.format(_number(v3[k])) for k, text in (
        ("loaded_cells", "{} loaded cells"),
        ("mirror_factor", "the whole silo {} times the part computed"),
        ("snapshots", "{} snapshots")) if k in v3]
    lines.append("")
    if extra:
        lines += _wrap("The 3D run: " + ", ".join(extra) + ".") + [""]
    if demo:
        vd = demo["values"]
        parts = [f"{label} {_number(_ratio(v3[k], vd[k]))} times the demo's"
                 for k, label in (("total_s", "total"), ("simulation_s", "simulation"),
                                  ("peak_rss_mb", "peak memory"))
                 if k in v3 and k in vd]
        if parts:
            side = (r3["measured"][:10] == demo["measured"][:10]
                    and r3["machine"] == demo["machine"])
            lines += _wrap("The 3D reference: " + ", ".join(parts) + (
                "." if side else f" (not side by side: the demo measured {_when(demo)}, the 3D "
                "run " + _when(r3) + "; see above on comparing times).")) + [""]
    if r3.get("note"):
        lines += _wrap(r3["note"][:1].upper() + r3["note"][1:]) + [""]
    return lines


def timing_sentence(store: dict) -> str:
    """The README's one sentence on the demo's and the 2.5 mm run's time and memory, and the
    test command's time from a fresh clone (figure ``test_suite`` with ``values.total_s``)."""
    figures = {r["key"]: r for r in store["figures"]}
    parts = []
    for key, name in (("demo", "The demo"), ("fine_2p5mm", "the 2.5 mm run")):
        if key in figures:
            v = figures[key]["values"]
            parts.append(f"{name} takes {_number(v['total_s'])} s and "
                         f"{_memory(v['peak_rss_mb'])} of memory")
    suite = figures.get("test_suite", {}).get("values", {})
    if "total_s" in suite:
        parts.append(f"the test command from a fresh clone takes {_number(suite['total_s'])} s "
                     f"({suite.get('what', 'the install and the cold kernel compile included')})")
    if not parts:
        return "Timings: [`docs/performance.md`](docs/performance.md)."
    when = sorted({(figures[k]["measured"][:10], figures[k]["machine"])
                   for k in ("demo", "fine_2p5mm", "test_suite")
                   if k in figures and "total_s" in figures[k].get("values", {})})
    where = "; ".join(f"{d} on {m}" for d, m in when)
    return "\n".join(_wrap(", ".join(parts[:-1]) + (" and " if len(parts) > 1 else "")
                           + parts[-1] + f" (measured {where}; each figure with its "
                           "commit in [`docs/performance.md`](docs/performance.md))."))


def outputs(store: dict, root: Path = ROOT) -> dict:
    """``{path: text}`` of the store, the page and the README with its sentence filled."""
    readme = root / README.relative_to(ROOT)
    text = _docs.fill(readme.read_text(encoding="utf-8"), "timings", timing_sentence(store),
                      COMMAND)
    return {root / STORE.relative_to(ROOT): json.dumps(store, indent=2, ensure_ascii=False)
            + "\n", root / PAGE.relative_to(ROOT): page(store), readme: text}


def write(files: dict) -> list:
    """Write the files of :func:`outputs` that differ, each atomically; returns them."""
    from fipy_hopper.io import atomic_write_text

    changed = [p for p, t in files.items()
               if not p.is_file() or p.read_text(encoding="utf-8") != t]
    for path in changed:
        atomic_write_text(path, files[path])
    return changed


def load(root: Path = ROOT) -> dict:
    path = root / STORE.relative_to(ROOT)
    return json.loads(path.read_text(encoding="utf-8")) if path.is_file() else {"figures": []}


def run_benchmarks(names, json_path: Path) -> None:
    """Run the benchmarks ``names`` (keys of :data:`BENCHMARKS`) into ``json_path``."""
    cmd = [sys.executable, "-m", "pytest", *(BENCHMARKS[n] for n in names),
           "--benchmark-enable", "--benchmark-only", f"--benchmark-json={json_path}",
           "-p", "no:cacheprovider", "-q"]
    print("+ " + " ".join(cmd), flush=True)
    subprocess.run(cmd, cwd=ROOT, check=True)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", nargs="+", choices=sorted(BENCHMARKS), default=None,
                        help="run these benchmarks (default: all)")
    parser.add_argument("--from-json", nargs="+", type=Path, default=None, metavar="BENCH.json",
                        help="take the figures from saved pytest-benchmark output, run nothing")
    parser.add_argument("--drop", nargs="+", default=(), metavar="KEY",
                        help="remove these figures from the store")
    parser.add_argument("--render", action="store_true",
                        help="run nothing; rewrite the page and the README's sentence from "
                             "docs/performance.json")
    parser.add_argument("--check", action="store_true",
                        help="run nothing, write nothing; exit 1 if a file is not what the "
                             "store makes")
    args = parser.parse_args(argv)
    store = load()
    if args.check:
        files = outputs(store)
        changed = [p for p, t in files.items()
                   if not p.is_file() or p.read_text(encoding="utf-8") != t]
        names = ", ".join(str(p.relative_to(ROOT)) for p in changed)
        print(f"not as generated: {names} (run {COMMAND} --from-json or --drop)" if changed
              else "up to date")
        return 1 if changed else 0
    new = []
    if args.from_json:
        for path in args.from_json:
            new += records(json.loads(path.read_text(encoding="utf-8")))
    elif not (args.drop or args.render):
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "bench.json"
            run_benchmarks(args.only or list(BENCHMARKS), path)
            new = records(json.loads(path.read_text(encoding="utf-8")))
    changed = write(outputs(merge(store, new, drop=set(args.drop))))
    print("rewritten: " + (", ".join(str(p.relative_to(ROOT)) for p in changed) or "nothing"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
