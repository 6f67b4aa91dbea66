"""Active-vs-0.80 investigation: the default synthetic sweep (seed 0, n_query 6, 200 runs) with another epsilon.

    python scripts/investigations/gap_epsilon.py -20    # log2 of epsilon (the default is -80)

Prints the final median similarity per protocol as JSON. Same runs and random streams as the sweep.
"""

from __future__ import annotations

import json
import sys
import time

import numpy as np

from tableteach.core.hypotheses import HypothesisSpace, get_space
from tableteach.experiments import simulate
from tableteach.experiments.settings import ExperimentSettings


def main(log2_epsilon: float) -> dict[str, float]:
    """Final median similarity per protocol with the likelihood's epsilon set to 2**log2_epsilon."""
    base = get_space("synthetic", "chains-2020-sat")
    space = HypothesisSpace(base.domain, base.prior_name, base.spec, base.masks, base.log_prior,
                            log2_epsilon * np.log(2))
    simulate.get_space = lambda task, prior: space  # this process only: the sweep code is unchanged
    settings = ExperimentSettings(domain="synthetic", runs=200, n_query=(6,), seed=0)
    col = {c: i for i, c in enumerate(simulate.COLUMNS)}
    final: dict[str, list[float]] = {p: [] for p in ("active", "random", "batch")}
    for run in range(settings.runs):
        for row in simulate.simulate_run(settings, run):
            if row[col["n_executions"]] == settings.n_demonstrations + 6:
                final[row[col["protocol"]]].append(row[col["similarity"]])
    return {p: round(float(np.median(v)), 4) for p, v in final.items()}


if __name__ == "__main__":
    started = time.time()
    result = main(float(sys.argv[1]))
    print(json.dumps({"log2_epsilon": float(sys.argv[1]), "seconds": round(time.time() - started), **result}))
