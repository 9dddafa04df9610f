"""The command line: ``pkmcal`` and its sub-commands (one module per group of commands)."""
