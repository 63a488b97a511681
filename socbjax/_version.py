"""The package version (one place, imported by the package and its file writers)."""

__version__ = "0.2.0"
