"""The `topdress` command and the wiring of its subcommands: the only place that puts the
subsystems together (terminal, devices, simulator, display, session log, maps)."""
