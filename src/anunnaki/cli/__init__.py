"""The ``anunnaki`` command line (see :mod:`anunnaki.cli.main`)."""
