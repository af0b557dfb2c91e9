"""Numerical stability on stiff and extreme cases, with error and run time for each (issue 7).

Every case runs in its own forked process with a wall-time bound, so a hang becomes a
``timeout`` row instead of a stuck report, and records: whether it converged (ε target met
in every frame), how it failed otherwise (exception class and first line), the error
against the analytic truth (mean and 95th percentile, mm), the largest ε reached (rad),
Gauss–Newton iterations, step halvings (trial steps that would have inverted an element),
the smallest det F reached and the wall time of the tracking call. A result that holds NaN
is reported as ``nan`` (it must never happen).

The cases, their scenes and the measurement of one run are in
``benchmarks/stability_cases.py``.

Writes ``benchmarks/results/stability.{csv,md}`` and ``stability_<group>.png``; with
``--previous`` an earlier ``stability.csv`` is compared and the rows that changed carry its
status and errors beside the new ones (``--compare-only`` compares an existing run).

Usage::

    python benchmarks/stability.py                  # everything
    python benchmarks/stability.py --groups motion degenerate --timeout 120
    python benchmarks/stability.py --out /tmp/stab --previous benchmarks/results/stability.csv
    python benchmarks/stability.py --out /tmp/stab --previous old.csv --compare-only
"""

from __future__ import annotations

import argparse
import csv
import multiprocessing as mp
import sys
import time
import traceback
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from stability_cases import GROUPS, OUT, Row, _describe, _guard, _Halvings  # noqa: E402


# ------------------------------------------------------------------------------ running
def _child(run: Callable[[], list[Row]], conn: Any) -> None:
    _Halvings.install()
    try:
        rows = run()
    except Exception as exc:  # noqa: BLE001
        rows = [
            {
                "status": "raised",
                "error": _describe(exc),
                "traceback": traceback.format_exc(limit=3),
            }
        ]
    conn.send(rows)
    conn.close()


def run_bounded(group: str, label: str, run: Callable[[], list[Row]], timeout: float) -> list[Row]:
    """Run one case in a forked process; a case that exceeds ``timeout`` s is killed."""
    ctx = mp.get_context("fork")
    recv, send = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_child, args=(run, send), daemon=True)
    start = time.perf_counter()
    proc.start()
    send.close()
    rows: list[Row]
    if recv.poll(timeout):
        try:
            rows = recv.recv()
        except EOFError:
            rows = [{"status": "crashed", "error": f"worker exited with code {proc.exitcode}"}]
    else:
        proc.terminate()
        rows = [{"status": "timeout", "error": f"no result within {timeout:g} s (killed)"}]
    proc.join(10)
    if proc.is_alive():
        proc.kill()
        proc.join()
    elapsed = time.perf_counter() - start
    for row in rows:
        row.setdefault("group", group)
        row.setdefault("case", label)
        row.setdefault("case_seconds", round(elapsed, 1))
    return rows


# ------------------------------------------------------------------------------ output
COLUMNS = [
    "group",
    "case",
    "parameter",
    "value",
    "method",
    "status",
    "error",
    "mean",
    "p95",
    "max",
    "epsilon",
    "iterations",
    "halvings",
    "penalty",
    "min_J",
    "coverage",
    "cells_without_data",
    "phase_error",
    "wall_time",
    "frames",
    "epsilon_frames",
    "line_search",
    "cells",
    "case_seconds",
    "previous_status",
    "previous_mean",
    "previous_p95",
]


def _fmt(value: Any, digits: int = 3) -> str:
    if value is None or value == "":
        return ""
    if isinstance(value, float):
        if not np.isfinite(value):
            return "nan"
        if abs(value) >= 1e3 or abs(value) < 1e-2:
            return f"{value:.{digits}g}"
        return f"{value:.{digits}f}"
    return str(value)


