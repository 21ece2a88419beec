"""`so101 learn OUT --task cube_to_box [--sees]`: from nothing to a trained policy, in one command.

The recipe, each stage said with its time as it ends:
1. demonstrations: `so101 demos` (the scripted expert, the simulator's state, no pictures);
2. with `--sees`, pictures for the eyes: thousands of front pictures drawn from those demonstrations'
   frames, each in varied looks with its answers (so101.perception.pictures), and a few held out; half
   of them over photos and surfaces of the backdrop pool (so101.bodies.backdrop_pool), or all over
   `--backdrop front=IMAGE` where one is given;
3. training, the two at once, one PyTorch thread each: LeRobot's `lerobot-train` makes a state policy
   of the demonstrations (in the policy environment), and with `--sees` the eyes learn to find the
   cube, the box and the gripper's tip in the pictures (so101.perception.training);
4. the folder: OUT/policy (the state policy), and with `--sees` OUT/eyes and so101_recipe.json, which
   `so101 eval --policy OUT` and `so101 teleop --policy OUT` run whole: the perception node fills the
   policy's object_state from the front picture and the joints, never from the simulator.
The last line printed is the folder to give `--policy`. Ctrl-C stops it, keeping the stages that
finished; run the same command again to resume from there. A folder learned with other options is
refused in one line.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from dataclasses import asdict
from pathlib import Path
from typing import Callable

from so101.bodies.camera_file import camera_file_from, orbit_of
from so101.bodies.physics import physics_mode
from so101.bodies.registry import SIMULATED_BODIES
from so101.launch.camera_poses import add_backdrop_option, add_camera_pose_option
from so101.perception.recipe import EYES_DIR, POLICY_DIR, write_recipe
from so101.policy.environment import OFFLINE, PolicyEnvError, build, default_dir, python_in, with_checkout
from so101.runtime.argtypes import parsed_by, whole_number
from so101.runtime.dataflow import ROOT
from so101.tasks import TASKS

STATE_FILE = "so101_learn.json"
POOL_SHARE = 0.5  # of the eyes' pictures over the backdrop pool, where no --backdrop front is given
HELD_OUT_SEED = 900_000  # the held-out pictures' demonstrations: layouts no score uses
# The layouts the candidates are scored on to choose one: no score in the docs uses them (those are 1000-1049).
VALIDATION_SEED = 800_000
# DAgger's layouts (so101 demos --learner): round r's are DAGGER_SEED + (r - 1) * episodes onward, apart from all above.
DAGGER_SEED = 700_000
# How lerobot-train runs here, from scratch or on from a policy (a DAgger round): on the CPU, offline.
TRAINING_ARGS = ("--policy.device=cpu", "--policy.push_to_hub=false", "--batch_size=64", "--num_workers=0",
                 "--wandb.enable=false")
# The state policy's recipe (docs/loop/policy.md): a small ACT on the joints and the objects' state.
STATE_POLICY_ARGS = (
    "--policy.type=act", "--policy.dim_model=128",
    "--policy.n_heads=4", "--policy.dim_feedforward=512", "--policy.n_encoder_layers=2", "--policy.n_decoder_layers=1",
    "--policy.use_vae=false", "--policy.chunk_size=20", "--policy.n_action_steps=20", "--policy.optimizer_lr=3e-4",
    '--policy.normalization_mapping={"VISUAL": "MEAN_STD", "STATE": "MEAN_STD", "ENV": "MEAN_STD", "ACTION": "MEAN_STD"}',
    *TRAINING_ARGS,
)
ONE_THREAD = {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
# A DAgger round trains on from the policy before at a tenth of the recipe's rate: at the recipe's own 3e-4 a
# round took a policy from 40/50 to 31/50, at 3e-5 to 50/50 (docs/experiments/as-good-as-its-teacher.md).
ROUND_LR = "3e-5"


def add_arguments(parser: argparse.ArgumentParser, name: str) -> None:
    parser.add_argument("out", type=Path, metavar="OUT", help="the folder to learn into: new, or one this command began")
    parser.add_argument("--task", choices=sorted(TASKS), required=True, help="the task to learn")
    parser.add_argument("--sees", action="store_true",
                        help="a policy that sees: eyes taught by the simulator in front of the state policy (the "
                             "policy then reads no simulator state); without it, a state policy that reads the "
                             "simulator's object_state")
    parser.add_argument("--body", choices=SIMULATED_BODIES, default="pybullet", help="the simulator (default pybullet)")
    parser.add_argument("--physics", type=parsed_by(physics_mode), default="fixed", metavar="fixed|varied|FILE.json",
                        help="the demonstrations' physics, and the validation's: fixed (default, the simulator's own), "
                             "varied (each layout's seed draws the cube's size, mass and friction, the servos, a "
                             "calibration off by up to 2°: docs/loop/physics.md) or a ranges file to vary within (one "
                             "`so101 physics --fit` wrote, for your arm; the folder keeps its ranges); the eyes' "
                             "pictures are drawn with each episode's")
    add_camera_pose_option(parser)
    add_backdrop_option(parser)
    parser.add_argument("--episodes", type=whole_number(10, 100_000), default=300, metavar="N",
                        help="demonstrations (default 300)")
    parser.add_argument("--pictures", type=whole_number(100, 1_000_000), default=40_000, metavar="N",
                        help="--sees: pictures drawn for the eyes (default 40000; 2.3 GB of memory at 160x120)")
    parser.add_argument("--eyes-steps", type=whole_number(10, 1_000_000), default=4000, metavar="N",
                        help="--sees: the eyes' training steps, of 32 pictures (default 4000)")
    parser.add_argument("--policy-steps", type=whole_number(1, 1_000_000), default=6500, metavar="N",
                        help="lerobot-train's steps for the state policy, of 64 frames (default 6500)")
    parser.add_argument("--seed", type=whole_number(0, 2**31 - 1), default=1, metavar="S",
                        help="the training seed of the eyes and of the first state policy (default 1); a score moves "
                             "with it (docs/experiments/eyes-taught-by-the-simulator.md)")
    parser.add_argument("--candidates", type=whole_number(1, 8), default=2, metavar="N",
                        help="state policies trained, with seeds S, S+1, ...; the one that scores best on the "
                             f"validation layouts (seeds {VALIDATION_SEED} on, which no documented score uses) is kept "
                             "(default 2)")
    parser.add_argument("--validation", type=whole_number(1, 10_000), default=20, metavar="N",
                        help="episodes each candidate is scored on when there are several (default 20)")
    parser.add_argument("--rounds", type=whole_number(0, 20), default=1, metavar="R",
                        help="DAgger rounds after the candidates: the best policy so far drives, the expert takes over "
                             "from where it left things (so101 demos --learner), and the policy goes on training on "
                             "all the demonstrations so far; the best on the validation layouts is kept (default 1)")
    parser.add_argument("--round-episodes", type=whole_number(1, 100_000), default=100, metavar="N",
                        help="--rounds: episodes driven by the learner in each round (default 100)")
    parser.add_argument("--round-steps", type=whole_number(1, 1_000_000), default=2000, metavar="N",
                        help="--rounds: lerobot-train's steps in each round, from the policy before (default 2000)")
    parser.add_argument("--policy-python", type=Path, default=None, metavar="PY",
                        help=f"the policy environment's Python, with LeRobot (default {python_in(default_dir())}, "
                             "which so101 policy-env makes)")


def run(args: argparse.Namespace) -> int:
    out = args.out.expanduser().resolve()
    python = (args.policy_python or python_in(default_dir())).expanduser()
    if not python.exists() and args.policy_python is None:  # the first time on this machine: made here, once
        print(f"learn: no policy environment yet: making it in {default_dir()} as `so101 policy-env` does (LeRobot "
              "and torch, several GB to download; once per machine)...", flush=True)
        started = time.monotonic()
        try:
            build(default_dir(), say=lambda line: print(f"learn: {line}", flush=True))
        except PolicyEnvError as error:
            return _fail(f"the policy environment could not be made: {error}")
        print(f"learn: policy environment made in {time.monotonic() - started:.0f} s", flush=True)
    if not python.exists():
        return _fail(f"{python} does not exist: make the policy environment with `so101 policy-env`, or give "
                     "--policy-python PY")
    trainer = python.parent / "lerobot-train"
    if not trainer.exists():
        return _fail(f"{python} has no lerobot-train beside it: give the Python of a policy environment (so101 policy-env)")
    settings = {"task": args.task, "sees": args.sees, "body": args.body, "physics": args.physics, "episodes": args.episodes,
                "pictures": args.pictures if args.sees else 0, "eyes_steps": args.eyes_steps if args.sees else 0,
                "policy_steps": args.policy_steps, "seed": args.seed, "candidates": args.candidates,
                "rounds": args.rounds, "round_episodes": args.round_episodes if args.rounds else 0,
                "round_steps": args.round_steps if args.rounds else 0,
                "validation": args.validation if args.candidates > 1 or args.rounds else 0}
    if (args.camera_poses or args.backdrops) and not args.sees:
        return _fail("--camera-pose and --backdrop shape the eyes' pictures: they go with --sees")
    if args.camera_poses:  # kept in the state file whole: the pictures are drawn from there, the eyes assume it
        settings["camera_poses"] = {name: pose.as_dict() for name, pose in sorted(args.camera_poses.items())}
    if args.backdrops:
        settings["backdrops"] = dict(sorted(args.backdrops.items()))
    if args.sees and "front" not in args.backdrops:  # eyes for a table they will not have seen
        settings["backdrop_pool_share"] = POOL_SHARE
    state_file = out / STATE_FILE
    if out.exists() and not state_file.is_file() and any(out.iterdir()):
        return _fail(f"{out} is not empty and not a folder `so101 learn` began: give a new folder")
    done: dict[str, float] = {}
    scores: dict[str, int] = {}
    if state_file.is_file():
        try:
            saved = json.loads(state_file.read_text(encoding="utf-8"))
        except ValueError:
            saved = None
        if not isinstance(saved, dict) or not isinstance(saved.get("settings"), dict):
            return _fail(f"{state_file} is not a file `so101 learn` wrote: give a new folder")
        if "backdrop_pool_share" not in saved["settings"]:  # begun before the pool: it resumes as it began
            settings.pop("backdrop_pool_share", None)
        if saved.get("settings") != settings:
            differ = ", ".join(f"{key} {saved['settings'].get(key)!r} there, {value!r} now"
                               for key, value in settings.items() if saved.get("settings", {}).get(key) != value)
            return _fail(f"{out} was learned with other options ({differ}): use those, or another folder")
        done = dict(saved.get("done", {}))
        scores = dict(saved.get("validation", {}))
    out.mkdir(parents=True, exist_ok=True)
    work = out / "work"
    work.mkdir(exist_ok=True)
    learning = Learning(out, work, settings, done, python, scores)
    learning.save()  # from here the folder is this command's: interrupted in any stage, it resumes
    print(f"learn: {args.task} on {args.body}, {'a policy that sees (eyes + state policy)' if args.sees else 'a state policy'}"
          f", into {out}" + (f"; resuming after: {', '.join(done)}" if done else ""), flush=True)
    started = time.monotonic()
    try:
        learning.stage("demos", lambda: learning.demos(out / "demos", args.episodes, 0))
        if args.sees:
            learning.stage("held-out demos", lambda: learning.demos(work / "held-out-demos", 20, HELD_OUT_SEED))
            learning.stage("pictures", lambda: learning.pictures(args.pictures))
        learning.stage("training", lambda: learning.train(args.policy_steps, args.eyes_steps if args.sees else 0))
        if settings["validation"]:
            learning.stage("validation", lambda: learning.validate(learning.candidates(), args.validation))
        for number in range(1, args.rounds + 1):
            learning.stage(f"round {number} demos", lambda: learning.dagger_demos(number, args.round_episodes))
            learning.stage(f"round {number} training", lambda: learning.dagger_train(number, args.round_steps))
            learning.stage(f"round {number} validation", lambda: learning.validate([f"round{number}"], args.validation))
        learning.stage("folder", lambda: learning.assemble())
    except KeyboardInterrupt:
        learning.stop_children()
        print(f"learn: stopped; the stages done ({', '.join(learning.done) or 'none'}) stay. Run the same command "
              "again to resume", file=sys.stderr, flush=True)
        return 130
    except StageFailed as error:
        learning.stop_children()
        return _fail(str(error))
    if settings["validation"]:
        print(f"learn: kept {learning.describe(learning.best())}, {learning.scores[learning.best()]}/{args.validation} on "
              "the validation layouts", flush=True)
    print(f"learn: done in {time.monotonic() - started:.0f} s this run "
          f"({', '.join(f'{name} {seconds:.0f} s' for name, seconds in learning.done.items())}). "
          f"Score it: so101 eval --task {args.task} --policy {out if args.sees else out / POLICY_DIR} --episodes 50 --seed 1000", flush=True)
    print(out if args.sees else out / POLICY_DIR, flush=True)
    return 0


class StageFailed(Exception):
    """A stage's command failed; str() is one line, naming its log."""


