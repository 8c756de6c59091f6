"""Prepared views made ahead of the runs that need them, in a background thread, in the order the runs
will start; a lane waits only for its own run's view. A view found damaged before a run is prepared again
(a new generation beside it, see views.prepare)."""

from __future__ import annotations

import threading
from pathlib import Path

from runner.datasets.views import Direction, PreparedView, Profile, prepare, verify_view
from runner.errors import DatasetError, InfraError, SlamRunError

ViewKey = tuple[str, Direction, Profile]  # (sequence folder, direction, profile)


class ViewPreparer:
    def __init__(self, order: list[ViewKey], cache: Path, frame_format: str = "png", on_ready=None):
        self.cache = Path(cache)
        self.frame_format = frame_format
        self.on_ready = on_ready or (lambda key, view: None)
        self._order = list(dict.fromkeys(order))
        self._views: dict[ViewKey, PreparedView] = {}
        self._errors: dict[ViewKey, BaseException] = {}
        self._cond = threading.Condition()
        self._lock = threading.Lock()  # one preparation at a time (2 cores: the lanes need the rest)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, name="view-preparer", daemon=True)

    def start(self) -> ViewPreparer:
        self._thread.start()
        return self

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=60)

    def _loop(self) -> None:
        for key in self._order:
            if self._stop.is_set():
                return
            self._prepare(key)

    def _prepare(self, key: ViewKey) -> None:
        with self._lock:
            with self._cond:
                if key in self._views or key in self._errors:
                    return
            try:
                view = prepare(Path(key[0]), key[1], key[2], self.cache, frame_format=self.frame_format)
            except Exception as exc:  # noqa: BLE001 - a full disk, an undecodable frame: the runs say it
                with self._cond:
                    self._errors[key] = exc
                    self._cond.notify_all()
                return
        with self._cond:
            self._views[key] = view
            self._cond.notify_all()
        self.on_ready(key, view)

    def get(self, key: ViewKey) -> PreparedView:
        """The view, once prepared (preparing it now if the background thread has not reached it)."""
        with self._cond:
            known = key in self._views or key in self._errors
        if not known and key not in self._order:
            self._prepare(key)
        with self._cond:
            while key not in self._views and key not in self._errors:
                self._cond.wait(0.5)
            if key in self._errors:
                exc = self._errors[key]
                raise exc if isinstance(exc, (SlamRunError, OSError)) else InfraError(str(exc))
            return self._views[key]

    def checked(self, key: ViewKey) -> tuple[PreparedView, str | None]:
        """The view, whole: one found missing or damaged is prepared again first. Returns the view and what
        was wrong with the previous one (None when it was whole)."""
        view = self.get(key)
        problem = verify_view(view.root)
        if problem is None:
            return view, None
        with self._lock:
            with self._cond:
                current = self._views[key]
            if current.root == view.root:  # not rebuilt by another lane meanwhile
                try:
                    current = prepare(Path(key[0]), key[1], key[2], self.cache, frame_format=self.frame_format)
                except DatasetError as exc:
                    raise InfraError(f"{key[0]}: its view is damaged and cannot be prepared again: {exc}") from None
                with self._cond:
                    self._views[key] = current
        return current, problem

    def prepared(self) -> dict[ViewKey, PreparedView]:
        with self._cond:
            return dict(self._views)
