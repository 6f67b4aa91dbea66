"""The ``tableteach`` command: learner subcommands (infer, query, plan) and the app's entry points."""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from .core.belief import Belief, LabelledExecution
from .core.data_io import InputError, load_authors_demo, load_executions
from .core.domain import Domain, get_domain
from .core.hypotheses import get_space
from .core.exact import commands as exact_commands
from .core.exact.objects import objects_domain, parse_objects
from .core.priors import DEFAULT_PRIOR, NAMED_PRIORS
from .core.puns import CRITERIA
from .core.queries import QUERY_STRATEGIES, plan_execution, query

EXIT_USAGE = 2


class CliError(Exception):
    """A user-facing error: printed as one line on stderr, exit code 2."""


def _domain(args: argparse.Namespace) -> Domain:
    """The task's domain: a named one (--task) or the objects the user named (--objects)."""
    if (args.task is None) == (args.objects is None):
        raise CliError("give exactly one of --task dinner|synthetic and --objects a,b,c,...")
    if args.objects is not None:
        if args.authors_format:
            raise CliError("--authors-format reads the dinner objects W0..W4; use it with --task dinner")
        return objects_domain(parse_objects(args.objects))
    return get_domain(args.task)


def _factorised(args: argparse.Namespace) -> bool:
    """Whether the task is past what enumeration handles (more than five named objects)."""
    return args.objects is not None and len(_domain(args).orderable) > exact_commands.ENUMERATED_UP_TO


def _executions(args: argparse.Namespace) -> list[LabelledExecution]:
    domain = _domain(args)
    if not args.authors_format:
        if len(args.data) != 1:
            raise CliError("--data takes exactly one executions JSON file (or use --authors-format)")
        return load_executions(args.data[0], domain)
    out: list[LabelledExecution] = []
    for item in args.data:
        path = Path(item)
        if path.is_dir():
            files = sorted(path.glob("demo_*")) + sorted(path.glob("query_*_trace.json"))
            if not files:
                raise CliError(f"{path}: no demo_* or query_*_trace.json files in this folder")
        elif path.exists():
            files = [path]
        else:
            raise CliError(f"{path}: no such file or folder")
        out += [load_authors_demo(f, domain) for f in files]
    return out


def _posterior(args: argparse.Namespace) -> tuple[Belief, float]:
    executions = _executions(args)
    if args.task:
        space = get_space(args.task, args.prior)
    else:
        space = exact_commands.enumerated_space(_domain(args), args.prior)
    started = time.perf_counter()
    belief = Belief.prior(space).observe_all(executions)
    _ = belief.probs
    return belief, time.perf_counter() - started


def cmd_infer(args: argparse.Namespace) -> dict:
    """Posterior over formulas from labelled executions."""
    if args.top <= 0:
        raise CliError(f"--top must be a positive whole number, got {args.top}")
    if _factorised(args):
        return exact_commands.infer(_domain(args), args.prior, _executions(args), args.top)
    belief, seconds = _posterior(args)
    space = belief.space.domain.clause_space
    support = [
        {"formula": space.text_of(mask), "clauses": space.clause_texts(mask), "p": p,
         "description": space.describe(mask)}
        for mask, p in belief.top(args.top)
    ]
    return {
        "support": support,
        "entropy": belief.entropy,
        "map": space.text_of(belief.map_mask),
        "n_hypotheses": belief.space.size,
        "seconds": seconds,
    }


def cmd_query(args: argparse.Namespace) -> dict:
    """The robot's next query under a strategy."""
    if _factorised(args):
        return exact_commands.query(_domain(args), args.prior, _executions(args), args.strategy, args.seed)
    belief, _ = _posterior(args)
    started = time.perf_counter()
    execution, p = query(belief, args.strategy, np.random.default_rng(args.seed))
    return {"execution": list(execution.events), "p_acceptable": p, "seconds": time.perf_counter() - started}


def cmd_plan(args: argparse.Namespace) -> dict:
    """The robot's best execution under a PUnS criterion."""
    if _factorised(args):
        return exact_commands.plan(_domain(args), args.prior, _executions(args), args.criterion)
    belief, _ = _posterior(args)
    started = time.perf_counter()
    execution, p = plan_execution(belief, args.criterion, np.random.default_rng(args.seed), risk=args.risk)
    return {"execution": list(execution.events), "p_acceptable": p, "seconds": time.perf_counter() - started}


def _learner_args(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--task", choices=["dinner", "synthetic"], help="task domain (or --objects)")
    parser.add_argument("--objects", help="the task's own objects, 2 to 10 comma-separated names (or --task)")
    parser.add_argument("--prior", default=DEFAULT_PRIOR, choices=list(NAMED_PRIORS),
                        help=f"prior over formulas (default {DEFAULT_PRIOR})")
    parser.add_argument("--data", required=True, action="append",
                        help="executions JSON file; with --authors-format, authors' files or folders (repeatable)")
    parser.add_argument("--authors-format", action="store_true",
                        help="read the paper authors' demo_*/query_* files (W0..W4 naming)")


class _OneLineErrorParser(argparse.ArgumentParser):
    """An argument parser whose usage errors are one line on stderr (exit code 2)."""

    def error(self, message: str) -> None:  # type: ignore[override]
        raise CliError(f"{self.prog}: {message} (see --help)")


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of every subcommand."""
    parser = _OneLineErrorParser(prog="tableteach", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)

    infer = sub.add_parser("infer", help="exact posterior over task formulas from labelled executions")
    _learner_args(infer)
    infer.add_argument("--top", type=int, default=10, help="how many formulas to list (default 10)")
    infer.set_defaults(run=cmd_infer)

    q = sub.add_parser("query", help="the execution the robot would show the teacher next")
    _learner_args(q)
    q.add_argument("--strategy", choices=list(QUERY_STRATEGIES), default="active")
    q.add_argument("--seed", type=int, default=0)
    q.set_defaults(run=cmd_query)

    plan = sub.add_parser("plan", help="the robot's best execution under a PUnS criterion")
    _learner_args(plan)
    plan.add_argument("--criterion", choices=list(CRITERIA), default="min-regret")
    plan.add_argument("--risk", type=float, default=0.1, help="chance-constrained: allowed failure mass")
    plan.add_argument("--seed", type=int, default=0)
    plan.set_defaults(run=cmd_plan)

    for register in _EXTRA_COMMANDS:
        register(sub)
    return parser


# Entry points of other packages (server, experiments) register their subcommands here.
_EXTRA_COMMANDS: list[Callable[[argparse._SubParsersAction], None]] = []


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; user errors print one line on stderr and exit 2."""
    _load_extra_commands()
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
        result = args.run(args)
    except (CliError, InputError, ValueError) as exc:
        print(f"tableteach: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("tableteach: interrupted", file=sys.stderr)
        return 130
    if result is not None:
        print(json.dumps(result))
    return 0


def _load_extra_commands() -> None:
    """Import the optional subcommand modules (kept out of the learner's import path)."""
    import importlib

    for module in ("tableteach.experiments.cli", "tableteach.web.cli"):
        try:
            mod = importlib.import_module(module)
        except ModuleNotFoundError as exc:
            if exc.name != module:
                raise
            continue
        register = getattr(mod, "register", None)
        if register is not None and register not in _EXTRA_COMMANDS:
            _EXTRA_COMMANDS.append(register)


if __name__ == "__main__":
    sys.exit(main())
