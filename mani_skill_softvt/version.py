"""The package's version, below every module that records it (cards, records, the server's metadata)."""

__version__ = "0.1.0"