def write_csv(rows: list[Row], path: Path) -> None:
    with open(path, "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=COLUMNS, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(rows)


def check_monotone_epsilon(rows: list[Row]) -> str:
    """Is ε non-increasing in the pinned penalty λ, frame by frame (per penalty scene)?"""
    verdicts = []
    cases = sorted(
        {r["case"] for r in rows if r.get("group") == "penalty" and r.get("epsilon_frames")}
    )
    for case in cases:
        pinned = sorted(
            (r for r in rows if r.get("case") == case and r.get("epsilon_frames")),
            key=lambda r: float(r["value"]),
        )
        if len(pinned) < 2:
            continue
        eps = np.array([[float(e) for e in str(r["epsilon_frames"]).split()] for r in pinned])
        lam = [float(r["value"]) for r in pinned]
        rises = np.diff(eps, axis=0)
        # monotone up to which λ? (the first rise above 1e-3 rad, the Gauss–Newton tolerance)
        bad = np.nonzero((rises > 1e-3).any(axis=1))[0]
        if bad.size == 0:
            verdict = f"non-increasing over the whole sweep ({lam[0]:g} … {lam[-1]:g} × default)"
        else:
            i = int(bad[0])
            frame = int(np.argmax(rises[i])) + 1
            verdict = (
                f"non-increasing up to {lam[i]:g} × default; it rises by "
                f"{rises[i].max():.2g} rad from {lam[i]:g} to {lam[i + 1]:g} (frame {frame})"
                f", largest rise {rises.max():.2g} rad"
            )
        verdicts.append(f"ε against pinned λ, {case}: {verdict}.")
    return "\n".join(verdicts)


def headline(rows: list[Row]) -> list[str]:
    """One line per swept series: value → mean error, marking the frames that failed."""
    series: dict[tuple[str, str, str], list[Row]] = {}
    for r in rows:
        if r.get("parameter") and r.get("mean") not in (None, ""):
            series.setdefault((r["group"], r["case"], r.get("method", "")), []).append(r)
    out = []
    for (group, case, method), rs in series.items():
        rs = sorted(rs, key=lambda r: float(r["value"]))
        points = ", ".join(
            f"{_fmt(r['value'])} → {_fmt(r['mean'])}"
            + ("" if r.get("status") in ("converged", "pinned") else f" ({r.get('status')})")
            for r in rs
        )
        out.append(f"- **{group}**, {case}, {method} — {rs[0]['parameter']}: {points}")
    return out


def _number(value: Any) -> float:
    try:
        return float(value)
    except (TypeError, ValueError):
        return float("nan")


def _key(row: Row) -> tuple[str, str, str, str]:
    value = _number(row.get("value"))
    shown = f"{value:g}" if np.isfinite(value) else str(row.get("value", ""))
    return (str(row.get("group", "")), str(row.get("case", "")), shown, str(row.get("method", "")))


def mark_changes(
    rows: list[Row], previous: list[Row], *, relative: float = 0.1, absolute: float = 0.005
) -> int:
    """Put an earlier record's status and errors beside each row that changed; return how many.

    Rows match by group, case, value and method. A row changed if its status differs, or
    its mean error moved by more than ``relative`` of the larger of the two and more than
    ``absolute`` mm (or is now finite and was not, or the reverse).
    """
    before = {_key(r): r for r in previous}
    changed = 0
    for row in rows:
        for column in ("previous_status", "previous_mean", "previous_p95"):
            row.pop(column, None)
        old = before.get(_key(row))
        if old is None:
            continue
        now, then = _number(row.get("mean")), _number(old.get("mean"))
        moved = bool(np.isfinite(now)) != bool(np.isfinite(then)) or (
            bool(np.isfinite(now) and np.isfinite(then))
            and abs(now - then) > max(absolute, relative * max(abs(now), abs(then)))
        )
        if moved or row.get("status") != old.get("status"):
            row["previous_status"] = old.get("status", "")
            row["previous_mean"] = old.get("mean", "")
            row["previous_p95"] = old.get("p95", "")
            changed += 1
    return changed


def _changes(rows: list[Row], previous: str) -> list[str]:
    """Markdown section: the rows that changed against ``previous``, before and after."""
    changed = [r for r in rows if r.get("previous_status") not in (None, "")]
    lines = [
        "## Changed against the previous record",
        "",
        f"{len(changed)} of {len(rows)} rows changed against `{previous}` (status, or mean "
        "error by more than 10 % and 0.005 mm); the CSV carries the previous numbers in "
        "`previous_status`, `previous_mean`, `previous_p95`.",
        "",
        "| group | case | value | method | before: status | mean | p95 | now: status | mean | "
        "p95 |",
        "|" + "---|" * 10,
    ]
    for r in changed:
        cells = [
            r.get("group", ""),
            r.get("case", ""),
            _fmt(r.get("value", "")),
            r.get("method", ""),
            r.get("previous_status", ""),
            _fmt(_number(r.get("previous_mean"))),
            _fmt(_number(r.get("previous_p95"))),
            r.get("status", ""),
            _fmt(_number(r.get("mean"))),
            _fmt(_number(r.get("p95"))),
        ]
        lines.append("| " + " | ".join(str(c).replace("|", "/") for c in cells) + " |")
    return [*lines, ""]


def write_markdown(
    rows: list[Row], path: Path, generated: str, previous: str | None = None
) -> None:
    """Write the report; ``generated`` says when, by which command and how long it took."""
    lines = [
        "# Stability report (issue 7)",
        "",
        f"{generated} Errors are "
        "|u − u_true| in mm over the body voxels and all frames after the reference "
        "(per frame for the rotation to 180°); ε is the largest per-frame tracking residual "
        "(rad); halvings are Gauss–Newton steps that would have inverted an element "
        "(cut-backs for `newton.solve`); time is the wall time of the tracking call (s).",
        "",
    ]
    verdict = check_monotone_epsilon(rows)
    if verdict:
        lines += [v + "  " for v in verdict.splitlines()] + [""]
    if previous is not None:
        lines += _changes(rows, previous)
    lines += ["## Headline: mean error (mm) against each swept parameter", ""]
    lines += headline(rows) + ["", "## All cases", ""]
    header = (
        "| group | case | parameter | value | method | status | mean | p95 | ε | "
        "GN it. | halvings | min J | time (s) | note |"
    )
    lines += [header, "|" + "---|" * 14]
    for r in rows:
        note = r.get("error", "")
        if r.get("phase_error") not in (None, ""):
            note = (note + " " if note else "") + (
                f"image phase error (x, y tags) {_fmt(r['phase_error'])} rad"
            )
        if r.get("cells_without_data"):
            note = (note + " " if note else "") + f"{r['cells_without_data']} cells without data"
        cells = [
            r.get("group", ""),
            r.get("case", ""),
            r.get("parameter", ""),
            _fmt(r.get("value", "")),
            r.get("method", ""),
            r.get("status", ""),
            _fmt(r.get("mean")),
            _fmt(r.get("p95")),
            _fmt(r.get("epsilon")),
            _fmt(r.get("iterations")),
            _fmt(r.get("halvings")),
            _fmt(r.get("min_J")),
            _fmt(r.get("wall_time"), 2),
            str(note).replace("|", "/"),
        ]
        lines.append("| " + " | ".join(str(c) for c in cells) + " |")
    path.write_text("\n".join(lines) + "\n")


def plot(rows: list[Row], out: Path) -> list[Path]:
    """Error (mean, p95) and wall time against each swept parameter, one PNG per group."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    written = []
    groups: dict[str, list[Row]] = {}
    for r in rows:
        swept = r.get("parameter") and isinstance(r.get("value"), int | float)
        if swept and r.get("mean") is not None:
            groups.setdefault(str(r["group"]), []).append(r)
    for group, members in groups.items():
        series: dict[str, list[Row]] = {}
        for r in members:
            series.setdefault(f"{r['case']} — {r.get('method', '')}", []).append(r)
        height = 4.0 + 0.17 * ((len(series) + 1) // 2)
        fig, (ax_e, ax_t) = plt.subplots(1, 2, figsize=(11, height), layout="constrained")
        for label, rs in series.items():
            rs = sorted(rs, key=lambda r: float(r["value"]))
            x = [float(r["value"]) for r in rs]
            (line,) = ax_e.plot(x, [r["mean"] for r in rs], "o-", label=label)
            ax_e.plot(x, [r.get("p95", np.nan) for r in rs], "x:", color=line.get_color())
            if any(r.get("wall_time") is not None for r in rs):
                ax_t.plot(x, [r.get("wall_time", np.nan) for r in rs], "o-", color=line.get_color())
        parameter = members[0]["parameter"]
        for ax in (ax_e, ax_t):
            ax.set_xlabel(parameter)
            values = [float(r["value"]) for r in members]
            if min(values) > 0 and max(values) / min(values) >= 100:
                ax.set_xscale("log")
            ax.grid(alpha=0.3)
        ax_e.set_yscale("log")
        ax_e.set_ylabel("error (mm): mean (o), p95 (x)")
        ax_t.set_ylabel("wall time (s)")
        ax_e.set_title(f"{group}: error against truth", fontsize=10)
        ax_t.set_title(f"{group}: run time", fontsize=10)
        handles, labels = ax_e.get_legend_handles_labels()
        fig.legend(handles, labels, fontsize=7, loc="outside lower center", ncol=2)
        path = out / f"stability_{group.replace(' ', '_')}.png"
        fig.savefig(path, dpi=110)
        plt.close(fig)
        written.append(path)
    return written


def read_csv(path: Path) -> list[Row]:
    """Rows of a ``stability.csv`` with numbers parsed back (for ``--replot``)."""
    rows = []
    with open(path, newline="") as fh:
        for raw in csv.DictReader(fh):
            row: Row = {}
            for key, text in raw.items():
                if text in ("", None):
                    continue
                try:
                    row[key] = int(text) if text.lstrip("-").isdigit() else float(text)
                except ValueError:
                    row[key] = text
            rows.append(row)
    return rows


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--groups", nargs="+", choices=list(GROUPS), default=list(GROUPS))
    parser.add_argument("--timeout", type=float, default=240.0, help="wall-time bound per case, s")
    parser.add_argument("--out", type=Path, default=OUT)
    parser.add_argument(
        "--replot", action="store_true", help="redraw the PNGs from an existing stability.csv"
    )
    parser.add_argument(
        "--previous",
        type=Path,
        help="an earlier stability.csv: rows that changed get its numbers beside the new ones",
    )
    parser.add_argument(
        "--compare-only",
        action="store_true",
        help="with --previous: compare the stability.csv in --out instead of running",
    )
    args = parser.parse_args(argv)
    command = "python benchmarks/stability.py " + " ".join(sys.argv[1:] if argv is None else argv)
    today = time.strftime("%Y-%m-%d")
    args.out.mkdir(parents=True, exist_ok=True)
    if args.replot:
        for path in plot(read_csv(args.out / "stability.csv"), args.out):
            print("wrote", path)
        return
    previous = None if args.previous is None else read_csv(args.previous)
    if args.compare_only:
        if previous is None:
            parser.error("--compare-only needs --previous")
        rows = read_csv(args.out / "stability.csv")
        print(mark_changes(rows, previous), "rows changed")
        report = args.out / "stability.md"
        first = next(
            (ln for ln in report.read_text().splitlines() if ln.startswith("Generated")), ""
        )
        generated = first.split(" Errors are ")[0] + (
            f" Compared on {today} with the previous record by `{command.strip()}`."
        )
        write_csv(rows, args.out / "stability.csv")
        write_markdown(rows, report, generated, str(args.previous))
        return
    start = time.perf_counter()
    rows: list[Row] = []
    for group in args.groups:
        for group_name, label, run in GROUPS[group]():
            new = run_bounded(
                group_name, label, _guard(run, group_name, label, "", ""), args.timeout
            )
            for r in new:
                print(
                    f"[{time.perf_counter() - start:6.0f} s] {r.get('group')} | "
                    f"{r.get('case')} | "
                    f"{r.get('parameter', '')}={r.get('value', '')} | {r.get('method', '')} | "
                    f"{r.get('status')} | mean {_fmt(r.get('mean'))} p95 {_fmt(r.get('p95'))} "
                    f"eps {_fmt(r.get('epsilon'))} | halvings {r.get('halvings', '')} "
                    f"min J {_fmt(r.get('min_J'))} | {_fmt(r.get('wall_time'), 2)} s "
                    f"{r.get('error', '')}",
                    flush=True,
                )
            rows += new
    seconds = time.perf_counter() - start
    compared = None
    if previous is not None:
        print(mark_changes(rows, previous), "rows changed")
        compared = str(args.previous)
    generated = f"Generated on {today} by `{command.strip()}` in {seconds / 60:.1f} min."
    write_csv(rows, args.out / "stability.csv")
    write_markdown(rows, args.out / "stability.md", generated, compared)
    for path in plot(rows, args.out):
        print("wrote", path)
    print(check_monotone_epsilon(rows))
    print(f"{len(rows)} rows in {seconds / 60:.1f} min -> {args.out / 'stability.md'}")


if __name__ == "__main__":
    main()
