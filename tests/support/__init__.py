"""Processes and helpers the tests start (importable when tests/ is on PYTHONPATH)."""
