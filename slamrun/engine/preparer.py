"""Prepared views made ahead of the runs that need them, in a background thread, one at a time, in the order
the runs will start; a lane waits only for its own run's view. The first `head` views (one per lane: the
lanes are idle until theirs is ready) are prepared with every core, one after another, so the first lane
starts after one view's preparation rather than all of theirs (and a view whose other direction is ready
links its frames: cache.prepare); the rest with `workers` threads (the lanes need the cores then). A view
found damaged before a run is prepared again (a new generation beside it, see cache.prepare)."""

from __future__ import annotations

import os
import threading
from pathlib import Path

from slamrun.datasets.cache import prepare, verify_view
from slamrun.datasets.perturb import Perturbation
from slamrun.datasets.view import Direction, PreparedView, Profile
from slamrun.errors import DatasetError, InfraError, SlamRunError

ViewKey = tuple[str, Direction, Profile, Perturbation]  # (sequence folder, direction, profile, perturbation)


class ViewPreparer:
    def __init__(
        self,
        order: list[ViewKey],
        cache: Path,
        frame_format: str = "png",
        on_ready=None,
        head: int = 1,
        workers: int = 2,
    ) -> None:
        self.cache = Path(cache)
        self.head = max(1, head)
        self.workers = max(1, workers)
        self.head_workers = max(self.workers, len(os.sched_getaffinity(0)))
        self.frame_format = frame_format
        self.on_ready = on_ready or (lambda key, view: None)
        self._order = list(dict.fromkeys(order))
        self._views: dict[ViewKey, PreparedView] = {}
        self._errors: dict[ViewKey, BaseException] = {}
        self._inflight: set[ViewKey] = set()
        self._reached: set[ViewKey] = set()  # those the background thread has come to
        self._cond = threading.Condition()
        self._lock = threading.Lock()  # one preparation at a time (each uses several cores)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, name="view-preparer", daemon=True)

    def start(self) -> ViewPreparer:
        self._thread.start()
        return self

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=60)

    def _loop(self) -> None:
        for i, key in enumerate(self._order):
            if self._stop.is_set():
                return
            with self._cond:
                self._reached.add(key)
            self._prepare(key, self.head_workers if i < self.head else self.workers)

    def _prepare(self, key: ViewKey, workers: int | None = None) -> None:
        with self._cond:
            while key in self._inflight:  # another thread prepares it: its result serves
                self._cond.wait(0.5)
            if key in self._views or key in self._errors:
                return
            self._inflight.add(key)
        view = None
        try:
            with self._lock:
                view = self._build(key, workers or self.workers)
        except Exception as exc:  # noqa: BLE001 - a full disk, an undecodable frame: the runs say it
            with self._cond:
                self._errors[key] = exc
        finally:
            with self._cond:
                if view is not None:
                    self._views[key] = view
                self._inflight.discard(key)
                self._cond.notify_all()
        if view is not None:
            self.on_ready(key, view)

    def _build(self, key: ViewKey, workers: int) -> PreparedView:
        seq, direction, profile, perturbation = key
        return prepare(Path(seq), direction, profile, self.cache, workers, self.frame_format, perturbation)

    def get(self, key: ViewKey) -> PreparedView:
        """The view, once prepared: the background thread's, or prepared now when it will not come to it. A
        failure is raised; one of the data (DatasetError) stays the view's, any other (the cache deleted under
        the preparation) is raised once and the next request prepares the view anew."""
        while True:
            with self._cond:
                if key in self._views:
                    return self._views[key]
                if key in self._errors:
                    exc = self._errors[key]
                    if not isinstance(exc, DatasetError):
                        del self._errors[key]
                    raise exc if isinstance(exc, (SlamRunError, OSError)) else InfraError(str(exc))
                if key in self._inflight or (key in self._order and key not in self._reached):
                    self._cond.wait(0.5)
                    continue
            self._prepare(key)

    def checked(self, key: ViewKey) -> tuple[PreparedView, str | None]:
        """The view, whole: one found missing or damaged is prepared again first. Returns the view and what
        was wrong with the previous one (None when it was whole)."""
        view = self.get(key)
        problem = verify_view(view.root, view.build_id)
        if problem is None:
            return view, None
        with self._lock:
            with self._cond:
                current = self._views[key]
            if current.root == view.root:  # not rebuilt by another lane meanwhile
                try:
                    current = self._build(key, self.head_workers)
                except DatasetError as exc:
                    raise InfraError(f"{key[0]}: its view is damaged and cannot be prepared again: {exc}") from None
                with self._cond:
                    self._views[key] = current
        return current, problem

    def prepared(self) -> dict[ViewKey, PreparedView]:
        with self._cond:
            return dict(self._views)
