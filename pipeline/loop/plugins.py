"""The boundary between the loop and a planner or controller of the user's own (``_target_``).

What a plug-in returns is checked where it enters the loop, before any number of it is used or
logged: its type, its shape, that it is finite, and that it lies in the range the configuration
schema allows. A bad output stops the run with :class:`~pipeline.errors.PluginOutputError`, one
line naming the plug-in (its ``_target_``), the method and the field, what it was and what is
allowed. The built-in planner and controllers are not wrapped: their steps cost what they cost,
and no number of a built-in run changes.
"""

from __future__ import annotations

import functools
import math
from typing import Any

import numpy as np

from pipeline.errors import PluginOutputError, plain_value
from pipeline.loop.controller.base import ControlStep, Observation
from pipeline.loop.planner import ApfRollout

#: The planned speed a planner may return (m/s): from standing still to the largest
#: ``scenario.speed_mps`` the schema allows (:attr:`ScenarioConfig.SPEED_BOUNDS_MPS`).
PLANNED_SPEED_MIN_MPS = 0.0
#: Slack on a command's bound (a solver's last bits), relative to the bound: an interior-point
#: solver's tolerance (Clarabel's 1e-8) leaves bits beyond it (the kinematic MPC-DCBF peer's
#: steering at -0.4000000005 rad on a Euro NCAP test refused at 1e-9).
BOUND_SLACK = 1e-6


def _refuse(who: str, field: str, found: str, allowed: str) -> PluginOutputError:
    return PluginOutputError(f"plug-in error: {who} returned {field} = {found}; allowed: "
                             f"{allowed}")


def _shape_text(value: Any) -> str:
    shape = getattr(value, "shape", None)
    return f"an array of shape {tuple(shape)}" if shape is not None \
        else f"a {type(value).__name__}"


def _array(who: str, field: str, value: Any, shape: tuple[int, ...], what: str) -> np.ndarray:
    """``value`` as a float array of ``shape``, finite; else the one-line refusal."""
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise _refuse(who, field, _shape_text(value), what) from None
    if array.shape != shape:
        raise _refuse(who, field, _shape_text(array), what)
    if not np.isfinite(array).all():
        bad = array[~np.isfinite(array)].ravel()[0]
        raise _refuse(who, field, f"{bad} (non-finite)", f"finite numbers, {what}")
    return array


def _has_methods(who: str, plugin: Any, names: tuple[str, ...], how: str) -> None:
    """Refuse a plug-in that lacks a method the loop calls, before the run starts."""
    missing = [name for name in names if not callable(getattr(plugin, name, None))]
    if missing:
        raise PluginOutputError(f"plug-in error: {who} has no {', '.join(m + '()' for m in missing)}; "
                                f"allowed: a class with {', '.join(n + '()' for n in names)} "
                                f"({how})")


