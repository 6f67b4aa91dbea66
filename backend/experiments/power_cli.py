"""The ``tableteach power`` subcommand: power to detect a protocol contrast, per number of participants."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from ..core.belief import check_flip_rate
from ..core.teachers import DEFAULT_DEMO_MODE, DEMO_MODES
from .pilot_teacher import fitted_demo_mode, fitted_flip_rate
from .power import CONTRASTS, POWER_COLUMNS, parse_sizes, plot_power, pool_differences, power_table
from .settings import DOMAINS, ExperimentSettings, resolve_truth_sampler
from .summary import write_csv

DESCRIPTION = """Power from simulation: a pool of --runs simulated participants (a sweep into OUT/pool, resumable)
gives each one's paired difference; for each --participants size, --studies simulated studies are drawn
from it and tested (two-sided sign-flip permutation test of the mean difference, alpha 0.05). Writes
power.csv and power.png/.svg into --out. The teacher: --demo-mode and --flip-rate, or --pilot EXPORT
(the flip rate and the demonstration mode fitted from a pilot's exports.zip; a --demo-mode given beside it wins)."""


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``power`` subcommand."""
    p = subparsers.add_parser("power", help="power to detect a protocol contrast per number of participants",
                              description=DESCRIPTION)
    p.add_argument("--contrast", choices=list(CONTRASTS), default="active-batch")
    p.add_argument("--participants", default="10,20,40,60", help="sample sizes, e.g. 10,20,40,60")
    p.add_argument("--runs", type=int, default=200, help="simulated participants in the pool (default 200)")
    p.add_argument("--studies", type=int, default=1000, help="simulated studies per sample size (default 1000)")
    p.add_argument("--domain", choices=list(DOMAINS), default="dinner-task1",
                   help="the task (default dinner-task1, the paper's user study's Task 1)")
    p.add_argument("--n-query", type=int, default=3, help="queries (Batch: extra demonstrations) (default 3)")
    p.add_argument("--prior", default="chains-2020", help="the learner's prior (default chains-2020, the study's)")
    p.add_argument("--demo-mode", choices=list(DEMO_MODES), default=None,
                   help=f"how the simulated teacher demonstrates (default {DEFAULT_DEMO_MODE}, or fitted with --pilot)")
    p.add_argument("--flip-rate", type=float, default=None,
                   help="the teacher's verdict-flip probability, [0, 0.5) (default 0: a perfect teacher)")
    p.add_argument("--pilot", metavar="EXPORT", default=None,
                   help="fit the flip rate from a pilot's exports.zip (or folder) instead of --flip-rate")
    p.add_argument("--alpha", type=float, default=0.05)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--workers", type=int, default=None)
    p.add_argument("--out", required=True)
    p.add_argument("--no-progress", action="store_true")
    p.set_defaults(run=cmd_power)


def cmd_power(args: argparse.Namespace) -> dict[str, Any]:
    """Simulate the pool, compute the power table and the figure."""
    from .compare import read_sweep
    from .sweep import run_sweep

    sizes = parse_sizes(args.participants)
    if args.pilot is not None and args.flip_rate is not None:
        raise ValueError("give the teacher's flip rate (--flip-rate) or a pilot to fit it from (--pilot), not both")
    check_flip_rate(0.0 if args.flip_rate is None else args.flip_rate, "--flip-rate")
    if not 0.0 < args.alpha < 1.0:
        raise ValueError(f"--alpha must lie in (0, 1), got {args.alpha}")
    if args.studies < 10:
        raise ValueError(f"--studies must be at least 10, got {args.studies}")
    flip, demo_mode, fitted_from = args.flip_rate or 0.0, args.demo_mode or DEFAULT_DEMO_MODE, None
    if args.pilot is not None:
        flip, verdicts = fitted_flip_rate(args.pilot)
        fit = fitted_demo_mode(args.pilot)
        fitted_from = {"pilot": Path(args.pilot).name, "query_verdicts": verdicts,
                       "demonstrations": fit.demonstrations, "demo_mode_log_likelihood": fit.log_likelihood}
        demo_mode = args.demo_mode or fit.mode
    settings = ExperimentSettings(domain=args.domain, runs=args.runs, n_query=(args.n_query,), seed=args.seed,
                                  prior=args.prior, truth_sampler=resolve_truth_sampler(args.domain, None),
                                  demo_mode=demo_mode, noise=flip)
    out = Path(args.out)
    result = run_sweep(settings, out / "pool", workers=args.workers, progress=not args.no_progress, figures=False)
    _, rows = read_sweep(out / "pool")
    diffs = pool_differences(rows, settings, args.contrast)
    table = [{"contrast": args.contrast, **r, "pool_runs": int(diffs.size), "teacher_flip_rate": flip,
              "demo_mode": demo_mode, "domain": args.domain, "n_query": args.n_query}
             for r in power_table(diffs, sizes, args.studies, args.alpha, args.seed, not args.no_progress)]
    write_csv(out / "power.csv", table, POWER_COLUMNS)
    plot_power(table, f"{args.contrast} on {args.domain}, {args.n_query} queries, teacher {demo_mode}, flip "
                      f"{flip:.3g}; pool of {diffs.size} simulated participants", out / "power")
    return {"out": str(out), "pool_runs": result.runs_total, "teacher_flip_rate": round(flip, 4),
            "demo_mode": demo_mode, "fitted_from": fitted_from,
            "power": {str(r["participants"]): r["power"] for r in table}}
