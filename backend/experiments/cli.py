"""The ``tableteach experiment`` subcommand: the paper's simulation study (Active, Random, Batch)."""

from __future__ import annotations

import argparse
from typing import Any

from ..core.priors import DEFAULT_PRIOR, NAMED_PRIORS
from ..core.metrics import DEFAULT_METRIC, SIMILARITY_METRICS
from ..core.queries import ACTIVE_STRATEGIES, DEFAULT_ACTIVE_STRATEGY, DEFAULT_QUERY_TIES, QUERY_TIES
from ..core.teachers import DEFAULT_DEMO_MODE, DEMO_MODES
from .settings import DOMAINS, SIZE_DEFAULTS, TRUTH_SAMPLERS, ExperimentSettings, parse_n_query, resolve_truth_sampler

DESCRIPTION = """Simulated teaching sessions comparing Active, Random and Batch learning, paired within
each run (same ground truth, same first two demonstrations). Writes runs.csv, summary.csv,
figures (PNG, SVG) and config.json into --out; rerunning into the same folder resumes."""


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``experiment`` subcommand."""
    p = subparsers.add_parser("experiment", help="simulation sweep of Active, Random and Batch learning",
                              description=DESCRIPTION)
    p.add_argument("--domain", required=True, choices=list(DOMAINS),
                   help="synthetic (5 waypoints + 5 threats), a dinner study task, or dinner with random truths")
    p.add_argument("--out", required=True, help="output folder (created; rerun into it to resume)")
    p.add_argument("--runs", type=int, default=200, help="runs per setting (default 200)")
    p.add_argument("--n-query", default="1-6",
                   help="numbers of queries to compare, e.g. 1,2,3 or 1-6 (default 1-6)")
    p.add_argument("--seed", type=int, default=0, help="sweep seed (default 0)")
    p.add_argument("--prior", default=DEFAULT_PRIOR, choices=list(NAMED_PRIORS),
                   help=f"the learner's prior (default {DEFAULT_PRIOR})")
    p.add_argument("--truth-sampler", choices=list(TRUTH_SAMPLERS), default=None,
                   help="how random ground truths are drawn: from the prior (satisfiable only; default) "
                        "or the authors' sampler; not for dinner-task1/2, whose truth is fixed")
    p.add_argument("--demo-mode", choices=list(DEMO_MODES), default=DEFAULT_DEMO_MODE,
                   help="demonstrations: required-only (default; the authors' demonstrator: required items "
                        "in a random valid order, then stop), optimal (optimal policy, random ties, extras "
                        "included), uniform (over satisfying executions) or fixed (the same one every time)")
    p.add_argument("--similarity", choices=list(SIMILARITY_METRICS), default=DEFAULT_METRIC,
                   help="similarity metric: the authors' IoU (default) or strict (drops orders on any "
                        "forbidden item)")
    p.add_argument("--query-ties", choices=list(QUERY_TIES), default=DEFAULT_QUERY_TIES,
                   help="active query ties: uniform among all tied executions (default, as the authors) "
                        "or shortest first")
    p.add_argument("--noise", type=float, default=0.0,
                   help="probability that the teacher flips an assessment (default 0)")
    p.add_argument("--active-strategy", choices=list(ACTIVE_STRATEGIES), default=DEFAULT_ACTIVE_STRATEGY,
                   help="how Active picks a query: uncertainty sampling (default, the authors') or expected "
                        "information gain (exact over the belief; ours)")
    p.add_argument("--learner-flip-rate", "--flip-rate", type=float, default=0.0, metavar="P",
                   help="the noise-aware learner: assume each verdict is flipped with probability P in [0, 0.5) "
                        "(default 0: the authors' learner, which treats every verdict as certain)")
    p.add_argument("--test-success", action="store_true",
                   help="also record whether the robot's test execution (the min-regret plan) after each "
                        "n_query's final step satisfies the truth (slower)")
    p.add_argument("--n-waypoints", type=int, default=SIZE_DEFAULTS["n_waypoints"],
                   help="synthetic domain: waypoints (default 5; 2 to 5 while the sweep enumerates)")
    p.add_argument("--n-threats", type=int, default=SIZE_DEFAULTS["n_threats"],
                   help="synthetic domain: threats (default 5)")
    p.add_argument("--workers", type=int, default=None, help="local worker processes (default: all cores)")
    p.add_argument("--dask", metavar="ADDRESS", default=None,
                   help="run on an existing Dask cluster, e.g. tcp://scheduler:8786, instead of locally")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(run=cmd_experiment)
    from .replay_cli import register as register_replay

    register_replay(subparsers)
    from .power_cli import register as register_power

    register_power(subparsers)


def settings_from_args(args: argparse.Namespace) -> ExperimentSettings:
    """Validated settings from the parsed command line (ValueError names what is wrong)."""
    return ExperimentSettings(
        domain=args.domain,
        runs=args.runs,
        n_query=parse_n_query(args.n_query),
        seed=args.seed,
        prior=args.prior,
        truth_sampler=resolve_truth_sampler(args.domain, args.truth_sampler),
        demo_mode=args.demo_mode,
        noise=args.noise,
        learner_flip_rate=args.learner_flip_rate,
        similarity=args.similarity,
        query_ties=args.query_ties,
        active_strategy=args.active_strategy,
        test_success=args.test_success,
        n_waypoints=args.n_waypoints,
        n_threats=args.n_threats,
    )


def cmd_experiment(args: argparse.Namespace) -> dict[str, Any]:
    """Run or resume a sweep; print a short JSON summary of what was done."""
    from .sweep import run_sweep

    settings = settings_from_args(args)
    if args.workers is not None and args.dask is not None:
        raise ValueError("--workers and --dask exclude each other: the Dask cluster decides its own workers")
    result = run_sweep(settings, args.out, workers=args.workers, dask_address=args.dask,
                       progress=not args.no_progress)
    return {
        "out": str(result.out),
        "runs": result.runs_total,
        "runs_computed": result.runs_done,
        "runs_resumed": result.runs_skipped,
        "seconds": round(result.seconds, 1),
        "final_median_similarity": {
            f"{row.protocol}@{row.n_query}": round(row.stats["similarity_median"], 3) for row in result.summary
        },
    }
