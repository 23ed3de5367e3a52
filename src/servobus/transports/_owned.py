"""The task group a link owns: entered by ``open()``, left by ``close()`` in the same task.

anyio (and trio under it) ties a task group to the task that entered it and to the cancel scopes
around it: the group must be left by that task, with no cancel scope entered after it still open
(a ``with anyio.CancelScope(shield=True): await link.close()`` is refused; ``close()`` shields its
own clean-up). While the group is open, the opening task runs inside its cancel scope: a
background task that fails cancels that task too, and ``close()`` (or ``async with``'s exit) raises
the failure, so no error of a link's tasks is lost.

A link's tasks run shielded until ``close()`` (or a loss) cancels them: a link lives until it is
closed, so a cancellation of the scope around an opened link (Ctrl-C, SIGTERM through
:func:`servobus.signals.stop_on`) does not take its writer, readers or clock away while a Bus on it
still sends its motors the safe stop.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from types import TracebackType
from typing import Any

import anyio
from anyio import TaskInfo
from anyio.abc import TaskGroup

__all__ = ["LinkTasks", "OwnedTaskGroup", "owned_exit"]


class LinkTasks:
    """Where a link starts its background tasks: each runs in a shielded scope of its own, which
    only the link cancels (its own stop, or :meth:`OwnedTaskGroup.leave`)."""

    __slots__ = ("_group", "_scopes")

    def __init__(self, group: TaskGroup) -> None:
        self._group = group
        self._scopes: set[anyio.CancelScope] = set()

    def start_soon(self, func: Callable[..., Awaitable[Any]], *args: object, name: object = None) -> None:
        scope = anyio.CancelScope(shield=True)
        self._scopes.add(scope)
        self._group.start_soon(self._run, scope, func, args, name=name)

    async def _run(
        self, scope: anyio.CancelScope, func: Callable[..., Awaitable[Any]], args: tuple[object, ...]
    ) -> None:
        try:
            with scope:
                await func(*args)
        finally:
            self._scopes.discard(scope)

    def cancel(self) -> None:
        for scope in list(self._scopes):
            scope.cancel()


class OwnedTaskGroup:
    """One link's task group, and the task that opened it."""

    __slots__ = ("_group", "_name", "_owner", "_tasks")

    def __init__(self, name: str) -> None:
        self._name = name
        self._group: TaskGroup | None = None
        self._tasks: LinkTasks | None = None
        self._owner: TaskInfo | None = None

    @property
    def tasks(self) -> LinkTasks | None:
        """Where the link starts its tasks (None while the group is not entered)."""
        return self._tasks

    def open_tasks(self) -> LinkTasks:
        """The group's task starter while it is open.

        Raises:
            RuntimeError: the link is not open (no group).
        """
        if self._tasks is None:
            raise RuntimeError(f"{self._name}: no task group: the link is not open")
        return self._tasks

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
        self._tasks = LinkTasks(group)
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
        tasks = self._tasks
        self._group = self._owner = self._tasks = None
        if tasks is not None:
            tasks.cancel()
        group.cancel_scope.cancel()
        absorbed = await group.__aexit__(exc_type, exc, tb)
        return exc is not None and bool(absorbed)  # (True with no exception passed means nothing)


def owned_exit(
    exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
) -> tuple[type[BaseException] | None, BaseException | None, TracebackType | None]:
    """What ``async with link:``'s exit passes to :meth:`OwnedTaskGroup.leave`: a cancellation (it
    may be the group's own), never the block's own error (that is not the task group's)."""
    if exc is not None and not isinstance(exc, anyio.get_cancelled_exc_class()):
        return None, None, None
    return exc_type, exc, tb
