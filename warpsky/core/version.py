"""The package version, importable without importing the package (its ``__init__`` loads Warp)."""

__version__ = "0.1.0"
