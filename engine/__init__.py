"""panotopo engine: everything that computes. Imports no Qt, ever."""

__version__ = "0.1.0"
