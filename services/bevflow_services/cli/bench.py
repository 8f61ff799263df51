"""``bevflow bench``: every benchmark in one run, printed and (``--json OUT``) written.

Parts, in order: the cylinder fit (batched against the reference), the tracker service's tick
(fusion + tracking + analytics), the detector, the live system (frame-to-alert latency and the
most cameras the machine keeps up with), the gateway (REST and websocket fan-out) and the bus.
``--quick`` shortens every part so the whole run takes about a minute. Timers are the standard
library's; every figure is a median (or percentile) of repeated runs. See
``bevflow_services.benchmarks.suite`` for the JSON layout.
"""

from __future__ import annotations

import argparse
import json
import shlex
from pathlib import Path

from bevflow_services.runtime import UserError

EPILOG = """\
examples:
  bevflow bench --quick                        about a minute, every part
  bevflow bench --json bench.json              the full run (several minutes)
  bevflow bench --quick --only cylinder tracking
  bevflow bench --json bench.json --markdown docs/BENCHMARKS.md --note "machine shared with other jobs"

The JSON's top-level keys (cylinder_batched_ms_per_box, tracking_ms_per_tick_1000_people_64_cameras,
live_latency_p99_ms, gateway_rest_p99_ms, ...) are the same in every run, so runs can be compared;
a key that could not be measured is null and 'null_reasons' says why. Exit status: 0 when every
part that ran worked (a detector without a model is not a failure), 1 when a part failed, 2 for a
usage error."""


def register(subparsers: argparse._SubParsersAction) -> None:
    from bevflow_services.benchmarks.suite import PARTS

    parser = subparsers.add_parser(
        "bench",
        help="measure speed: cylinder fit, tracking tick, detector, live latency, gateway, bus",
        description="Run bevflow's benchmarks and print the numbers; --json also writes them to a file.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--quick", action="store_true", help="shorter runs of every part (about a minute in all)")
    parser.add_argument("--json", type=Path, metavar="OUT", help="also write the results to this JSON file")
    parser.add_argument("--markdown", type=Path, metavar="OUT", help="also write the results as a Markdown page (docs/BENCHMARKS.md)")
    parser.add_argument("--note", default="", help="a line about the machine for the Markdown page, e.g. that it was shared")
    parser.add_argument("--only", nargs="+", choices=PARTS, metavar="PART", help=f"run only these parts ({', '.join(PARTS)})")
    parser.add_argument("--skip", nargs="+", choices=PARTS, default=[], metavar="PART", help="leave these parts out")
    parser.add_argument("--detector-model", type=Path, metavar="ONNX", help="time this detector model (default: the shipped one)")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from bevflow_services.benchmarks.report import console_lines, markdown
    from bevflow_services.benchmarks.suite import FULL, PARTS, QUICK, run_suite

    parts = tuple(p for p in (args.only or PARTS) if p not in args.skip)
    if not parts:
        raise UserError("--only and --skip leave no part to run")
    if args.detector_model is not None and not args.detector_model.is_file():
        raise UserError(f"--detector-model: {args.detector_model} is not a file")
    for out in (args.json, args.markdown):
        if out is not None and not out.parent.is_dir():
            raise UserError(f"cannot write {out}: folder {out.parent} does not exist")
    result = run_suite(QUICK if args.quick else FULL, parts, args.detector_model, echo=lambda line: print(line, flush=True))
    result["command"] = command_line(args)
    print("\n".join(console_lines(result)))
    if args.json is not None:
        args.json.write_text(json.dumps(result, indent=2, allow_nan=False) + "\n")
        print(f"wrote {args.json}")
    if args.markdown is not None:
        args.markdown.write_text(markdown(result, result["command"], args.note))
        print(f"wrote {args.markdown}")
    return 1 if result["failed"] else 0


def command_line(args: argparse.Namespace) -> str:
    """The ``bevflow bench`` command that reruns this run and rewrites its Markdown page (the JSON
    file, a side output, is left out)."""
    words = ["bevflow", "bench"]
    if args.quick:
        words.append("--quick")
    for option in ("only", "skip"):
        if getattr(args, option):
            words += [f"--{option}", *getattr(args, option)]
    if args.detector_model is not None:
        words += ["--detector-model", str(args.detector_model)]
    if args.markdown is not None:
        words += ["--markdown", str(args.markdown)]
    if args.note:
        words += ["--note", args.note]
    return " ".join(shlex.quote(w) for w in words)
