"""OMPL termination conditions on a planning budget's clock (`planners.base.Budget`).

On the wall clock, OMPL's own `timedPlannerTerminationCondition` (as before budgets had clocks).
On the CPU clock, a condition that reads the process's CPU time (`time.process_time`) through a
Python callable. OMPL evaluates a condition from the thread that asks, and its Python bindings
(2.0.1) keep the GIL held during `solve`: a planner that evaluates its condition from a thread of
its own would deadlock on the callable. Of ours, PRM does (its solution-checking thread); it is
solved in slices already (`ompl_solve.OmplPlanner._solve_in_slices`), each slice a wall-timed
condition no longer than the CPU time left, which a process cannot overrun by more than its other
threads' share of the slice: wall time is never less than one thread's CPU time.
"""

from __future__ import annotations

from ompl import base as ob

from planners.base import clock_now


def termination(clock: str, seconds: float) -> ob.PlannerTerminationCondition:
    """A condition that fires after `seconds` on budget clock `clock` ("wall" or "cpu").

    Only for planners that evaluate their condition in the calling thread (see the module
    docstring): RRT-Connect, AORRTC's single solve and OMPL's PathSimplifier.
    """
    if clock == "wall":
        return ob.timedPlannerTerminationCondition(seconds)
    end = clock_now(clock) + seconds
    return ob.PlannerTerminationCondition(lambda: clock_now(clock) >= end)
