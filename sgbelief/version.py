"""The version of sgbelief (one place; the package face and the saved files' ``created_by`` read it)."""

__version__ = "0.1.0"
