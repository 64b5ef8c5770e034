"""The ``irtps`` command."""