class Learning:
    def __init__(self, out: Path, work: Path, settings: dict, done: dict[str, float], python: Path,
                 scores: dict[str, int]):
        self.out, self.work, self.settings, self.done, self.python = out, work, settings, done, python
        self.scores = scores  # each policy's successes on the validation layouts, by its name (`seed1`, `round1`)
        self.children: list[subprocess.Popen] = []

    @property
    def seeds(self) -> list[int]:
        """The candidates' training seeds: the first is --seed, also the eyes'."""
        return [self.settings["seed"] + index for index in range(self.settings["candidates"])]

    def save(self) -> None:
        """The state file, replaced whole: an interruption leaves the old one or the new one."""
        state = {"settings": self.settings, "done": self.done, "validation": self.scores}
        path = self.out / STATE_FILE
        partial = path.with_name(path.name + ".partial")
        partial.write_text(json.dumps(state, indent=1) + "\n", encoding="utf-8")
        os.replace(partial, path)

    def stage(self, name: str, action: Callable[[], None]) -> None:
        if name in self.done:
            return
        print(f"learn: {name}...", flush=True)
        started = time.monotonic()
        action()
        self.done[name] = round(time.monotonic() - started, 1)
        self.save()
        print(f"learn: {name} done in {self.done[name]:.0f} s", flush=True)

    def start(self, command: list[str], log: Path, env: dict[str, str] | None = None) -> subprocess.Popen:
        child = subprocess.Popen(command, stdout=log.open("w"), stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                 env={**os.environ, **(env or {}), "PYTHONPATH": with_checkout(os.environ.get("PYTHONPATH"))},
                                 cwd=ROOT, start_new_session=True)
        self.children.append(child)
        return child

    def wait(self, children: list[tuple[subprocess.Popen, Path, str]]) -> None:
        """Until every child has ended; the first to fail is said at once (the caller stops the others)."""
        running = list(children)
        while running:
            for entry in list(running):
                child, log, what = entry
                if child.poll() is None:
                    continue
                running.remove(entry)
                if child.returncode != 0:
                    tail = log.read_text(encoding="utf-8", errors="replace").strip().splitlines()[-1:] or ["(no output)"]
                    raise StageFailed(f"{what} failed (exit code {child.returncode}): {tail[0][-300:]} (log: {log})")
            time.sleep(0.5)
        self.children.clear()

    def stop_children(self) -> None:
        """Each stage's command stopped as Ctrl-C stops it (so101 demos stops its dataflows), then harder."""
        for stop, wait_s in ((signal.SIGINT, 30), (signal.SIGTERM, 10), (signal.SIGKILL, 5)):
            running = [child for child in self.children if child.poll() is None]
            for child in running:
                try:
                    os.killpg(child.pid, stop)
                except ProcessLookupError:
                    pass
            for child in running:
                try:
                    child.wait(timeout=wait_s)
                except subprocess.TimeoutExpired:
                    pass
        self.children.clear()

    def demos(self, folder: Path, episodes: int, seed: int) -> None:
        shutil.rmtree(folder, ignore_errors=True)  # a stage that did not finish starts again
        log = self.work / f"{folder.name}.log"
        command = [sys.executable, "-m", "so101.cli", "demos", str(folder), "--task", self.settings["task"],
                   "--body", self.settings["body"], "--episodes", str(episodes), "--seed", str(seed), "--no-video",
                   "--workers", "2", "--physics", self.settings["physics"]]
        self.wait([(self.start(command, log), log, "so101 demos")])

    def pictures(self, count: int) -> None:
        halves = [count // 2, count - count // 2]
        children = []
        for index, part in enumerate(halves):
            log = self.work / f"pictures-{index}.log"
            command = [sys.executable, "-m", "so101.perception.draw", str(self.out / "demos"),
                       str(self.work / f"pictures-{index}.npz"), "--count", str(part), "--seed", str(index + 1),
                       *self.scenario_args()]
            children.append((self.start(command, log), log, "drawing the pictures"))
        log = self.work / "pictures-held-out.log"
        self.wait(children)
        command = [sys.executable, "-m", "so101.perception.draw", str(self.work / "held-out-demos"),
                   str(self.work / "pictures-held-out.npz"), "--count", "1500", "--seed", "77", "--held-out",
                   *self.scenario_args()]
        self.wait([(self.start(command, log), log, "drawing the held-out pictures")])

    def scenario_args(self) -> list[str]:
        """What the pictures are drawn in, beyond varied looks: the camera poses and backdrops given."""
        given = {key: self.settings[key] for key in ("camera_poses", "backdrops") if key in self.settings}
        share = self.settings.get("backdrop_pool_share", 0.0)
        return (["--scenario", json.dumps(given)] if given else []) + (["--pool-share", str(share)] if share else [])

    def camera_args(self) -> list[str]:
        """The validation's --camera-pose and --backdrop options: where the eyes were taught."""
        args: list[str] = []
        for name, fields in self.settings.get("camera_poses", {}).items():
            path = self.work / f"camera-{name}.json"
            path.write_text(json.dumps(fields, indent=1) + "\n", encoding="utf-8")
            args += ["--camera-pose", f"{name}={path}"]
        for name, path in self.settings.get("backdrops", {}).items():
            args += ["--backdrop", f"{name}={path}"]
        return args

    def candidates(self) -> list[str]:
        """The names of the state policies trained from scratch, one per seed."""
        return [f"seed{seed}" for seed in self.seeds]

    def trained(self, name: str) -> Path:
        """The state policy `name` (a candidate, `seed1`, or a DAgger round's, `round1`), as lerobot-train leaves it."""
        folder = f"state-policy-{name}" if name.startswith("seed") else name
        return self.work / folder / "checkpoints" / "last" / "pretrained_model"

    @staticmethod
    def describe(name: str) -> str:
        return f"the state policy of seed {name[4:]}" if name.startswith("seed") else f"the state policy of DAgger {name[:5]} {name[5:]}"

    def best(self) -> str:
        """The policy kept: the most validation successes; on a tie the later round (it learned from all the
        demonstrations of the policy it ties with, and the expert's corrections of it besides), else the first
        seed; without a validation, the first candidate."""
        candidates = self.candidates()
        names = candidates + [f"round{number}" for number in range(1, self.settings.get("rounds", 0) + 1)]
        scored = [name for name in names if name in self.scores] or names[:1]
        # Ties: a round's place (1 or more) above a candidate's negated one (0 or less), so the later round, the first seed.
        return max(scored, key=lambda name: (self.scores.get(name, -1),
                                             -names.index(name) if name in candidates else names.index(name)))

    def dagger_demos(self, number: int, episodes: int) -> None:
        """Round `number`'s demonstrations: the demonstrations so far, copied, and `episodes` more in which the best
        policy so far drives first and the expert takes over (so101 demos --learner)."""
        before = self.out / "demos" if number == 1 else self.work / f"round{number - 1}-demos"
        folder = self.work / f"round{number}-demos"
        shutil.rmtree(folder, ignore_errors=True)  # a round that did not finish starts again from the copy
        shutil.copytree(before, folder)
        log = self.work / f"round{number}-demos.log"
        command = [sys.executable, "-m", "so101.cli", "demos", str(folder), "--task", self.settings["task"],
                   "--body", self.settings["body"], "--episodes", str(episodes),
                   "--seed", str(DAGGER_SEED + (number - 1) * episodes), "--no-video", "--workers", "2",
                   "--physics", self.settings["physics"],
                   "--learner", str(self.trained(self.best())), "--policy-python", str(self.python)]
        print(f"learn: round {number}: {self.describe(self.best())} drives, the expert takes over", flush=True)
        self.wait([(self.start(command, log, OFFLINE), log, f"so101 demos --learner (round {number})")])

    def dagger_train(self, number: int, steps: int) -> None:
        """Round `number`'s policy: the best so far, trained `steps` more on all the round's demonstrations."""
        trained = self.work / f"round{number}"
        shutil.rmtree(trained, ignore_errors=True)
        log = self.work / f"round{number}.log"
        command = [str(self.python.parent / "lerobot-train"), f"--policy.path={self.trained(self.best())}",
                   f"--dataset.repo_id=local/{self.out.name}-round{number}", f"--dataset.root={self.work / f'round{number}-demos'}",
                   f"--policy.optimizer_lr={ROUND_LR}", *TRAINING_ARGS, f"--seed={self.settings['seed']}",
                   f"--steps={steps}", f"--save_freq={steps}",
                   f"--output_dir={trained}"]
        self.wait([(self.start(command, log, {**OFFLINE, **ONE_THREAD}), log, f"lerobot-train (round {number})")])

    def train(self, policy_steps: int, eyes_steps: int) -> None:
        children = []
        for seed in self.seeds:
            trained = self.work / f"state-policy-seed{seed}"
            shutil.rmtree(trained, ignore_errors=True)
            log = self.work / f"state-policy-seed{seed}.log"
            command = [str(self.python.parent / "lerobot-train"), f"--dataset.repo_id=local/{self.out.name}-demos",
                       f"--dataset.root={self.out / 'demos'}", *STATE_POLICY_ARGS, f"--seed={seed}",
                       f"--steps={policy_steps}", f"--save_freq={policy_steps}", f"--output_dir={trained}"]
            children.append((self.start(command, log, {**OFFLINE, **ONE_THREAD}), log,
                             f"lerobot-train (the state policy, seed {seed})"))
        seed = self.settings["seed"]
        if eyes_steps:
            eyes_log = self.work / "eyes.log"
            shutil.rmtree(self.work / EYES_DIR, ignore_errors=True)
            command = [str(self.python), "-m", "so101.perception.teach", "--pictures",
                       *(str(self.work / f"pictures-{index}.npz") for index in (0, 1)),
                       "--held-out", str(self.work / "pictures-held-out.npz"), "--out", str(self.work / EYES_DIR),
                       "--steps", str(eyes_steps), "--seed", str(seed)]
            children.append((self.start(command, eyes_log, ONE_THREAD), eyes_log, "the eyes' training"))
        policies = "the state policy" if len(self.seeds) == 1 else f"{len(self.seeds)} state policies"
        print(f"learn: {policies}{' and the eyes' if eyes_steps else ''} at once, logs: "
              f"{', '.join(str(log) for _, log, _ in children)}", flush=True)
        self.wait(children)

    def validate(self, names: list[str], episodes: int) -> None:
        """Each policy of `names` scored by `so101 eval` on `episodes` validation layouts, as the folder it would make
        runs (a seeing recipe behind its eyes, in varied looks); each score is kept as it comes."""
        for name in names:
            if name in self.scores:
                continue
            folder = self.work / f"candidate-{name}"
            shutil.rmtree(folder, ignore_errors=True)
            self.assemble_into(folder, self.trained(name))
            log = self.work / f"validation-{name}.log"
            command = [sys.executable, "-m", "so101.cli", "eval", "--task", self.settings["task"],
                       "--body", self.settings["body"], "--policy", str(folder if self.settings["sees"] else folder / POLICY_DIR),
                       "--policy-python", str(self.python), "--episodes", str(episodes), "--seed", str(VALIDATION_SEED),
                       "--workers", "2", "--physics", self.settings["physics"],
                       *(("--looks", "varied", *self.camera_args()) if self.settings["sees"] else ())]
            self.wait([(self.start(command, log, OFFLINE), log, f"so101 eval ({self.describe(name)})")])
            successes = validation_successes(log.read_text(encoding="utf-8", errors="replace"))
            if successes is None:
                raise StageFailed(f"so101 eval ({self.describe(name)}) printed no score line (log: {log})")
            self.scores[name] = successes
            self.save()
            print(f"learn: {self.describe(name)}: {successes}/{episodes} on the validation layouts "
                  f"(seeds {VALIDATION_SEED}-{VALIDATION_SEED + episodes - 1})", flush=True)

    def assemble(self) -> None:
        self.assemble_into(self.out, self.trained(self.best()))

    def assemble_into(self, folder: Path, policy: Path) -> None:
        for name in (POLICY_DIR, EYES_DIR):
            shutil.rmtree(folder / name, ignore_errors=True)
        shutil.copytree(policy, folder / POLICY_DIR)
        if self.settings["sees"]:
            (folder / EYES_DIR).mkdir()
            for name in ("eyes.pt", "eyes.json"):  # the weights at each 1,000 steps stay in work/eyes/steps
                shutil.copy2(self.work / EYES_DIR / name, folder / EYES_DIR / name)
            eyes = json.loads((folder / EYES_DIR / "eyes.json").read_text(encoding="utf-8"))
            if "front" in self.settings.get("camera_poses", {}):  # the geometry the eyes assume: the camera taught from
                front = orbit_of(camera_file_from(self.settings["camera_poses"]["front"], "front"))
                eyes["camera"] = asdict(front)
                (folder / EYES_DIR / "eyes.json").write_text(json.dumps(eyes, indent=1) + "\n", encoding="utf-8")
            write_recipe(folder, {"recipe": "eyes + state policy", "task": self.settings["task"],
                                  "body": self.settings["body"], "eyes": EYES_DIR, "policy": POLICY_DIR,
                                  "eyes_held_out": eyes.get("trained", {}).get("held_out", {}),
                                  "kept": self.best(), "validation": self.scores, "stages_s": self.done,
                                  **{key: self.settings[key] for key in ("camera_poses", "backdrops", "backdrop_pool_share")
                                     if key in self.settings}})


def validation_successes(eval_output: str) -> int | None:
    """The successes in so101 eval's score line (`success: K/N (...)`), or None where it printed none."""
    found = re.findall(r"^success: (\d+)/\d+ ", eval_output, re.M)
    return int(found[-1]) if found else None


def _fail(message: str) -> int:
    print(f"so101 learn: {message}", file=sys.stderr, flush=True)
    return 2
