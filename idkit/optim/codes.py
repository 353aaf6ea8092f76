"""The fast kernel's calling convention, in one place: every integer code and array layout that
the Python side (``idkit.optim.fast``, ``idkit.optim.base_map``) and the compiled side
(``idkit.optim.kernel``) exchange.

The cache of compiled kernels is keyed by this file's and the kernel's source (``idkit.optim.fast``),
so a change here never meets machine code compiled with the old values.
"""

from __future__ import annotations

#: The kernel form of each factor (``idkit.costs.factors.FACTORS`` names them; code ``0``: no
#: factor). ``tests/optim/test_kernel.py`` checks that every registered factor has one and that it
#: agrees with the factor's reference.
FORMS = {"fro": 1, "2": 2, "1": 3, "inf": 4, "max_row_sq": 5, "max_abs": 6, "huber": 7, "trimmed": 8}
FRO, SPECTRAL, COLUMN_SUM, ROW_SUM, ROW_SQUARES, MAX_ABS, HUBER, TRIMMED = range(1, 9)
#: Most factors one cost may multiply (the paper's f6 has three).
MAX_FACTORS = 4

#: Boundary rules, in the order of ``idkit.optim.swarm.BOUNDARIES``.
CLAMP, REFLECT, RANDOM = 0, 1, 2

#: How positions become base parameters: the identity (a base-space search), a tape of
#: elementwise operations (``idkit.optim.base_map``), or given by the caller for each move.
MAP_IDENTITY, MAP_TAPE, MAP_GIVEN = 0, 1, 2

#: Tape operations, rows ``[op, register written, a, b]``: ``OP_X`` loads coordinate ``a`` of the
#: position, ``OP_CONST`` the tape's constant of its row, the others combine registers ``a``, ``b``.
OP_X, OP_CONST, OP_ADD, OP_SUB, OP_MUL, OP_DIV, OP_NEG, OP_SIN, OP_COS, OP_SQRT, OP_SQUARE = range(11)

#: ``run_trial``'s float settings array, by index.
C1, C2, VELOCITY_LIMIT = 0, 1, 2
#: ``run_trial``'s integer settings array, by index.
BOUNDARY, PER_PARTICLE, MAP_MODE = 0, 1, 2
