"""Moved to ``gui.model.layout`` (Qt-free): the layout of the map as decided."""

from .model.layout import EMBED_MAX_NODES, SMACOF_ITERATIONS, decided_layout, path_layout, serpentine  # noqa: F401
