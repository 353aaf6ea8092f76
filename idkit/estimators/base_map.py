"""The robot's map from search positions to base parameters, translated to C for the native kernel.

Why: with the map in torch, each PSO move of the native engine still costs a handful of tensor ops
(~20 µs) — more than the kernel's own work for a paper-sized swarm. Most robots' ``base_params``
are short elementwise formulas (products, sums and squares of the physical parameters), so the
map is traced once with ``make_fx`` (the aten ops it runs, on a ``[1, P]`` example) and, when every
op is one of a few elementwise ones, written as a C function ``base_map(x[P]) -> alpha[B]`` that
the kernel calls per particle. Node by node, in the same order: the same rounding as torch's ops.
Anything else (a shape op, a matmul, a constant tensor) returns ``None`` and the kernel reads the
map's output from torch instead.
"""

from __future__ import annotations

import operator

import torch
from torch.fx.experimental.proxy_tensor import make_fx

from idkit.interfaces import Robot

aten = torch.ops.aten
BINARY = {aten.add.Tensor: "+", aten.sub.Tensor: "-", aten.mul.Tensor: "*", aten.div.Tensor: "/"}
UNARY = {aten.neg.default: "-", aten.sin.default: "sin", aten.cos.default: "cos", aten.sqrt.default: "sqrt"}


def identity_source(parameters: int) -> str:
    """The C map of a search in base space (``alpha = x``)."""
    body = "".join(f"    alpha[{i}] = x[{i}];\n" for i in range(parameters))
    return f"static void base_map(const double *x, double *alpha) {{\n{body}}}\n"


def map_source(robot: Robot, parameters: int) -> str | None:
    """C source of ``static void base_map(const double *x, double *alpha)``, or ``None``.

    Args:
        robot: its ``base_params`` is traced on a ``[1, parameters]`` float64 example.
        parameters: ``P``.
    """

    def base_params(x: torch.Tensor) -> torch.Tensor:
        return robot.base_params(x)

    try:
        graph = make_fx(base_params)(torch.zeros(1, parameters, dtype=torch.float64)).graph
    except Exception:  # a map that cannot be traced keeps the torch path
        return None
    names: dict[str, object] = {}  # node -> C expression, or list of expressions (unbind)
    lines = []
    for node in graph.nodes:
        if node.op == "placeholder":
            names[node.name] = "x"
            continue
        if node.op == "output":
            (result,) = node.args
            values = names.get(result.name)
            if not isinstance(values, list):
                return None
            lines += [f"    alpha[{i}] = {value};" for i, value in enumerate(values)]
            break
        if node.op != "call_function":
            return None
        expression = _expression(node, names, parameters)
        if expression is None:
            return None
        if isinstance(expression, list):
            names[node.name] = expression
        else:
            lines.append(f"    double {node.name} = {expression};")
            names[node.name] = node.name
    else:
        return None
    return "static void base_map(const double *x, double *alpha) {\n" + "\n".join(lines) + "\n}\n"


def _scalar(value: object, names: dict[str, object]) -> str | None:
    """C expression of an argument: a traced scalar node or a Python number."""
    if isinstance(value, torch.fx.Node):
        name = names.get(value.name)
        return name if isinstance(name, str) and name != "x" else None
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    return repr(float(value))


def _expression(node: torch.fx.Node, names: dict[str, object], parameters: int) -> str | list[str] | None:
    target, args = node.target, node.args
    if target is aten.unbind.int and names.get(args[0].name) == "x" and args[1] in (-1, 1):
        return [f"x[{i}]" for i in range(parameters)]
    if target is aten.select.int and names.get(args[0].name) == "x" and args[1] in (-1, 1):
        return f"x[{int(args[2])}]"
    if target is operator.getitem:
        values = names.get(args[0].name)
        return values[args[1]] if isinstance(values, list) else None
    if target is aten.stack.default and (len(args) < 2 or args[1] in (-1, 1)):
        parts = [_scalar(a, names) for a in args[0]]
        return None if any(p is None for p in parts) else parts
    if node.kwargs:
        return None
    if target in BINARY and len(args) == 2:
        a, b = (_scalar(v, names) for v in args)
        return None if a is None or b is None else f"({a} {BINARY[target]} {b})"
    if target in UNARY and len(args) == 1:
        a = _scalar(args[0], names)
        return None if a is None else f"{UNARY[target]}({a})"
    if target is aten.pow.Tensor_Scalar and args[1] == 2:
        a = _scalar(args[0], names)
        return None if a is None else f"({a} * {a})"
    return None
