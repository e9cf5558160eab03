"""Shared compiled row kernels and their typed constants: the lowest layer of the estimators.

Both the estimators (:mod:`depthnormals.estimators`) and the discontinuity module
(:mod:`depthnormals.ddm`) import from here; nothing here imports them (docs/architecture.md).

- :mod:`.depth`: input preparation (``prepare``, ``row_dtype``), the constants row of the
  vectorised passes (``row_arrays``, slots ``C_*``) and ``Pinhole``.
- :mod:`.orient`: normalise a normal and turn it toward the camera.
- :mod:`.stencils`: validity-aware derivative stencils, the NaN-outside sampler.
- :mod:`.eig3`: closed-form smallest eigenvector of a symmetric 3x3 matrix.
- :mod:`.threefn_rows`: the 3F2N row kernels (vectorised FD pass and per-pixel reference).

Submodules are imported where used; importing this package compiles nothing.
"""
