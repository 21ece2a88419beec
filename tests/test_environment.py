"""A bad environment gives one clear message: no display, broken model files, mixed dora versions."""

from __future__ import annotations

import importlib.metadata
import os
import subprocess
from pathlib import Path

import pytest

from so101.runtime.versions import cli_version_from_output, dora_version_problem, version_mismatch
from tests.helpers.dataflow import (
    BROKEN_MESH, PROMPT_COMMAND, VENV_BIN, DoraRun, corrupt, error_lines, run_so101,
    unused_display, write_test_dataflow,
)

NO_DISPLAY_NOTICE = "no display found"
LIBRARY_VERSION = importlib.metadata.version("dora-rs")


# -- no display -------------------------------------------------------------------------

@pytest.mark.parametrize("display", [None, "stale"], ids=["DISPLAY unset", "DISPLAY without a server"])
def test_inspect_without_display_runs_direct_with_one_notice(display):
    env = {"DISPLAY": unused_display()} if display == "stale" else {}
    result = run_so101("inspect", "--mode", "auto", "--steps", "1", "--lang", "en", **env)
    assert result.returncode == 0, result.stderr
    notices = [line for line in (result.stdout + result.stderr).splitlines() if NO_DISPLAY_NOTICE in line]
    assert notices == [
        "no display found (DISPLAY is not set or not reachable): running headless in DIRECT mode"
    ]
    assert "joint 0: shoulder_pan" in result.stdout


@pytest.mark.dataflow
def test_dataflow_without_display_runs_direct_with_one_notice(tmp_path):
    dataflow = write_test_dataflow(tmp_path, sim_env={"SO101_MODE": "auto", "SO101_LANG": "en"})
    dora = DoraRun(dataflow, tmp_path / "dora.log")  # dora_env() removes DISPLAY
    try:
        dora.wait_for("SO-101 loaded", timeout_s=60)
    finally:
        exit_code = dora.stop()
    log = dora.log()
    assert exit_code == 0, log[-3000:]
    assert len([line for line in log.splitlines() if NO_DISPLAY_NOTICE in line]) == 1, log[-3000:]
    assert "(DIRECT mode" in log


# -- model files ------------------------------------------------------------------------

def break_model(model_copy: Path, how: str) -> Path:
    """One mesh of the copy deleted or altered; returns that file."""
    mesh = model_copy / BROKEN_MESH
    if how == "missing":
        mesh.unlink()
    else:
        corrupt(mesh)
    return mesh


@pytest.mark.parametrize("how", ["missing", "corrupt"])
def test_inspect_with_broken_model_says_which_file_and_exits_2(model_copy, how):
    bad_file = break_model(model_copy, how)
    result = run_so101("inspect", "--mode", "direct", "--steps", "1", SO101_ASSETS_DIR=str(model_copy))
    assert result.returncode == 2
    lines = error_lines(result.stderr)
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith(f"so101 inspect: SO-101 model file {how}: {bad_file}")
    assert "so101 assets" in lines[0]
    assert "Traceback" not in result.stdout + result.stderr
    assert "shoulder_pan" not in result.stdout  # stopped before loading anything


@pytest.mark.dataflow
@pytest.mark.parametrize("how", ["missing", "corrupt"])
def test_simulation_with_broken_model_stops_the_dataflow_with_the_message(tmp_path, model_copy, how):
    bad_file = break_model(model_copy, how)
    dataflow = write_test_dataflow(tmp_path, sim_env={"SO101_ASSETS_DIR": str(model_copy)})
    dora = DoraRun(dataflow, tmp_path / "dora.log", stop_after_s=120)
    try:
        exit_code = dora.process.wait(90)  # the node exits at once, and the dataflow with it
    finally:
        dora.stop()
    log = dora.log()
    assert exit_code != 0
    assert f"[simulation] cannot start: SO-101 model file {how}: {bad_file}" in log, log[-3000:]
    assert "exited with code 2" in log, log[-3000:]
    assert "Traceback" not in log


# -- dora CLI and library versions ------------------------------------------------------

