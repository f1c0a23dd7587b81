"""The ``panotopo`` console script: the engine's commands plus ``gui``.

The entry point lives here, in the top layer, so that ``engine`` never imports the
desktop app; Qt is imported only when the ``gui`` command runs.
"""

from __future__ import annotations

import argparse
import sys
from typing import Optional, Sequence

from engine import cli as engine_cli


def add_gui_command(sub: argparse._SubParsersAction, common: argparse.ArgumentParser) -> None:
    p = sub.add_parser("gui", parents=[common], help="open the desktop app")
    p.add_argument("input", nargs="*", help="a recording, a descriptors .npz, a session file or a site map "
                   "(.graphml); several recordings: one site of them")
    p.add_argument("--screenshot", help="load INPUT, run the engine, save a picture of the window and exit")
    p.set_defaults(func=_run_gui)


def _run_gui(args: argparse.Namespace) -> int:
    from .app import run

    inputs = list(args.input or [])
    return run(inputs if len(inputs) > 1 else (inputs[0] if inputs else None), args.screenshot)


def main(argv: Optional[Sequence[str]] = None) -> int:
    return engine_cli.main(argv, extra_commands=[add_gui_command])


if __name__ == "__main__":
    sys.exit(main())
