"""``python -m pkmcal``: the same command line as ``pkmcal``."""

from pkmcal.cli.main import main

if __name__ == "__main__":
    main()