class CheckedPlanner:
    """A user's planner with its outputs checked (see the module docstring): ``rollout``'s
    path of ``horizon`` points and its forces and flags, ``speed`` in
    [``PLANNED_SPEED_MIN_MPS``, the schema's largest speed]."""

    def __init__(self, planner: Any, target: str, horizon: int, speed_max_mps: float) -> None:
        self.inner, self.who = planner, f"planner {target}"
        self.horizon, self.speed_max_mps = int(horizon), float(speed_max_mps)
        _has_methods(self.who, planner, ("rollout", "speed"),
                     "subclass pipeline.loop.planner.ApfPlanner")
        inner_speed = planner.speed

        @functools.wraps(inner_speed)  # its signature: the loop asks for path_m by it
        def speed(*args: Any, **kwargs: Any) -> float:
            return self._speed(inner_speed(*args, **kwargs))

        self.speed = speed

    def __getattr__(self, name: str) -> Any:
        if name == "inner":  # not built yet (a copy being made): no recursion
            raise AttributeError(name)
        return getattr(self.inner, name)

    def rollout(self, *args: Any, **kwargs: Any) -> ApfRollout:
        out = self.inner.rollout(*args, **kwargs)
        n, who = self.horizon, self.who
        if not isinstance(out, ApfRollout):
            raise _refuse(who, "rollout()", f"a {type(out).__name__}",
                          "an ApfRollout (pipeline.loop.planner)")
        steps = max(n - 1, 0)
        path = _array(who, "rollout().path_m", out.path_m, (n, 2),
                      f"shape ({n}, 2): controller.horizon = {n} points (x, y) in metres")
        attraction = _array(who, "rollout().attraction", out.attraction, (steps, 2),
                            f"shape ({steps}, 2): one force per step")
        repulsion = _array(who, "rollout().repulsion", out.repulsion, (steps, 2),
                           f"shape ({steps}, 2): one force per step")
        flags = []
        for name in ("step_cap_active", "step_min_active"):
            value = np.asarray(getattr(out, name))
            if value.shape != (steps,):
                raise _refuse(who, f"rollout().{name}", _shape_text(value),
                              f"shape ({steps},): one flag per step")
            flags.append(value.astype(bool, copy=False))
        return ApfRollout(path, attraction, repulsion, flags[0], flags[1])

    def _speed(self, value: Any) -> float:
        try:
            speed = float(value)
        except (TypeError, ValueError):
            raise _refuse(self.who, "speed()", _shape_text(value),
                          "one number (m/s)") from None
        if not (math.isfinite(speed) and PLANNED_SPEED_MIN_MPS <= speed <= self.speed_max_mps):
            raise _refuse(self.who, "speed()", f"{plain_value(speed)} m/s",
                          f"a speed in [{PLANNED_SPEED_MIN_MPS:g}, {self.speed_max_mps:g}] m/s "
                          "(the range of scenario.speed_mps)")
        return speed


class CheckedController:
    """A user's controller with each step's output checked: a :class:`ControlStep` whose
    ``command`` has the plant's input count, finite and within the vehicle's limits
    (``bounds``: one ``(low, high, name)`` per input)."""

    def __init__(self, controller: Any, target: str,
                 bounds: tuple[tuple[float, float, str], ...]) -> None:
        self.inner, self.who, self.bounds = controller, f"controller {target}", bounds
        _has_methods(self.who, controller, ("step",),
                     "step(observation) -> ControlStep, see pipeline.loop.controller.base")
        self._low = np.array([b[0] for b in bounds], float)
        self._high = np.array([b[1] for b in bounds], float)
        slack = BOUND_SLACK * np.maximum(np.abs(self._low), np.abs(self._high))
        self._low, self._high = self._low - slack, self._high + slack

    @property
    def compile_count(self) -> int:
        return getattr(self.inner, "compile_count", 0)

    @property
    def compile_time_s(self) -> float:
        return getattr(self.inner, "compile_time_s", 0.0)

    def __getattr__(self, name: str) -> Any:
        if name == "inner":  # not built yet (a copy being made): no recursion
            raise AttributeError(name)
        return getattr(self.inner, name)

    def step(self, observation: Observation) -> ControlStep:
        out = self.inner.step(observation)
        who, n_u = self.who, len(self.bounds)
        if not isinstance(out, ControlStep):
            raise _refuse(who, "step()", f"a {type(out).__name__}",
                          "a ControlStep (pipeline.loop.controller)")
        names = ", ".join(b[2] for b in self.bounds)
        command = _array(who, "step().command", out.command, (n_u,),
                         f"shape ({n_u},): [{names}]")
        outside = (command < self._low) | (command > self._high)
        if outside.any():
            i = int(np.argmax(outside))
            low, high, name = self.bounds[i]
            raise _refuse(who, f"step().command[{i}] ({name})", plain_value(command[i]),
                          f"[{low:g}, {high:g}] (the vehicle's limit)")
        try:
            solve_time = float(out.solve_time_s)
        except (TypeError, ValueError):
            solve_time = math.nan
        if not (math.isfinite(solve_time) and solve_time >= 0.0):
            raise _refuse(who, "step().solve_time_s", plain_value(out.solve_time_s),
                          "a finite time >= 0 (s)")
        return out if out.command is command else _with_command(out, command)


def _with_command(step: ControlStep, command: np.ndarray) -> ControlStep:
    import dataclasses

    return dataclasses.replace(step, command=command)
