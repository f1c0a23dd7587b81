"""Entry point of the frozen app: the same ``panotopo`` command as the console script.

The console script is ``gui.cli:main`` (the engine's commands plus ``gui``), see pyproject.toml.
"""

import multiprocessing
import sys

from gui.cli import main

if __name__ == "__main__":
    multiprocessing.freeze_support()  # a frozen app must not re-run main() in child processes
    sys.exit(main())
