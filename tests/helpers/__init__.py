"""What several test modules share; no tests here (pytest collects only tests/test_*.py).

- calibrate.py: `so101 calibrate` as a person runs it, its output read as it comes, lines typed on its stdin.
- course_motion.py: the course's motions as joint targets, one command after another, and the steps each is given.
- dataflow.py: running the project as a user does (`so101`, `dora run` on a copy of a dataflow file with
  absolute paths and extra nodes, a body's node in-process under MockNode), the emulated arm a real-arm
  test drives, and the course's commands typed into the prompt with the arm checked after each.
- images.py: the project's pictures read back (PNG size and pixels) and the arm in a CPU render.
- lerobot_written.py: LeRobot v3.0 datasets written the way LeRobot 0.4.x writes them, by code of its own.
- processes.py: lines read from a process's output with a timeout; the processes a test's `dora run`
  started, found by a marker in their environment, until they are gone.
- screen.py: an Xvfb display's screen: the marks a window's test carries, screenshots, the arm's pixels.
- terminal.py: the tmux terminal a person types in, and `so101 teleop` and `so101 calibrate` started in one.

Fixtures (an Xvfb display, a machine with no other dataflow) are in tests/conftest.py.
"""
