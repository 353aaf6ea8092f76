"""Conformance checks for ``Robot`` plugins.

Shapes (``idkit.interfaces``): ``inverse_dynamics(params[..., P], q[N, n], qd[N, n], qdd[N, n])
-> tau[..., N, n]``; where a regressor exists, ``regressor(q, qd, qdd) -> Y[N, n, B]``,
``base_params(params[..., P]) -> alpha[..., B]`` and ``params_from_base(alpha[..., B]) ->
params[..., P]`` with ``tau = Y @ alpha``.
"""

from __future__ import annotations

from collections.abc import Callable

import torch
from torch import Tensor

from idkit.interfaces import Robot
from idkit.testing._common import (
    BATCH_SHAPES,
    DTYPES,
    RTOL,
    call,
    check_hyperparameters,
    conformance_check,
    expect_close,
    expect_raises,
    expect_tensor,
    fail,
    shape_str,
)

#: Number of samples in the checks' states (7: distinct from any n or P, so a transposed result shows).
N_SAMPLES = 7


def states(
    robot: Robot, dtype: torch.dtype = torch.float64, n_samples: int = N_SAMPLES
) -> tuple[Tensor, ...]:
    """Reproducible joint states ``(q, qd, qdd)``, each ``[N, n]``, uniform in ``[-1, 1]``."""
    gen = torch.Generator().manual_seed(20260101)
    return tuple(
        (2 * torch.rand(n_samples, robot.n_joints, generator=gen, dtype=torch.float64) - 1).to(dtype)
        for _ in range(3)
    )


def sample_params(robot: Robot, batch: tuple[int, ...] = (), dtype: torch.dtype = torch.float64) -> Tensor:
    """Reproducible physical parameters ``[*batch, P]`` uniform within ``robot.bounds()``."""
    lower, upper = (b.to(torch.float64) for b in robot.bounds())
    gen = torch.Generator().manual_seed(20260102)
    u = torch.rand(*batch, robot.n_params, generator=gen, dtype=torch.float64)
    return (lower + u * (upper - lower)).to(dtype)


def _id_call(robot: Robot, params: Tensor, q: Tensor, qd: Tensor, qdd: Tensor) -> Tensor:
    what = f"inverse_dynamics({shape_str('params', params.shape)}, q[{q.shape[0]}, {q.shape[1]}], ...)"
    return call(what, robot.inverse_dynamics, params, q, qd, qdd)


@conformance_check
def check_robot_names(robot: Robot) -> None:
    """``joint_names``, ``param_names``, ``base_param_names``: tuples of unique non-empty strings."""
    for attr in ("joint_names", "param_names", "base_param_names"):
        names = getattr(robot, attr, None)
        if not isinstance(names, tuple) or not all(isinstance(x, str) and x for x in names):
            fail(f"{attr} must be a tuple of non-empty strings, got {names!r}")
        if len(set(names)) != len(names):
            dupes = sorted({x for x in names if names.count(x) > 1})
            fail(f"{attr} has duplicates {dupes}; names key the estimates and must be unique")
    if not robot.joint_names or not robot.param_names:
        fail(f"needs at least one joint and one parameter, got {robot.joint_names} / {robot.param_names}")
    if robot.search_space not in ("physical", "base"):
        fail(f"search_space must be 'physical' or 'base', got {robot.search_space!r}")
    if robot.has_regressor and not robot.base_param_names:
        fail("implements regressor() but lists no base_param_names (one name per regressor column)")


def _check_box(robot: Robot, method: str, names: tuple[str, ...]) -> None:
    box = call(f"{method}()", getattr(robot, method))
    if not (isinstance(box, tuple) and len(box) == 2):
        fail(f"{method}() must return a tuple (lower, upper), got {type(box).__name__}")
    lower, upper = box
    for side, value in (("lower", lower), ("upper", upper)):
        if not isinstance(value, Tensor) or not value.is_floating_point():
            fail(f"{method}() {side} must be a floating-point tensor, got {value!r}")
        expect_tensor(value, f"{method}() {side}", (len(names),), value.dtype)
    empty = (lower >= upper).nonzero().flatten().tolist()
    if empty:
        i = empty[0]
        fail(
            f"{method}(): lower >= upper for {names[i]!r} ({lower[i].item()} >= {upper[i].item()}); "
            "every parameter needs a non-empty search interval"
        )


