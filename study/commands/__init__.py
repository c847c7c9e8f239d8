"""Subcommand groups of the `study` command, one module per group, registered in `study.cli`."""
