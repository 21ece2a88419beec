"""dora's log lines (written by its Rust side to descriptor 1) go to a file; the prompt's own lines do not."""

from __future__ import annotations

import subprocess
import sys
import textwrap

from tests.helpers.dataflow import ROOT


def test_descriptor_1_goes_to_the_log_and_python_output_stays_where_it_was(tmp_path):
    log = tmp_path / "logs" / "prompt.log"
    script = textwrap.dedent(f"""
        import os, sys
        from pathlib import Path
        from so101.prompt.terminal import dora_logs_to
        print("before")
        with dora_logs_to(Path({str(log)!r})):
            os.write(1, b'{{"level":"WARN","fields":{{"message":"Discarding event"}}}}\\n')
            print("a reply")
            sys.stdout.flush()
        os.write(1, b"descriptor 1 is back\\n")
        print("after")
    """)
    result = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, cwd=ROOT, timeout=60)
    assert result.returncode == 0, result.stderr
    assert result.stdout == "before\na reply\ndescriptor 1 is back\nafter\n"
    assert log.read_text() == '{"level":"WARN","fields":{"message":"Discarding event"}}\n'
