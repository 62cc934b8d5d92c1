"""`python -m suite ...`: the command-line interface.

Each subcommand lives in its own module, imported only when it runs, so `--help` stays fast and
one command's heavy imports (Drake, OMPL) never slow another down.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import sys

from scenes.errors import SuiteError
from suite.run.interrupt import Interrupted

#: subcommand -> (module, one-line help). The module defines add_arguments(parser) and run(args).
COMMANDS = {
    "scene": ("suite.cli.scene", "generate a scene from a seed and print its ground truth"),
    "perceive": ("suite.cli.perceive", "render the cameras and detect the cans (paper's geometric pipeline)"),
    "plan": ("suite.cli.plan", "plan every pick-and-place motion of one scene with one planner"),
    "compare": ("suite.cli.compare", "run the planner comparison and write results, table and plots"),
    "execute": ("suite.cli.execute", "plan one scene and execute the plans in physics: are the cans recycled?"),
    "dataset": ("suite.cli.dataset", "build, verify or show a frozen dataset of problems with reference solutions"),
    "tune": ("suite.cli.tune", "choose a planner's settings on a dataset's tuning split (planners/configs/NAME.yaml)"),
    "plot": ("suite.cli.plot", "redraw the plots and tables of a run from its trials.jsonl"),
    "report": ("suite.cli.report", "write a run's self-contained one-page report (RUN/report.html)"),
    "replay": ("suite.cli.replay", "write a 3-D replay (Meshcat, static HTML) of every planner's path of one problem"),
    "rescore": ("suite.cli.rescore", "recompute every metric of a run from its stored paths, then redraw its report"),
    "export": ("suite.cli.export", "write a dataset's problems as files any planner can read (problems, schema, URDFs)"),
    "import": ("suite.cli.import_", "judge an external planner's paths like a suite trial and add them as records"),
    "regions": ("suite.cli.regions", "build gcs's collision-free convex regions of a dataset's worlds ahead (cached)"),
    "paper": ("suite.cli.paper", "reproduce a published experiment on the suite's planners (gcs-arm: the GCS paper's arm)"),
    "bench": ("suite.cli.bench", "print speed figures (collision, perception, planners)"),
    "docs": ("suite.cli.docs", "rewrite the figures of README.md and docs/ from the committed files they come from"),
}


class _Parser(argparse.ArgumentParser):
    """Bad arguments give one line (naming the value and what is allowed) and exit code 2."""

    def error(self, message: str):  # type: ignore[override]
        self.exit(2, f"{self.prog}: error: {message}\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="python -m suite",
        description="Compare motion planners on the can-recycling pick-and-place task.",
    )
    parser.add_argument("-v", "--verbose", action="store_true", help="log debug messages")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    for name, (module, help_) in COMMANDS.items():
        p = sub.add_parser(name, help=help_, description=help_)
        p.set_defaults(_module=module)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    parser = build_parser()
    # Only the chosen subcommand's module is imported to add its arguments.
    chosen = next((a for a in argv if not a.startswith("-")), None)
    if chosen in COMMANDS:
        sub_action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
        try:
            module = importlib.import_module(COMMANDS[chosen][0])
        except ModuleNotFoundError as exc:
            if exc.name == COMMANDS[chosen][0]:
                print(f"error: command {chosen!r} is not available yet", file=sys.stderr)
                return 2
            raise
        module.add_arguments(sub_action.choices[chosen])
    args = parser.parse_args(argv)
    logging.basicConfig(
        level=logging.DEBUG if args.verbose else logging.INFO,
        format="%(levelname)s %(name)s: %(message)s",
    )
    if args.command is None:
        parser.print_help()
        return 2
    try:
        return int(importlib.import_module(args._module).run(args) or 0)
    except SuiteError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except Interrupted as exc:  # SIGINT/SIGTERM under a command's SignalGuard: no traceback
        print(f"interrupted by {exc.name}", file=sys.stderr)
        return exc.exit_code
    except BrokenPipeError:  # e.g. piped into `head`: the reader has gone, nothing to report
        sys.stderr.close()
        return 0
