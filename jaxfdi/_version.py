"""The package version, in a module of its own so that the bottom layer (``_io``'s
provenance records) reads it without importing the whole package."""

__version__ = "0.1.0"
