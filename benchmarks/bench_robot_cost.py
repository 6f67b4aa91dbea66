"""Robot CPU per participant session: the MuJoCo robot's physics, recordings and .viser files, cold and warm.

Everything goes through tableteach.sim.robot.MujocoRobot as the server drives it and counts CPU seconds around
the robot's calls only: this process's (time.process_time) and, for the sessions with --workers N, its robot
worker processes' too (from /proc). Without workers executions are worked out in this process, so one clock
sees all of it and every cache is shared; with them, as the server runs by default (one worker), the worker
works executions out and reads the placement clips the server wrote (and the server the worker's). Medians:

- placement: cold (nothing cached: simulated) and warm (the same placement on the same table again: a clip);
- execution of all 5 objects: cold (nothing cached), placements warm (its placements are clips, the execution
  itself is new: replayed, recorded, written) and warm (another participant's identical execution: the
  shared motion is linked);
- the .viser writer alone on a 5-object execution;
- sessions: N simulated participants, one after another, of bench_scale's study (one task, "task1";
  2 demonstrations, 2 queries, 1 test; active protocol), each demonstrating as bench_scale's participants do
  (tableteach.core.teachers.SimulatedTeacher, the authors' required-only demonstrator, verdicts flipped with
  probability 0.1) while the real learner (tableteach.core.session) picks the robot's queries and test from
  what they taught, and a random session seed per participant as the server gives. Per session: a reset, the
  placements and a saved recording per demonstration, and each execution planned twice (the plan-ahead job and
  the work_out job). The repeat rate is what these participants produce, not a chosen number: it is printed
  (placements from clips, executions from shared motion), and the cost per session for the first and later
  participants shows how it grows with the study;
- with --warmed N: the tree of the task's placements simulated ahead by `tableteach warm-robot --tasks 1` (its
  CPU printed), then N more such participants on that data folder.

    .venv/bin/python benchmarks/bench_robot_cost.py                      # 5 repeats, 40 participants
    .venv/bin/python benchmarks/bench_robot_cost.py --repeats 3 --participants 20 --workers 1 --warmed 10
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
import uuid
from collections.abc import Callable
from pathlib import Path

import numpy as np

from tableteach.client import truth_mask
from tableteach.core import session as learner
from tableteach.core.domain import get_domain
from tableteach.core.teachers import SimulatedTeacher
from tableteach.recording_store import RecordingId
from tableteach.sim.clips import ClipCache, clip_folder
from tableteach.sim.robot import MujocoRobot

ALL = ("dinner_plate", "small_plate", "bowl", "knife", "fork")


def cpu(fn: Callable[[], object]) -> float:
    """CPU seconds of this process while fn runs."""
    started = time.process_time()
    fn()
    return time.process_time() - started


def children_cpu() -> float:
    """CPU seconds used so far by this process's running child processes (the robot workers)."""
    total, me, tick = 0.0, os.getpid(), os.sysconf("SC_CLK_TCK")
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == me:  # fields after the command: state, ppid, ..., utime (12th), stime (13th)
            total += (int(fields[11]) + int(fields[12])) / tick
    return total


def fresh_clips(folder: Path) -> ClipCache:
    """A clip cache with nothing in memory or on disk yet."""
    return ClipCache(folder=clip_folder(folder))


def rid(kind: str = "query", index: int = 0) -> str:
    return RecordingId(uuid.uuid4().hex, 0, kind, index).name


def load() -> str:
    return "load average " + " ".join(f"{x:.2f}" for x in os.getloadavg())


def placements(robot: MujocoRobot, repeats: int) -> tuple[float, float, float]:
    """CPU per placement of all five objects on a fresh table: nothing cached, from clips in memory, from the clip
    files another process wrote."""
    def five() -> None:
        robot.reset("1/0")
        for obj in ALL:
            robot.place("1/0", obj)

    cold, warm, files = [], [], []
    for r in range(repeats):
        folder = robot.data_dir / f"placements-{r}"
        robot.clips = fresh_clips(folder)
        cold.append(cpu(five) / len(ALL))
        warm.append(cpu(five) / len(ALL))
        robot.clips = ClipCache(folder=clip_folder(folder))  # as another process: nothing in its memory
        files.append(cpu(five) / len(ALL))
    return statistics.median(cold), statistics.median(warm), statistics.median(files)


