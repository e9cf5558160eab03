"""CLI sub-commands, one module each (see :mod:`depthnormals.cli`)."""
