"""Errors of the workbench: one base class, each error names the input and what to do (CONVENTIONS.md, Errors)."""


class WorkbenchError(Exception):
    """Base class of every error the workbench raises on bad input or an impossible request."""


class MeshError(WorkbenchError):
    """A mesh file or mesh array that cannot be used as an object."""


class GripperError(WorkbenchError):
    """A gripper description (URDF or parametric) that cannot be used."""


class RobotError(WorkbenchError):
    """A robot description (URDF, tip frame, base pose) that cannot be used."""


class StoreError(WorkbenchError):
    """A DuckDB store that cannot be opened, is locked, damaged or lacks the requested rows."""


class PlanningError(WorkbenchError):
    """A query the planner cannot answer: unstable, unreachable or unconnected poses."""


class ParameterError(WorkbenchError):
    """A parameter outside its documented range, or parameters that contradict each other (workbench.params)."""


class MemoryBudgetError(WorkbenchError):
    """Work whose estimated memory is above the budget (workbench.params.check_memory)."""


class PartialStageWarning(UserWarning):
    """A consumer went on with a stage that did not complete (asked for with --allow-partial)."""


class RobotWarning(UserWarning):
    """A robot was loaded with a change the user should know of (bounded continuous joints, links replaced)."""


class SimulationError(WorkbenchError):
    """A plan that cannot be replayed in physics: no physics engine, a part whose convex decomposition fails."""
