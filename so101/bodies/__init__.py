"""The bodies: one class each behind the Body protocol, their registry, their settings and the one node loop that makes any of them a dora node."""
