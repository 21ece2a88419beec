"""The windows: where a display is found, and the viewer processes that mirror the arm."""
