"""Subcommands of the ``piste`` CLI, one module each (see :mod:`piste.cli`)."""
