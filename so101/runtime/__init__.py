"""The plumbing: dataflow files, processes, dora versions, the virtual environment, a dora cluster."""
