"""Real cameras: USB cameras (V4L2, through OpenCV) or video files standing in for them, as the real
arm's eyes. `--camera NAME=SOURCE` and the scaling rules (sources.py), the capture that paces a file
and retries a camera that stopped (capture.py), a source tried before it is used (probe.py), what
V4L2 says a camera offers (v4l2.py, listing.py), the camera node's settings (settings.py).
The simulated bodies' cameras are so101/bodies/'s."""
