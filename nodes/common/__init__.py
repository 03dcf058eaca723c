"""Plumbing shared by every PPOD node: parameters, lifecycle base, diagnostics, QoS, main()."""
