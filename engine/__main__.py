import sys

from .cli import main

sys.exit(main())  # the engine's commands; `python -m gui.cli` adds the desktop app