def executions(robot: MujocoRobot, data: Path, repeats: int) -> tuple[float, float, float]:
    """CPU of a 5-object execution: nothing cached, its placements cached, the execution shared."""
    cold, clips, warm = [], [], []
    for r in range(repeats):
        robot.data_dir = data / f"cold-{r}"
        robot.clips = fresh_clips(robot.data_dir)
        cold.append(cpu(lambda: robot.plan_execution("1/0", ALL, rid())))
        robot.data_dir = data / f"clips-{r}"  # a folder without the shared motion: the clips only
        clips.append(cpu(lambda: robot.plan_execution("2/0", ALL, rid())))
        warm.append(cpu(lambda: robot.plan_execution("3/0", ALL, rid())))
    return statistics.median(cold), statistics.median(clips), statistics.median(warm)


def first_file(robot: MujocoRobot, data: Path) -> float:
    """CPU of the process's first execution of one object beyond a later one: the scene's snapshot, once."""
    robot.data_dir = data / "first"
    first = cpu(lambda: robot.plan_execution("0/99", ("bowl",), rid()))
    second = cpu(lambda: robot.plan_execution("0/98", ("bowl",), rid()))
    return first - second


def writer(repeats: int) -> float:
    """CPU of the .viser file of a 5-object execution (the writer alone)."""
    from tableteach.sim.motion_file import Studio
    from tableteach.sim.physics import MujocoWorld

    world = MujocoWorld(0)
    for obj in ALL:
        world.place(obj)
    studio = Studio(world.model)
    studio.scene()
    captions = [(0.0, "The robot is placing the dinner plate (1 of 5)")]
    return statistics.median(cpu(lambda: studio.render(world.recording, captions)) for _ in range(repeats))


