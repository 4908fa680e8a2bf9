"""The summary of a run as text: what ``fipy-hopper run`` prints at its end and the run writes
to ``summary.txt`` beside ``summary.json`` (one formatter for both)."""

from __future__ import annotations

from . import io as fio

#: the command's name, which begins the summary's first line (and the command's messages)
PROG = "fipy-hopper"


def _is_number(value) -> bool:
    """True for an int or a float that is not NaN (never for a bool, a string or None)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool) and value == value


def _fmt(value, spec: str) -> str:
    """``value`` formatted by ``spec``; ``n/a`` when it is missing, NaN or not a number."""
    if not _is_number(value):
        return "n/a"
    try:
        return format(value, spec)
    except ValueError:            # an integer format given a float
        return format(value, "g")


def summary_lines(summary: dict, out) -> list:
    """The summary of a run in lines of text, as ``fipy-hopper run`` prints them and
    ``summary.txt`` holds them: the stop reason, the discharge rate against Beverloo's, the
    flow mode, the mass balance and where the results are (``out``), or a fill-only run's
    loads at rest; a 3D run's pressure around the wall and flow mode per sector; a flow that
    stopped, its heel.  ``summary`` is ``summary.json``'s dict (a wedge's names per metre); a
    value that is missing, NaN or not what it should be reads ``n/a``."""
    s = fio._jsonable(summary)
    wedge = "steady_discharge_rate_kg_s_m" in s       # per metre of length

    def num(key, spec, scale=1):
        value = s.get(fio.result_key(key, axisymmetric=not wedge))
        return _fmt(scale * value if _is_number(value) else None, spec)

    def text(key):
        value = s.get(key)
        return "n/a" if value is None else str(value)

    per = "/m" if wedge else ""
    theory = "Beverloo, slot" if wedge else "Beverloo x Rose-Tanaka"
    if s.get("stop_reason") in ("filled", "fill_not_at_rest"):      # the loads at rest
        lines = [
            f"{PROG}: {text('stop_reason')} after {num('fill_time_s', '.3g')} s of filling "
            f"({num('steps', 'd')} steps, {num('wall_time_s', '.0f')} s wall time)",
            f"  weight at rest         {num('fill_weight_N', '.4g')} N{per}: the walls carry "
            f"{num('fill_wall_vertical_N', '.4g')} N{per}, the outlet plate "
            f"{num('fill_outlet_N', '.4g')} N{per} (residual "
            f"{num('fill_equilibrium_residual', '.1e')})",
            f"  bin wall               K = p_n / sigma_v {num('wall_k_bin', '.3f')}, axial "
            f"compression at the transition {num('bin_wall_axial_compression_N_m', '.4g')} "
            f"N/m (Janssen {num('janssen_wall_axial_compression_N_m', '.4g')} N/m)",
            f"  hopper                 tension at the transition "
            f"{num('hopper_meridional_tension_N_m', '.4g')} N/m, ring compression "
            f"{num('transition_ring_compression_N', '.4g')} N",
            f"  mass                   {num('initial_mass_kg', '.4g')} kg{per} filled",
            f"  results in             {out}/ (wall_pressure.csv: the loads along the wall)"]
        if s.get("dimensions") == 3:
            lines += _circumference_lines(s)
        return lines
    lines = [
        f"{PROG}: {text('stop_reason')} after {num('discharge_time_s', '.3g')} s of discharge "
        f"({num('steps', 'd')} steps, {num('wall_time_s', '.0f')} s wall time)",
        f"  steady discharge rate  {num('steady_discharge_rate_kg_s', '.4g')} kg/s{per} "
        f"({theory} {num('beverloo_rate_kg_s', '.4g')} kg/s{per})",
        f"  flow mode              {text('flow_mode')} (wall slip ratio "
        f"{num('wall_slip_ratio', '.2f')}, sliding over {num('wall_slip_fraction', '.0%')} of "
        f"the hopper wall; Jenike expects {text('jenike_flow_mode')})",
        f"  mass                   {num('initial_mass_kg', '.4g')} kg{per} filled, "
        f"{num('remaining_mass_kg', '.4g')} kg{per} left "
        f"(mass balance error {num('mass_balance_error', '.1e')})",
        f"  results in             {out}/"]
    if s.get("distortion"):
        lines.append(f"  Lagrangian mesh        stopped by distortion: {text('distortion')}")
    if s.get("dimensions") == 3:
        lines += _circumference_lines(s)
    if _is_number(s.get("flow_stopped_time_s")):
        lines.append(
            f"  outcome                {text('flow_mode')}: the flow stopped "
            f"{num('flow_stopped_time_s', '.3g')} s after the opening with "
            f"{num('remaining_mass_fraction', '.2f', scale=100)} % of the mass left"
            + (f", a rathole {num('rathole_diameter_m', '.3g')} m wide"
               if _is_number(s.get("rathole_diameter_m")) else "")
            + (f", its surface at {num('heap_angle_deg', '.1f')} deg from the horizontal "
               f"(against the angle of repose)" if _is_number(s.get("heap_angle_deg")) else ""))
    return lines


def _circumference_lines(s: dict) -> list:
    """The 3D lines of the summary: the wall pressure's largest over smallest around the
    circumference (across each face of a rectangular plan) at rest and in discharge, the bin's
    corners of a rectangular plan, and the flow mode per sector."""
    def ratio(stage):
        return _fmt(s.get(f"{stage}_wall_pressure_max_over_min_largest"), ".3g")

    calls = [c for c in s.get("flow_mode_by_sector") or [] if c in ("mass", "funnel")]
    mass = sum(c == "mass" for c in calls)
    offset = s.get("outlet_offset_m", 0)
    rectangular = s.get("plan") == "rectangular"
    offset = (f"[{', '.join(_fmt(v, 'g') for v in offset)}] m" if isinstance(offset, list)
              else f"{_fmt(offset, 'g')} m")
    lines = [f"  {'across each face ' if rectangular else 'around the wall   '}     largest / "
             f"smallest pressure up to {ratio('filling')} at "
             f"rest, {ratio('early_discharge')} from 90 % left, {ratio('discharge_envelope')} "
             f"in the envelope (wall_extremes.csv; outlet offset {offset})"]
    if rectangular:
        for stage in ("filling", "discharge_envelope"):
            corners = s.get(f"{stage}_corner_pressure_Pa") or {}
            peaks = [max(found) for found in
                     ([v for v in values or [] if _is_number(v)] for values in corners.values())
                     if found]
            if corners:
                lines.append(f"  bin's corners          {stage.replace('_', ' ')}: the largest "
                             f"pressure {_fmt(min(peaks, default=None), '.4g')} to "
                             f"{_fmt(max(peaks, default=None), '.4g')} Pa over the four "
                             f"corners (summary.json: {stage}_corner_pressure_Pa)")
    if calls:
        lines.append(f"  flow mode by sector    mass in {mass} of {len(calls)} measured sectors")
    return lines


def write_summary_text(path, summary: dict, out) -> None:
    """Write ``summary.txt``: :func:`summary_lines` of ``summary`` (what the terminal shows at
    the end of a run), one line each, atomically."""
    fio.atomic_write_text(path, "\n".join(summary_lines(summary, out)) + "\n")
