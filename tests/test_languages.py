"""One language for every line a session prints: the rule (so101/lang.py), and the commands and the
real arm's log lines that follow it, in each language."""

from __future__ import annotations

import os
import re
import subprocess
import time

import pytest

from so101.feetech.bus import FeetechBus
from so101.feetech.calibration import MOTOR_IDS, MOTOR_NAMES, load_calibration
from so101.feetech.fake_arm import FakeArmProcess, calibrate_as_at_the_factory
from so101.lang import LOCALE_VARS, session_language
from tests.helpers.calibrate import Calibrate
from tests.helpers.dataflow import SO101, TICK, body_environment, run_so101, run_simulation_node
from tests.helpers.processes import Lines

CHINESE = re.compile(r"[\u4e00-\u9fff]")


def in_language(line: str, lang: str) -> bool:
    """A Chinese line holds Chinese characters; an English one none."""
    return bool(CHINESE.search(line)) == (lang == "zh")


# -- the rule ------------------------------------------------------------------------------------------


@pytest.mark.parametrize("chosen, environ, expected", [
    (None, {}, "zh"),  # no locale at all: the course's language
    (None, {"LANG": "C"}, "zh"),
    (None, {"LANG": "C.UTF-8"}, "zh"),  # a bare container's
    (None, {"LANG": "POSIX"}, "zh"),
    (None, {"LANG": "zh_CN.UTF-8"}, "zh"),
    (None, {"LANG": "zh_TW.Big5"}, "zh"),
    (None, {"LANG": "en_US.UTF-8"}, "en"),
    (None, {"LANG": "de_DE.UTF-8"}, "en"),  # another language: the docs', English
    (None, {"LANG": "en_US.UTF-8", "LC_MESSAGES": "zh_CN.UTF-8"}, "zh"),  # LC_MESSAGES before LANG
    (None, {"LANG": "zh_CN.UTF-8", "LC_ALL": "en_GB.UTF-8", "LC_MESSAGES": "zh_CN.UTF-8"}, "en"),  # LC_ALL first
    (None, {"LANG": "en_US.UTF-8", "LC_ALL": ""}, "en"),  # an empty variable is an unset one
    (None, {"LANG": "en_US.UTF-8", "SO101_LANG": "zh"}, "zh"),  # SO101_LANG before the locale
    (None, {"LANG": "zh_CN.UTF-8", "SO101_LANG": "en"}, "en"),
    (None, {"LANG": "en_US.UTF-8", "SO101_LANG": ""}, "en"),
    ("en", {"LANG": "zh_CN.UTF-8", "SO101_LANG": "zh"}, "en"),  # --lang before everything
    ("zh", {"LANG": "en_US.UTF-8"}, "zh"),
])
def test_the_session_language_is_lang_then_so101_lang_then_the_locale(chosen, environ, expected):
    assert session_language(chosen, environ) == expected


@pytest.mark.parametrize("chosen, environ", [("fr", {}), (None, {"SO101_LANG": "english", "LANG": "en_US.UTF-8"})])
def test_a_language_that_is_neither_zh_nor_en_is_one_line(chosen, environ):
    bad = chosen or environ["SO101_LANG"]
    with pytest.raises(ValueError, match=re.escape(f"unknown language {bad!r} (from --lang or $SO101_LANG); use zh or en")):
        session_language(chosen, environ)


# -- so101 calibrate and so101 fake-arm, one session ---------------------------------------------------

# What each says, per language: the fake-arm's first line after its port, its hint once a calibration
# begins, its reply to `sweep 2`; calibrate's first instruction, its second, and its last line.
SAID = {
    "zh": ("模拟的 SO-101 总线", "此总线上开始了一次校准", "正在 2 秒内转动关节", "扭矩已关闭", "完成后按 Enter", "使用它:"),
    "en": ("an emulated SO-101 bus", "a calibration has begun on this bus", "sweeping 1, 2, 3, 4, 5, 6 over 2 s",
           "Torque is off.", "Press Enter when done.", "Use it: "),
}


def start_fake_arm(*options: str, **env: str) -> tuple[subprocess.Popen, Lines]:
    environ = {name: value for name, value in os.environ.items() if name not in ("SO101_LANG", *LOCALE_VARS)}
    process = subprocess.Popen([str(SO101), "fake-arm", *options], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, env={**environ, **env})
    return process, Lines(process.stdout)


def stop(process: subprocess.Popen) -> str:
    process.kill()
    _, err = process.communicate(timeout=10)
    return err.decode()


@pytest.mark.realtime
@pytest.mark.parametrize("lang", ["zh", "en"])
def test_calibrating_the_emulated_arm_is_one_language_and_the_emulator_says_to_type_sweep(tmp_path, lang):
    about, hint, sweeping, middle, ends, use_it = SAID[lang]
    fake_arm, fake_lines = start_fake_arm("--lang", lang)
    try:
        port = fake_lines.next()
        fake_said = [fake_lines.next()]
        assert fake_said[0].startswith(about)
        out = tmp_path / "arm.json"
        calibrate = Calibrate("--port", port, "--out", str(out), "--lang", lang)
        calibrate.wait_for(middle)
        fake_said.append(fake_lines.next())
        assert fake_said[-1].startswith(hint) and "sweep" in fake_said[-1]
        calibrate.enter()  # the emulated arm rests in the middle pose
        calibrate.wait_for(ends)
        fake_arm.stdin.write(b"sweep 2\n")
        fake_arm.stdin.flush()
        fake_said.append(fake_lines.next())
        assert fake_said[-1].startswith(sweeping)
        time.sleep(2.5)  # the sweep's two seconds: the emulator moves the joints by the clock
        calibrate.enter()
        code, output, err = calibrate.finish()
        assert code == 0, output + err
        assert output.rstrip().splitlines()[-1].startswith(use_it)
        fake_arm.stdin.write(b"status\n")
        fake_arm.stdin.flush()
        fake_said += [fake_lines.next() for _ in range(7)]
    finally:
        fake_err = stop(fake_arm)
    assert fake_err == "" and err == ""
    # Each line of both terminals in the session's language: the hint came once, and only then.
    for line in [line for line in output.splitlines() if line.strip()] + fake_said:
        assert in_language(line, lang), line
    assert sum(line.startswith(hint) for line in fake_said) == 1
    assert set(load_calibration(out)) == set(MOTOR_NAMES)


