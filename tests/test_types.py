"""The type checker: mypy over so101/ and nodes/ as pyproject.toml's [tool.mypy] configures it
(strict for so101.bodies), from the project's root."""

from __future__ import annotations

import subprocess
import sys

from tests.helpers.dataflow import ROOT


def test_mypy_finds_no_errors():
    result = subprocess.run(
        [sys.executable, "-m", "mypy"], cwd=ROOT, capture_output=True, text=True, timeout=600,
    )
    assert result.returncode == 0, result.stdout + result.stderr
