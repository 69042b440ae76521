"""Command-line subcommands of the core (dataset generation and rendering)."""
