"""The latest values by key, up to a limit: the caches a sweep and a diagnosis keep (model specs, settled starts,
residuals), one rule for all three."""
from __future__ import annotations

import threading
from collections import OrderedDict
from typing import Any, Callable, Hashable


class Latest:
    """A thread-safe map that keeps its most recently used entries while their sizes (`size(value)`, 1 each unless
    given) sum to at most `limit`; the least recently used go first."""

    def __init__(self, limit: float, size: Callable[[Any], float] = lambda value: 1):
        self.limit, self.size = limit, size
        self._items: OrderedDict = OrderedDict()
        self._total = 0.0
        self._lock = threading.Lock()

    def get(self, key: Hashable, default: Any = None) -> Any:
        """The value kept under `key` (now the most recently used), or `default`."""
        with self._lock:
            if key not in self._items:
                return default
            self._items.move_to_end(key)
            return self._items[key]

    def put(self, key: Hashable, value: Any) -> None:
        """Keep `value` under `key`, dropping the least recently used beyond the limit."""
        with self._lock:
            if key in self._items:
                self._total -= self.size(self._items.pop(key))
            self._items[key] = value
            self._total += self.size(value)
            while self._total > self.limit and self._items:
                self._total -= self.size(self._items.popitem(last=False)[1])

    def __contains__(self, key: Hashable) -> bool:
        return key in self._items

    def __len__(self) -> int:
        return len(self._items)

    def clear(self) -> None:
        with self._lock:
            self._items.clear()
            self._total = 0.0
