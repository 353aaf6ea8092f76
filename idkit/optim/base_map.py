"""A map from search positions to base parameters, translated into a tape the fast kernel runs.

Why: with the map in torch, each move of the fast engine costs a handful of tensor ops — more than
the kernel's own work for a paper-sized swarm (docs/speed.md, "Measurements behind design choices").
Most robots' ``base_params`` are short elementwise formulas (products, sums and squares of the
physical parameters), so the map is traced once with ``make_fx`` (the aten ops it runs, on a
``[1, P]`` example) and, when every op is one of a few elementwise ones, written as a ``Tape``: rows
``[op, register, a, b]`` that the kernel (``idkit.optim.kernel._base_params``) executes for all
particles of a swarm, op by op. Node by node, in the same order: the same rounding as torch's ops.
Anything else (a shape op, a matmul, a constant tensor) gives ``None`` and the kernel is handed the
map's output from torch each move.

A tape is data, not code: it is cached on disk as JSON (``cached_tape``), so a later process skips
the trace (seconds, for torch's tracer import) without loading anything executable.
"""

from __future__ import annotations

import contextlib
import enum
import json
import operator
import time
import warnings
import weakref
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
import torch
from torch import Tensor

from idkit.optim import cache
from idkit.optim.codes import (
    OP_ADD,
    OP_CONST,
    OP_COS,
    OP_DIV,
    OP_MUL,
    OP_NEG,
    OP_SIN,
    OP_SQRT,
    OP_SQUARE,
    OP_SUB,
    OP_X,
)

aten = torch.ops.aten
BINARY = {aten.add.Tensor: OP_ADD, aten.sub.Tensor: OP_SUB, aten.mul.Tensor: OP_MUL, aten.div.Tensor: OP_DIV}
UNARY = {
    aten.neg.default: OP_NEG,
    aten.sin.default: OP_SIN,
    aten.cos.default: OP_COS,
    aten.sqrt.default: OP_SQRT,
}


@dataclass(frozen=True)
class Tape:
    """An elementwise map ``x[P] → alpha[B]`` as register operations.

    Attributes:
        ops: ``[R, 4]`` int64 rows ``[op, register written, register a, register b]`` (``OP_X``:
            ``a`` is the coordinate of ``x``); row ``r`` writes register ``r``.
        constants: ``[R]`` float64, the value an ``OP_CONST`` row loads (0 elsewhere).
        outputs: ``[B]`` int64, the register holding each base parameter.
    """

    ops: np.ndarray
    constants: np.ndarray
    outputs: np.ndarray

    def to_json(self) -> str:
        return json.dumps(
            {"ops": self.ops.tolist(), "constants": self.constants.tolist(), "outputs": self.outputs.tolist()}
        )

    @classmethod
    def from_json(cls, text: str) -> Tape:
        data = json.loads(text)
        tape = cls(
            np.array(data["ops"], dtype=np.int64).reshape(-1, 4),
            np.array(data["constants"], dtype=np.float64),
            np.array(data["outputs"], dtype=np.int64),
        )
        rows = len(tape.ops)
        if len(tape.constants) != rows or not ((tape.outputs >= 0) & (tape.outputs < rows)).all():
            raise ValueError("a tape whose outputs or constants do not fit its rows")
        return tape

    def __call__(self, x: Tensor) -> Tensor:
        """The map in numpy on ``x[..., P]`` (tests compare it with the traced function)."""
        values = np.asarray(x, dtype=np.float64)
        registers: list[np.ndarray] = []
        binary = {OP_ADD: np.add, OP_SUB: np.subtract, OP_MUL: np.multiply, OP_DIV: np.divide}
        unary = {OP_NEG: np.negative, OP_SIN: np.sin, OP_COS: np.cos, OP_SQRT: np.sqrt, OP_SQUARE: np.square}
        for (op, _, a, b), constant in zip(self.ops.tolist(), self.constants.tolist(), strict=True):
            if op == OP_X:
                registers.append(values[..., a])
            elif op == OP_CONST:
                registers.append(np.full(values.shape[:-1], constant))
            elif op in binary:
                registers.append(binary[op](registers[a], registers[b]))
            else:
                registers.append(unary[op](registers[a]))
        return torch.from_numpy(np.stack([registers[r] for r in self.outputs.tolist()], axis=-1))


def identity(parameters: int) -> Tape:
    """The tape of a search in base space (``alpha = x``)."""
    ops = np.array([[OP_X, r, r, 0] for r in range(parameters)], dtype=np.int64).reshape(-1, 4)
    return Tape(ops, np.zeros(parameters), np.arange(parameters, dtype=np.int64))


def trace(function: Callable[[Tensor], Tensor], parameters: int) -> Tape | None:
    """The tape of ``function`` (``x[..., P] → alpha[..., B]``), or ``None`` if it is not a short
    elementwise formula of the coordinates.

    Args:
        function: traced on a ``[1, parameters]`` float64 example.
        parameters: ``P``.
    """
    from torch.fx.experimental.proxy_tensor import make_fx  # seconds to import: only when tracing

    def one_argument(x: Tensor) -> Tensor:  # make_fx traces plain functions, not bound methods
        return function(x)

    try:
        graph = make_fx(one_argument)(torch.zeros(1, parameters, dtype=torch.float64)).graph
    except Exception:  # a map that cannot be traced keeps the torch path
        return None
    rows: list[tuple[int, int, int]] = []  # (op, a, b); row r writes register r
    constants: list[float] = []
    names: dict[str, object] = {}  # node -> register, "x", or list of registers (unbind)

    def emit(op: int, a: int = 0, b: int = 0, constant: float = 0.0) -> int:
        rows.append((op, a, b))
        constants.append(constant)
        return len(rows) - 1

    def register(value: object) -> int | None:
        """The register of an argument: a traced scalar node, or a Python number loaded as a constant."""
        if isinstance(value, torch.fx.Node):
            found = names.get(value.name)
            return found if isinstance(found, int) else None
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            return None
        return emit(OP_CONST, constant=float(value))

    for node in graph.nodes:
        if node.op == "placeholder":
            names[node.name] = "x"
            continue
        if node.op == "output":
            (result,) = node.args
            outputs = names.get(result.name)
            if not isinstance(outputs, list):
                return None
            ops = np.array([[op, r, a, b] for r, (op, a, b) in enumerate(rows)], dtype=np.int64).reshape(
                -1, 4
            )
            return Tape(ops, np.array(constants, dtype=np.float64), np.array(outputs, dtype=np.int64))
        if node.op != "call_function":
            return None
        value = _node(node, names, parameters, emit, register)
        if value is None:
            return None
        names[node.name] = value
    return None