@pytest.mark.parametrize(
    "output, version",
    [("dora-cli 1.1.0\n", "1.1.0"), ("dora-cli 0.3.12", "0.3.12"), ("dora-cli 1.2.0-rc.1", "1.2.0-rc.1"),
     ("", None), ("dora-cli\n", None)],
)
def test_cli_version_is_read_from_dora_version_output(output, version):
    assert cli_version_from_output(output) == version


def test_same_versions_are_fine_and_different_ones_named():
    assert version_mismatch("1.1.0", "1.1.0") is None
    message = version_mismatch("0.3.12", "1.1.0", "/usr/local/bin/dora")
    assert message == (
        "the dora CLI (/usr/local/bin/dora) is version 0.3.12 but the dora-rs library is version 1.1.0; "
        "they must match: pip install 'dora-rs-cli==1.1.0' (or put the matching `dora` first on PATH)"
    )


def fake_dora(tmp_path: Path, script: str) -> Path:
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    dora = bin_dir / "dora"
    dora.write_text(f"#!/bin/sh\n{script}\n")
    dora.chmod(0o755)
    return bin_dir


def test_installed_cli_and_library_match():
    assert dora_version_problem(str(VENV_BIN / "dora")) is None


def test_other_dora_first_on_path_is_named_with_both_versions(tmp_path, monkeypatch):
    bin_dir = fake_dora(tmp_path, 'echo "dora-cli 1.0.4"')
    monkeypatch.setenv("PATH", f"{bin_dir}{os.pathsep}{os.environ['PATH']}")
    message = dora_version_problem()
    assert message is not None
    assert f"the dora CLI ({bin_dir / 'dora'}) is version 1.0.4" in message
    assert f"the dora-rs library is version {LIBRARY_VERSION}" in message


def test_dora_that_does_not_run_is_reported(tmp_path, monkeypatch):
    bin_dir = fake_dora(tmp_path, "exit 3")
    monkeypatch.setenv("PATH", str(bin_dir))
    message = dora_version_problem()
    assert message == (
        f"could not read the version of the dora CLI ({bin_dir / 'dora'} --version); the dora-rs library "
        f"is version {LIBRARY_VERSION}: pip install 'dora-rs-cli=={LIBRARY_VERSION}'"
    )


def test_no_dora_on_path_is_reported(tmp_path, monkeypatch):
    monkeypatch.setenv("PATH", str(tmp_path))
    assert dora_version_problem() == f"the dora CLI is not on PATH: pip install 'dora-rs-cli=={LIBRARY_VERSION}'"


def test_teleop_with_mismatched_dora_stops_before_starting_anything(tmp_path, monkeypatch, capsys):
    from so101.cli import main as cli
    from so101.launch import beside_prompt

    bin_dir = fake_dora(tmp_path, 'echo "dora-cli 1.0.4"')
    monkeypatch.setattr(beside_prompt, "dora_executable", lambda: str(bin_dir / "dora"))
    log_file = tmp_path / "dora.log"
    assert cli.main(["teleop", "--mode", "direct", "--lang", "en", "--log", str(log_file)]) == 2
    error = capsys.readouterr().err.strip()
    assert error.startswith(f"so101 teleop: the dora CLI ({bin_dir / 'dora'}) is version 1.0.4")
    assert f"the dora-rs library is version {LIBRARY_VERSION}" in error
    assert len(error.splitlines()) == 1
    assert not log_file.exists()  # no dataflow was started


def test_a_prompt_that_cannot_join_names_a_dora_of_another_version(tmp_path):
    bin_dir = fake_dora(tmp_path, 'echo "dora-cli 1.0.4"')
    result = subprocess.run(
        PROMPT_COMMAND, input="", capture_output=True, text=True, timeout=60,
        env=dict(os.environ, PATH=f"{bin_dir}{os.pathsep}{os.environ['PATH']}", SO101_LANG="en"),
    )
    assert result.returncode == 1
    lines = result.stderr.strip().splitlines()
    assert lines[0].startswith("cannot join the dataflow as keyboard_control (start it first in another terminal")
    assert lines[1] == (
        f"keyboard_control: the dora CLI ({bin_dir / 'dora'}) is version 1.0.4 but the dora-rs library is version "
        f"{LIBRARY_VERSION}; they must match: pip install 'dora-rs-cli=={LIBRARY_VERSION}' (or put the matching `dora` first on PATH)"
    )
