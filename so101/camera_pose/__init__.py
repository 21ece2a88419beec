"""Where a real camera stands, against the simulated one of the same name: `so101 cameras --fit` and
`--align`. Its place and field of view fitted to pictures of the arm (fit.py), the way to move it in
words (moves.py), the simulated arm over the live picture (overlay.py), and the align loop that shows
it while the arm is moved by hand (align.py)."""
