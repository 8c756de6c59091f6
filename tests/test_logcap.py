"""CappedLog.wait_for and Tap: a finished process's output is read while it comes; a reader that stalls is cut off
and writes nothing more (tests/test_docker.py: real containers' streams slowed, ended early, hung)."""

import threading

from slamrun.backends.logcap import CappedLog, Tap


def _reader(log: CappedLog | Tap, release: threading.Event) -> threading.Thread:
    def read() -> None:
        log.write(b"first line\n")
        release.wait()  # a stream that hangs until the test lets it go
        log.write(b"the rest\n")

    t = threading.Thread(target=read, daemon=True)
    t.start()
    return t


def test_a_stream_that_stops_coming_is_cut_off_and_writes_nothing_more(tmp_path):
    log = CappedLog(tmp_path / "log.txt", 2**20)
    tap, release = Tap(log), threading.Event()
    reader = _reader(tap, release)
    assert log.wait_for(reader, stall_s=0.3) is False
    tap.cut()
    release.set()
    reader.join(timeout=5)
    log.cut_short = "the end may be missing"
    log.close()
    assert (tmp_path / "log.txt").read_text() == "first line\n\n[slamrun: the end may be missing]\n"
    assert log.received == len(b"first line\n")


def test_a_stream_read_to_its_end_leaves_no_note(tmp_path):
    log = CappedLog(tmp_path / "log.txt", 2**20)
    release = threading.Event()
    release.set()
    reader = _reader(log, release)
    assert log.wait_for(reader, stall_s=30) is True
    log.close()
    log.close()  # a second close changes nothing
    assert (tmp_path / "log.txt").read_text() == "first line\nthe rest\n"