@pytest.mark.parametrize("options, env, lang", [
    ((), {"LANG": "en_US.UTF-8"}, "en"),  # an English reader's shell, nothing set: English
    ((), {"LANG": "zh_CN.UTF-8"}, "zh"),
    ((), {}, "zh"),  # no locale: the course's language
    ((), {"LANG": "en_US.UTF-8", "SO101_LANG": "zh"}, "zh"),
    (("--lang", "en"), {"LANG": "zh_CN.UTF-8", "SO101_LANG": "zh"}, "en"),
])
def test_a_command_follows_the_locale_unless_told(options, env, lang):
    process, lines = start_fake_arm(*options, **env)
    try:
        lines.next()  # the port
        about = lines.next()
    finally:
        err = stop(process)
    assert about.startswith(SAID[lang][0]) and err == ""


# -- the emulator notices a calibration ------------------------------------------------------------------


def reset_as_a_calibration_does(bus: FeetechBus) -> None:
    """The first writes of so101 calibrate (so101/cli/calibrate.py): torque off, unlocked, offsets reset."""
    everyone = dict.fromkeys(MOTOR_IDS, 0)
    bus.sync_write("Torque_Enable", everyone)
    for name in ("Lock", "Homing_Offset", "Min_Position_Limit"):
        for servo_id in MOTOR_IDS:
            bus.write(servo_id, name, 0)


def test_the_emulator_notices_each_calibration_once_and_nothing_else():
    from so101.bodies.real_arm import SO101Real
    from so101.leader.arm import SO101Leader

    with FakeArmProcess() as arm:  # calibrations_begun counts what on_calibration is told (torque off only)
        calibration = calibrate_as_at_the_factory(arm)  # a test's own writes, not the bus's
        with SO101Real(arm.port, calibration) as body:  # driven: torque on, goals, reads, torque off
            for _ in range(5):
                body.step()
        with SO101Leader(arm.port, calibration):
            pass
        assert arm.calibrations_begun == 0
        bus = FeetechBus(arm.port).open()
        try:
            reset_as_a_calibration_does(bus)
            assert (arm.calibrations_begun, arm.read_register(1, "Torque_Enable")) == (1, 0)  # once for six servos
            for servo_id in MOTOR_IDS:  # the middle pose taken, the ranges written, locked
                bus.write(servo_id, "Homing_Offset", 300)
                bus.write(servo_id, "Lock", 1)
            assert arm.calibrations_begun == 1
            reset_as_a_calibration_does(bus)  # the next calibration
            assert arm.calibrations_begun == 2
        finally:
            bus.close()


# -- the real arm's log --------------------------------------------------------------------------------


@pytest.mark.parametrize("lang", ["zh", "en"])
def test_the_real_arms_log_is_in_the_sessions_language(tmp_path, monkeypatch, capsys, lang):
    from dora.testing import MockNode

    next_event = MockNode.__next__
    with body_environment("real", tmp_path) as (env, arm):
        events_taken = []

        def silent_for_two_ticks(self):
            events_taken.append(1)
            if len(events_taken) == 4:
                arm.silence(2)  # its reads fail: "retrying" ...
            elif len(events_taken) == 6:
                arm.answer(2)  # ... then "the servos answer again"
            return next_event(self)

        monkeypatch.setattr(MockNode, "__next__", silent_for_two_ticks)
        for name, value in env.items():
            monkeypatch.setenv(name, value)
        code, node = run_simulation_node(monkeypatch, [TICK] * 12, body="real", SO101_LANG=lang)
    captured = capsys.readouterr()
    assert code == 0, captured.err
    lines = [line for line in captured.out.splitlines() if line.strip()]
    tag = {"zh": "[机械臂节点]", "en": "[arm]"}[lang]
    # loaded, retrying, answering again, torque off: each tagged and worded in the session's language.
    assert len(lines) == 4 and all(line.startswith(tag) and in_language(line, lang) for line in lines), lines


# -- the cluster's lines ---------------------------------------------------------------------------------


WROTE = {"zh": "已写入 {file}:用 `dora start {file}", "en": "wrote {file}: start it with `dora start {file}"}


@pytest.mark.parametrize("lang", ["zh", "en"])
def test_cluster_dataflow_says_what_it_wrote_in_the_sessions_language(tmp_path, lang):
    wrote = WROTE[lang]
    written = tmp_path / "cluster.yml"
    result = run_so101("cluster-dataflow", "--output", str(written), LANG="en_US.UTF-8", SO101_LANG=lang)
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith(wrote.format(file=written)) and in_language(result.stdout, lang)
