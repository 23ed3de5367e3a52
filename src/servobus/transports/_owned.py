"""The task group a link owns: entered by ``open()``, left by ``close()`` in the same task.

anyio (and trio under it) ties a task group to the task that entered it and to the cancel scopes
around it: the group must be left by that task, with no cancel scope entered after it still open
(a ``with anyio.CancelScope(shield=True): await link.close()`` is refused; ``close()`` shields its
own clean-up). While the group is open, the opening task runs inside its cancel scope: a
background task that fails cancels that task too, and ``close()`` (or ``async with``'s exit) raises
the failure, so no error of a link's tasks is lost.
"""

from __future__ import annotations

from types import TracebackType

import anyio
from anyio import TaskInfo
from anyio.abc import TaskGroup

__all__ = ["OwnedTaskGroup"]


class OwnedTaskGroup:
    """One link's task group, and the task that opened it."""

    __slots__ = ("_group", "_name", "_owner")

    def __init__(self, name: str) -> None:
        self._name = name
        self._group: TaskGroup | None = None
        self._owner: TaskInfo | None = None

    @property
    def group(self) -> TaskGroup | None:
        """The entered task group (None while not entered)."""
        return self._group

    async def enter(self) -> TaskGroup:
        """Enter a new task group in the calling task.

        Raises:
            RuntimeError: one is entered already.
        """
        if self._group is not None:
            raise RuntimeError(f"{self._name}: its task group is entered already")
        group = anyio.create_task_group()
        await group.__aenter__()
        self._group = group
        self._owner = anyio.get_current_task()
        return group

    def check_owner(self, what: str) -> None:
        """Raises RuntimeError when called by another task than the one that entered the group."""
        owner = self._owner
        if self._group is None or owner is None:
            return
        current = anyio.get_current_task()
        if current.id != owner.id:
            raise RuntimeError(
                f"{self._name}: {what} must be called by the task that opened it ({owner.name!r}), "
                f"not by {current.name!r} (anyio ties a task group to one task)"
            )

    async def leave(
        self,
        exc_type: type[BaseException] | None = None,
        exc: BaseException | None = None,
        tb: TracebackType | None = None,
    ) -> bool:
        """Cancel every task of the group, wait for them, and leave it.

        Pass a cancellation the opening task is leaving with (so that one caused by the group's own
        scope ends here); any other exception of that task is not the group's and is not passed.

        Returns:
            True when the cancellation passed in was the group's own and has been absorbed.

        Raises:
            BaseExceptionGroup: a task of the group failed.
        """
        group = self._group
        if group is None:
            return False
        self.check_owner("close()")
        self._group = self._owner = None
        group.cancel_scope.cancel()
        absorbed = await group.__aexit__(exc_type, exc, tb)
        return exc is not None and bool(absorbed)  # (True with no exception passed means nothing)
