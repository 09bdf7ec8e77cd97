"""The ``ladder`` command line.

Exit codes: 0 ok, 1 the task failed (no plan), 2 bad input (message names file, key, reason),
130 interrupted. Human-readable output by default; ``--json`` prints one JSON object.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
from pathlib import Path
from typing import Any

from models.scenario import Scenario, ScenarioError, load_scenario, parse_overrides

EXIT_OK, EXIT_FAILED, EXIT_BAD_INPUT, EXIT_INTERRUPTED = 0, 1, 2, 130

#: Subcommands the design reserves whose machinery is not built yet, with what they will do.
RESERVED = {
    "simulate": "replay a plan or the scenario's policy under a chosen rung",
    "plan": "plan up the model ladder (geometric -> kinematic -> quasistatic -> dynamic)",
    "sweep": "map feasible sets over design parameters (the paper's Fig. 5)",
    "bench": "work-precision, throughput and scaling benchmarks",
    "serve": "serve planning requests over HTTP",
}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="ladder",
        description="Hierarchical manipulation planning: plan with the cheapest contact model, "
        "then upgrade the model and replan until the plan holds under the highest-fidelity one.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    check = sub.add_parser(
        "check",
        help="validate a scenario file and summarise it",
        description="Validate a scenario file (structure, parameters, geometry, initial penetration) "
        "and print its bodies, coordinates, contact pairs, parameters and ladder.",
    )
    check.add_argument("file", type=Path, help="scenario file (TOML)")
    _add_param_option(check)
    check.add_argument("--json", action="store_true", help="print one JSON object instead of tables")
    check.add_argument("--out", type=Path, help="also write the JSON summary to this file")
    check.set_defaults(handler=cmd_check)

    schema = sub.add_parser(
        "schema",
        help="print the JSON Schema of scenario files",
        description="Print (or write) the JSON Schema of the scenario format, for editors such as "
        "Taplo / Even Better TOML (put '#:schema ./scenario.schema.json' on a file's first line).",
    )
    schema.add_argument("--out", type=Path, help="write the schema to this file instead of printing it")
    schema.set_defaults(handler=cmd_schema)

    for name, what in RESERVED.items():
        reserved = sub.add_parser(name, help=f"(not built yet) {what}", description=f"Not built yet: {what}.")
        reserved.add_argument("args", nargs=argparse.REMAINDER, help=argparse.SUPPRESS)
        reserved.set_defaults(handler=cmd_reserved)
    return parser


def _add_param_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--param",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="override a design parameter of the file (repeatable)",
    )


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.handler(args)
    except ScenarioError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED


# ----------------------------------------------------------------------------- commands


def load_from_args(args: argparse.Namespace) -> Scenario:
    return load_scenario(args.file, parse_overrides(args.param))


def cmd_check(args: argparse.Namespace) -> int:
    scenario = load_from_args(args)
    summary = scenario.summary()
    if args.out:
        write_atomic(args.out, json.dumps(summary, indent=2) + "\n")
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        print_summary(summary)
        if args.out:
            print(f"summary written to {args.out}")
    return EXIT_OK


def cmd_schema(args: argparse.Namespace) -> int:
    from models.schema import json_schema

    text = json.dumps(json_schema(), indent=2) + "\n"
    if args.out:
        write_atomic(args.out, text)
        print(f"schema written to {args.out}")
    else:
        print(text, end="")
    return EXIT_OK


def cmd_reserved(args: argparse.Namespace) -> int:
    print(
        f"error: 'ladder {args.command}' is not built yet ({RESERVED[args.command]}); "
        "available now: ladder check, ladder schema",
        file=sys.stderr,
    )
    return EXIT_BAD_INPUT


# ----------------------------------------------------------------------------- output


def write_atomic(path: Path, text: str) -> None:
    """Write via a temporary file and a rename, so a failure never leaves half a file."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as handle:
            handle.write(text)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def print_summary(summary: dict[str, Any]) -> None:
    from rich.console import Console
    from rich.table import Table

    console = Console(highlight=False)
    console.print(f"[bold]{summary['name']}[/bold]  ({summary['file']}, {summary['dimension']}D): ok")
    if summary["description"]:
        console.print(summary["description"])

    bodies = Table(title="bodies", title_justify="left")
    for col in ("name", "role", "shape", "free DOFs", "actuated", "mass"):
        bodies.add_column(col)
    for b in summary["bodies"]:
        mass = "" if b["mass"] is None else f"{b['mass']:g}"
        bodies.add_row(b["name"], b["role"], b["shape"], ", ".join(b["dofs"]) or "-", ", ".join(b["actuated"]) or "-", mass)
    console.print(bodies)

    coords = Table(title="generalized coordinates q (in order)", title_justify="left")
    for col in ("#", "name", "start", "actuated"):
        coords.add_column(col)
    for i, (name, value) in enumerate(summary["start"].items()):
        coords.add_row(str(i), name, f"{value:g}", "yes" if name in summary["actuated"] else "")
    console.print(coords)

    pairs = Table(title="contact pairs", title_justify="left")
    for col in ("bodies", "mu", "K", "C"):
        pairs.add_column(col)
    for p in summary["contact_pairs"]:
        pairs.add_row(" - ".join(p["bodies"]), f"{p['mu']:g}", f"{p['K']:g}", f"{p['C']:g}")
    console.print(pairs)

    if summary["parameters"]:
        params = Table(title="design parameters", title_justify="left")
        params.add_column("name")
        params.add_column("value")
        for name, value in summary["parameters"].items():
            params.add_row(name, f"{value:g}")
        console.print(params)

    ladder = summary["ladder"]
    steps = ", ".join(f"{m} (h={h:g})" if h else m for m, h in ladder["steps"].items())
    console.print(f"ladder: {steps}; planner {ladder['planner']}, seed {ladder['seed']}, {ladder['time_limit']:g} s per rung")
