"""The `so101` command: one module per subcommand, dispatched by so101/cli/main.py."""
