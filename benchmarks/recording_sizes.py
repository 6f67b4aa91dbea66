"""What the database holds per step with TABLETEACH_RECORDING_STORE=database: one server (SQLite, MuJoCo robot at
speed 4) runs scripted participants through a study, then the recording tables are read.

    .venv/bin/python benchmarks/recording_sizes.py [--seeds 3,3,5]

Prints, per step kind and file type, how many files and their mean size; then the files named, the distinct
bytes stored (a motion participants share is stored once) and both totals. Everything lives in a temporary folder.
"""

from __future__ import annotations

import argparse
import sqlite3
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tableteach.client import run_teacher  # noqa: E402
from tests.web.conftest import ServerProcess, open_study, study_spec  # noqa: E402


def main() -> None:
    """Run the participants and print the sizes."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="3,3,5", help="one scripted teacher per seed (the same seed twice: "
                                                         "likely the same executions, so shared motion)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="recording-sizes-") as scratch:
        tmp = Path(scratch)
        server = ServerProcess(tmp / "m.db", TABLETEACH_ROBOT="mujoco", TABLETEACH_ROBOT_SPEED="4",
                               TABLETEACH_RECORDING_STORE="database", TABLETEACH_DATA_DIR=str(tmp / "data")).start()
        try:
            study = open_study(server.url, study_spec(["active"], n_practice=0, n_demonstrations=2, n_queries=2,
                                                      n_tests=1))
            for seed in (int(x) for x in args.seeds.split(",")):
                run_teacher(server.url, study, ["task1"], seed=seed)
        finally:
            server.stop()
        with sqlite3.connect(tmp / "m.db") as con:
            rows = con.execute("SELECT f.name, b.size FROM recording_files f JOIN recording_blobs b "
                               "USING (digest)").fetchall()
            blobs, stored = con.execute("SELECT count(*), coalesce(sum(size), 0) FROM recording_blobs").fetchone()
    by_kind: dict[str, list[int]] = {}
    for name, size in rows:
        kind = name.split("/")[2].split("-")[0] + name[name.rindex("."):]
        by_kind.setdefault(kind, []).append(size)
    for kind, sizes in sorted(by_kind.items()):
        print(f"{kind:20s} files {len(sizes):3d}  mean {sum(sizes) / len(sizes) / 1000:7.1f} kB")
    named = sum(size for _, size in rows)
    print(f"files {len(rows)}  distinct {blobs}  named {named / 1e6:.2f} MB  stored {stored / 1e6:.2f} MB")


if __name__ == "__main__":
    main()
