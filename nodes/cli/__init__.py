"""The ``ppod`` command line: one module per subcommand, registered in :mod:`ppod_nodes.cli.main`."""
