"""The house's plan: import-linter's contracts (pyproject.toml's [tool.importlinter]) over so101/, and
no script of nodes/ or tools/ importing another."""

from __future__ import annotations

import ast
import shutil
import subprocess
from pathlib import Path

import pytest

from tests.helpers.dataflow import ROOT

LINT_IMPORTS = Path(shutil.which("lint-imports") or Path(__file__).parents[1] / ".venv" / "bin" / "lint-imports")


def lint_imports(root: Path) -> subprocess.CompletedProcess:
    return subprocess.run([str(LINT_IMPORTS), "--no-cache"], cwd=root, capture_output=True, text=True, timeout=300,
                          env={"PATH": "/usr/bin:/bin", "PYTHONPATH": str(root)})


def test_every_contract_is_kept():
    result = lint_imports(ROOT)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "Contracts: 4 kept, 0 broken." in result.stdout


@pytest.mark.parametrize("module, added, broken", [
    # A body that knows a task: the wrong way round (tasks hand their scene to the body).
    ("bodies/protocol.py", "import so101.tasks.cube_to_box", "so101.bodies is not allowed to import so101.tasks"),
    # One command taking another's plumbing (so101.launch holds what they share).
    ("cli/demos.py", "import so101.cli.teleop", "so101.cli.demos is not allowed to import so101.cli.teleop"),
    # A circle inside a room.
    ("dataset/layout.py", "import so101.dataset.writer", "No cycles are allowed in so101.dataset"),
])
def test_a_wrong_way_import_breaks_a_contract(tmp_path, module, added, broken):
    shutil.copytree(ROOT / "so101", tmp_path / "so101", ignore=shutil.ignore_patterns("__pycache__", "*.sha256"))
    shutil.copy(ROOT / "pyproject.toml", tmp_path)
    path = tmp_path / "so101" / module
    path.write_text(path.read_text() + f"\n{added}  # the wrong way\n")
    result = lint_imports(tmp_path)
    assert result.returncode == 1
    assert broken in result.stdout


@pytest.mark.parametrize("folder", ["nodes", "tools"])
def test_no_script_imports_another(folder):
    """nodes/ and tools/ are folders of scripts: each stands on so101/ alone, so none can start a circle."""
    scripts = {path.stem for path in (ROOT / folder).glob("*.py")}
    for path in sorted((ROOT / folder).glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            names = ([alias.name for alias in node.names] if isinstance(node, ast.Import)
                     else [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
            for name in names:
                assert name.split(".")[0] not in {folder, *scripts}, f"{path.name} imports {name}"