def _node(node, names, parameters, emit, register):  # noqa: ANN001, ANN202
    """The register (or list of registers) a traced node computes, or ``None`` if not translatable."""
    target, args = node.target, node.args
    source = names.get(args[0].name) if args and isinstance(args[0], torch.fx.Node) else None
    if target is aten.unbind.int and source == "x" and args[1] in (-1, 1):
        return [emit(OP_X, i) for i in range(parameters)]
    if target is aten.select.int and source == "x" and args[1] in (-1, 1):
        return emit(OP_X, int(args[2]) % parameters)
    if target is operator.getitem:
        return source[args[1]] if isinstance(source, list) else None
    if target is aten.stack.default and (len(args) < 2 or args[1] in (-1, 1)):
        parts = [register(a) for a in args[0]]
        return None if any(p is None for p in parts) else parts
    if node.kwargs:
        return None
    if target in BINARY and len(args) == 2:
        a, b = (register(v) for v in args)
        return None if a is None or b is None else emit(BINARY[target], a, b)
    if target in UNARY and len(args) == 1:
        a = register(args[0])
        return None if a is None else emit(UNARY[target], a)
    if target is aten.pow.Tensor_Scalar and args[1] == 2:
        a = register(args[0])
        return None if a is None else emit(OP_SQUARE, a)
    return None


#: Tapes per map object in this process: ``id -> (weak reference, tape or None, seconds)``.
_KNOWN: dict[int, tuple[weakref.ref, Tape | None, float]] = {}


def cached_tape(
    owner: object, function: Callable[[Tensor], Tensor], parameters: int, key: Callable[[], str | None]
) -> tuple[Tape | None, float]:
    """``trace(function, parameters)``, cached per ``owner`` object in memory and under ``key`` on disk.

    Args:
        owner: the object the map belongs to (a robot), weakly referenced.
        key: what identifies the map across processes (e.g. a hash of the pickled robot and its
            class's source), or ``None`` to trace once per process; called only when the tape
            is not known in memory.

    Returns:
        The tape (``None``: not translatable) and the seconds this process spent obtaining it.
    """
    known = _KNOWN.get(id(owner))
    if known is not None and known[0]() is owner:
        return known[1], 0.0
    started = time.perf_counter()
    name = key()
    folder, manifest = cache.prepared("maps") if name is not None else (None, None)
    file = folder / f"{name}.json" if folder is not None else None
    tape = _read(file) if file is not None else _MISSING
    if isinstance(tape, Tape) and not agrees(tape, function, parameters):
        warnings.warn(
            f"idkit's cache file {file} holds a base-map tape that disagrees with the map it stands for "
            "(stale or altered); traced again",
            cache.CacheWarning,
            stacklevel=2,
        )
        tape = _MISSING
    if tape is _MISSING:
        tape = trace(function, parameters)
        if file is not None and manifest is not None:
            with manifest.locked():  # another process's check never sees the file unrecorded
                cache.write_atomically(file, (tape.to_json() if tape is not None else "null").encode())
                manifest.record()
    seconds = time.perf_counter() - started
    with contextlib.suppress(TypeError):  # not weak-referenceable: traced (or read) again next time
        _KNOWN[id(owner)] = (weakref.ref(owner), tape, seconds)
    return tape, seconds


class _Missing(enum.Enum):
    """A tape not on disk (a typed sentinel: ``None`` is a recorded "not translatable")."""

    MISSING = enum.auto()


_MISSING = _Missing.MISSING


def agrees(tape: Tape, function: Callable[[Tensor], Tensor], parameters: int) -> bool:
    """Whether ``tape`` computes ``function`` at one probe point ``[1, P]`` (fixed, in 0.5–1.5 so a
    square root or a quotient stays finite): a tape read from disk may be stale (a map whose code the
    cache key does not cover) or altered, and a wrong tape would silently change every fit."""
    probe = 0.5 + torch.rand(1, parameters, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    try:
        expected = function(probe).detach().to("cpu", torch.float64)
        found = tape(probe)
    except Exception:  # a tape that does not fit the map (other sizes) cannot even run
        return False
    return found.shape == expected.shape and torch.allclose(
        found, expected, rtol=1e-9, atol=1e-12, equal_nan=True
    )


def _read(file: Path) -> Tape | None | Literal[_Missing.MISSING]:
    """The tape cached in ``file`` (already checked by ``cache.prepared``), ``None`` for a recorded
    "not translatable", or ``_MISSING``."""
    try:
        text = file.read_text()
    except OSError:
        return _MISSING
    try:
        return None if text.strip() == "null" else Tape.from_json(text)
    except (ValueError, KeyError, TypeError):
        return _MISSING
