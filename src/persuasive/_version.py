"""The package's version, alone in a module at the bottom of the package, so that any module
can name it without importing the package's ``__init__`` (and everything it imports)."""

__version__ = "0.1.1"
