"""Write an exports.zip of the demo study completed by scripted teachers (no server, no network: in-process).

    python scripts/examples/demo_export.py --teachers 6 --flip 0.2 --out docs/experiments/replay-demo/exports.zip

Half the teachers are perfect, half flip each verdict with probability --flip; each knows the study's
Task 1 and Task 2 goals. The example data for tableteach replay and the consistency score.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import warnings
from pathlib import Path

from tqdm import tqdm


def main() -> int:
    """Run the teachers in-process and save the study's exports.zip (pilots included: the demo study is a pilot)."""
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--teachers", type=int, default=6)
    parser.add_argument("--flip", type=float, default=0.2)
    parser.add_argument("--out", required=True)
    args = parser.parse_args()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        from starlette.testclient import TestClient

    from tableteach import services
    from tableteach.client import ParticipantClient, run_teacher
    from tableteach.config import Settings
    from tableteach.db.migrate import upgrade_head
    from tableteach.services import TASK_FORMULAS
    from tableteach.web.app import create_app

    token = "demo-export-token-0123456789abcdef"
    with tempfile.TemporaryDirectory() as tmp:
        settings = Settings(database_url=f"sqlite:///{Path(tmp) / 'app.db'}", experimenter_token=token,
                            data_dir=Path(tmp) / "data")
        upgrade_head(settings.database_url)
        app = create_app(settings)
        with TestClient(app) as client:
            study = services.seed_demo_study(app.state.context)
            for i in tqdm(range(args.teachers), unit="teacher", file=sys.stderr):
                api = ParticipantClient("http://testserver")
                api.http = client
                run_teacher("http://testserver", study["id"], [TASK_FORMULAS["task1"], TASK_FORMULAS["task2"]],
                            noise=args.flip if i % 2 else 0.0, seed=i, client=api, poll_seconds=0.0, timeout=600)
            response = client.get(f"/api/v1/studies/{study['id']}/exports/exports.zip?include_pilot=true",
                                  headers={"Authorization": f"Bearer {token}"})
            response.raise_for_status()
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_bytes(response.content)
    print(f"wrote {out} ({len(response.content)} bytes, {args.teachers} teachers)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
