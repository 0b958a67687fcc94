"""One progress bar over named stages, for the commands whose work is a few long steps.

``--progress/--no-progress`` (:func:`orokit.cli.options.progress_option`) switches it; the
bar goes to stderr, so stdout stays the command's result.
"""
from __future__ import annotations

import sys
from collections.abc import Sequence
from types import TracebackType
from typing import Any


class StageProgress:
    """Progress over ``stages`` (names shown beside the bar); a no-op when not ``enabled``.

    >>> with StageProgress("demo", ["read", "work"], enabled=False) as bar:
    ...     bar.advance()  # "read" done, "work" shown next
    ...     bar.advance()
    >>> bar.done
    2
    """

    def __init__(self, desc: str, stages: Sequence[str], *, enabled: bool = True) -> None:
        self.stages = list(stages)
        self.done = 0
        self._bar: Any = None
        if enabled and self.stages:
            from tqdm.auto import tqdm

            self._bar = tqdm(total=len(self.stages), desc=desc, unit="stage", file=sys.stderr, leave=True)
            self._bar.set_postfix_str(self.stages[0])

    def advance(self) -> None:
        """Mark the current stage done and show the next one."""
        self.done = min(self.done + 1, len(self.stages))
        if self._bar is not None:
            self._bar.update(1)
            if self.done < len(self.stages):
                self._bar.set_postfix_str(self.stages[self.done])
            else:
                self._bar.set_postfix_str("done")

    def close(self) -> None:
        """Close the bar (left on screen)."""
        if self._bar is not None:
            self._bar.close()
            self._bar = None

    def __enter__(self) -> StageProgress:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()
