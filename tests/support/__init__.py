"""Helpers shared by test modules: truth models, fixtures and data builders (never imported by the package)."""
