"""ppod_bench: benchmark programs (``ppod bench NAME``) that print tables and save plots."""
