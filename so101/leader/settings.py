"""The leader node's settings (nodes/leader_node.py, dataflow_leader.yml's `env:`), declared as
so101/runtime/settings.py says; the docs' table of the node is made from them."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from so101.bodies.settings import read_language
from so101.lang import DEFAULT_LANGUAGE, ENV_VAR as LANG_ENV_VAR
from so101.runtime.settings import EnvironSettings, read_file_path, read_stripped_text, read_whole_number, setting

# 50 ms at the 10 ms tick: a lost reply or two (real buses lose the odd one) passes without a word,
# five in a row is a silence worth a line. The body holds through either.
DEFAULT_LEADER_RETRIES = 5
CALIBRATE_LEADER_HINT = "make one with `so101 calibrate --leader --port {port} --out FILE`, or use LeRobot's so101_leader calibration"


@dataclass(frozen=True)
class LeaderSettings(EnvironSettings):
    port: str = setting(
        "SO101_LEADER_PORT", "", "the leader arm's serial port (`so101 fake-arm` prints an emulated one)",
        read_stripped_text,
        required="(the dataflow's env:, or so101 teleop --leader) to the leader arm's serial port "
                 "(/dev/ttyACM1, ...; `so101 fake-arm` prints an emulated one)")
    calibration_file: Path = setting(
        "SO101_LEADER_CALIBRATION", "", "LeRobot's so101_leader calibration JSON, or one from `so101 calibrate --leader`",
        read_file_path,
        required="(the dataflow's env:, or so101 teleop --leader-calibration) to the leader's calibration file; "
                 + CALIBRATE_LEADER_HINT.format(port="{port}"))
    retries: int = setting(
        "SO101_LEADER_RETRIES", f"{DEFAULT_LEADER_RETRIES}",
        "ticks the leader may fail to answer before the log says so (the body holds meanwhile)", read_whole_number)
    lang: str = setting(LANG_ENV_VAR, DEFAULT_LANGUAGE, "log language, `zh` or `en`", read_language)