class Study:
    """Participants of bench_scale's study, one after another, on one robot and one data folder."""

    def __init__(self, robot: MujocoRobot, data: Path, keep_clips: bool = False) -> None:
        robot.data_dir = data
        if not keep_clips:
            robot.clips = fresh_clips(data)
        self.robot = robot
        self.teacher = SimulatedTeacher(get_domain("dinner"), truth_mask("task1"), 0.1)
        self.placed = self.executed = self.shared = 0
        self.seen: set[tuple[str, ...]] = set()

    def session(self, i: int) -> float:
        """One participant's session; the robot's CPU seconds in it."""
        rng = np.random.default_rng(1000 + i)
        key, uid, spent, workers_before = f"{i}/0", uuid.uuid4().hex, 0.0, children_cpu()
        state = learner.start(learner.SessionConfig(task="dinner", protocol="active", n_practice=0,
                                                    n_demonstrations=2, n_queries=2, n_tests=1,
                                                    seed=int(rng.integers(2**31))))
        while (step := learner.next_step(state)).kind != "done":
            name = RecordingId(uid, 0, step.kind, step.index).name
            if step.kind == "demonstration":
                events = tuple(dict.fromkeys(self.teacher.demonstrate(rng).events))
                started = time.process_time()
                self.robot.reset(key)
                for obj in events:
                    self.robot.place(key, obj)
                self.robot.save_recording(key, name)
                trace = self.robot.trace(key)
                self.robot.release(key)
                spent += time.process_time() - started
                assert trace is not None
                self.placed += len(events)
                state = learner.observe(state, "demonstration", [sorted(labels) for labels in trace])
            else:
                assert step.robot_execution is not None
                events = step.robot_execution.events
                started = time.process_time()
                for _ in range(2):  # the plan-ahead job, then the work_out job
                    plan = self.robot.plan_execution(key, events, name)
                spent += time.process_time() - started
                self.executed += 1
                self.shared += events in self.seen
                self.seen.add(events)
                self.placed += len(events)
                verdict = self.teacher.assess(plan.trace, rng) if step.kind == "query" else None
                state = learner.observe(state, step.kind, [sorted(labels) for labels in plan.trace], verdict)
        return spent + children_cpu() - workers_before


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--participants", type=int, default=40)
    parser.add_argument("--workers", type=int, default=0, help="robot worker processes for the sessions")
    parser.add_argument("--warmed", type=int, default=0, help="participants after warm-robot (0: not run)")
    args = parser.parse_args()
    print(f"start: {load()}", flush=True)
    with tempfile.TemporaryDirectory(prefix="bench-robot-cost-") as folder:
        data = Path(folder)
        robot = MujocoRobot(data_dir=data / "placements")  # one per process, as in the server
        try:
            once = first_file(robot, data)
            print(f"once per process: the scene's snapshot for .viser files {once:.3f} s CPU", flush=True)
            cold, warm, files = placements(robot, args.repeats)
            print(f"placement: cold {cold:.3f} s, warm {warm:.4f} s (from its clip file: {files:.4f} s) CPU "
                  f"(median of {args.repeats})", flush=True)
            ex_cold, ex_clips, ex_warm = executions(robot, data, args.repeats)
            print(f"execution of 5 objects: cold {ex_cold:.3f} s, placements warm {ex_clips:.3f} s, "
                  f"warm (shared) {ex_warm:.4f} s CPU (median of {args.repeats})", flush=True)
            print(f".viser file of a 5-object execution: {writer(args.repeats):.3f} s CPU", flush=True)
        finally:
            robot.shutdown()
        robot = MujocoRobot(data_dir=data / "study", workers=args.workers)
        try:
            robot.plan_execution("0/99", ("bowl",), rid())  # the scene's snapshot and the workers started
            study = Study(robot, data / "study")
            costs = [study.session(i) for i in range(args.participants)]
            cache = study.robot.clips
            n = len(costs)
            clip_rate = cache.hits / max(1, cache.hits + cache.misses)
            where = "" if args.workers == 0 else f" of those in this process ({args.workers} robot worker(s))"
            print(f"sessions: {n} participants, {study.placed} placements ({100 * clip_rate:.0f}% from clips{where}), "
                  f"{study.executed} executions ({100 * study.shared / max(1, study.executed):.0f}% shared); "
                  f"clips held {cache.nbytes / 2**20:.1f} MiB", flush=True)
        finally:
            robot.shutdown()
        blocks = [costs[k : k + 10] for k in range(0, n, 10)]
        print("robot CPU per session, by arrival: " + ", ".join(
            f"participants {k * 10 + 1}-{k * 10 + len(b)} median {statistics.median(b):.3f} s"
            for k, b in enumerate(blocks)), flush=True)
        later = costs[n // 2 :] or costs
        print(f"first session {costs[0]:.3f} s; median of the later half {statistics.median(later):.3f} s; "
              f"mean of all {statistics.mean(costs):.3f} s", flush=True)
        if args.warmed:
            warmed = data / "warmed"
            done = subprocess.run([sys.executable, "-m", "tableteach.cli", "warm-robot", "--tasks", "1",
                                   "--data-dir", str(warmed)], check=True, capture_output=True, text=True)
            print(f"warm-robot --tasks 1: {json.loads(done.stdout)}", flush=True)
            robot = MujocoRobot(data_dir=warmed, workers=args.workers)
            try:
                robot.plan_execution("0/99", ("bowl",), rid())
                study = Study(robot, warmed, keep_clips=True)
                after = [study.session(args.participants + i) for i in range(args.warmed)]
            finally:
                robot.shutdown()
            print(f"after warm-robot: {args.warmed} participants, {study.executed} executions "
                  f"({100 * study.shared / max(1, study.executed):.0f}% shared); robot CPU per session median "
                  f"{statistics.median(after):.3f} s, first {after[0]:.3f} s, max {max(after):.3f} s", flush=True)
    print(f"end: {load()}")
    print(f"placement_cold_s {cold:.3f} placement_warm_s {warm:.4f} execution_cold_s {ex_cold:.3f} "
          f"execution_warm_s {ex_warm:.4f} session_first_s {costs[0]:.3f} session_steady_s "
          f"{statistics.median(later):.3f}")


if __name__ == "__main__":
    main()
