"""The plumbing: dataflow files, a node's event loop, processes, dora versions, the virtual environment, a dora cluster."""