@conformance_check
def check_robot_bounds(robot: Robot) -> None:
    """``bounds()`` is ``(lower[P], upper[P])``, finite, ``lower < upper``; ``base_bounds()`` too when
    the robot is searched in base space."""
    _check_box(robot, "bounds", robot.param_names)
    if robot.search_space == "base":
        _check_box(robot, "base_bounds", robot.base_param_names)


@conformance_check
def check_robot_nominal_params(robot: Robot) -> None:
    """``nominal_params()`` is ``None`` or finite ``[P]``; with a physical search box, inside it
    (estimators could not find a truth outside their box)."""
    nominal = call("nominal_params()", robot.nominal_params)
    if nominal is None:
        return
    expect_tensor(nominal, "nominal_params()", (robot.n_params,), nominal.dtype)
    if robot.search_space == "physical":
        lower, upper = robot.bounds()
        outside = ((nominal < lower) | (nominal > upper)).nonzero().flatten().tolist()
        if outside:
            i = outside[0]
            fail(
                f"nominal {robot.param_names[i]} = {nominal[i].item()} is outside bounds() "
                f"[{lower[i].item()}, {upper[i].item()}]"
            )


@conformance_check
def check_robot_shapes_and_dtypes(robot: Robot) -> None:
    """``inverse_dynamics`` maps ``params[*b, P]`` to finite ``tau[*b, N, n]`` of the input dtype
    for ``b`` in ``()``, ``(2,)``, ``(2, 3)`` and float32/float64, without changing its inputs."""
    for dtype in DTYPES:
        q, qd, qdd = states(robot, dtype)
        for batch in BATCH_SHAPES:
            params = sample_params(robot, batch, dtype)
            before = [x.clone() for x in (params, q, qd, qdd)]
            tau = _id_call(robot, params, q, qd, qdd)
            what = f"inverse_dynamics({shape_str('params', params.shape)}, {dtype})"
            expect_tensor(tau, what, (*batch, N_SAMPLES, robot.n_joints), dtype)
            after = (params, q, qd, qdd)
            for name, old, new in zip(("params", "q", "qd", "qdd"), before, after, strict=True):
                if not torch.equal(old, new):
                    fail(f"{what} modified its input {name!r} in place")


@conformance_check
def check_robot_batch_invariance(robot: Robot) -> None:
    """A batched call equals the stack of unbatched calls (no mixing across the batch)."""
    q, qd, qdd = states(robot)
    params = sample_params(robot, (2, 3))
    batched = _id_call(robot, params, q, qd, qdd)
    single = torch.stack(
        [torch.stack([_id_call(robot, params[i, j], q, qd, qdd) for j in range(3)]) for i in range(2)]
    )
    expect_close(batched, single, "inverse_dynamics(params[2, 3, P]) vs. six calls with params[P]", 1e-10)


@conformance_check
def check_robot_rejects_bad_sizes(robot: Robot) -> None:
    """Wrong trailing sizes raise (ValueError preferred) instead of being silently broadcast or cut."""
    q, qd, qdd = states(robot)
    params = sample_params(robot, (2,))
    n, p = robot.n_joints, robot.n_params
    fix = "Check params.shape[-1] == len(param_names) and q/qd/qdd shape [N, n] and raise ValueError."
    wider = torch.cat([params, params[..., :1]], dim=-1)
    expect_raises(
        f"inverse_dynamics(params[2, {p + 1}]) (P = {p})", robot.inverse_dynamics, wider, q, qd, qdd, fix=fix
    )
    if p > 1:
        expect_raises(
            f"inverse_dynamics(params[2, {p - 1}]) (P = {p})",
            robot.inverse_dynamics,
            params[..., :-1],
            q,
            qd,
            qdd,
            fix=fix,
        )
    extra = torch.cat([q, q[:, :1]], dim=1)
    expect_raises(
        f"inverse_dynamics with q[{N_SAMPLES}, {n + 1}] (n = {n})",
        robot.inverse_dynamics,
        params,
        extra,
        torch.cat([qd, qd[:, :1]], dim=1),
        torch.cat([qdd, qdd[:, :1]], dim=1),
        fix=fix,
    )


