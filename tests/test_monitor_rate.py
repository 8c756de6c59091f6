"""The container monitor samples at a fixed rate: the time a stats call takes is not added to each period."""

from __future__ import annotations

from slamrun.backends import docker as docker_backend


class Clock:
    def __init__(self) -> None:
        self.now = 100.0

    def monotonic(self) -> float:
        return self.now


class SlowStats:
    """A running container whose stats call takes `cost_s` (on the fake clock)."""

    def __init__(self, clock: Clock, cost_s: float) -> None:
        self.clock, self.cost_s, self.cpu_ns = clock, cost_s, 0

    def stats(self, stream: bool, one_shot: bool) -> dict:
        self.clock.now += self.cost_s
        self.cpu_ns += 10**8
        return {"cpu_stats": {"cpu_usage": {"total_usage": self.cpu_ns}}, "memory_stats": {"usage": 50 * 2**20}}


class StopAfter:
    """The monitor's stop event: each wait moves the fake clock on; set after `n` waits."""

    def __init__(self, clock: Clock, n: int) -> None:
        self.clock, self.n, self.waits = clock, n, []

    def is_set(self) -> bool:
        return len(self.waits) >= self.n

    def wait(self, seconds: float) -> bool:
        self.waits.append(seconds)
        self.clock.now += seconds
        return self.is_set()


def test_a_slow_stats_call_does_not_stretch_the_sampling_period(monkeypatch):
    clock = Clock()
    monkeypatch.setattr(docker_backend.time, "monotonic", clock.monotonic)
    monitor = docker_backend.ContainerMonitor(SlowStats(clock, 0.3), 0.5, t0=clock.now)
    monitor._stop = StopAfter(clock, 6)
    monitor._loop()
    times = [round(s.t_s, 6) for s in monitor.series.samples]
    assert times == [0.3, 0.8, 1.3, 1.8, 2.3, 2.8], times  # every 0.5 s, each 0.3 s after its start
    assert [round(w, 6) for w in monitor._stop.waits] == [0.2] * 6


def test_a_stats_call_longer_than_the_period_samples_again_at_once_without_a_burst(monkeypatch):
    clock = Clock()
    monkeypatch.setattr(docker_backend.time, "monotonic", clock.monotonic)
    monitor = docker_backend.ContainerMonitor(SlowStats(clock, 1.2), 0.5, t0=clock.now)
    monitor._stop = StopAfter(clock, 4)
    monitor._loop()
    assert [round(w, 6) for w in monitor._stop.waits] == [0.0] * 4  # behind: no sleep, and no catching up in a burst
    assert [round(s.t_s, 6) for s in monitor.series.samples] == [1.2, 2.4, 3.6, 4.8]
