"""The windows: where a display is found, the viewer processes that mirror the arm, and a
window that shows a picture with lines of text (picture_window.py)."""