@conformance_check
def check_robot_regressor(robot: Robot) -> None:
    """Where ``has_regressor``: ``Y[N, n, B]``, ``Y @ base_params(p) == inverse_dynamics(p)``,
    ``base_params(params_from_base(alpha)) == alpha``, shapes over batches and dtypes preserved."""
    if not robot.has_regressor:
        return
    n, p, b = robot.n_joints, robot.n_params, len(robot.base_param_names)
    for dtype in DTYPES:
        q, qd, qdd = states(robot, dtype)
        y = call("regressor(q, qd, qdd)", robot.regressor, q, qd, qdd)
        expect_tensor(y, f"regressor(q[{N_SAMPLES}, {n}], ..., {dtype})", (N_SAMPLES, n, b), dtype)
        for batch in BATCH_SHAPES:
            params = sample_params(robot, batch, dtype)
            alpha = call("base_params(params)", robot.base_params, params)
            expect_tensor(
                alpha, f"base_params({shape_str('params', params.shape)}, {dtype})", (*batch, b), dtype
            )
            back = call("params_from_base(alpha)", robot.params_from_base, alpha)
            expect_tensor(
                back, f"params_from_base({shape_str('alpha', alpha.shape)}, {dtype})", (*batch, p), dtype
            )
            if dtype is torch.float64:
                tau = _id_call(robot, params, q, qd, qdd)
                linear = torch.einsum("snb,...b->...sn", y, alpha)
                expect_close(
                    linear,
                    tau,
                    f"Y @ base_params(params{list(params.shape)}) vs inverse_dynamics(params)",
                    RTOL[dtype],
                )
                again = call("base_params(params_from_base(alpha))", robot.base_params, back)
                expect_close(again, alpha, "base_params(params_from_base(alpha)) vs alpha", RTOL[dtype])


@conformance_check
def check_robot_differentiable(robot: Robot) -> None:
    """Autograd gives finite gradients of the torques w.r.t. the parameters (for gradient estimators)."""
    q, qd, qdd = states(robot)
    params = sample_params(robot, (2,)).requires_grad_(True)
    tau = _id_call(robot, params, q, qd, qdd)
    if not tau.requires_grad:
        fail("inverse_dynamics output does not depend on params through autograd (detached?)")
    (grad,) = torch.autograd.grad(tau.sum(), params, allow_unused=True)
    if grad is None:
        fail("inverse_dynamics output has no gradient w.r.t. params")
    expect_tensor(grad, "d sum(tau) / d params", tuple(params.shape), params.dtype)


@conformance_check
def check_robot_excitation(robot: Robot) -> None:
    """``excitation(t[N])`` gives finite ``(q, qd, qdd)``, each ``[N, n]`` in ``t``'s dtype, on which the
    nominal (or mid-box) parameters give finite torques: the scenarios simulate robots this way."""
    for dtype in DTYPES:
        t = torch.linspace(0.5, 10.0, 5, dtype=dtype)
        out = call(f"excitation(t[5], {dtype})", robot.excitation, t)
        if not (isinstance(out, tuple) and len(out) == 3):
            fail(f"excitation(t) must return a tuple (q, qd, qdd), got {type(out).__name__}")
        for name, x in zip(("q", "qd", "qdd"), out, strict=True):
            expect_tensor(x, f"excitation(t[5], {dtype}) {name}", (5, robot.n_joints), dtype)
    nominal = robot.nominal_params()
    if nominal is None:
        lower, upper = robot.bounds()
        nominal = (lower + upper) / 2
    q, qd, qdd = robot.excitation(torch.linspace(0.5, 10.0, 5, dtype=torch.float64))
    tau = _id_call(robot, nominal.to(torch.float64), q, qd, qdd)
    expect_tensor(tau, "inverse_dynamics(nominal, *excitation(t))", (5, robot.n_joints), torch.float64)


ROBOT_CHECKS: tuple[Callable[[Robot], None], ...] = (
    check_hyperparameters,
    check_robot_names,
    check_robot_bounds,
    check_robot_nominal_params,
    check_robot_shapes_and_dtypes,
    check_robot_batch_invariance,
    check_robot_rejects_bad_sizes,
    check_robot_regressor,
    check_robot_differentiable,
    check_robot_excitation,
)
